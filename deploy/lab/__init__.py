"""The lab: running experiment grids (the engine's executors: a local process pool or a Dask cluster)."""
