"""Live decode served to Foxglove over its WebSocket protocol (foxglove-sdk)."""
