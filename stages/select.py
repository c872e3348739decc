"""Part of a pipeline: target stages and what they need (``run PIPELINE STAGE ...``, ``--until``), and the stages
a run recomputes even when cached (``--force STAGE``: that stage and its downstream stages).

Works on stage names and the dependencies the pipeline file declares (inputs, ``foreach`` / ``pairs``,
``candidates``); nothing here knows what the stages compute.
"""
from __future__ import annotations

import dataclasses
import difflib

from .config import Pipeline, StageSpec
from .errors import PipelineError


def stage_deps(spec: StageSpec, stages: dict[str, StageSpec]) -> set[str]:
    """The stages ``spec`` reads directly: its inputs, what it runs over and its candidates stage."""
    return ({r.source for r in spec.inputs.values() if r.source in stages}
            | ({spec.over} if spec.over in stages else set())
            | ({spec.candidates} if spec.candidates in stages else set()))


def check_stages(pipe: Pipeline, names, option: str) -> None:
    """PipelineError naming the first of ``names`` that is not a stage of ``pipe`` (``option``: how it was given)."""
    for n in names:
        if n not in pipe.stages:
            close = difflib.get_close_matches(n, list(pipe.stages), n=1)
            raise PipelineError(f"{option} '{n}': the pipeline has no stage '{n}'", file=pipe.file,
                                fix=(f"did you mean '{close[0]}'? " if close else "")
                                + f"its stages: {', '.join(pipe.stages)}")


def upstream(pipe: Pipeline, targets) -> list[str]:
    """The ``targets`` and every stage they need, directly or not, in pipeline order."""
    need, todo = set(), list(targets)
    while todo:
        n = todo.pop()
        if n not in need:
            need.add(n)
            todo.extend(stage_deps(pipe.stages[n], pipe.stages))
    return [n for n in pipe.stages if n in need]


def downstream(pipe: Pipeline, names) -> list[str]:
    """The stages ``names`` and every stage that reads them, directly or not, in pipeline order."""
    out = set(names)
    for n, spec in pipe.stages.items():  # topological order: a stage's dependencies come first
        if stage_deps(spec, pipe.stages) & out:
            out.add(n)
    return [n for n in pipe.stages if n in out]


def only(pipe: Pipeline, targets) -> Pipeline:
    """``pipe`` with only the ``targets`` and the stages they need (all stages when ``targets`` is empty).

    Raises:
        PipelineError: a target is not a stage of the pipeline.
    """
    if not targets:
        return pipe
    check_stages(pipe, targets, "target")
    keep = upstream(pipe, targets)
    return dataclasses.replace(pipe, stages={n: pipe.stages[n] for n in keep})


def forced(pipe: Pipeline, names, full: Pipeline | None = None) -> frozenset[str]:
    """The stages a run recomputes even when cached: ``names`` and their downstream stages within ``pipe``.

    ``full``: the whole pipeline when ``pipe`` holds only some targets (a forced stage must be one of those).

    Raises:
        PipelineError: a name is not a stage of the pipeline, or not one that this run computes.
    """
    if not names:
        return frozenset()
    check_stages(full or pipe, names, "--force")
    outside = [n for n in names if n not in pipe.stages]
    if outside:
        raise PipelineError(f"--force {outside[0]}: the targets of this run ({', '.join(pipe.stages)}) do not need "
                            f"stage '{outside[0]}'", file=pipe.file,
                            fix=f"add it as a target (python -m stages run {pipe.file} ... {outside[0]}) or leave "
                                "out --force")
    return frozenset(downstream(pipe, names))
