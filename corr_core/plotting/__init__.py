"""All figures of the project, in one home: ``charts`` (matplotlib charts and image grids: alignment figures,
frequency matrices, error curves) and ``meshes`` (meshes rendered with the project's own ray caster, with
per-vertex colours and labelled points). The chart functions are re-exported here
(``from corr_core.plotting import plot_aligned_grid``)."""
from corr_core.plotting import meshes  # noqa: F401
from corr_core.plotting.charts import *  # noqa: F401,F403
from corr_core.plotting.charts import __all__ as _charts

__all__ = [*_charts, "meshes"]
