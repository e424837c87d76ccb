"""Sweeps (issue 28): seeded random relative tasks x robots x solvers as Dask tasks, rows in Parquet, the report."""
