"""The event log: rare traffic and records of a batch as events, and their texts."""
