"""Log readers: one module per format, each yielding FrameBatch columns."""
