"""The JSONL output: one JSON object per frame and record."""
