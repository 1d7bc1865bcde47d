"""Device knowledge: profiles from EDS/DCF (canopen) and TOML sidecars, built-ins discovered in decoders/, DBC loading (cantools), and the CiA 401/402 tables and their words."""
