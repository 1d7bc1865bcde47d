"""Fleets: many logs decoded in parallel on Dask into one partitioned Parquet dataset.

`orchestrate.run_fleet` (the cluster, one task per log), `task.process` (one log on a
worker: the export pipeline, then the commit), `layout` (paths, staging, atomic
commits), `schema` (the dataset's fixed table schemas), `inputs` (files, folders,
globs), `query` (DuckDB views over the dataset), `logsindex` (the `logs` rows a
rerun decides from, cached in `_index/`). docs/fleet.md.
"""
