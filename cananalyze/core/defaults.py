"""Defaults every door shares (the CLI's flags, `Options`, `load()`, the SDO tracker), one place each."""

SDO_TIMEOUT = 1.0  # seconds: an SDO request unanswered this long is a timeout
