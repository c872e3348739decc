"""Landmark transfer through a dense map and the dense-map file: ids carried over, every bad id named."""
from __future__ import annotations

import numpy as np
import pytest

from corr_core.correspondence.dense import format_dense_map, read_dense_map, transfer_landmarks


def test_a_landmark_without_an_image_is_an_error_naming_its_vertex():
    """-1 in a map: a template vertex off the template's kept component; a landmark there has no target vertex
    and must not come back as -1 (which numpy would read as the target's last vertex)."""
    p2p = np.array([4, -1, 2, 0, -1])
    np.testing.assert_array_equal(transfer_landmarks(p2p, [3, 0, 2]), [0, 4, 2])
    with pytest.raises(ValueError, match=r"template landmarks at vertices \[1, 4\] have no image"):
        transfer_landmarks(p2p, [0, 1, 4])


def test_dense_map_file_round_trips_and_names_the_bad_line(tmp_path):
    vm = np.array([3, 0, -1, 2])
    path = tmp_path / "map.txt"
    path.write_text(format_dense_map(vm, header=("template: t.obj", "target: s.obj")))
    np.testing.assert_array_equal(read_dense_map(path, n_template=4, n_target=4), vm)
    np.testing.assert_array_equal(np.loadtxt(path, dtype=np.int64), vm)       # plain numpy reads it too
    with pytest.raises(ValueError, match=r"map\.txt:3: target vertex id 3 is not -1 or a vertex id 0\.\.2"):
        read_dense_map(path, n_target=3)                          # line 3: the first id, after 2 header lines
    with pytest.raises(ValueError, match="holds 4 ids, one per template vertex is 5"):
        read_dense_map(path, n_template=5)
