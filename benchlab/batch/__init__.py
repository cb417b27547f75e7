"""`benchlab batch`: many runs, one task each (or one per group of runs), on dask.distributed; one results table.

adapter: the library calls (identify, diagnose, wear); tasks: what one task computes on a worker;
plan: run globs to tasks; cluster: the local cluster or a scheduler; table: rows to Parquet/CSV;
trends: parameters against run index or time.
"""
