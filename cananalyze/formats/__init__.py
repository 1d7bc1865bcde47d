"""Log formats: one module per format that sniffs and reads it (and writes it, where we write that format), registered once in `registry`; the facade `source.open_log`; live python-can buses."""
