"""The package version: one place, read by pyproject (setuptools' attr:), the CLI and every file we write."""

__version__ = "0.1.0"
