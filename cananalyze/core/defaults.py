"""Defaults every door shares (the CLI's flags, `Options`, `load()`, the SDO tracker), one place each."""

SDO_TIMEOUT = 1.0  # seconds: an SDO request unanswered this long is a timeout
TASK_TIMEOUT = 3600.0  # seconds: a fleet log not done by then is given up (no healthy one is)
COMPACT_TARGET_SIZE = (
    128 << 20
)  # bytes: `fleet compact`'s file size, what query engines ask (64-128 MB)
