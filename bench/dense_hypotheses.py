"""Every automatic starting map refined, on generated bodies of other people: which one the distortion keeps,
by what margin, and whether it is the right one (the data behind ``init.HYPOTHESIS_WKS_RATIO``,
``refine.CONFIDENT_MARGIN`` and ``refine.LOW_CONFIDENCE``; never tuned on the course poses).

Per seed, ``write_humanoid_dataset(n_poses, seed, vary_bodies=True)`` (the generator of pipelines/bodies.yaml:
each pose is another person too; vertex i <-> i is the truth, used only to score), with ``--decimated`` also a
decimated, vertex-shuffled copy of pose 1 (other connectivity). For every target the ``--candidates`` best ranked
initial maps (``init.automatic_hypotheses``) are each upsampled and refined (``refine.refine_map``, the default
steps, the bodies pipeline's settings: k 60, 1000 samples, 150 patches) and printed: chirality agreement, WKS
disagreement, refined ``map_distortion``, mean geodesic error / sqrt(area) at 500 template samples, landmark
accuracy (< 0.5: a flipped map; at least 0.5 with a mean error above ``TWISTED_ERROR``: a twisted one, part of the
body mapped the wrong way round). The summary: targets, flips and twists of the map ``refine_best`` keeps among
the hypotheses ``hypotheses_to_refine`` selects, its confidence, and the smallest margin of a right choice.

Run:  python bench/dense_hypotheses.py [--seeds 0-9] [--poses 6] [--decimated] [--meshes mesh007] [--json OUT]
          [--refine extrinsic+deform]  (another refinement plan than the default)
      (an existing --json file is resumed: its targets are not run again, and the summary covers all of them)
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402

# Mean error / sqrt(area) above which a kept map with landmark accuracy >= 0.5 counts as twisted, not right: the
# right maps of the runs in docs/dense.md "Confidence" stay below 0.03, turned maps near 0.5, twists near 0.25.
TWISTED_ERROR = 0.1
SETTINGS = {"k": 60, "n_samples": 1000, "k_init": 30, "n_patches": 150, "eval_vertices": 500}


def seed_range(text: str) -> list[int]:
    """"0-9" or "0,3,5" -> [ints]."""
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in text.split(",")]


def resumed_results(path: str | None, seeds: list[int] | None = None) -> list[dict]:
    """The per-target results already in the ``--json`` file ``path`` (none when it is None or absent), those of
    ``seeds`` only when given: a bench run again with the same file skips them."""
    if not path or not os.path.isfile(path):
        return []
    with open(path) as fh:
        return [r for r in json.load(fh) if seeds is None or r["seed"] in seeds]


def score_candidates(S, T, V_t, F_t, truth, landmarks, n_candidates: int, plan: str | None = None) -> list[dict]:
    """Every one of the ``n_candidates`` best ranked starting maps, refined and scored (module docstring)."""
    from corr_core.correspondence.dense import init, measures, refine, upsample_spectral
    from corr_core.correspondence.dense.basis import map_to_original
    from corr_core.correspondence.dense.transfer import transfer_landmarks
    from corr_core.geometry.geodesic import GeodesicSolver

    maps, info = init.automatic_hypotheses(S, T, n_candidates, k_init=SETTINGS["k_init"], k_end=SETTINGS["k"],
                                           return_info=True)
    ranked = init.rank_candidates(info["candidates"])
    solver = GeodesicSolver(V_t, F_t)
    rows = []
    steps = refine.refine_plan(plan or refine.DEFAULT_REFINE, {"extrinsic": {"n_patches": SETTINGS["n_patches"]}})
    for c, (C, p2p) in zip(ranked, maps):
        refined = upsample_spectral(S, T, C, p2p)
        step_distortions = [refine.map_distortion(S, T, refined)]          # after upsampling, then each step
        round_distortions = []
        for i, step in enumerate(steps):
            if i == 0 and step.name == "extrinsic" and not step.only_if_lower:
                refined, round_distortions = extrinsic_by_rounds(S, T, refined, step)
            else:
                refined = step.run(S, T, refined)
            step_distortions.append(refine.map_distortion(S, T, refined))
        vertex_map = map_to_original(S, T, refined)
        errors = measures.dense_errors(V_t, F_t, {"m": vertex_map}, truth,
                                       vertices=S.vids[S.samples[:SETTINGS["eval_vertices"]]], solver=solver)["m"]
        _, nearest = measures.landmark_errors(V_t, F_t, transfer_landmarks(vertex_map, landmarks),
                                              truth[landmarks], solver=solver)
        rows.append({"chirality": c.chirality, "wks": c.wks, "distortion": step_distortions[-1],
                     "step_distortions": step_distortions, "round_distortions": round_distortions,
                     "mean_error": float(errors.mean()), "landmark_accuracy": measures.landmark_accuracy(nearest)})
    return rows


def extrinsic_by_rounds(S, T, p2p, step):
    """``step`` (an extrinsic ``RefineStep``) run one round at a time: the same map as ``step.run`` (each round
    starts from the map alone, and a round that changes nothing ends it), and ``map_distortion`` after every round
    run ([floats])."""
    from corr_core.correspondence.dense import refine

    split = refine.first_round_split(step)           # None: a step of one round
    one_round, rounds = (split[0], 1 + split[1].options["rounds"]) if split else (step, 1)
    distortions = []
    for _ in range(rounds):
        new = one_round.run(S, T, p2p)
        if np.array_equal(new, p2p):
            break
        p2p = new
        distortions.append(refine.map_distortion(S, T, p2p))
    return p2p, distortions


def choice(rows: list[dict]) -> dict:
    """What the automatic mode does with these scored candidates: how many it refines, which of them it drops
    after the first step and after later ones (``refine.surviving_after_step``, step by step as ``refine_best``),
    which it keeps, its confidence, and whether that map is right (landmark accuracy >= 0.5). Rows of a file
    without ``step_distortions`` count as never dropped (and are compared by their last distortion)."""
    from corr_core.correspondence.dense.init import hypotheses_to_refine
    from corr_core.correspondence.dense.refine import (EARLY_DROP_MARGIN, best_refined, surviving_after_step,
                                                       surviving_hypotheses)

    n = hypotheses_to_refine([r["chirality"] for r in rows], [r["wks"] for r in rows])
    steps = [r.get("step_distortions", [None, r["distortion"]])[1:] for r in rows[:n]]   # after each step
    alive, got, early = list(range(n)), [len(s) for s in steps], ()
    if all(len(s) > 1 for s in steps):
        if n > 1 and all("round_distortions" in r for r in rows[:n]):   # after the first round of the first step
            early = tuple(r["round_distortions"][0] if r["round_distortions"] else r["step_distortions"][0]
                          for r in rows[:n])
            alive = surviving_hypotheses(early, drop_margin=EARLY_DROP_MARGIN)
        got = [1 if i in alive else 0 for i in range(n)]
        for k in range(1, len(steps[0])):                     # after step k, before the last
            alive = surviving_after_step([s[:got[i]] for i, s in enumerate(steps)], alive)
            for i in alive:
                got[i] = k + 1
    best = best_refined([np.zeros(0, dtype=np.int64)] * n, [s[:got[i]] for i, s in enumerate(steps)], alive=alive,
                        early=early)
    kept = rows[best.index]
    return {"refined": n, "dropped": sum(best.dropped), "dropped_later": sum(1 < g < len(steps[0]) for g in got),
            "dropped_early": sum(g == 0 for g in got),
            "kept": best.index, "confidence": best.confidence, "margin": best.margin,
            "right": kept["landmark_accuracy"] >= 0.5, "mean_error": kept["mean_error"],
            "twisted": kept["landmark_accuracy"] >= 0.5 and kept["mean_error"] > TWISTED_ERROR}


CHOICE_RULES = {"last step": lambda steps: steps[-1],
                "first and last steps": lambda steps: (steps[0] * steps[-1]) ** 0.5,
                "first step": lambda steps: steps[0]}


def choice_rules_line(results: list[dict]) -> None:
    """Print the flips other choice rules would have made among the same refined hypotheses (every one refined to
    the end, none dropped; a hypothesis scored by ``CHOICE_RULES``' function of its distortions after each step),
    next to ``refine.refinement_score``'s (the code's: the geometric mean over every step). ``results``: rows with
    ``choice``'s keys ("refined": how many candidates the code refines)."""
    from corr_core.correspondence.dense.refine import refinement_score

    rules = {"every step (the code's)": refinement_score, **CHOICE_RULES}
    flips = {rule: [] for rule in rules}
    for r in results:
        rows = r["candidates"][:r["refined"]]
        if len(rows) < 2 or any("step_distortions" not in c for c in rows):
            continue
        for rule, score in rules.items():
            kept = min(range(len(rows)), key=lambda i: (score(rows[i]["step_distortions"][1:]), i))
            if rows[kept]["landmark_accuracy"] < 0.5:
                flips[rule].append(f"seed {r['seed']} {r['mesh']}")
    print("flips when every hypothesis is refined to the end and chosen by its distortion after: " + "; ".join(
        f"{rule} {len(f)}" + (f" ({', '.join(f)})" if f else "") for rule, f in flips.items()))


def first_step_line(results: list[dict]) -> None:
    """Print how well the distortion after the first refinement step already tells the right map (the least
    distorted right one among the refined hypotheses) from the others: on how many targets it is the least
    distorted, and the others' excess over it (the ground of ``refine.surviving_hypotheses``)."""
    least, excess, counted = 0, [], 0
    for r in results:
        refined = r["candidates"][:r["refined"]]
        right = [i for i, c in enumerate(refined) if c["landmark_accuracy"] >= 0.5]
        if not right or len(refined) < 2 or any("step_distortions" not in c for c in refined):
            continue
        kept = min(right, key=lambda i: refined[i]["distortion"])
        first = [c["step_distortions"][1] for c in refined]
        counted += 1
        least += first[kept] == min(first)
        excess += [first[i] / first[kept] - 1 for i in range(len(refined)) if i != kept]
    if counted:
        print(f"after the first step: the right map the least distorted on {least} of {counted} targets; the "
              f"others' distortion above it by {min(excess):.1%} to {max(excess):.1%} (median "
              f"{np.median(excess):.1%})")


def later_steps_line(results: list[dict]) -> None:
    """Print how well the score so far (``refine.refinement_score`` of the distortions after the first k steps)
    tells the right map (the least distorted right one at the end) from the others after each step k >= 2 but the
    last: the largest ratio of the right map's score to the least one's, and how many of the other hypotheses are
    beyond ``refine.LATER_DROP_MARGIN`` there (the ground of dropping after a later step)."""
    from corr_core.correspondence.dense.refine import LATER_DROP_MARGIN, refinement_score

    refined = [r["candidates"][:r["refined"]] for r in results]
    refined = [c for c in refined if len(c) > 1 and all("step_distortions" in x for x in c)]
    n_steps = min((len(x["step_distortions"]) - 1 for c in refined for x in c), default=0)
    parts = []
    for k in range(2, n_steps):
        worst, beyond, others = 1.0, 0, 0
        for cands in refined:
            right = [i for i, x in enumerate(cands)
                     if x["landmark_accuracy"] >= 0.5 and x["mean_error"] <= TWISTED_ERROR]
            if not right:
                continue
            kept = min(right, key=lambda i: cands[i]["distortion"])
            so_far = [refinement_score(x["step_distortions"][1:k + 1]) for x in cands]
            least = min(so_far)
            worst = max(worst, so_far[kept] / least)
            beyond += sum(1 for i, d in enumerate(so_far) if i != kept and d > (1 + LATER_DROP_MARGIN) * least)
            others += len(so_far) - 1
        parts.append(f"after {k} steps: {worst:.3f}, {beyond}/{others}")
    if parts:
        print(f"score so far (the right map's / the least one's at most, the others beyond LATER_DROP_MARGIN "
              f"{LATER_DROP_MARGIN}): " + "; ".join(parts))


def rounds_line(results: list[dict]) -> None:
    """Print how well a shorter first step would judge: after each round r of the first (extrinsic) step, the
    largest ratio of the right map's distortion (the least distorted right one at the end) to the least
    distorted hypothesis's, and how many of the other hypotheses are beyond ``refine.DROP_MARGIN`` there (r = 0:
    the starting maps). A cheaper first step could drop hypotheses after r rounds only if that ratio stays well
    below 1 + DROP_MARGIN."""
    from corr_core.correspondence.dense.refine import DROP_MARGIN

    refined = [r["candidates"][:r["refined"]] for r in results]
    refined = [c for c in refined if len(c) > 1 and all("round_distortions" in x for x in c)]
    rounds = max((len(x["round_distortions"]) for c in refined for x in c), default=0)
    parts = []
    for r in range(rounds + 1):
        worst, beyond, others = 1.0, 0, 0
        for cands in refined:
            right = [i for i, x in enumerate(cands) if x["landmark_accuracy"] >= 0.5 and x["mean_error"] <= TWISTED_ERROR]
            if not right:
                continue
            kept = min(right, key=lambda i: cands[i]["distortion"])
            at = [x["round_distortions"][min(r, len(x["round_distortions"])) - 1] if r and x["round_distortions"]
                  else x["step_distortions"][0] for x in cands]
            worst = max(worst, at[kept] / min(at))
            beyond += sum(1 for i, d in enumerate(at) if i != kept and d > (1 + DROP_MARGIN) * min(at))
            others += len(at) - 1
        parts.append(f"{r}: {worst:.3f}, {beyond}/{others}")
    if parts:
        print(f"after r rounds of the first step (r: the right map's distortion / the least one's at most, the "
              f"others beyond DROP_MARGIN {DROP_MARGIN}): " + "; ".join(parts))


def generated_template(work: str, seed: int, n_poses: int, *, vary_bodies: bool = True, decimated: bool = True,
                       patch_geodesics: bool = True):
    """(dataset folder, template vertices (n,3), template basis) of one seed's generated humanoids under ``work``:
    the folder (``bodies_seed<seed>``, or ``same_seed<seed>`` for one body in every pose) is written on first use
    (``write_humanoid_dataset``, with a decimated copy of pose 1 when ``decimated``); the basis at ``SETTINGS``,
    with its refinement patches' geodesics computed once when ``patch_geodesics``."""
    from corr_core.correspondence.dense import basis
    from corr_core.generate.humanoid import write_humanoid_dataset
    from corr_core.geometry.mesh_io import load_mesh

    root = os.path.join(work, f"{'bodies' if vary_bodies else 'same'}_seed{seed}")
    if not os.path.isdir(root):
        write_humanoid_dataset(root, n_poses=n_poses, seed=seed, vary_bodies=vary_bodies,
                               remeshed=("decimated",) if decimated else ())
    V_s, F_s = load_mesh(os.path.join(root, "meshes", "template", "mesh000.obj"))
    S = basis.mesh_basis(V_s, F_s, k=SETTINGS["k"], n_samples=SETTINGS["n_samples"])
    if patch_geodesics:
        S.sample_distances(SETTINGS["n_patches"])
    return root, V_s, S


def generated_targets(root: str, decimated: bool):
    """(name, V, F, truth (n_template,) int) of every test mesh of a generated dataset."""
    from corr_core.geometry.mesh_io import load_mesh

    for path in sorted(glob.glob(os.path.join(root, "meshes", "test", "*.obj"))):
        name = os.path.splitext(os.path.basename(path))[0]
        V, F = load_mesh(path)
        gt = os.path.join(root, "ground_truth", f"{name}.txt")
        truth = np.loadtxt(gt, dtype=np.int64) if os.path.isfile(gt) else np.arange(len(V))
        if decimated or not os.path.isfile(gt):
            yield name, V, F, truth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--poses", type=int, default=6)
    ap.add_argument("--candidates", type=int, default=4, help="starting maps refined per target (all scored)")
    ap.add_argument("--decimated", action="store_true", help="also a decimated, shuffled copy of pose 1")
    ap.add_argument("--meshes", default=None, help="only these test meshes, e.g. mesh007 (comma-separated names)")
    ap.add_argument("--work", default=None, help="folder for the generated data (default: a temporary one)")
    ap.add_argument("--refine", default=None, help="refinement plan (default: refine.DEFAULT_REFINE)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    from corr_core.correspondence.dense import basis
    from corr_core.correspondence.landmarks import read_landmarks

    work = args.work or tempfile.mkdtemp(prefix="dense_hypotheses_")
    results = resumed_results(args.json)                     # resume: targets already in the file are kept
    done = {(r["seed"], r["mesh"]) for r in results}
    for seed in seed_range(args.seeds):
        root, V_s, S = generated_template(work, seed, args.poses, decimated=args.decimated)
        landmarks, _ = read_landmarks(os.path.join(root, "landmark_vids.txt"), n_vertices=len(V_s))
        for name, V_t, F_t, truth in generated_targets(root, args.decimated):
            if (seed, name) in done or (args.meshes and name not in args.meshes.split(",")):
                continue
            T = basis.mesh_basis(V_t, F_t, k=SETTINGS["k"], n_samples=SETTINGS["n_samples"])
            rows = score_candidates(S, T, V_t, F_t, truth, landmarks, args.candidates, args.refine)
            results.append({"seed": seed, "mesh": name, "n_vertices": len(V_t), "candidates": rows})
            c = choice(rows)
            cells = "  ".join(f"[{i}] chir {r['chirality']:.2f} wks {r['wks']:.4f} dist {r['distortion']:.4f} "
                              f"err {r['mean_error']:.4f} acc {r['landmark_accuracy']:.2f}"
                              for i, r in enumerate(rows))
            print(f"seed {seed} {name} ({len(V_t)} v): refined {c['refined']} (dropped {c['dropped']}), "
                  f"kept [{c['kept']}] "
                  f"{'FLIPPED' if not c['right'] else 'TWISTED' if c['twisted'] else 'right'}, confidence {c['confidence']:.2f} "
                  f"(margin {c['margin']:.3f})  |  {cells}", flush=True)
            if args.json:
                with open(args.json, "w") as fh:
                    json.dump(results, fh, indent=1)
    results = [{**r, **choice(r["candidates"])} for r in results]   # the choice as today's code makes it
    right = [r for r in results if r["right"] and not r["twisted"]]
    wrong = [r for r in results if not r["right"]]
    flipped = ", ".join(f"seed {r['seed']} {r['mesh']}" for r in wrong) or "none"
    print(f"\n{len(results)} targets, seeds {args.seeds}: {len(wrong)} flipped ({flipped}); mean error of the kept "
          f"maps {np.mean([r['mean_error'] for r in results]):.4f}")
    dropped_later = sum(r['dropped_later'] for r in results)
    dropped_early = sum(r.get('dropped_early', 0) for r in results)
    print(f"hypotheses refined: {sum(r['refined'] for r in results)}, of which dropped after the first round of the "
          f"first step: {dropped_early}, after the first step: "
          f"{sum(r['dropped'] for r in results) - dropped_later - dropped_early}, after a later step: "
          f"{dropped_later} (of the {sum(r['refined'] - 1 for r in results)} not kept)")
    first_step_line(results)
    later_steps_line(results)
    rounds_line(results)
    choice_rules_line(results)
    if right:
        margins = sorted(r["margin"] for r in right)
        print(f"right choices: margin min {margins[0]:.3f}, 10th percentile {np.percentile(margins, 10):.3f}, "
              f"median {np.median(margins):.3f}; confidence < 0.5 on {sum(r['confidence'] < 0.5 for r in right)} "
              f"of {len(right)}")
    if wrong:
        print("flipped choices: confidence " + ", ".join(f"{r['confidence']:.2f}" for r in wrong))
    twisted = [r for r in results if r["right"] and r["twisted"]]
    print(f"twisted (landmark accuracy >= 0.5, mean error > {TWISTED_ERROR}): {len(twisted)}" + "".join(
        f"; seed {r['seed']} {r['mesh']} (error {r['mean_error']:.3f}, confidence {r['confidence']:.2f})"
        for r in twisted))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
