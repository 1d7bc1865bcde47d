"""Device profiles of the CiA 4xx family as data: CiA 402 drives, CiA 401 generic I/O.

A node whose device type (0x1000) names one of these profiles gets its object names,
units and default PDOs without an EDS (`generic.generic_profile`); the tables here are
the one place each of these facts is written.
"""
