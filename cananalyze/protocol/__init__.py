"""Device-agnostic CiA 301: one module per service (nmt, sync, time, emcy, pdo, sdo, lss),
COB-ID classification, data types, communication objects."""
