"""Engine benchmark: a synthetic pipeline with 100 items and 4,950 pairs.

Prints the cold time, the no-op rerun time and their ratio (target <= 0.05), and the engine's time against
calling the same functions in a plain loop (overhead target <= 20%), both in-process (pure engine overhead:
planning, hashing, zarr storage) and on the default LocalCluster of 2 worker processes.

    python bench/engine.py [--items 100] [--item-ms 20] [--pair-us 500]
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
# the synthetic.* functions are the test-only plugin, loaded through the STAGES_PLUGINS development hook
# (the LocalCluster's workers inherit the variable)
SYNTHETIC_PLUGIN = "tests.stages.synthetic_plugin"
os.environ["STAGES_PLUGINS"] = ",".join(filter(None, [os.environ.get("STAGES_PLUGINS"), SYNTHETIC_PLUGIN]))
os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(Path(__file__).resolve().parents[1]),
                                                         os.environ.get("PYTHONPATH")]))

from stages import api  # noqa: E402
from tests.stages import synthetic_plugin as synthetic  # noqa: E402

YAML = """\
name: bench
params: {item_ms: 20, pair_us: 500}
datasets:
  items: {files: "data/*.txt"}
stages:
  feat: {function: synthetic.features, foreach: items, inputs: {path: items}, params: {work: "${item_ms}"}}
  dist: {function: synthetic.pair_distances, pairs: feat, tile: 32, params: {work_us: "${pair_us}"}}
  summary: {function: synthetic.summarize, inputs: {distances: dist}, metrics: true}
"""


def plain_loop(files: list[Path], item_ms: int, pair_us: int) -> float:
    """The same computation without the engine: features, all pairs in one block, summary."""
    t0 = time.perf_counter()
    F = {f.stem: synthetic.features(str(f), work=item_ms) for f in files}
    names = sorted(F)
    stack = np.stack([F[n] for n in names])
    M = synthetic.pair_distances(stack, stack, work_us=pair_us)
    synthetic.summarize({"names": names, "matrix": M})
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--items", type=int, default=100)
    ap.add_argument("--item-ms", type=int, default=20)
    ap.add_argument("--pair-us", type=int, default=500)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="engine-bench-"))
    cwd = os.getcwd()
    try:
        os.chdir(work)
        (work / "data").mkdir()
        for i in range(args.items):
            (work / "data" / f"item{i:04d}.txt").write_text(f"item {i} {i * 7919 % 10007}\n")
        (work / "p.yaml").write_text(YAML)
        files = sorted((work / "data").glob("*.txt"))
        n_pairs = args.items * (args.items - 1) // 2
        sets = [f"item_ms={args.item_ms}", f"pair_us={args.pair_us}"]
        print(f"synthetic pipeline: {args.items} items, {n_pairs} pairs, {args.item_ms} ms/item, "
              f"{args.pair_us} us/pair")

        loop = plain_loop(files, args.item_ms, args.pair_us)
        print(f"plain loop (1 process, all N*N pairs)   {loop:8.2f} s")

        t0 = time.perf_counter()
        s = api.run("p.yaml", sets, workers=0, quiet=True, cache_dir="cache-inproc")
        inproc = time.perf_counter() - t0
        tasks = sum(v["tasks"] for v in s["stages"].values())
        print(f"engine, in-process, cold ({tasks} tasks) {inproc:8.2f} s   overhead vs loop {inproc / loop - 1:+.1%}"
              f"  (target <= +20%)")

        with api.client_session(2, None, str(work / "cluster")) as get_client:   # its scratch space: not in the cache
            client = get_client()
            t0 = time.perf_counter()
            api.run("p.yaml", sets, quiet=True, client_getter=lambda: client)
            cold = time.perf_counter() - t0
            t0 = time.perf_counter()
            s = api.run("p.yaml", sets, quiet=True, client_getter=lambda: client)
            noop = time.perf_counter() - t0
        assert sum(v["executed"] for v in s["stages"].values()) == 0
        print(f"engine, LocalCluster 2 workers, cold     {cold:8.2f} s   vs plain loop {cold / loop:.2f}x time")
        print(f"no-op rerun (plan + cache check)         {noop:8.3f} s   no-op / cold = {noop / cold:.4f}"
              f"  (target <= 0.05)")
        t0 = time.perf_counter()
        api.run("p.yaml", sets, workers=2, quiet=True)
        noop_fresh = time.perf_counter() - t0
        print(f"no-op rerun without a running cluster    {noop_fresh:8.3f} s   (no cluster is started for a no-op)")
    finally:
        os.chdir(cwd)
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
