"""Joint azimuthal alignment of a shape collection (problem 1).

- ``render`` / ``views``: grayscale views of a mesh / the course's pre-rendered views; ``hog``: HoG features;
- ``pair_costs``: C_ij(theta) between all shapes, mirror, shifts, auto sigma, nearest shapes;
- ``circulant``: the MRF's pairwise operator ``CirculantPairwise`` (dense or kNN-sparse);
- ``sync``: spectral synchronization and the projected power method;
- ``solvers``: the solver dispatch (``solve_alignment``, ``solve_labels``), sigma choice, kNN graph, unary terms;
- ``azimuth``: label conventions, agreement up to one offset, aligned views and vertices;
- ``measures``: seed stability, equivariance, solver quality, ground-truth and mode agreement.
"""
