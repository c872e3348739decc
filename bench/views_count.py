"""How many views? Accuracy, continuous error and time against the view count V on generated chairs at random
continuous azimuths (run: python bench/views_count.py [--n 24] [--views 8,12,16,24,36] [--seed 0]).

For each V: render V views of every chair (``align.views``, 120x120), HoG (``align.hog``), pair costs, the
spectral solver with the continuous refinement (``solve_alignment``). Prints a Markdown table, all measured in
this run (no assertions):
- exact / within one view: labels against the nearest view of the true azimuth turned into the solution's
  frame (by the continuous global offset of the angles; with continuous azimuths a whole-step offset alone
  would put the rounding cuts in the wrong place);
- labels error: mean error in degrees of the labels' own angles (label * 360 / V), up to one global offset;
- continuous error (mean, max): of ``angles_deg``, up to one global offset;
- time: views + HoG (all chairs, one process), pair costs, solve (seconds, wall clock).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from corr_core.alignment.measures import agreement, continuous_error  # noqa: E402
from corr_core.alignment.pair_costs import pair_costs  # noqa: E402
from corr_core.alignment.solvers import solve_alignment  # noqa: E402
from corr_core.generate.chairs import write_chair_collection  # noqa: E402
from shapecorr.alignment import hog, views  # noqa: E402


def measure(files: list[str], truth_deg: np.ndarray, V: int) -> dict:
    """One row of the table for V views (see the module docstring)."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # mesh repairs of the generated boxes
        F = np.stack([hog(views([f], n_views=V)) for f in files])
    t1 = time.perf_counter()
    C = pair_costs(F)
    t2 = time.perf_counter()
    sol = solve_alignment(C, solver="spectral")
    t3 = time.perf_counter()
    cont = continuous_error(sol["angles_deg"], truth_deg)
    # nearest view of the true azimuth in the solution's frame (its global offset is any angle, not whole steps)
    nearest = np.rint((truth_deg + cont["offset_deg"]) * V / 360.0).astype(np.int64) % V
    acc = agreement(sol["labels"], nearest, V)
    return {"V": V, "exact": acc["exact"], "within_one_view": acc["within_one_view"],
            "labels_error": continuous_error(sol["labels"] * 360.0 / V, truth_deg)["mean_error_deg"],
            "mean_error": cont["mean_error_deg"], "max_error": cont["max_error_deg"],
            "t_views_hog": t1 - t0, "t_pairs": t2 - t1, "t_solve": t3 - t2}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=24, help="chairs (default 24)")
    ap.add_argument("--views", default="8,12,16,24,36", help="view counts, comma-separated")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = write_chair_collection(Path(tmp) / "chairs", n=args.n, seed=args.seed, continuous=True)
        truth = np.array(out["azimuth_deg"])
        rows = [measure(out["files"], truth, int(v)) for v in args.views.split(",")]
    print(f"{args.n} generated chairs (seed {args.seed}) at random continuous azimuths, spectral solver, 120x120 views")
    print()
    print("| V | exact | within one view | labels error (deg) | continuous error mean / max (deg) "
          "| views + HoG (s) | pair costs (s) | solve (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['V']} | {r['exact']:.2f} | {r['within_one_view']:.2f} | {r['labels_error']:.2f} "
              f"| {r['mean_error']:.2f} / {r['max_error']:.2f} | {r['t_views_hog']:.1f} | {r['t_pairs']:.2f} "
              f"| {r['t_solve']:.2f} |")


if __name__ == "__main__":
    main()
