"""``tests.helpers.cli_main`` (the CLI's main run in the test process, to spare a subprocess per command) prints
what a real ``python -m stages`` process prints: the same exit code, stdout and stderr (numbers and the folder
masked) for a plan, a run with --workers 0, results, a warning about a damaged engine table, a pipeline error and
a usage error."""
from __future__ import annotations

import re

from tests.helpers import cli, cli_main, make_project

COMMANDS = (["status", "p.yaml"],
            ["run", "p.yaml", "--workers", "0", "--summary-json", "s.json"],
            ["results", "p.yaml", "--json"],
            "damage",                                    # filehash.json made unreadable: a warning, then rebuilt
            ["status", "p.yaml"],
            ["run", "nope.yaml"],
            ["run", "p.yaml", "--workers", "two"])


def _masked(text: str, folder) -> str:
    return re.sub(r"\d+(\.\d+)?", "N", text.replace(str(folder), "<dir>"))


def test_cli_main_prints_what_a_stages_process_prints(tmp_path):
    folders = {how: tmp_path / how for how in ("process", "in_process")}
    for folder in folders.values():
        folder.mkdir()
        make_project(folder, n=6)
    stderr = []
    for command in COMMANDS:
        if command == "damage":
            for folder in folders.values():
                (folder / "cache" / "filehash.json").write_bytes(b"\xff\xfe{truncated")
            continue
        real = cli(command, folders["process"])
        mine = cli_main(command, folders["in_process"])
        assert mine.returncode == real.returncode, (command, real.stderr, mine.stderr)
        assert _masked(mine.stdout, folders["in_process"]) == _masked(real.stdout, folders["process"]), command
        assert _masked(mine.stderr, folders["in_process"]) == _masked(real.stderr, folders["process"]), command
        stderr.append(mine.stderr)
    assert "filehash.json" in stderr[3] and "warning:" in stderr[3]     # the comparison covered a warning,
    assert "error:" in stderr[4] and "--workers" in stderr[5]           # a pipeline error and a usage error
