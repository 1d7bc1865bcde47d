"""The format modules the facade imports (each registers itself in registry.FORMATS)."""

FORMAT_MODULES = ["candump"]
