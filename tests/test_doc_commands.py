"""Every ``--set`` / ``--grid`` key in README.md and docs/*.md names a parameter that exists.

A documented command line (``python -m stages CMD PIPELINE ... --set k=v``, in a code block or an inline code
span, lines joined where a span or a ``\\`` continuation wraps) is checked against the pipeline it names: the
pipeline file is read with those overrides (plan only, nothing runs), which fails on an unknown key. A bare
``--set k=v`` span (advice without a command) must be valid in at least one of the project's pipelines.
"""
from __future__ import annotations

import re
import shlex

import pytest

from stages.config import load_pipeline
from stages.errors import PipelineError

from tests.helpers import ROOT

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PIPELINES = [ROOT / "pipeline.yaml", *sorted((ROOT / "pipelines").glob("*.yaml"))]
PLACEHOLDER = re.compile(r"^[A-Z_]+$")     # PIPELINE in the usage lines of docs/engine.md
SYNTAX = {"a.b=v", "STAGE.PARAM=v"}        # docs/engine.md explaining the syntax


def _snippets(text: str) -> list[str]:
    """Code-block lines (continuations joined) and inline code spans (line breaks joined) of a Markdown text."""
    out, blocks = [], re.split(r"^```.*$", text, flags=re.M)
    for i, part in enumerate(blocks):
        joined = re.sub(r"\\\n\s*", " ", part).splitlines()
        if i % 2:                                  # inside a fenced block
            out += joined
        else:                                      # inline spans, and indented blocks' command lines
            out += [span.replace("\n", " ") for span in re.findall(r"`([^`]+)`", part, flags=re.S)]
            out += [line for line in joined if line.startswith("    ") and "python -m stages" in line]
    return out


def _overrides(tokens: list[str]) -> list[str]:
    """The key=value texts of every --set and --grid in a token list (a grid's first value stands for all)."""
    out = []
    for flag, value in zip(tokens, tokens[1:]):
        if flag == "--set":
            out.append(value)
        elif flag == "--grid":
            key, _, values = value.partition("=")
            out.append(f"{key}={values.split(',')[0]}")
    return out


def documented() -> tuple[list, list]:
    """([(doc, pipeline, overrides, text)] command lines with keys, [(doc, overrides, text)] bare advice)."""
    commands, bare = [], []
    for doc in DOCS:
        for snippet in _snippets(doc.read_text(encoding="utf-8")):
            if "--set" not in snippet and "--grid" not in snippet:
                continue
            for part in snippet.split(" #", 1)[0].split(";"):   # "git show ... > old.yaml; python -m stages ..."
                text = part.strip().lstrip("$ ").strip()
                try:
                    tokens = shlex.split(text)
                except ValueError:
                    tokens = text.split()
                keys = _overrides(tokens)
                if not keys:
                    continue
                if tokens[:3] == ["python", "-m", "stages"] and len(tokens) > 4:
                    pipeline = tokens[4]
                    if PLACEHOLDER.match(pipeline) or pipeline == "old.yaml":   # usage text; an old revision
                        continue
                    commands.append((doc.name, pipeline, keys, text))
                elif tokens and tokens[0] == "--set" and not set(keys) <= SYNTAX:
                    bare.append((doc.name, keys, text))
    return commands, bare


COMMANDS, BARE = documented()


def test_the_docs_have_commands_to_check():
    assert len(COMMANDS) >= 15 and len(BARE) >= 5, (len(COMMANDS), len(BARE))


@pytest.mark.parametrize("doc,pipeline,keys,text", COMMANDS, ids=[f"{c[0]}:{c[3][:60]}" for c in COMMANDS])
def test_documented_command_keys_exist_in_the_pipeline_it_names(doc, pipeline, keys, text, tmp_path):
    path = ROOT / pipeline
    assert path.is_file(), f"{doc}: `{text}` names {pipeline}, which does not exist"
    try:
        load_pipeline(str(path), keys, cache_dir=str(tmp_path / "cache"))
    except PipelineError as e:
        pytest.fail(f"{doc}: `{text}` fails on {pipeline}:\n{e}")


@pytest.mark.parametrize("doc,keys,text", BARE, ids=[f"{b[0]}:{b[2][:60]}" for b in BARE])
def test_documented_set_advice_is_valid_in_some_pipeline(doc, keys, text, tmp_path):
    errors = []
    for path in PIPELINES:
        try:
            load_pipeline(str(path), keys, cache_dir=str(tmp_path / "cache"))
            return
        except PipelineError as e:
            if "--set" not in str(e).splitlines()[0]:   # the keys were taken; another setting is missing
                return
            errors.append(f"{path.name}: {str(e).splitlines()[0]}")
    pytest.fail(f"{doc}: `{text}` is valid in no pipeline:\n" + "\n".join(errors))


@pytest.mark.parametrize("key,expected", [
    ("solve.sigma_scale=2", "did you mean align.sigma_scale (parameter of stage 'align' (align.solve))"),
    ("data.root=/x", "humans.root (pipeline parameter, used by the datasets)"),
    ("sigmaa=1", "sigma (pipeline parameter, used by stages mrf, mrf_oriented)"),
    ("mrf.sigmaa=1", "did you mean mrf.sigma (parameter of stage 'mrf' (corr.match_mrf))"),
])
def test_unknown_key_names_the_closest_keys_and_their_stage(key, expected, tmp_path):
    with pytest.raises(PipelineError) as info:
        load_pipeline(str(ROOT / "pipeline.yaml"), [key], cache_dir=str(tmp_path / "cache"))
    assert expected in str(info.value)
