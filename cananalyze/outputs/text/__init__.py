"""The `decode` text output: frame lines, record lines, signal lines."""
