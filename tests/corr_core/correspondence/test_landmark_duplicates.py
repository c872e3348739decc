"""A landmark file listing the same vertex twice is an error naming the file and both lines."""
import pytest

from corr_core.correspondence.landmarks import read_landmarks


@pytest.mark.parametrize("text, line, first", [("361,Left Toe\n368,Right Toe\n361,Nose\n", 3, 1),
                                               ("# ids\n5\n\n7\n5\n", 5, 2)])
def test_duplicate_landmark_id_is_an_error(tmp_path, text, line, first):
    path = tmp_path / "landmark_vids.txt"
    path.write_text(text)
    with pytest.raises(ValueError, match=rf"landmark_vids\.txt:{line}: vertex id \d+ is listed twice "
                                         rf"\(first on line {first}\)"):
        read_landmarks(path, n_vertices=1000)


def test_distinct_ids_and_names_are_fine(tmp_path):
    path = tmp_path / "landmark_vids.txt"
    path.write_text("1,A\n2,B\n3,C\n")
    ids, names = read_landmarks(path)
    assert ids.tolist() == [1, 2, 3] and names == ["A", "B", "C"]


def test_duplicate_landmark_name_is_an_error_naming_it_and_its_lines(tmp_path):
    """A repeated name is an error naming it and its lines, not a "lacks the landmarks [...]" of another file
    later."""
    path = tmp_path / "landmark_vids.txt"
    path.write_text("1,A\n2,B\n3,A\n")
    with pytest.raises(ValueError, match=r"landmark_vids\.txt:3: landmark name 'A' is listed twice \(lines 1 and 3\)"):
        read_landmarks(path)
