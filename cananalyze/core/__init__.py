"""The lowest layer: FrameBatch, the decoded-batch record model and findings as columns, errors, the version, atomic files, and column builders (text, hex, JSON, Arrow) every layer above shares."""
