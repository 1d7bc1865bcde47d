"""One module per log format: each sniffs and reads its format and registers its LogFormat as it is imported (`formats/source.py` imports every module here). A new format is one more module."""
