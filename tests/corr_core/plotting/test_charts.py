"""corr_core.plotting: every figure function writes a non-trivial image from small arrays."""
import numpy as np
import pytest

from corr_core import plotting
from corr_core.correspondence.measures import correspondence_matrix, frequency_matrix


def test_correspondence_plots_are_written(tmp_path):
    F = frequency_matrix([correspondence_matrix(np.array([0, 2, 1]), 3), correspondence_matrix(np.arange(3), 3)])
    names = ["Left Toe", "Right Toe", "Vertex"]
    plotting.plot_frequency_matrix(F, names, names, "test", tmp_path / "f.png")
    thr = np.linspace(0, 0.25, 51)
    plotting.plot_error_curves({"a": (thr, np.linspace(0, 1, 51)), "b": (thr, np.linspace(0.5, 1, 51))},
                               tmp_path / "c.png")
    plotting.plot_accuracy_bars({"descriptor": 0.5, "mrf": 0.75}, tmp_path / "a.png")
    for name in ("f.png", "c.png", "a.png"):
        assert (tmp_path / name).stat().st_size > 1000


@pytest.fixture
def collection():
    rng = np.random.default_rng(0)
    names = [f"{i:03d}" for i in range(12)]
    views = {n: rng.integers(0, 256, size=(8, 30, 30), dtype=np.uint8) for n in names}
    features = {n: rng.random((8, 15 * 15 * 36)).astype(np.float32) for n in names}  # Dollar HoG layout
    return names, views, features


def test_alignment_plots_are_written(tmp_path, collection):
    names, views, features = collection
    labels = {n: i % 8 for i, n in enumerate(names)}
    plotting.plot_hog_drawings(views, features, names[:3], [0, 4], tmp_path / "hog.png")
    plotting.plot_pair_cost_heatmap(np.arange(8.0), "000", "001", tmp_path / "dij.png")
    plotting.plot_view_pairs(views["000"], views["001"], features["000"], features["001"], "000", "001",
                             tmp_path / "pairs.png")
    plotting.plot_aligned_grid(views, labels, names[:9], tmp_path / "grid.png")
    plotting.plot_contact_sheet(views, names, np.array([labels[n] for n in names]), tmp_path / "sheet.png",
                                columns=5)
    for name in ("hog.png", "dij.png", "pairs.png", "grid.png", "sheet.png"):
        assert (tmp_path / name).stat().st_size > 1000


def test_a_tightly_laid_out_figure_is_drawn_once_when_saved(tmp_path, monkeypatch):
    """``save_figure`` lays out and writes with one drawing: matplotlib draws a figure twice when a layout
    engine is left on it (``tight_layout`` leaves one), a third of a frequency matrix's time."""
    from matplotlib.figure import Figure

    from corr_core.plotting.charts import save_figure

    draws = []
    real_draw = Figure.draw
    monkeypatch.setattr(Figure, "draw", lambda self, renderer: (draws.append(1), real_draw(self, renderer))[1])
    plt = plotting.pyplot()
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot([0, 1], [1, 0])
    ax.set_title("a title")
    save_figure(fig, tmp_path / "one.png", 80)
    assert len(draws) == 1 and (tmp_path / "one.png").stat().st_size > 1000
    draws.clear()
    F = frequency_matrix([correspondence_matrix(np.array([0, 2, 1]), 3)])
    plotting.plot_frequency_matrix(F, ["a", "b", "c"], ["a", "b", "c"], "t", tmp_path / "f.png")
    assert len(draws) == 1


def _pixels(path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGBA"), dtype=np.int16)


def _whole_drawing(freq, names, title, path) -> None:
    """The frequency figure drawn whole by matplotlib (``savefig``), as ``plot_frequency_matrix`` drew it before
    figures were shared."""
    from corr_core.plotting import charts

    fig, ax, image = charts._frequency_figure(names, names, max(1.0, float(freq.max())))
    image.set_data(freq)
    charts._frequency_cells(ax, freq)
    ax.set_title(title)
    charts.save_figure(fig, path, charts.FREQUENCY_DPI)


def test_frequency_matrices_drawn_together_are_each_drawn_as_alone(tmp_path, monkeypatch):
    """A figure shared by matrices with the same names is drawn whole once; each image then has the pixels of
    its matrix's figure drawn whole by matplotlib: its own cells, numbers and title, nothing of the one before."""
    from matplotlib.figure import Figure

    names, sparse = [f"landmark {i}" for i in range(6)], ["a", "b"]
    rng = np.random.default_rng(0)
    mats = [np.where(rng.random((6, 6)) > 0.6, rng.random((6, 6)), 0.0) for _ in range(3)]
    entries = [(m, names, f"method {i}: {i} meshes", tmp_path / f"m{i}.png") for i, m in enumerate(mats)]
    entries.append((np.eye(2), sparse, "method 0: 0 meshes", tmp_path / "s.png"))
    draws = []
    real_draw = Figure.draw
    monkeypatch.setattr(Figure, "draw", lambda self, renderer: (draws.append(1), real_draw(self, renderer))[1])
    plotting.plot_frequency_matrices([(m, rows, rows, title, path) for m, rows, title, path in entries])
    assert len(draws) == 2                                     # one whole drawing per set of names
    monkeypatch.setattr(Figure, "draw", real_draw)
    for freq, rows, title, path in entries:
        _whole_drawing(freq, rows, title, tmp_path / "whole.png")
        assert np.array_equal(_pixels(path), _pixels(tmp_path / "whole.png")), path.name
    assert not np.array_equal(_pixels(tmp_path / "m1.png"), _pixels(tmp_path / "m0.png"))
