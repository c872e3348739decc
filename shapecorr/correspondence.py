"""Stage wiring for problem 2: landmark correspondence from a template mesh to each test pose.

Per mesh (cached per mesh): mesh check -> spectral descriptors (HKS, WKS) at the landmarks, landmark
geodesics (normalized by the geodesic diameter), mid-edge flattening with surface samples.
Per test mesh (one stage per method, so changing the MRF sigma or K reruns only that matching):
descriptors + Hungarian, geodesic-consistency MRF (Leordeanu & Hebert), Möbius voting.
Once: accuracies, frequency-matrix figures, dense-map error curves.
"""
from __future__ import annotations

import glob
import json
import os

import numpy as np

from corr_core.correspondence import descriptors as desc
from corr_core.correspondence import measures as evaluation
from corr_core.geometry import geodesic
from corr_core.correspondence import landmark_mrf
from corr_core.geometry import laplacian
from corr_core.geometry import checks as meshcheck
from corr_core.geometry import midedge
from corr_core.correspondence import mobius
from corr_core.correspondence.landmarks import read_landmarks
from corr_core.correspondence.matching import hungarian_match
from corr_core.geometry.mesh_io import load_mesh
from corr_core.geometry.sampling import farthest_point_samples

from stages.registry import register


def _landmarks(path: str, n_vertices: int | None = None) -> tuple[np.ndarray, list[str]]:
    ids, names = read_landmarks(path, n_vertices=n_vertices)
    return np.asarray(ids, dtype=np.int64), list(names)


def _sparse_index(all_path: str, sparse_path: str, n_vertices: int | None = None) -> np.ndarray:
    """Positions of the sparse landmarks within the full landmark list: (k,) int."""
    ids, _ = _landmarks(all_path, n_vertices)
    sids, _ = _landmarks(sparse_path, n_vertices)
    where = {int(v): i for i, v in enumerate(ids)}
    missing = [int(v) for v in sids if int(v) not in where]
    if missing:
        raise ValueError(f"{sparse_path}: sparse landmark vertices {missing} are not in {all_path}")
    return np.array([where[int(v)] for v in sids], dtype=np.int64)


@register("corr.mesh", fanout="item")
def mesh(path, *, allow_components: bool = False) -> dict:
    """Load and check one mesh (non-manifold edges, degenerate faces, several components are errors).

    Returns {"V": (n,3) float64, "F": (m,3) int64, "area": float, "warnings": [str]}.
    """
    V, F = load_mesh(path)
    warnings = meshcheck.check_correspondence_mesh(V, F, name=os.path.basename(path),
                                                   allow_components=allow_components)
    return {"V": V, "F": F.astype(np.int64), "area": evaluation.surface_area(V, F), "warnings": list(warnings)}


@register("corr.spectral", fanout="item")
def spectral(mesh, landmarks, *, k: int = 100, n_times: int = 16, n_energies: int = 100,
             wks_variance: float = 6.0) -> dict:
    """HKS and WKS at the landmark vertices from the first k Laplace-Beltrami eigenpairs.

    Returns {"hks": (L, n_times), "wks": (L, n_energies), "evals": (k,)}.
    """
    V, F = mesh["V"], mesh["F"]
    ids, _ = _landmarks(landmarks, len(V))
    evals, evecs = laplacian.eigenpairs(V, F, k=k)
    return {"hks": desc.hks(evals, evecs[ids], n_times=n_times).astype(np.float64),
            "wks": desc.wks(evals, evecs[ids], n_energies=n_energies, variance=wks_variance).astype(np.float64),
            "evals": np.asarray(evals)}


@register("corr.geodesics", fanout="item")
def geodesics(mesh, landmarks) -> dict:
    """Landmark geodesic distances normalized by the geodesic diameter, and landmark chirality.

    Returns {"D": (L,L) float, "diameter": float, "chirality": (L,L,L) float}.
    """
    V, F = mesh["V"], mesh["F"]
    ids, _ = _landmarks(landmarks, len(V))
    D = geodesic.landmark_geodesics(V, F, ids, normalize=False)
    diameter = geodesic.geodesic_diameter(V, F)
    return {"D": D / diameter, "diameter": float(diameter),
            "chirality": landmark_mrf.landmark_chirality(V, F, ids)}


def _given_flat(folder, item_path: str, n_edges: int):
    """Z from a given flattened mesh (course layout: flattened_meshes/<template|test>/<name>.obj), if any."""
    if not folder:
        return None
    sub = os.path.basename(os.path.dirname(item_path))
    candidate = os.path.join(folder, sub, os.path.basename(item_path))
    if not os.path.isfile(candidate):
        return None
    P, _ = load_mesh(candidate, require_faces=False)
    if len(P) != n_edges:
        raise ValueError(f"{candidate}: has {len(P)} vertices but the mesh has {n_edges} edges; "
                         "a flattened mesh must have one vertex per edge")
    return P[:, 0] + 1j * P[:, 1]


@register("corr.flatten", fanout="item")
def flatten(mesh, path, landmarks, flattened=None, samples=None, *, source: str = "compute",
            sample_source: str = "auto", n_samples: int = 300) -> dict:
    """Mid-edge flattening (one complex point per edge) and uniform surface samples.

    source: "compute" (the project's own flattening, the default: on SCAPE it is more accurate than the course
    files, which are stored with 6 digits), "given" / "auto" (use the mesh's file in ``flattened`` =
    flattened_meshes/{template,test}/ when present, else compute it).
    sample_source: "fps" (farthest-point samples of the edge midpoints), "given" / "auto" (the vertex ids in
    ``samples``, e.g. uniform_sample_vids.txt, when present, else fps). Note: the course's sample file lists the
    same vertex ids for every mesh, i.e. samples already in correspondence; "fps" does not use that.
    Returns {"Z": (E,2) float (x, y), "lam": (E,) local scale of the flattening, "landmark_eids": (L,),
    "sample_eids": (S,), "edges": (E,2), "area": float, "source": str, "sample_source": str}.
    """
    V, F = mesh["V"], mesh["F"]
    if source not in ("auto", "compute", "given"):
        raise ValueError(f"source must be 'auto', 'compute' or 'given', got {source!r}")
    if sample_source not in ("auto", "fps", "given"):
        raise ValueError(f"sample_source must be 'auto', 'fps' or 'given', got {sample_source!r}")
    Z, edges, face_edges, kept = midedge.midedge_flatten(V, F)
    used = "computed"
    if source in ("auto", "given"):
        given = _given_flat(flattened, path, len(edges))
        if given is not None:
            Z, used = given, "given"
    lam = midedge.midedge_conformal_factor(V, edges, face_edges, kept, Z, F)
    sample_used = "fps"
    if sample_source in ("auto", "given") and samples:
        svids, _ = read_landmarks(samples, n_vertices=len(V))
        sample_eids = np.array([midedge.vertex_to_edge(int(v), edges) for v in svids], dtype=np.int64)
        sample_used = "given"
    else:
        M = midedge.edge_midpoints(V, edges)
        start = int(np.argmax(np.linalg.norm(M - M.mean(axis=0), axis=1)))
        sample_eids = farthest_point_samples(M, n_samples, start=start)
    ids, _ = _landmarks(landmarks, len(V))
    eids = np.array([midedge.vertex_to_edge(int(v), edges) for v in ids], dtype=np.int64)
    return {"Z": np.stack([Z.real, Z.imag], axis=1), "lam": lam, "landmark_eids": eids,
            "sample_eids": np.asarray(sample_eids, dtype=np.int64), "edges": edges.astype(np.int64),
            "area": float(mesh["area"]), "source": used, "sample_source": sample_used}


def _descriptor_matrix(s: dict, kind: str) -> np.ndarray:
    if kind == "hks":
        return s["hks"]
    if kind == "wks":
        return s["wks"]
    if kind == "hks+wks":
        return np.concatenate([s["hks"], s["wks"]], axis=1)
    raise ValueError(f"descriptor must be hks, wks or hks+wks, got {kind!r}")


@register("corr.match_descriptor", fanout="item")
def match_descriptor(template, target, landmarks, sparse_landmarks, *, descriptor: str = "hks+wks",
                     metric: str = "relative_l1") -> dict:
    """(a) Descriptor distance + Hungarian assignment, with all landmarks and with the sparse ones.

    Returns {"all": (L,) predicted target landmark per template landmark, "sparse": (k,) within the sparse set}.
    """
    DT, DS = _descriptor_matrix(template, descriptor), _descriptor_matrix(target, descriptor)
    cost = desc.descriptor_distance(DT, DS, metric=metric)
    sp = _sparse_index(landmarks, sparse_landmarks)
    return {"all": hungarian_match(cost), "sparse": hungarian_match(cost[np.ix_(sp, sp)])}


@register("corr.match_mrf", fanout="item")
def match_mrf(template, target, landmarks, sparse_landmarks, *, sigma: float = 0.05,
              orientation: bool = False) -> dict:
    """(b) Pairwise geodesic-consistency MRF, w = exp(-(d(ia,ja) - d(ib,jb))^2 / (2 sigma)), solved by
    Leordeanu & Hebert; ``orientation`` adds the chirality test that resolves left/right swaps.

    Returns {"all": (L,), "sparse": (k,)}.
    """
    sp = _sparse_index(landmarks, sparse_landmarks)
    out = {}
    for key, idx in (("all", np.arange(len(template["D"]))), ("sparse", sp)):
        dT, dS = template["D"][np.ix_(idx, idx)], target["D"][np.ix_(idx, idx)]
        if orientation:
            cT = template["chirality"][np.ix_(idx, idx, idx)]
            cS = target["chirality"][np.ix_(idx, idx, idx)]
            out[key] = landmark_mrf.match_landmarks_oriented(dT, dS, cT, cS, sigma=sigma)
        else:
            out[key] = landmark_mrf.match_landmarks_mrf(dT, dS, sigma=sigma)
    return out


def _z(flat: dict) -> np.ndarray:
    return flat["Z"][:, 0] + 1j * flat["Z"][:, 1]


def _same_triangles(F_a: np.ndarray, F_b: np.ndarray) -> bool:
    """True when F_a: (m,3) and F_b: (m,3) hold the same triangles as vertex sets, in any order."""
    if F_a.shape != F_b.shape:
        return False
    A, B = np.sort(F_a, axis=1), np.sort(F_b, axis=1)
    return np.array_equal(A[np.lexsort(A.T[::-1])], B[np.lexsort(B.T[::-1])])


@register("corr.match_mobius", fanout="item")
def match_mobius(template, target, template_mesh, target_mesh, landmarks, sparse_landmarks, *, K: float = 0.5,
                 metric: str = "surface", K_scale: float = 0.3, power: float = 4.0, top: int = 100,
                 dense_points: int = 200) -> dict:
    """(c) Möbius voting on the flattened meshes from triplets of sparse landmarks, extended to all landmarks
    by the consensus maps; plus a dense map from the best map and its geodesic errors.

    K: deformation-error threshold; with metric "surface" in units of the sample spacing
    sqrt(area / n_samples) (docs/mobius_notes.md), with "plane" in canonical-frame units (the paper).
    Returns {"sparse": (k,), "all": (L,), "dense_errors": (dense_points,) geodesic error / sqrt(area),
    "best_score": float}. The dense errors need the truth "vertex i <-> vertex i", i.e. the same vertex count
    and faces as the template; otherwise they are left out and "dense_skipped" (str) says why.
    """
    sp = _sparse_index(landmarks, sparse_landmarks)
    Zs, Zt = _z(template), _z(target)
    Ss, St = template["sample_eids"], target["sample_eids"]
    hs, ht = np.sqrt(template["area"] / len(Ss)), np.sqrt(target["area"] / len(St))
    Ls, Lt = template["landmark_eids"], target["landmark_eids"]
    lam_samples = (template["lam"][Ss] * hs, target["lam"][St] * ht) if metric == "surface" else None
    lam_lm = (template["lam"][Ls[sp]] * hs, target["lam"][Lt[sp]] * ht) if metric == "surface" else None
    res = mobius.mobius_vote_landmarks(Zs[Ss], Zt[St], Zs[Ls[sp]], Zt[Lt[sp]], K=K, metric=metric,
                                       lam_samples=lam_samples, lam_landmarks=lam_lm, power=power,
                                       K_scale=K_scale if metric == "surface" else None)
    maps = res["consensus_maps"] or res["best_maps"]
    ext_metric = "plane" if metric == "surface" else metric
    pred_all = mobius.extend_landmarks(maps, Zs[Ls], Zt[Lt], top=top, metric=ext_metric)
    # dense map from the best map, measured on evenly spread template vertices (truth: vertex i <-> i)
    out = {"sparse": np.asarray(res["pred"]), "all": np.asarray(pred_all),
           "best_score": float(res["best_maps"][0]["score"])}
    Vt, Ft = target_mesh["V"], target_mesh["F"]
    Vs, Fs = template_mesh["V"], template_mesh["F"]
    if len(Vt) != len(Vs) or not _same_triangles(Ft, Fs):
        out["dense_skipped"] = (f"{len(Vt)} vertices and {len(Ft)} faces vs the template's {len(Vs)} and {len(Fs)} "
                                "(the same connectivity is required): no vertex i <-> vertex i ground truth, "
                                "dense-map errors skipped")
    elif dense_points > 0:
        src_vertices = farthest_point_samples(template_mesh["V"], dense_points)
        edges_s, edges_t = template["edges"], target["edges"]
        src_eids = np.array([midedge.vertex_to_edge(int(v), edges_s) for v in src_vertices])
        nn = mobius.dense_map(maps[0], Zs[src_eids], Zt, metric=ext_metric)
        pred_vertices = edges_t[nn, 0]
        out["dense_errors"] = evaluation.geodesic_errors(Vt, Ft, pred_vertices, src_vertices)
    return out


def _plot_accuracy_bars(acc: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(acc)
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.bar(names, [acc[n] for n in names], color="#4477aa")
    for i, n in enumerate(names):
        ax.text(i, acc[n] + 0.01, f"{acc[n]:.3f}", ha="center", fontsize=8)
    ax.set_ylim(0, 1.08)
    ax.set_ylabel("accuracy")
    ax.set_title("landmark accuracy per method")
    plt.setp(ax.get_xticklabels(), rotation=20, ha="right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _top_confusions(mats: list[np.ndarray], rows: list[str], k: int = 10) -> dict[str, int]:
    """The k most frequent wrong correspondences 'A -> B' with how many meshes made them."""
    counts = np.sum(mats, axis=0)
    wrong = {f"{rows[i]} -> {rows[j]}": int(counts[i, j])
             for i in range(len(rows)) for j in np.flatnonzero(counts[i]) if j != i}
    return dict(sorted(wrong.items(), key=lambda kv: -kv[1])[:k])


def _method_report(label: str, preds: dict[str, np.ndarray], rows: list[str], out_dir: str) -> dict:
    """Accuracy, per-mesh accuracy, binary matrices, confusions and the frequency figure of one method."""
    n = len(rows)
    mats = [evaluation.correspondence_matrix(p, n) for p in preds.values()]
    truth = np.arange(n)
    per_mesh = {m: float(evaluation.accuracy(p, truth)) for m, p in preds.items()}
    acc = float(np.mean(list(per_mesh.values())))
    evaluation.plot_frequency_matrix(evaluation.frequency_matrix(mats), rows, rows,
                                     f"{label}: accumulated correspondences ({len(mats)} meshes, accuracy {acc:.3f})",
                                     os.path.join(out_dir, f"frequency_{label}.png"))
    return {"accuracy": acc, "per_mesh": per_mesh, "confusions": _top_confusions(mats, rows),
            "matrices": {m: mat.astype(int).tolist() for m, mat in zip(preds, mats)}}


def _dense_report(mobius_votes: dict, out_dir: str) -> dict:
    """Geodesic error curve of the Möbius dense maps (Kim et al. 2011 measure) and the meshes skipped."""
    out = {}
    skipped = {m: r["dense_skipped"] for m, r in sorted(mobius_votes.items()) if "dense_skipped" in r}
    if skipped:
        out["dense_map_skipped"] = skipped
    errors = np.concatenate([np.asarray(r["dense_errors"]) for r in mobius_votes.values() if "dense_errors" in r]
                            or [np.zeros(0)])
    if errors.size:
        thresholds = np.linspace(0, 0.25, 51)
        evaluation.plot_error_curves({"Möbius dense map": (thresholds, evaluation.geodesic_error_curve(errors, thresholds))},
                                     os.path.join(out_dir, "dense_map_error_curve.png"))
        out["dense_map"] = {"within_0.05": float(np.mean(errors <= 0.05)),
                            "within_0.10": float(np.mean(errors <= 0.10)),
                            "within_0.25": float(np.mean(errors <= 0.25)),
                            "mean_error": float(errors.mean()), "n_points": int(errors.size)}
    return out


@register("corr.evaluate", fanout="once", writes_files=True)
def evaluate(landmarks, sparse_landmarks, descriptor=None, mrf=None, mrf_oriented=None, mobius_votes=None,
             *, out_dir: str) -> dict:
    """Accuracy per method (correct / all over test meshes x landmarks), per-mesh binary correspondence
    matrices (correspondences.json), accumulated frequency matrices as figures with landmark names, and the
    dense-map geodesic error curve.

    Each method input is {test mesh: {"all": (L,), "sparse": (k,)}}; the truth is landmark i -> landmark i
    (the template's and the test's landmark files list the same anatomical points in the same order).
    """
    _, names = _landmarks(landmarks)
    sparse_names = [names[i] for i in _sparse_index(landmarks, sparse_landmarks)]
    reports = {}
    for label, results, key in (("descriptor", descriptor, "all"), ("descriptor_sparse", descriptor, "sparse"),
                                ("mrf", mrf, "all"), ("mrf_sparse", mrf, "sparse"),
                                ("mrf_oriented", mrf_oriented, "all"),
                                ("mrf_oriented_sparse", mrf_oriented, "sparse"),
                                ("mobius_sparse", mobius_votes, "sparse"), ("mobius_all", mobius_votes, "all")):
        if results:
            preds = {mesh_name: np.asarray(r[key]) for mesh_name, r in sorted(results.items())}
            reports[label] = _method_report(label, preds, sparse_names if key == "sparse" else names, out_dir)
    with open(os.path.join(out_dir, "correspondences.json"), "w", encoding="utf-8") as fh:
        json.dump({"landmarks": names, "sparse_landmarks": sparse_names,
                   "matrices": {k: r["matrices"] for k, r in reports.items()}}, fh)
    accuracy = {k: r["accuracy"] for k, r in reports.items()}
    _plot_accuracy_bars(accuracy, os.path.join(out_dir, "accuracy.png"))
    out = {"accuracy": accuracy, "accuracy_per_mesh": {k: r["per_mesh"] for k, r in reports.items()},
           "top_confusions": {k: r["confusions"] for k, r in reports.items()}}
    if mobius_votes:
        out.update(_dense_report(mobius_votes, out_dir))
    return out
