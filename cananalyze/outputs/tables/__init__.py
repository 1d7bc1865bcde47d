"""Parquet and CSV tables, written batch by batch."""
