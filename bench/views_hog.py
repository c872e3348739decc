"""Per-shape cost of the views and hog stages: this checkout against a baseline commit, measured in one run.

    python bench/views_hog.py                              # 24 generated chairs, baseline 7389271, 5 rounds
    python bench/views_hog.py --baseline-ref HEAD~1 --shapes 48 --rounds 7
    python bench/views_hog.py --engine 200                 # + both engines' views and hog stages on 200 chairs

The baseline is exported with ``git archive REF`` into a temporary folder. Each tree is timed in fresh processes
(PYTHONPATH = that tree, one BLAS thread), the rounds alternating between the trees so that both share the
machine's load. Per shape, CPU milliseconds (``time.process_time``: every thread of the process, Open3D's ray
casting threads included):

- views: ``shapecorr.alignment.views([mesh])`` (OBJ reading, repair, normalization, ray casting, uint8 views);
- hog:   ``shapecorr.alignment.hog(views)`` (16 x 8100 float32 HoG features);
- store: ``stages.store.Store.put`` of both results (the engine's write of the two cache entries).

Each part is the least over the rounds of its mean over the shapes (wall milliseconds likewise, in brackets).
Printed: both trees, the ratio this checkout / baseline, and whether the views and the HoG features of every
shape are bit-identical between the two trees.

``--engine N``: ``python -m stages run pipelines/scale.yaml --set n=N hog`` in a fresh cache per tree
(``--workers``, default 2), and the engine's own per-stage sums of task seconds (the wall time inside the stage
functions, as in docs/scale.md's N = 10,000 run) divided by N.
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PARTS = ("views", "hog", "store")
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def export_tree(ref: str, dest: str) -> str:
    """``git archive`` of ``ref`` (of this checkout's repository) unpacked into ``dest``; returns the full sha."""
    sha = subprocess.run(["git", "-C", ROOT, "rev-parse", ref], check=True, capture_output=True,
                         text=True).stdout.strip()
    archive = subprocess.run(["git", "-C", ROOT, "archive", sha], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", dest], input=archive, check=True)
    return sha


def current_label() -> str:
    """``branch@sha`` of this checkout, ``+`` when it has uncommitted changes."""
    def git(*args):
        return subprocess.run(["git", "-C", ROOT, *args], capture_output=True, text=True).stdout.strip()
    dirty = "+" if git("status", "--porcelain", "--untracked-files=no") else ""
    return f"{git('rev-parse', '--abbrev-ref', 'HEAD')}@{git('rev-parse', '--short', 'HEAD')}{dirty}"


def time_tree(chairs: str, out_json: str, arrays: str | None) -> None:
    """Child process: time views / hog / store per chair with the code on sys.path; write the means as JSON and,
    with ``arrays``, every chair's views and HoG features as .npz."""
    import numpy as np

    from shapecorr.alignment import hog, views
    from stages.store import Store

    files = sorted(glob.glob(os.path.join(chairs, "*.obj")))
    with tempfile.TemporaryDirectory(prefix="views_hog_store_") as cache:
        store = Store(cache)
        warm = views([files[0]])  # imports, Open3D start-up, cached rays: not part of a shape's cost
        store.put("warm-views", warm)
        store.put("warm-hog", hog(warm))
        cpu = dict.fromkeys(PARTS, 0.0)
        wall = dict.fromkeys(PARTS, 0.0)
        kept_views, kept_hog = [], []
        for i, path in enumerate(files):
            c0, w0 = time.process_time(), time.perf_counter()
            v = views([path])
            c1, w1 = time.process_time(), time.perf_counter()
            h = hog(v)
            c2, w2 = time.process_time(), time.perf_counter()
            store.put(f"views-{i}", v)
            store.put(f"hog-{i}", h)
            c3, w3 = time.process_time(), time.perf_counter()
            for part, (a, b, p, q) in zip(PARTS, ((c0, c1, w0, w1), (c1, c2, w1, w2), (c2, c3, w2, w3))):
                cpu[part] += b - a
                wall[part] += q - p
            if arrays:
                kept_views.append(v["views"])
                kept_hog.append(h)
    n = len(files)
    with open(out_json, "w") as fh:
        json.dump({"n": n, "cpu_ms": {k: 1e3 * s / n for k, s in cpu.items()},
                   "wall_ms": {k: 1e3 * s / n for k, s in wall.items()}}, fh)
    if arrays:
        np.savez(arrays, views=np.stack(kept_views), hog=np.stack(kept_hog))


def run_child(tree: str, chairs: str, work: str, tag: str, arrays: bool) -> dict:
    """One timing round of ``tree`` in a fresh process; returns its JSON (and the .npz path under "arrays")."""
    out = os.path.join(work, f"{tag}.json")
    npz = os.path.join(work, f"{tag}.npz") if arrays else ""
    env = {**os.environ, **ONE_THREAD, "PYTHONPATH": tree}
    subprocess.run([sys.executable, os.path.abspath(__file__), "--child", chairs, out, npz], check=True, env=env,
                   cwd=tree)
    with open(out) as fh:
        result = json.load(fh)
    result["arrays"] = npz
    return result


def best(rounds: list[dict], key: str) -> dict:
    """Per part, the least over the rounds of the mean per shape, plus the sums views+hog and views+hog+store."""
    out = {part: min(r[key][part] for r in rounds) for part in PARTS}
    out["views+hog"] = out["views"] + out["hog"]
    out["views+hog+store"] = out["views+hog"] + out["store"]
    return out


def identical(a: str, b: str) -> tuple[bool, bool]:
    """(views equal, HoG equal) bit for bit between two trees' .npz files."""
    import numpy as np

    with np.load(a) as x, np.load(b) as y:
        return (x["views"].dtype == y["views"].dtype and np.array_equal(x["views"], y["views"]),
                x["hog"].dtype == y["hog"].dtype and np.array_equal(x["hog"], y["hog"]))


def engine_seconds(tree: str, n: int, workers: int, work: str, tag: str) -> dict:
    """Per-shape task seconds (ms) of the views and hog stages of ``tree``'s engine on n chairs, and the wall."""
    cache, summary = os.path.join(work, f"engine-{tag}"), os.path.join(work, f"engine-{tag}.json")
    env = {**os.environ, "PYTHONPATH": tree}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "stages", "run", "pipelines/scale.yaml", "--set", f"n={n}", "hog",
                    "--cache", cache, "--out", os.path.join(work, f"out-{tag}"), "--workers", str(workers),
                    "--summary-json", summary, "--quiet"], check=True, env=env, cwd=tree)
    wall = time.perf_counter() - t0
    with open(summary) as fh:
        stages = json.load(fh)["stages"]
    shutil.rmtree(cache, ignore_errors=True)
    return {"views": 1e3 * stages["views"]["seconds"] / n, "hog": 1e3 * stages["hog"]["seconds"] / n,
            "wall": wall}


def main() -> None:
    if len(sys.argv) == 5 and sys.argv[1] == "--child":
        # the tree under test comes from PYTHONPATH; bench/ itself (sys.path[0]) must not shadow any module
        here = os.path.dirname(os.path.abspath(__file__))
        sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != here]
        time_tree(sys.argv[2], sys.argv[3], sys.argv[4] or None)
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline-ref", default="7389271", help="commit to compare with (default 7389271)")
    parser.add_argument("--shapes", type=int, default=24, help="generated chairs timed per round (default 24)")
    parser.add_argument("--rounds", type=int, default=5, help="timing rounds per tree (default 5)")
    parser.add_argument("--engine", type=int, default=0, metavar="N",
                        help="also run both engines' views and hog stages on N chairs (default: no)")
    parser.add_argument("--workers", type=int, default=2, help="engine workers for --engine (default 2)")
    args = parser.parse_args()

    sys.path.insert(0, ROOT)
    from corr_core.generate import write_chair_collection

    with tempfile.TemporaryDirectory(prefix="views_hog_") as work:
        base_tree = os.path.join(work, "baseline")
        os.makedirs(base_tree)
        base_sha = export_tree(args.baseline_ref, base_tree)
        chairs = os.path.join(work, "chairs")
        write_chair_collection(chairs, n=args.shapes, seed=0)
        trees = {"baseline": base_tree, "current": ROOT}
        rounds = {name: [] for name in trees}
        for r in range(args.rounds):
            for name in (trees if r % 2 == 0 else reversed(list(trees))):
                rounds[name].append(run_child(trees[name], chairs, work, f"{name}-{r}", arrays=(r == 0)))
        cpu = {name: best(rounds[name], "cpu_ms") for name in trees}
        wall = {name: best(rounds[name], "wall_ms") for name in trees}
        same_views, same_hog = identical(rounds["baseline"][0]["arrays"], rounds["current"][0]["arrays"])

        labels = {"baseline": f"baseline {base_sha[:7]}", "current": f"current {current_label()}"}
        columns = ("views", "hog", "store", "views+hog", "views+hog+store")
        print(f"per shape, {args.shapes} generated chairs (120 x 120 x 16 views): CPU ms, least over "
              f"{args.rounds} rounds of the mean per shape [wall ms]")
        print(f"{'':26s}" + "".join(f"{c:>20s}" for c in columns))
        for name in trees:
            print(f"{labels[name]:26s}" + "".join(f"{cpu[name][c]:>11.2f} [{wall[name][c]:5.1f}]" for c in columns))
        print(f"{'ratio current/baseline':26s}" + "".join(
            f"{cpu['current'][c] / cpu['baseline'][c]:>11.3f} [{wall['current'][c] / wall['baseline'][c]:5.2f}]"
            for c in columns))
        print(f"bit-identical to the baseline on all {args.shapes} chairs: views {same_views}, hog {same_hog}")

        if args.engine:
            eng = {name: engine_seconds(trees[name], args.engine, args.workers, work, name) for name in trees}
            print(f"engine (pipelines/scale.yaml --set n={args.engine} hog, --workers {args.workers}, cold): "
                  "task ms per shape (wall inside the stage functions)")
            for name in trees:
                e = eng[name]
                print(f"{labels[name]:26s} views {e['views']:7.2f}  hog {e['hog']:7.2f}  "
                      f"views+hog {e['views'] + e['hog']:7.2f}  (whole run {e['wall']:.1f} s)")
            total = {name: eng[name]["views"] + eng[name]["hog"] for name in trees}
            ratio = total["current"] / total["baseline"]
            print(f"{'ratio current/baseline':26s} views+hog {ratio:.3f}")


if __name__ == "__main__":
    main()
