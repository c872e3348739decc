"""Joint azimuthal alignment of a shape collection (problem 1).

- ``render`` / ``views``: grayscale views of a mesh / the course's pre-rendered views; ``hog``: HoG features;
- ``pair_costs``: C_ij(theta) between all shapes, mirror, shifts, auto sigma, nearest shapes;
- ``circulant``: the MRF's pairwise operator ``CirculantPairwise`` (dense or kNN-sparse);
- ``sync``: spectral synchronization and the projected power method;
- ``solvers``: the solver dispatch (``solve_alignment``, ``solve_labels``), sigma choice, kNN graph, unary terms;
- ``continuous``: continuous azimuths from the band-limited C_ij (interpolation, refinement of the labels);
- ``symmetry``: rotational symmetry orders from C_ii, alignment that keeps symmetric shapes from steering others;
- ``azimuth``: label conventions, agreement up to one offset, aligned views and vertices, declared up axis;
- ``measures``: seed stability, equivariance, solver quality, ground-truth (labels, continuous error, modulo
  symmetry) and mode agreement.
"""
