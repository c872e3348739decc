"""All figures of the project (matplotlib, Agg backend): alignment figures and correspondence figures.

Every function takes numpy arrays (and names), writes one image file to ``path`` (PNG or PDF by extension)
and returns nothing. View stacks are (V, S, S) uint8 grayscale (255 = white background); features (V, D).
"""
from __future__ import annotations

import os

import numpy as np

from corr_core.alignment.azimuth import aligned_view_index
from corr_core.alignment.hog import draw_hog

__all__ = ["pyplot", "plot_hog_drawings", "plot_pair_cost_heatmap", "plot_view_pairs", "plot_aligned_grid",
           "plot_contact_sheet", "plot_frequency_matrix", "plot_frequency_matrices",
           "plot_error_curves", "plot_accuracy_bars"]


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | os.PathLike, dpi: int, *, tight_rect: tuple | None = (0, 0, 1, 1),
                close: bool = True) -> None:
    """Lay ``fig`` out tightly within ``tight_rect`` (figure fractions; None: keep its layout) and write it to
    ``path`` at ``dpi``, drawing it once.

    ``Figure.tight_layout`` leaves a placeholder layout engine behind, and with any engine set ``savefig`` draws
    the whole figure once more before the real drawing (every text laid out again: a third of a frequency
    matrix's time); the layout is final here, so the engine is removed first. The pixels are the same.
    """
    if tight_rect is not None:
        fig.tight_layout(rect=tight_rect)
    fig.set_layout_engine(None)
    fig.savefig(path, dpi=dpi)
    if close:
        pyplot().close(fig)


def _axes_off(ax) -> None:
    """No frame, ticks or tick labels on ``ax`` (a picture): ``axis("off")``, and its axes hidden too, so that
    laying the figure out does not measure the tick labels it will not draw (same pixels, a fifth faster)."""
    ax.axis("off")
    ax.xaxis.set_visible(False)
    ax.yaxis.set_visible(False)


# ------------------------------------------------------------------------------------------------ alignment

def _hog_cells(H: np.ndarray):
    """(h, w, 36) cells of a flattened Dollar HoG vector, or None for other layouts."""
    side = int(round(np.sqrt(H.size / 36)))
    return H.reshape(side, side, 36) if side * side * 36 == H.size else None


def plot_hog_drawings(views: dict, features: dict, shapes: list[str], view_ids: list[int], path) -> None:
    """Each shape's chosen views next to their HoG glyph drawings. views {name: (V,S,S)}, features {name: (V,D)}."""
    plt = pyplot()
    fig, axes = plt.subplots(len(shapes), 2 * len(view_ids), figsize=(4.0 * len(view_ids), 2.1 * len(shapes)))
    axes = np.atleast_2d(axes)
    for r, n in enumerate(shapes):
        V = len(views[n])
        for c, k in enumerate(view_ids):
            axes[r, 2 * c].imshow(views[n][k % V], cmap="gray", vmin=0, vmax=255)
            axes[r, 2 * c].set_title(f"{n} view {k % V}", fontsize=8)
            cells = _hog_cells(np.asarray(features[n][k % V]))
            if cells is not None:
                axes[r, 2 * c + 1].imshow(draw_hog(cells), cmap="gray")
                axes[r, 2 * c + 1].set_title("HoG", fontsize=8)
    for ax in axes.ravel():
        _axes_off(ax)
    save_figure(fig, path, 90)


def plot_pair_cost_heatmap(C_ab: np.ndarray, a: str, b: str, path) -> None:
    """Heat map of D_ij(t1, t2) = C_ij(t2 - t1) for the pair costs C_ab: (V,) of shapes a, b."""
    plt = pyplot()
    V = len(C_ab)
    t = np.arange(V)
    fig, ax = plt.subplots(figsize=(5, 4.3))
    im = ax.imshow(np.asarray(C_ab)[(t[None, :] - t[:, None]) % V], cmap="viridis")
    ax.set_xlabel(f"label t2 of {b}")
    ax.set_ylabel(f"label t1 of {a}")
    ax.set_title(f"D_ij(t1,t2) = C_ij(t2-t1), {a} vs {b}")
    fig.colorbar(im, ax=ax)
    save_figure(fig, path, 90)


def plot_view_pairs(views_a: np.ndarray, views_b: np.ndarray, features_a: np.ndarray, features_b: np.ndarray,
                    a: str, b: str, path) -> None:
    """The most and the least similar view pair of shapes a and b (squared HoG distance per view)."""
    plt = pyplot()
    Fa, Fb = np.asarray(features_a, np.float64), np.asarray(features_b, np.float64)
    d = (Fa ** 2).sum(1)[:, None] + (Fb ** 2).sum(1)[None, :] - 2 * Fa @ Fb.T
    best, worst = np.unravel_index(np.argmin(d), d.shape), np.unravel_index(np.argmax(d), d.shape)
    fig, axes = plt.subplots(2, 2, figsize=(5, 5))
    for r, (pair, title) in enumerate(((best, "best"), (worst, "worst"))):
        for c, (shape, stack, k) in enumerate(((a, views_a, pair[0]), (b, views_b, pair[1]))):
            axes[r, c].imshow(stack[k], cmap="gray", vmin=0, vmax=255)
            axes[r, c].set_title(f"{title}: {shape} view {k}" + (f" (d={d[pair]:.1f})" if c else ""), fontsize=8)
            _axes_off(axes[r, c])
    save_figure(fig, path, 90)


def plot_aligned_grid(views: dict, labels: dict, shapes: list[str], path) -> None:
    """3x3 grid of aligned shapes: each shape's view at the common frame's view 0. labels {name: int}."""
    plt = pyplot()
    fig, axes = plt.subplots(3, 3, figsize=(6, 6))
    for ax, n in zip(axes.ravel(), shapes):
        ax.imshow(views[n][aligned_view_index(int(labels[n]), len(views[n]))], cmap="gray", vmin=0, vmax=255)
        ax.set_title(f"{n}: label {int(labels[n])}", fontsize=8)
    for ax in axes.ravel():
        _axes_off(ax)
    fig.suptitle("aligned shapes (common view 0)")
    save_figure(fig, path, 90)


def plot_contact_sheet(views: dict, names: list[str], labels: np.ndarray, path, *, columns: int = 10) -> None:
    """All shapes' aligned view 0 in one image (to check an alignment by eye), ``columns`` per row."""
    plt = pyplot()
    rows = int(np.ceil(len(names) / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(1.2 * columns, 1.3 * rows), squeeze=False)
    for ax in axes.ravel():
        _axes_off(ax)
    for ax, n, l in zip(axes.ravel(), names, labels):
        ax.imshow(views[n][aligned_view_index(int(l), len(views[n]))], cmap="gray", vmin=0, vmax=255)
        ax.set_title(n, fontsize=9)
    save_figure(fig, path, 80)


# ------------------------------------------------------------------------------------------- correspondence

def plot_frequency_matrix(freq: np.ndarray, names_rows, names_cols, title: str, path) -> None:
    """Heat map of a (n,L) frequency matrix with names on both axes."""
    plot_frequency_matrices([(freq, names_rows, names_cols, title, path)])


def plot_frequency_matrices(matrices) -> None:
    """Heat maps of several frequency matrices, one image file each, drawn as ``plot_frequency_matrix`` draws one.

    Matrices with the same names (and colour scale) share one figure: it is built, laid out (for the longest of
    their titles, so every title fits and the matrices line up from one image to the next) and drawn once without
    its matrix; each matrix then only draws its cells, their numbers, the frame and its title over that drawing
    (the pixels are those of a whole drawing). ``corr.evaluate``'s 8 figures of a 3-pose run: 5.57 -> 2.31 s
    (cProfile, session 29).

    Args: matrices: [(freq (n,L) float, names_rows (n,) str, names_cols (L,) str, title str, path)]; a path not
        ending in .png is written by matplotlib (e.g. PDF), the figure drawn whole.
    """
    plt = pyplot()
    groups: dict[tuple, list] = {}
    for freq, names_rows, names_cols, title, path in matrices:
        freq = np.asarray(freq, dtype=float)
        vmax = max(1.0, float(freq.max()))
        groups.setdefault((tuple(names_rows), tuple(names_cols), vmax), []).append((freq, title, path))
    for (names_rows, names_cols, vmax), entries in groups.items():
        fig, ax, image = _frequency_figure(names_rows, names_cols, vmax)
        ax.set_title(max((title for _, title, _ in entries), key=len))
        fig.tight_layout(rect=(0, 0, 1, 1))
        fig.set_layout_engine(None)
        names_drawing = _drawing_without(fig, [image, *ax.spines.values(), ax.title])  # drawn over it, in order
        for freq, title, path in entries:
            image.set_data(freq)
            cells = _frequency_cells(ax, freq)
            ax.set_title(title)
            if str(path).lower().endswith(".png"):
                fig.canvas.restore_region(names_drawing)
                for artist in [image, *ax.spines.values(), *cells, ax.title]:
                    ax.draw_artist(artist)
                _write_canvas_png(fig, path)
            else:
                fig.savefig(path, dpi=FREQUENCY_DPI)
            for cell in cells:
                cell.remove()
        plt.close(fig)


FREQUENCY_DPI = 130


def _frequency_figure(names_rows, names_cols, vmax: float):
    """An empty frequency-matrix figure for these names, colour scale 0 to vmax: (figure, axes, image), the colour
    bar beside it, at ``FREQUENCY_DPI``."""
    plt = pyplot()
    n, L = len(names_rows), len(names_cols)
    fig, ax = plt.subplots(figsize=(2.0 + 0.38 * L, 1.5 + 0.34 * n), dpi=FREQUENCY_DPI)
    image = ax.imshow(np.zeros((n, L)), cmap="viridis", vmin=0.0, vmax=vmax, aspect="equal")
    ax.set_xticks(range(L), labels=list(names_cols), rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(n), labels=list(names_rows), fontsize=8)
    ax.set_xlabel("test landmark (label)")
    ax.set_ylabel("template landmark")
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04, label="fraction of test meshes")
    return fig, ax, image


def _frequency_cells(ax, freq: np.ndarray) -> list:
    """Each non-zero frequency of freq (n,L) written in its cell. Returns the text artists (removed before the
    next matrix)."""
    return [ax.text(a, i, f"{freq[i, a]:.2f}".lstrip("0"), ha="center", va="center", fontsize=6, in_layout=False,
                    color="black" if freq[i, a] > 0.6 else "white")
            for i, a in zip(*np.nonzero(freq))]


def _drawing_without(fig, artists: list):
    """The Agg canvas's drawing of ``fig`` with ``artists`` hidden (``canvas.copy_from_bbox`` of the whole figure),
    to draw them over again and again."""
    for artist in artists:
        artist.set_visible(False)
    fig.canvas.draw()
    for artist in artists:
        artist.set_visible(True)
    return fig.canvas.copy_from_bbox(fig.bbox)


def _write_canvas_png(fig, path) -> None:
    """Write the Agg canvas of ``fig`` as drawn (RGBA) to the PNG file ``path``, with the figure's dpi."""
    from PIL import Image

    width, height = fig.canvas.get_width_height()
    Image.frombuffer("RGBA", (width, height), fig.canvas.buffer_rgba(), "raw", "RGBA", 0, 1).save(
        path, format="png", dpi=(fig.dpi, fig.dpi))


def plot_error_curves(curves: dict, path, title: str = "Geodesic error (Kim et al. 2011)") -> None:
    """Cumulative error curves. curves: {label: (thresholds (T,), fractions (T,))}."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4.2))
    colors = plt.get_cmap("tab10" if len(curves) <= 10 else "tab20")
    for c, (label, (thr, frac)) in enumerate(curves.items()):
        ax.plot(thr, 100 * np.asarray(frac), label=label, lw=1.8, color=colors(c % colors.N),
                ls="-" if c < 10 else "--")
    ax.set_xlabel("geodesic error / sqrt(area)")
    ax.set_ylabel("% correspondences")
    ax.set_ylim(0, 100)
    ax.set_xlim(0, max(float(np.max(t)) for t, _ in curves.values()))
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title)
    save_figure(fig, path, 130)


def plot_accuracy_bars(accuracy: dict[str, float], path) -> None:
    """Bar chart of landmark accuracy per method {method: accuracy in [0, 1]}."""
    plt = pyplot()
    names = list(accuracy)
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.bar(names, [accuracy[n] for n in names], color="#4477aa")
    for i, n in enumerate(names):
        ax.text(i, accuracy[n] + 0.01, f"{accuracy[n]:.3f}", ha="center", fontsize=8)
    ax.set_ylim(0, 1.08)
    ax.set_ylabel("accuracy")
    ax.set_title("landmark accuracy per method")
    plt.setp(ax.get_xticklabels(), rotation=20, ha="right")
    save_figure(fig, path, 110)
