"""The software a report's results came from: Python and package versions, and the git commit."""
from __future__ import annotations

import importlib.metadata
import platform
import subprocess

from .. import registry
from ..plan import Plan

ENGINE_PACKAGES = ("numpy", "dask", "distributed", "zarr", "pyyaml")


def package_versions(plan: Plan | None = None) -> dict[str, str]:
    """Python and package versions: the engine's dependencies, then the packages declared by the plugins
    that registered the plan's functions (all loaded plugins when ``plan`` is None)."""
    functions = [sp.spec.function for sp in plan.stages.values()] if plan is not None else None
    names = list(ENGINE_PACKAGES)
    for plugin in registry.plugins(functions):
        names += [n for n in plugin.report_packages if n not in names]
    out = {"python": platform.python_version()}
    for name in names:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def git_commit(folder: str) -> str | None:
    """``git rev-parse HEAD`` in ``folder``, or None outside a git checkout."""
    try:
        res = subprocess.run(["git", "rev-parse", "HEAD"], cwd=folder, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout.strip() if res.returncode == 0 else None
