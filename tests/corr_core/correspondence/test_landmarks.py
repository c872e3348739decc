"""Landmark files: named and bare ids, 1-based only when declared, errors naming file and line; writing them back;
subset positions."""
import warnings

import numpy as np
import pytest

from corr_core.correspondence.landmarks import format_landmarks, read_landmarks, subset_positions, write_landmarks


def test_read_landmarks_named_and_bare(tmp_path):
    p = tmp_path / "lm.txt"
    p.write_text("361,Left Toe\n368,Right Toe\n12464,Vertex")  # no trailing newline
    ids, names = read_landmarks(p, 12498)
    np.testing.assert_array_equal(ids, [361, 368, 12464])
    assert names == ["Left Toe", "Right Toe", "Vertex"]
    q = tmp_path / "bare.txt"
    q.write_text("5\n0\n9\n")
    ids, names = read_landmarks(q, 10)
    np.testing.assert_array_equal(ids, [5, 0, 9])
    assert names == ["5", "0", "9"]


def test_read_landmarks_is_one_based_only_when_declared(tmp_path):
    p = tmp_path / "one_based.txt"
    p.write_text("# 1-based\n10\n3\n1\n")
    ids, _ = read_landmarks(p, 10)              # the header says so
    np.testing.assert_array_equal(ids, [9, 2, 0])
    q = tmp_path / "undeclared.txt"
    q.write_text("10\n3\n1\n")
    with pytest.warns(UserWarning, match="1-based"):
        ids, _ = read_landmarks(q, 10, one_based="auto")   # the parameter asks for the guess
    np.testing.assert_array_equal(ids, [9, 2, 0])
    np.testing.assert_array_equal(read_landmarks(q, 10, one_based=True)[0], [9, 2, 0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ids, _ = read_landmarks(q)  # no vertex count: ids taken as they are
    np.testing.assert_array_equal(ids, [10, 3, 1])
    zero = tmp_path / "zero.txt"
    zero.write_text("# one-based\n4\n0\n")
    with pytest.raises(ValueError, match=r"zero.txt:3: vertex id 0 in a 1-based file"):
        read_landmarks(zero, 10)


def test_one_typo_id_equal_to_the_vertex_count_is_an_error_not_a_shift(tmp_path):
    """A 0-based file with one id == n (a typo) is an error, not read as 1-based with every landmark shifted by
    one and only a warning."""
    p = tmp_path / "mesh001.txt"
    p.write_text("5,Head\n3,Left Hand\n10,Right Hand\n7,Left Toe\n")
    with pytest.raises(ValueError, match=r"mesh001.txt:3: vertex id 10 is out of range for a mesh of 10 vertices "
                                         r"\(ids are 0-based, 0..9; if the whole file is 1-based, put a line "
                                         r"'# 1-based'"):
        read_landmarks(p, 10)


def test_duplicate_landmark_names_are_named_with_their_lines(tmp_path):
    """A name listed twice is an error naming its lines, not a missing name later."""
    p = tmp_path / "lm.txt"
    p.write_text("1,Head\n2,Left Hand\n3,Head\n")
    with pytest.raises(ValueError, match=r"lm.txt:3: landmark name 'Head' is listed twice \(lines 1 and 3\)"):
        read_landmarks(p, 10)


def test_read_landmarks_errors_name_file_and_line(tmp_path):
    p = tmp_path / "bad.txt"
    p.write_text("1,A\n0,B\n12,C\n")
    with pytest.raises(ValueError, match=r"bad.txt:3: vertex id 12 is out of range"):
        read_landmarks(p, 10)
    q = tmp_path / "mixed.txt"
    q.write_text("0\n10\n")
    with pytest.raises(ValueError, match=r"mixed.txt:2"):
        read_landmarks(q, 10)
    with pytest.raises(ValueError, match=r"mixed.txt:2: vertex id 10 is out of range"):
        read_landmarks(q, 10, one_based="auto")   # 0 and n: not 1-based, so n is out of range
    r = tmp_path / "junk.txt"
    r.write_text("3\nhello\n")
    with pytest.raises(ValueError, match=r"junk.txt:2"):
        read_landmarks(r)


def test_subset_positions_and_missing_ids_named():
    np.testing.assert_array_equal(subset_positions(np.array([7, 3, 9, 1]), np.array([9, 7])), [2, 0])
    with pytest.raises(ValueError, match=r"sparse.txt: sparse landmark vertices \[5\] are not in all.txt"):
        subset_positions(np.array([7, 3]), np.array([3, 5]), "sparse.txt", "all.txt")


def test_write_landmarks_round_trips_through_read_landmarks(tmp_path):
    ids, names = np.array([361, 0, 12464], dtype=np.int64), ["Left Toe", "Right Toe", "Vertex"]
    assert format_landmarks(ids, names) == "361,Left Toe\n0,Right Toe\n12464,Vertex\n"
    path = tmp_path / "sub" / "lm.txt"  # the folder is created
    write_landmarks(path, ids, names)
    back_ids, back_names = read_landmarks(path, 12498)
    np.testing.assert_array_equal(back_ids, ids)
    assert back_names == names
    assert format_landmarks([], []) == ""


def test_format_landmarks_rejects_what_read_landmarks_cannot_read_back():
    with pytest.raises(ValueError, match="2 vertex ids but 1 names"):
        format_landmarks([1, 2], ["A"])
    with pytest.raises(ValueError, match=r"'Left, Toe'"):
        format_landmarks([1], ["Left, Toe"])
    with pytest.raises(ValueError, match="negative vertex id -1"):
        format_landmarks([-1], ["A"])
