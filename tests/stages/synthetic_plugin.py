"""Synthetic stage functions for engine tests and benchmarks (no geometry involved): a test-only plugin.

Never registered in production: tests and ``bench/engine.py`` load it through the development hook
``STAGES_PLUGINS=tests.stages.synthetic_plugin`` (see stages/registry.py). They mimic the shape of the alignment pipeline: per-item feature extraction from a text file, per-pair
comparison of features, and a collection-level reduction whose parameter can be swept.
"""
from __future__ import annotations

import hashlib
import os
import time

import numpy as np

from stages.registry import Plugin, register
from stages.skipped import Skipped

PLUGIN = Plugin(name="synthetic", packages=(__name__,))


def _seed_from_text(text: str) -> int:
    return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=4).digest(), "little")


@register("synthetic.features", fanout="item")
def features(path, *, dim: int = 64, work: int = 0, fail_on: str = "") -> np.ndarray:
    """Read a text file and return a (8, dim) float32 feature; ``work`` adds that many ms of compute."""
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    if fail_on and fail_on in text:
        raise ValueError(f"{path}: contains the marker '{fail_on}'")
    rng = np.random.default_rng(_seed_from_text(text))
    F = rng.standard_normal((8, dim)).astype(np.float32)
    _spin(work)
    return F


@register("synthetic.scale", fanout="item")
def scale(features, *, factor: float = 1.0) -> np.ndarray:
    """Multiply a per-item feature by ``factor``."""
    return np.asarray(features) * np.float32(factor)


def _mirror_distances(block: np.ndarray) -> np.ndarray:
    return np.swapaxes(block, 0, 1)


@register("synthetic.pair_distances", fanout="pair", mirror=_mirror_distances)
def pair_distances(A, B, *, work_us: int = 0) -> np.ndarray:
    """(a, b) squared distances between stacks A (a,8,d) and B (b,8,d); ``work_us`` microseconds of compute
    added per pair."""
    A2 = A.reshape(len(A), -1)
    B2 = B.reshape(len(B), -1)
    D = (A2 ** 2).sum(1)[:, None] + (B2 ** 2).sum(1)[None, :] - 2 * A2 @ B2.T
    _spin(work_us * len(A) * len(B) / 1000.0)
    return D.astype(np.float32)


@register("synthetic.pair_distances_at", fanout="pair", mirror=_mirror_distances)
def pair_distances_at(A, B, *, pairs=None) -> np.ndarray:
    """Squared distances between stacks A (a,8,d) and B (b,8,d), pair by pair: (p,) float32 for the local
    index pairs ``pairs`` (p,2) of a candidate graph, or the (a, b) block of all pairs when ``pairs`` is None."""
    A2 = A.reshape(len(A), -1).astype(np.float64)
    B2 = B.reshape(len(B), -1).astype(np.float64)
    if pairs is None:
        return ((A2[:, None, :] - B2[None, :, :]) ** 2).sum(-1).astype(np.float32)
    return ((A2[pairs[:, 0]] - B2[pairs[:, 1]]) ** 2).sum(-1).astype(np.float32)


@register("synthetic.candidates", fanout="once")
def candidates(items, *, k: int = 2, bad: str = "") -> dict:
    """Candidate pairs of a collection ``{name: value}``: each item (sorted by name) with the next ``k`` items,
    cyclically: {"names": [M], "pairs": (P, 2) int64}. ``bad`` returns a broken result for tests: "self" (a
    pair (i, i)), "range" (an index M), "shape" ((P, 3) pairs), "names" (an unknown name), "float" pairs."""
    names = sorted(items)
    m = len(names)
    pairs = np.array([(i, (i + s) % m) for i in range(m) for s in range(1, k + 1) if (i + s) % m != i],
                     dtype=np.int64).reshape(-1, 2)
    if bad == "self":
        pairs[1] = (2, 2)
    elif bad == "range":
        pairs[0] = (0, m)
    elif bad == "shape":
        pairs = np.zeros((len(pairs), 3), dtype=np.int64)
    elif bad == "names":
        names[0] = "no_such_item"
    elif bad == "float":
        pairs = pairs.astype(np.float64)
    return {"names": names, "pairs": pairs}


@register("synthetic.collect_pairs", fanout="once")
def collect_pairs(distances) -> dict:
    """The sparse result of a candidate pair stage as received: names, pairs (P,2), values (P,)."""
    return {"names": list(distances["names"]), "pairs": np.asarray(distances["pairs"]),
            "values": np.asarray(distances["values"]), "n_pairs": int(len(distances["pairs"]))}


@register("synthetic.summarize", fanout="once")
def summarize(distances, *, sigma: float = 1.0, warn_below: float = 0.0) -> dict:
    """Collection-level metrics from the (N,N) distance matrix: mean affinity at ``sigma``; a "warnings" entry
    when it is below ``warn_below``."""
    M = np.asarray(distances["matrix"], dtype=np.float64)
    W = np.exp(-M / (sigma * np.median(M[M > 0]) if np.any(M > 0) else 1.0))
    out = {"n_items": int(len(M)), "mean_affinity": float(W.mean()), "sigma": float(sigma),
           "names": list(distances["names"])}
    if out["mean_affinity"] < warn_below:
        out["warnings"] = [f"mean affinity {out['mean_affinity']:.3f} is below {warn_below} at sigma {sigma}"]
    return out


@register("synthetic.collect", fanout="once")
def collect(items) -> dict:
    """Stack a per-item collection into one array with its names."""
    names = sorted(items)
    return {"names": names, "stack": np.stack([np.asarray(items[n]) for n in names]) if names else np.zeros(0)}


@register("synthetic.report", fanout="once", writes_files=True)
def report(summary, *, title: str = "synthetic", out_dir: str) -> dict:
    """Write a small text report file."""
    with open(os.path.join(out_dir, "summary.txt"), "w", encoding="utf-8") as fh:
        fh.write(f"{title}: {summary['n_items']} items, mean affinity {summary['mean_affinity']:.6f}\n")
    return {"files": ["summary.txt"]}


@register("synthetic.write_items", kind="generator")
def write_items(*, n: int = 10, seed: int = 0, out_dir: str) -> None:
    """Generator: ``n`` text files item000.txt ... with deterministic random content."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        with open(os.path.join(out_dir, f"item{i:03d}.txt"), "w", encoding="utf-8") as fh:
            fh.write(" ".join(map(str, rng.integers(0, 1000, 16))) + "\n")


def _spin(ms: float) -> None:
    if ms <= 0:
        return
    end = time.perf_counter() + ms / 1000.0
    x = np.ones(64)
    while time.perf_counter() < end:
        x = np.sqrt(x + 1.0)


@register("synthetic.maybe_skip", fanout="item")
def maybe_skip(path, *, skip_on: str = "") -> float | Skipped:
    """The length of a text file, or ``Skipped`` (naming the file) when it contains ``skip_on``."""
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    if skip_on and skip_on in text:
        return Skipped(f"{os.path.basename(path)} contains '{skip_on}'")
    return float(len(text))


@register("synthetic.count_skipped", fanout="once")
def count_skipped(items) -> dict:
    """{"skipped": {name: why} of the items received as ``Skipped``, "kept": how many others}."""
    skipped = {n: v.why for n, v in sorted(items.items()) if isinstance(v, Skipped)}
    return {"skipped": skipped, "kept": len(items) - len(skipped)}


def _most_blas_threads() -> int:
    """The largest thread count of the BLAS/OpenMP libraries loaded in this process."""
    import threadpoolctl
    return max(pool["num_threads"] for pool in threadpoolctl.threadpool_info())


@register("synthetic.write_blas_threads", kind="generator")
def write_blas_threads(*, n: int = 2, out_dir: str) -> None:
    """Generator: ``n`` text files, each holding the BLAS thread count the generator ran with."""
    threads = _most_blas_threads()
    for i in range(n):
        with open(os.path.join(out_dir, f"item{i:03d}.txt"), "w", encoding="utf-8") as fh:
            fh.write(f"{threads}\n")


@register("synthetic.blas_threads", fanout="item")
def blas_threads(path) -> dict:
    """{"generator": the BLAS threads written in the item file ``path``, "task": this task's BLAS threads}."""
    with open(path, encoding="utf-8") as fh:
        return {"generator": int(fh.read()), "task": _most_blas_threads()}
