"""The tool never deletes what it does not own: publishing replaces only the files it published (recorded in
OUTPUT/.stages-published.json), and nothing is cleaned in a cache folder without the engine's marker."""
from __future__ import annotations

import os
import time
import uuid

import pytest

from stages import api
from stages.errors import UserError
from stages.publish import PUBLISHED_NAME
from stages.store import CACHE_MARKER

from tests.helpers import SYNTHETIC_YAML, make_project, run_quiet


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
