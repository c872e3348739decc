"""Triangle-mesh geometry: plain functions of V: (n,3) float, F: (m,3) int.

- ``mesh_io``: reading/writing OBJ, OFF, PLY without reordering vertices; normalization;
- ``checks``: is a mesh fit for intrinsic correspondence; ``repair``: repairs that keep vertex ids;
- ``primitives``: areas, normals, centroid, edges, components, rotations about y (one formula each);
- ``laplacian``: cotan Laplace-Beltrami operators and eigenpairs;
- ``geodesic``: ``GeodesicSolver`` (heat method) and landmark geodesics;
- ``sampling``: farthest-point sampling; ``midedge``: mid-edge conformal flattening.
"""
