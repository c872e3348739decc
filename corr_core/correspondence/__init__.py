"""Landmark (and dense) correspondence from a template mesh to test meshes (problem 2).

- ``landmarks``: landmark files; ``mesh_features``: the per-mesh inputs of the matchers;
- ``descriptors``: HKS, WKS and descriptor distances; ``matching``: one-to-one assignment;
- ``landmark_mrf``: the geodesic-consistency MRF; ``orientation``: the chirality test against left/right swaps;
- ``mobius``: Möbius maps and Möbius voting; ``matchers``: the composed matchers the pipelines run;
- ``measures``: accuracy, frequency matrices, per-method reports, geodesic errors; ``dense``: dense maps.
"""
