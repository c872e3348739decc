"""Replay a run's tasks under several dispatch orders: how much the order the engine hands ready tasks to the workers
(``stages.execute.dispatch_order``) matters for a pipeline's wall time.

Reads the tasks of PIPELINE from a cache a run filled (their dependencies from the plan, their seconds from the
manifests), then simulates W workers taking the ready task that comes first in each order, every task costing
its stored seconds plus a fixed time to load its inputs and store its result.

    python -m stages run pipeline.yaml --cache /tmp/cold   # a cold run to replay
    python bench/dispatch_replay.py pipeline.yaml --cache /tmp/cold [--workers 2] [--overhead 0.07]
"""
from __future__ import annotations

import argparse
import heapq
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from stages import api  # noqa: E402
from stages.execute import dispatch_order  # noqa: E402


def replay(order: dict[str, tuple], deps: dict[str, list[str]], dependents: dict[str, list[str]],
           seconds: dict[str, float], workers: int, overhead: float) -> float:
    """Simulated wall seconds of running every task: a free worker takes the ready task first in ``order``."""
    waiting = {k: set(d) for k, d in deps.items()}
    ready = [(order[k], k) for k, d in waiting.items() if not d]
    heapq.heapify(ready)
    running: list[tuple[float, str]] = []
    now = 0.0
    while ready or running:
        while ready and len(running) < workers:
            _, k = heapq.heappop(ready)
            heapq.heappush(running, (now + seconds[k] + overhead, k))
        now, k = heapq.heappop(running)
        for d in dependents[k]:
            waiting[d].discard(k)
            if not waiting[d]:
                heapq.heappush(ready, (order[d], d))
    return now


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pipeline")
    ap.add_argument("--cache", required=True, help="the cache a run of PIPELINE filled")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--overhead", type=float, default=0.07, help="seconds per task to load and store (default 0.07)")
    args = ap.parse_args()
    plan = api.plan_pipeline(args.pipeline, cache_dir=args.cache, quiet=True)
    tasks = {t.key: t for t in plan.tasks()}
    seconds = {}
    for k in tasks:
        manifest = plan.store.manifest(k)
        if manifest is None:
            sys.exit(f"task {tasks[k].display} is not in {args.cache}: run the pipeline into that cache first")
        seconds[k] = float(manifest["info"].get("seconds", 0.0))
    deps = {k: [d for d in t.deps if d in tasks] for k, t in tasks.items()}
    dependents: dict[str, list[str]] = {k: [] for k in tasks}
    for k, ds in deps.items():
        for d in ds:
            dependents[d].append(k)
    engine = dispatch_order(tasks, dependents)
    plan_index = {k: i for i, k in enumerate(tasks)}
    work: dict[str, float] = {}
    for k in reversed(list(tasks)):        # dependency order: a task's dependents come after it
        work[k] = seconds[k] + max((work[d] for d in dependents[k]), default=0.0)
    orders = {
        "the engine's (longest chain still to come first)": engine,
        "plan order": {k: (i,) for k, i in plan_index.items()},
        "a task nothing waits for first, then the engine's": {
            k: (0 if not dependents[k] else 1, *engine[k]) for k in tasks},
        "most seconds still to come first (knows every time)": {k: (-work[k], plan_index[k]) for k in tasks},
    }
    total = sum(seconds.values())
    print(f"{args.pipeline}: {len(tasks)} tasks, {total:.1f} task seconds, {args.workers} workers, "
          f"{args.overhead * 1e3:.0f} ms per task to load and store; lower bound "
          f"{(total + args.overhead * len(tasks)) / args.workers:.1f} s")
    for name, order in orders.items():
        print(f"  {name:55s} {replay(order, deps, dependents, seconds, args.workers, args.overhead):6.1f} s")


if __name__ == "__main__":
    main()
