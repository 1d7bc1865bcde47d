"""Device-agnostic CiA 301: COB-ID classification, per-service decoding, tables."""
