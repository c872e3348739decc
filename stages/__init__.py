"""stages: a declarative, cached, parallel pipeline engine for geometry processing.

``python -m stages run pipeline.yaml`` builds a task graph from YAML, runs the cache misses under
dask.distributed and stores results content-addressed in zarr under ``cache/``.
"""
__version__ = "0.1.0"
