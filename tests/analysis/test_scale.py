"""Analysis at the scale of pooled studies (issue 58), on small samples that can still
fail: what made 10⁶ rows take hours is checked by what it did (a frame per session, attrs
copied into every frame, a table written once per participant), not by the clock — the
times are `hapticlab bench scale`'s."""

import json
import subprocess
import sys

import pandas as pd
import pytest

from analysis import load_sessions, select_sessions


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    from benchmarks._study import write_study

    data = tmp_path_factory.mktemp("scale") / "data"
    write_study(data, 12, protocol="factorial", seed=5)
    return data


def test_the_generator_writes_what_the_recorder_would(study):
    """Folders the loader reads as sessions, every row checked: the benchmark's data are
    session folders, not a shortcut around the reader."""
    d = load_sessions(study)
    t = d.attrs["session_table"]
    assert len(t) == 12 and set(t["identity"]) == {""} and set(t["status"]) == {"complete"}
    assert d.groupby("participant").size().between(26, 28).all()  # 24 sets, 3 refs, a redraw
    rated = d[d["valid"] & (d["status"] == "valid")]
    assert rated["rating"].between(1, 10).all() and set(rated["block"]) == {
        "rubber", "wood", "aluminum"}


def test_loading_builds_no_frame_per_session(study, monkeypatch):
    """One DataFrame per 50,000 rows, not one per session folder (40 ms each: 15 minutes
    for 21,700 sessions)."""
    import analysis.load as load

    made = []
    real = load.pd.DataFrame

    class Counting(real):
        def __init__(self, *a, **kw):
            made.append(1)
            super().__init__(*a, **kw)

    monkeypatch.setattr(load.pd, "DataFrame", Counting)
    load_sessions(study)
    assert len(made) <= 4  # the rows, the session table, and pandas' own


def test_the_loaded_tables_are_shared_not_copied_into_every_frame(study):
    """pandas deep-copies attrs into every derived frame: the session table and the files'
    hashes are kept shared (a column access cost 8 ms at 10⁵ rows when they were copied)."""
    d = load_sessions(study)
    sub = d[d["valid"]]
    col = d["rating"]
    for key in ("session_table", "files", "designs", "invalid_rows"):
        assert sub.attrs[key] is d.attrs[key] and col.attrs[key] is d.attrs[key], key
    rows, _ = select_sessions(d)
    assert rows.attrs["files"] is d.attrs["files"]


def test_a_backup_copy_is_still_found_without_reading_each_sessions_rows(study, tmp_path):
    import shutil

    data = shutil.copytree(study, tmp_path / "d")
    shutil.copytree(data / "sub-P00003", data / "backup" / "sub-P00003")
    _, table = select_sessions(load_sessions(data))
    dup = table[table["reason"].str.startswith("duplicate of")]
    assert list(dup["session_dir"]) == [str(data / "backup" / "sub-P00003" / "ses-1")]


@pytest.mark.slow
def test_beyond_the_stated_size_the_page_summarises_and_the_tsv_lists_all(study, tmp_path,
                                                                           monkeypatch):
    import analysis.report as report

    monkeypatch.setattr(report, "LISTED", 5)
    report.analyze(study, tmp_path / "r", formats=("md", "json"))
    md = (tmp_path / "r" / "report.md").read_text()
    assert "12 sessions were found, more than the 5 this page lists one by one" in md
    assert md.count("/sub-P000") <= 5  # no session's folder written out in the tables
    assert "24 files were read; the SHA-256 of each is in input_files.tsv" in md
    listed = pd.read_csv(tmp_path / "r" / "sessions.tsv", sep="\t", dtype=str)
    assert len(listed) == 12 and set(listed["included"]) == {"True"}
    files = pd.read_csv(tmp_path / "r" / "input_files.tsv", sep="\t", dtype=str)
    assert len(files) == 24
    rep = json.loads((tmp_path / "r" / "report.json").read_text())
    assert len(rep["selection"]["sessions"]) == 12  # report.json keeps every one


@pytest.mark.slow
def test_progress_is_told_for_each_step(study, tmp_path):
    from analysis.report import analyze

    said = []
    analyze(study, tmp_path / "r", formats=("json",),
            progress=lambda step, done, total: said.append((step.split(" (")[0], done, total)))
    steps = list(dict.fromkeys(s for s, _, _ in said))
    assert steps == ["loading sessions", "choosing the sessions", "analysing factorial/rating",
                     "drawing the figures", "writing the report"]
    assert ("loading sessions", 12, 12) in said


def test_the_command_line_tells_progress_on_long_work(monkeypatch, capsys):
    from app.api._say import progress_to_stderr

    clock = iter([0.0, 0.5, 2.5, 2.6, 3.0, 5.0, 5.1])
    monkeypatch.setattr("app.api._say.time.monotonic", lambda: next(clock))
    tell = progress_to_stderr()  # started at 0.0
    tell("loading sessions", 1, 100)    # 0.5: within the first 2 s, said nothing
    tell("loading sessions", 40, 100)   # 2.5: said
    tell("loading sessions", 41, 100)   # 2.6: too soon after the last
    tell("analysing x", 0, 1)           # 3.0: a new step, said at once
    tell("analysing x", 0, 1)           # 5.0: said again (every 2 s)
    err = capsys.readouterr().err.splitlines()
    assert err == ["hapticlab: loading sessions 40 of 100 (2 s)",
                   "hapticlab: analysing x (3 s)", "hapticlab: analysing x (5 s)"]


@pytest.mark.integration
@pytest.mark.slow
def test_the_scale_benchmark_runs_on_a_small_study(tmp_path):
    out = subprocess.run([sys.executable, "-m", "app", "bench", "scale", "--rows", "300,600",
                          "--repeats", "1", "--json"], capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads(out.stdout)
    small, big = res["sizes"]
    assert small["analyze_time_ratio"] == 1.0 and big["rows_ratio"] > 1.5
    assert small["analyze_peak_mb"] > 50 and big["export_peak_mb"] > 50  # measured, not 0
    assert "loading sessions" in big["analyze_steps_s"]
    assert all(a.startswith("realism/testing") for a in big["analyses"])
