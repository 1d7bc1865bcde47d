"""Output writers: text, JSONL, Parquet, MCAP, rerun, JUnit."""
