"""MCAP for Foxglove: topics, schemas and the chunked writer."""
