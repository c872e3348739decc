"""corr_core: algorithms for shape-collection alignment and shape correspondence.

Plain functions on numpy arrays, one concept per module, no knowledge of the pipeline engine.
"""
__version__ = "0.1.0"
