"""Errors name the file, the line, the key and the fix; a repeated warning is printed once."""
from __future__ import annotations

from stages.errors import CorruptEntry, PipelineError, UserError, warn_once


def test_pipeline_error_reads_file_line_key_message_and_fix():
    err = PipelineError("unknown parameter 'sigmaa'", file="p.yaml", key="stages.summary.params", line=22,
                        fix="did you mean 'sigma'?")
    assert str(err) == "p.yaml:22: stages.summary.params: unknown parameter 'sigmaa'\n  fix: did you mean 'sigma'?"
    assert str(PipelineError("no stages", file="p.yaml")) == "p.yaml: no stages"      # no line: no ':N'
    assert str(UserError("cannot write /x", fix="use --cache")) == "cannot write /x\n  fix: use --cache"
    assert str(CorruptEntry("0123456789abcdef", "array a0")) == "cache entry 0123456789ab is corrupt: array a0"


def test_warn_once_prints_a_message_once(capsys):
    for _ in range(3):
        warn_once("test_errors: the same message")
    warn_once("test_errors: another message")
    assert capsys.readouterr().err.splitlines() == ["warning: test_errors: the same message",
                                                    "warning: test_errors: another message"]
