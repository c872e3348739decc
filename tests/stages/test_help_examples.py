"""Every example command in ``python -m stages --help`` (and the subcommand helps) and every ``python -m stages``
command line in README.md is run here, with a temporary cache and output folder.

Commands that would compute a whole pipeline run with ``--dry-run`` (``run``, ``sweep``), ``gc`` with
``--dry-run``: the command line is still parsed and the pipeline planned with every ``--set`` / ``--grid`` key
checked, so an example naming a stage or parameter that does not exist fails. Placeholders in the README (a
scheduler address, ``/path/to/my/...``) are replaced by a free local address and a small folder of the right
layout.
"""
from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path

import pytest

from stages.cli import build_parser

from tests.helpers import COURSE_DATA, ROOT, cli, cli_main, free_port

PREFIX = "python -m stages"


def help_commands() -> list[str]:
    """The ``python -m stages ...`` lines of the main help and of each subcommand's help."""
    parser = build_parser()
    texts = [parser.format_help()]
    for action in parser._subparsers._group_actions:  # the subcommands
        texts += [p.format_help() for p in action.choices.values()]
    return [line.strip() for text in texts for line in text.splitlines() if line.strip().startswith(PREFIX + " ")]


def readme_commands() -> list[str]:
    """Every ``python -m stages ...`` command line in README.md: in code blocks (also after ``$ `` or
    ``&&``) and in inline code."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    found = []
    for block in re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S):
        block = re.sub(r"\\\n\s*", " ", block)        # a command continued on the next line
        for line in block.splitlines():
            for part in line.lstrip("$ ").split("&&"):
                if part.strip().startswith(PREFIX + " "):
                    found.append(part.strip())
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    found += [" ".join(m.split()) for m in re.findall(r"`(python -m stages [^`]+)`", prose)]   # may wrap
    return list(dict.fromkeys(found))


def _own_chairs(folder: Path) -> Path:
    """A small folder of the layout pipelines/chairs.yaml expects from a user (NAME.obj meshes)."""
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(3):
        (folder / f"chair{i}.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    return folder


def _own_poses(folder: Path, template: str = "mesh000") -> Path:
    """A copy of the course's SCAPE folder layout with two poses (what --set data.root expects), the template
    named ``template``."""
    src = COURSE_DATA / "scape"
    shutil.copytree(src, folder, ignore=lambda d, names: [n for n in names if n.endswith(".obj")
                                                          and n not in ("mesh000.obj", "mesh002.obj", "mesh004.obj")])
    if template != "mesh000":
        for kind in ("meshes", "flattened_meshes"):
            (folder / kind / "template" / "mesh000.obj").rename(folder / kind / "template" / f"{template}.obj")
    return folder


def _own_meshes(folder: Path, template: str) -> Path:
    """A folder of meshes with nothing else, ``template``.obj among them (pipelines/own_meshes.yaml)."""
    _own_chairs(folder)
    (folder / "chair0.obj").rename(folder / f"{template}.obj")
    return folder


def runnable(command: str, tmp: Path) -> list[str]:
    """The argument list to run for ``command``: placeholders replaced, a private cache and output, and
    ``--dry-run`` for the commands that would compute a whole pipeline."""
    args = shlex.split(command, comments=True)[3:]  # drop "python -m stages"
    template = next((a.split("=", 1)[1] for a in args if a.startswith("template=")), "mesh000")
    out = []
    for a in args:
        a = re.sub(r"tcp://SCHEDULER:\d+", f"tcp://127.0.0.1:{free_port()}", a)
        if "/path/to/my/chairs" in a:
            a = a.replace("/path/to/my/chairs", str(_own_chairs(tmp / "my_chairs")))
        if "/path/to/my/poses" in a:
            a = a.replace("/path/to/my/poses", str(_own_poses(tmp / "my_poses", template)))
        if "/path/to/my/meshes" in a:
            a = a.replace("/path/to/my/meshes", str(_own_meshes(tmp / "my_meshes", template)))
        if "/path/to/body_landmarks.txt" in a:
            (tmp / "body_landmarks.txt").write_text("0,tip\n1,corner\n")
            a = a.replace("/path/to/body_landmarks.txt", str(tmp / "body_landmarks.txt"))
        if re.fullmatch(r"\w+\.root=PATH", a):
            a = a.replace("PATH", str(_own_chairs(tmp / "my_shapes")))
        out.append(a)
    if "--cache" in out:
        out[out.index("--cache") + 1] = str(tmp / "cache")
    else:
        out += ["--cache", str(tmp / "cache")]
    command_name = out[0]
    if command_name in ("run", "sweep", "gc") and "--dry-run" not in out:
        out.append("--dry-run")
    if command_name == "run" and "--out" not in out:
        out += ["--out", str(tmp / "out")]
    if command_name == "report" and "--out" not in out:
        out += ["--out", str(tmp / "report.html")]
    if command_name == "functions":
        out = out[:1]  # takes no cache
    return out


def _needs_course_data(command: str) -> bool:
    return "pipelines/chairs.yaml" in command or "pipelines/scape.yaml" in command


def _check(command: str, tmp: Path) -> None:
    args = runnable(command, tmp)
    r = cli_main(args, ROOT)   # in this process: the same output as python -m stages (test_cli_in_process.py)
    ok = (0, 3) if args[0] == "results" else (0,)  # results of a configuration not computed yet: 3
    assert r.returncode in ok, f"{command}\n-> {args}\nrc={r.returncode}\n{r.stderr[-3000:]}"
    assert "Traceback" not in r.stderr, r.stderr


def test_the_examples_are_found():
    assert len(help_commands()) >= 4
    assert any(c.startswith(PREFIX + " sweep") for c in help_commands())
    assert len(readme_commands()) >= 8


@pytest.mark.parametrize("command", help_commands())
def test_help_example_runs(command, tmp_path):
    _check(command, tmp_path)


@pytest.mark.parametrize("command", [pytest.param(c, marks=[pytest.mark.course] if _needs_course_data(c) else [])
                                     for c in readme_commands()])
def test_readme_command_runs(command, tmp_path):
    if _needs_course_data(command) and not COURSE_DATA.is_dir():
        pytest.skip(f"course data not found at {COURSE_DATA}")
    _check(command, tmp_path)


def test_a_grid_on_a_stage_that_does_not_exist_fails(tmp_path):
    """The check above can fail: the old help example named a stage no pipeline has."""
    r = cli_main(runnable("python -m stages sweep pipeline.yaml --grid align_mrf.sigma_scale=0.5,1,2", tmp_path), ROOT)
    assert r.returncode == 2 and "align_mrf" in r.stderr, r.stderr
