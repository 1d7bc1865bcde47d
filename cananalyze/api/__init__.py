"""The public Python API above the pipeline: load() and check(), the Capture with its assert_* helpers, and the pytest assertions."""
