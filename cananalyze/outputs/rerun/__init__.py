"""Rerun recordings and viewers."""
