"""Entry points: one folder, many folders (Dask), the resume store."""
