"""`atlasnn suite`: every member in its default profile and in ``fixed``; a finished run is kept,
an interrupted one resumed. The trainings themselves are replaced by stubs here."""

from __future__ import annotations

import json

import pytest

from atlasnn.experiments import _suite
from atlasnn.experiments._suite import SUITE_PROFILES, run_suite, suite_members


@pytest.mark.slow  # 36 s; test_overwrite_runs_finished_members_again runs the suite in CI
def test_every_member_runs_in_both_profiles_and_finished_runs_are_kept(tmp_path, monkeypatch):
    started, resumed = [], []

    def fake_run(cfg, run_dir, **kw):
        started.append((cfg.name, cfg.profile, run_dir.name))
        run_dir.mkdir(parents=True)
        (run_dir / "meta.json").write_text(json.dumps({"status": "complete"}))
        (run_dir / "results.json").write_text("{}")

    monkeypatch.setattr(_suite, "run_experiment", fake_run)
    monkeypatch.setattr(_suite, "resume_experiment", lambda run_dir, **kw: resumed.append(run_dir.parent.name))
    monkeypatch.setattr(_suite, "suite_summary", lambda dirs: {"dirs": [str(d) for d in dirs], "problems": []})
    monkeypatch.setattr(_suite, "suite_markdown", lambda summary: "")
    members = suite_members("hard")
    assert "fixed" in SUITE_PROFILES and len(members) == 7
    run_suite("hard", tmp_path, log=lambda *a: None)
    assert [(n, d) for n, _, d in started] == [(m, p) for m in members for p in ("default", "fixed", "solve")]
    assert {p for n, p, d in started if d == "fixed"} == {"fixed"}
    # a second call keeps what is complete and resumes what is not
    (tmp_path / members[0] / "fixed" / "meta.json").write_text(json.dumps({"status": "interrupted", "run_id": "r1"}))
    started.clear()
    run_suite("hard", tmp_path, log=lambda *a: None)
    assert started == [] and resumed == [members[0]]


@pytest.mark.long
def test_profiles_pick_a_subset_and_an_unknown_one_is_refused(tmp_path, monkeypatch):
    import pytest

    from atlasnn.errors import ConfigError

    started = []

    def fake_run(cfg, run_dir, **kw):
        started.append((cfg.name, run_dir.name, cfg.schemes))
        run_dir.mkdir(parents=True)
        (run_dir / "meta.json").write_text(json.dumps({"status": "complete"}))

    monkeypatch.setattr(_suite, "run_experiment", fake_run)
    monkeypatch.setattr(_suite, "suite_summary", lambda dirs: {"problems": []})
    monkeypatch.setattr(_suite, "suite_markdown", lambda summary: "")
    run_suite("hard", tmp_path, profiles=["solve"], only=["kepler-e09", "toda-3"], log=lambda *a: None)
    assert started == [("kepler-e09", "solve", ("solve",)), ("toda-3", "solve", ("solve",))]
    with pytest.raises(ConfigError, match="--profile adaptive: not a profile of the suite"):
        run_suite("hard", tmp_path, profiles=["adaptive"], log=lambda *a: None)


@pytest.mark.long
def test_overwrite_runs_finished_members_again(tmp_path, monkeypatch):
    started = []

    def fake_run(cfg, run_dir, **kw):
        started.append((run_dir.parent.name, kw.get("overwrite")))
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / "meta.json").write_text(json.dumps({"status": "complete"}))
        (run_dir / "results.json").write_text("{}")

    monkeypatch.setattr(_suite, "run_experiment", fake_run)
    monkeypatch.setattr(_suite, "suite_summary", lambda dirs: {"problems": []})
    monkeypatch.setattr(_suite, "suite_markdown", lambda summary: "")
    for overwrite in (False, False, True):
        run_suite("hard", tmp_path, profiles=["solve"], only=["toda-3"], overwrite=overwrite, log=lambda *a: None)
    assert started == [("toda-3", True), ("toda-3", True)]  # the second call kept it, the third ran it again
