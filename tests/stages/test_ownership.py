"""The tool never deletes what it does not own: publishing replaces only the files it published (recorded in
OUTPUT/.stages-published.json), and nothing is cleaned in a cache folder without the engine's marker."""
from __future__ import annotations

import json
import os
import time
import uuid

import pytest

from stages import api
from stages.errors import UserError
from stages.publish import PUBLISHED_NAME
from stages.cache_root import CACHE_MARKER

from tests.helpers import SYNTHETIC_YAML, cli_main, make_project, run_quiet


@pytest.fixture()
def project(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return make_project(tmp_path)



def test_a_folder_the_engine_did_not_create_is_never_removed(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "some" / "folder"
    precious = out / "precious"
    precious.mkdir(parents=True)
    (precious / "thesis.tex").write_text("years of work\n")
    p = make_project(tmp_path, yaml_text=SYNTHETIC_YAML.replace("  rep:\n", "  precious:\n")
                     + f"output: {out}\n")
    s = run_quiet(p)
    assert (precious / "thesis.tex").read_text() == "years of work\n"
    assert sorted(os.listdir(precious)) == ["thesis.tex"]
    assert "was not written by the engine" in capsys.readouterr().err
    assert s["published"] == 0


def test_republishing_replaces_only_the_engines_files(project, tmp_path):
    run_quiet(project)
    stage_dir = tmp_path / "results" / "syn" / "rep"
    assert (tmp_path / "results" / "syn" / PUBLISHED_NAME).is_file()
    (stage_dir / "my_notes.txt").write_text("mine\n")
    run_quiet(project, overrides=["rep.title=second"])
    assert (stage_dir / "summary.txt").read_text().startswith("second:")
    assert (stage_dir / "my_notes.txt").read_text() == "mine\n"


def test_a_file_of_the_user_in_the_engines_place_is_not_overwritten(project, tmp_path, capsys):
    stage_dir = tmp_path / "results" / "syn" / "rep"
    run_quiet(project)
    os.remove(stage_dir / "summary.txt")
    (tmp_path / "results" / "syn" / PUBLISHED_NAME).unlink()   # the engine no longer knows it wrote there
    (stage_dir / "summary.txt").write_text("the user's own file\n")
    run_quiet(project, overrides=["rep.title=again"])
    assert (stage_dir / "summary.txt").read_text() == "the user's own file\n"
    assert "was not written by the engine" in capsys.readouterr().err


def test_a_foreign_folder_is_never_used_or_cleaned_as_a_cache(project, tmp_path):
    foreign = tmp_path / "not_a_cache"
    (foreign / "tmp" / "old").mkdir(parents=True)
    (foreign / "tmp" / "old" / "keep.txt").write_text("x\n")
    (foreign / "photos").mkdir()
    old = time.time() - 10 * 3600
    os.utime(foreign / "tmp" / "old", (old, old))
    with pytest.raises(UserError, match="not a stages cache"):
        run_quiet(project, cache_dir=str(foreign))
    with pytest.raises(UserError, match=CACHE_MARKER):
        api.gc([str(project)], cache_dir=str(foreign))
    assert (foreign / "tmp" / "old" / "keep.txt").is_file() and (foreign / "photos").is_dir()


def test_the_cache_gets_a_marker_and_tmp_cleanup_removes_only_engine_folders(project, tmp_path):
    run_quiet(project)
    cache = tmp_path / "cache"
    assert (cache / CACHE_MARKER).is_file()
    engine_tmp = cache / "tmp" / uuid.uuid4().hex
    user_tmp = cache / "tmp" / "my_things"
    for d in (engine_tmp, user_tmp):
        d.mkdir(parents=True)
        (d / "f").write_text("x\n")
        old = time.time() - 10 * 3600
        os.utime(d, (old, old))
    run_quiet(project)
    assert not engine_tmp.exists()
    assert (user_tmp / "f").is_file()


def test_a_cache_without_marker_is_not_cleaned(project, tmp_path):
    run_quiet(project)
    cache = tmp_path / "cache"
    (cache / CACHE_MARKER).unlink()
    (cache / "photos").mkdir()  # now it is not recognisably the engine's folder
    stale = cache / "tmp" / uuid.uuid4().hex
    stale.mkdir(parents=True)
    old = time.time() - 10 * 3600
    os.utime(stale, (old, old))
    with pytest.raises(UserError):
        run_quiet(project)
    with pytest.raises(UserError):
        api.gc([str(project)])
    assert stale.is_dir()


def test_gc_removes_only_what_the_engine_created(project, tmp_path):
    run_quiet(project)
    cache = tmp_path / "cache"
    mine = cache / "generated" / "my_dataset"
    mine.mkdir(parents=True)
    (mine / "a.obj").write_text("v 0 0 0\n")
    (cache / "manifest" / "zz").mkdir(parents=True)
    (cache / "manifest" / "zz" / "notes.json").write_text("{}")
    api.run(str(project), workers=0, quiet=True, overrides=["sigma=3"])
    res = api.gc([str(project)])
    assert res["removed"] == 2                    # summary and rep of sigma=3
    assert (mine / "a.obj").is_file()
    assert (cache / "manifest" / "zz" / "notes.json").is_file()


# --- the engine's own files in the output folder, and folders it must never publish into ---

def test_a_users_metrics_json_is_never_replaced(project, tmp_path, capsys):
    """A metrics.json of the user's in the output folder (there before the first run, or put in place of the
    engine's later) is left as it is, with a warning naming it; the values stay readable from the cache."""
    out = tmp_path / "results" / "syn"
    out.mkdir(parents=True)
    (out / "metrics.json").write_text("precious\n")
    run_quiet(project)
    assert (out / "metrics.json").read_text() == "precious\n"
    assert f"{out / 'metrics.json'} exists and was not written by the engine" in capsys.readouterr().err
    assert api.metrics(api.plan_pipeline(str(project), quiet=True))["mean_affinity"] > 0

    other = tmp_path / "elsewhere"   # --out at a folder holding such a file: the same
    other.mkdir()
    (other / "metrics.json").write_text("mine too\n")
    run_quiet(project, output_dir=str(other))
    assert (other / "metrics.json").read_text() == "mine too\n"
    assert (other / "rep" / "summary.txt").is_file()            # the rest is published


def test_the_engines_metrics_json_replaced_by_the_user_is_kept(project, tmp_path, capsys):
    out = tmp_path / "results" / "syn"
    run_quiet(project)
    first = json.loads((out / "metrics.json").read_text())
    run_quiet(project, overrides=["sigma=2.0"])                 # the engine replaces its own file
    assert json.loads((out / "metrics.json").read_text()) != first
    (out / "metrics.json").write_text("precious\n")             # now the user's
    capsys.readouterr()
    run_quiet(project, overrides=["sigma=3.0"])
    assert (out / "metrics.json").read_text() == "precious\n"
    assert "metrics.json exists and was not written by the engine" in capsys.readouterr().err


def test_a_published_file_the_user_edited_is_not_overwritten_or_removed(project, tmp_path, capsys):
    stage_dir = tmp_path / "results" / "syn" / "rep"
    run_quiet(project)
    (stage_dir / "summary.txt").write_text("my edits\n")
    run_quiet(project, overrides=["rep.title=second"])
    assert (stage_dir / "summary.txt").read_text() == "my edits\n"
    assert "summary.txt exists and was not written by the engine" in capsys.readouterr().err
    os.remove(stage_dir / "summary.txt")                          # moved away: published again
    run_quiet(project, overrides=["rep.title=third"])
    assert (stage_dir / "summary.txt").read_text().startswith("third:")


def test_the_default_report_does_not_replace_a_users_report_html(project, tmp_path):
    from stages.report import write_report

    run_quiet(project)
    out = tmp_path / "results" / "syn"
    first = write_report(str(project))
    assert first == str(out / "report.html")
    assert write_report(str(project)) == first                   # its own file: replaced
    (out / "report.html").write_text("<p>my report</p>\n")
    with pytest.raises(UserError, match="report.html exists and was not written by the engine"):
        write_report(str(project))
    assert (out / "report.html").read_text() == "<p>my report</p>\n"


def test_a_sweep_figure_does_not_replace_a_users_file(tmp_path, capsys):
    from stages.sweep import plot_sweep

    rows = [{"point": {"sigma": str(s)}, "metrics": {"m": m}} for s, m in ((1, 2.0), (2, 5.0), (3, 3.0))]
    assert plot_sweep(rows, str(tmp_path), "sweeps/a.png") == str(tmp_path / "sweeps" / "a.png")
    assert plot_sweep(rows, str(tmp_path), "sweeps/a.png")       # its own: replaced
    (tmp_path / "sweeps" / "b.png").write_bytes(b"my picture")
    assert plot_sweep(rows, str(tmp_path), "sweeps/b.png") is None
    assert (tmp_path / "sweeps" / "b.png").read_bytes() == b"my picture"
    assert "b.png exists and was not written by the engine" in capsys.readouterr().err


@pytest.mark.parametrize("where", ["root", "mount", "home", "above-home", "cache", "inside-cache"])
def test_an_output_folder_where_publishing_could_do_harm_is_refused(project, tmp_path, monkeypatch, where):
    """Tested on stand-ins (a HOME under tmp_path; a folder the test declares a mount point, or the root of the
    file system as os.path sees it for a folder declared to be its own parent), so that a broken check
    publishes into tmp_path, never into / or the real home folder."""
    home = tmp_path / "home" / "me"
    home.mkdir(parents=True)
    monkeypatch.setenv("HOME", str(home))
    standin = tmp_path / "standin"
    standin.mkdir()
    if where == "mount":
        real_ismount = os.path.ismount
        monkeypatch.setattr(os.path, "ismount", lambda p: os.path.realpath(p) == str(standin) or real_ismount(p))
    if where == "root":
        real_dirname = os.path.dirname
        monkeypatch.setattr(os.path, "dirname", lambda p: p if p == str(standin) else real_dirname(p))
    out = {"root": str(standin), "mount": str(standin), "home": str(home), "above-home": str(home.parent),
           "cache": str(tmp_path / "cache"), "inside-cache": str(tmp_path / "cache" / "results")}[where]
    before = sorted(os.listdir(out)) if os.path.isdir(out) else None
    with pytest.raises(UserError, match="the engine does not publish there") as err:
        run_quiet(project, output_dir=out)
    monkeypatch.undo()
    assert out in str(err.value) and "--out" in err.value.fix
    assert (sorted(os.listdir(out)) if os.path.isdir(out) else None) == before   # nothing written there


def test_out_at_the_home_folder_is_an_error_line(project, tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    r = cli_main(["run", str(project), "--workers", "0", "--out", str(home)], tmp_path, env={"HOME": str(home)})
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert f"error: the output folder {home} is your home folder" in r.stderr, r.stderr
    assert os.listdir(home) == []


def test_a_damaged_publish_record_does_not_block_publishing_unchanged_files(project, tmp_path, capsys):
    """OUTPUT/.stages-published.json nested too deeply (or truncated): one warning; the published files that
    still hold exactly the stage's content are taken back, so the next publish works again."""
    out = tmp_path / "results" / "syn"
    run_quiet(project)
    (out / PUBLISHED_NAME).write_text("[" * 200000)
    capsys.readouterr()
    run_quiet(project)
    assert f"warning: {out / PUBLISHED_NAME}" in capsys.readouterr().err
    run_quiet(project, overrides=["rep.title=again"])
    assert (out / "rep" / "summary.txt").read_text().startswith("again:")


def test_the_default_report_refuses_a_dangerous_folder(project, tmp_path, monkeypatch):
    from stages.report import write_report

    run_quiet(project)
    monkeypatch.setenv("HOME", str(tmp_path / "results"))
    with pytest.raises(UserError, match="the engine does not publish there"):
        write_report(str(project), output_dir=str(tmp_path / "results"))
    assert not (tmp_path / "results" / "report.html").exists()


def test_metrics_json_under_a_record_of_an_older_engine_is_still_updated(project, tmp_path):
    """A record from before the engine kept checksums (stages only, paths without checksums): the metrics.json
    and report.html beside it were written by the engine (it always did), so they are still replaced."""
    out = tmp_path / "results" / "syn"
    run_quiet(project)
    from stages.checksums import write_checked_json
    write_checked_json(str(out / PUBLISHED_NAME), {"stages": {"rep": ["rep/summary.txt"]}})
    (out / "metrics.json").write_text('{"old": 1}')
    run_quiet(project, overrides=["sigma=2.0"])
    assert json.loads((out / "metrics.json").read_text())["sigma"] == 2.0
