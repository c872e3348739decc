"""Requests an object-store cache costs: the tests' synthetic pipeline (N items) on a local S3 server (moto),
cold, a no-op rerun and a changed parameter, in this process (no workers); the server's own request log counted.

Prints per run the requests by method, their total and per task, for the code of a git revision (``--ref``,
checked out in a temporary worktree) and for the working tree, side by side.

    python bench/s3_requests.py [--items 8] [--ref HEAD]

Needs the ``test`` extras (moto[server], s3fs).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r"""
import collections, json, logging, os, pathlib, sys, tempfile
root, items = sys.argv[1], int(sys.argv[2])
sys.path.insert(0, root)
os.environ["STAGES_PLUGINS"] = "tests.stages.synthetic_plugin"
from moto.server import ThreadedMotoServer
from tests.helpers import free_port, make_project, run_quiet
from stages import api
port = free_port()
server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
server.start()
os.environ.update({"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing",
                   "AWS_DEFAULT_REGION": "us-east-1", "AWS_ENDPOINT_URL": f"http://127.0.0.1:{port}"})
counts = collections.Counter()

class Count(logging.Handler):
    def emit(self, record):
        parts = record.getMessage().split('"')
        if len(parts) > 1:
            counts[parts[1].split(" ")[0].split("m")[-1]] += 1   # the method, without a colour code

log = logging.getLogger("werkzeug")
log.setLevel(logging.INFO)
log.addHandler(Count())
log.propagate = False
import fsspec
fsspec.filesystem("s3", use_listings_cache=False).mkdir("bench")
tmp = pathlib.Path(tempfile.mkdtemp())
os.chdir(tmp)
os.environ["STAGES_LOCAL_CACHE"] = str(tmp / "local")
project = make_project(tmp, n=items)
tasks = len(api.plan_pipeline(str(project), cache_dir="s3://bench/cache", quiet=True).tasks())
out = {"tasks": tasks}
for label, overrides in [("cold", []), ("no-op", []), ("sigma changed", ["sigma=2.0"])]:
    counts.clear()
    run_quiet(project, cache_dir="s3://bench/cache", overrides=overrides)
    out[label] = dict(counts)
server.stop()
print(json.dumps(out))
"""


def count(root: Path, items: int) -> dict:
    """Run the child script against the code at ``root``; its JSON (requests by method per run)."""
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(root), str(items)], capture_output=True, text=True,
                          cwd=root, env={**os.environ, "PYTHONPATH": str(root)})
    if proc.returncode:
        sys.exit(f"the count failed at {root}:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--items", type=int, default=8, help="items of the synthetic pipeline (default 8)")
    ap.add_argument("--ref", default="HEAD", help="git revision to compare with (default HEAD)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "ref"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tree), args.ref], check=True)
        try:
            before = count(tree, args.items)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)
    after = count(ROOT, args.items)
    print(f"synthetic pipeline, {args.items} items, {after['tasks']} tasks; requests to the S3 server")
    print(f"{'run':15s} {args.ref:>12s} {'working tree':>14s}  per task  (by method, working tree)")
    for run in ("cold", "no-op", "sigma changed"):
        b, a = sum(before[run].values()), sum(after[run].values())
        print(f"{run:15s} {b:12d} {a:14d}  {b / before['tasks']:.1f} -> {a / after['tasks']:.1f}  {after[run]}")


if __name__ == "__main__":
    main()
