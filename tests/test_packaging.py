"""Every third-party package that stages/, corr_core/ and shapecorr/ import is declared in pyproject.toml."""
import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions

from tests.helpers import ROOT

OWN_PACKAGES = ("stages", "corr_core", "shapecorr")


def _normalize(name: str) -> str:
    """PEP 503 name: lower case, runs of -, _ and . become -."""
    return re.sub(r"[-_.]+", "-", name).lower()


def declared_distributions(pyproject: dict) -> set[str]:
    """Normalized names of [project] dependencies (requirement strings like 'numpy>=1.24; python_version...')."""
    names = set()
    for requirement in pyproject["project"]["dependencies"]:
        names.add(_normalize(re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement).group(1)))
    return names


def imported_top_level_modules(folders=OWN_PACKAGES) -> dict[str, str]:
    """{top-level module: first file importing it} over every .py file of the folders (lazy imports too)."""
    found: dict[str, str] = {}
    for folder in folders:
        for path in sorted((ROOT / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
                if isinstance(node, ast.Import):
                    modules = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    modules = [node.module]
                else:
                    continue
                for module in modules:
                    found.setdefault(module.split(".")[0], str(path.relative_to(ROOT)))
    return found


def third_party(modules: dict[str, str]) -> dict[str, str]:
    return {m: f for m, f in modules.items()
            if m not in sys.stdlib_module_names and m not in OWN_PACKAGES and m != "__future__"}


def undeclared(modules: dict[str, str], declared: set[str]) -> list[str]:
    """'module (file): provided by ...' for each imported module no declared distribution provides."""
    providers = packages_distributions()
    problems = []
    for module, path in sorted(modules.items()):
        dists = {_normalize(d) for d in providers.get(module, [])}
        if not dists & declared:
            problems.append(f"{module} (imported by {path}; distribution {sorted(dists) or 'not installed'})")
    return problems


def test_every_imported_package_is_declared():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    modules = third_party(imported_top_level_modules())
    assert {"numpy", "PIL", "trimesh", "yaml"} <= set(modules)  # the walk sees lazy imports too
    problems = undeclared(modules, declared_distributions(pyproject))
    assert not problems, "imported but not declared in pyproject.toml [project] dependencies: " + "; ".join(problems)


def test_removing_a_declared_dependency_is_caught():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    modules = third_party(imported_top_level_modules())
    for removed in ("pillow", "trimesh", "pyyaml", "scikit-image"):
        declared = declared_distributions(pyproject) - {removed}
        assert undeclared(modules, declared), f"removing {removed} went unnoticed"
