"""Adaptive phases through the whole session path (issue 57): run by the simulated observer
on the simulated device, killed and resumed, recorded and analysed."""

from pathlib import Path

import pytest

from benchmarks.crash import kill_and_resume

pytestmark = [pytest.mark.integration, pytest.mark.slow]

JND_MINI = Path(__file__).parents[1] / "data" / "jnd_mini.toml"


def test_a_killed_adaptive_session_resumes_its_procedures_exactly(tmp_path):
    """kill -9 at random moments, then resume: every row kept, and the final rows — each
    trial's track, intensity and procedure state among them — those of the uninterrupted
    session (benchmarks.crash compares them column by column)."""
    r = kill_and_resume(4, protocol=str(JND_MINI), workdir=tmp_path / "scripted",
                        delay=(0.5, 3.0), traces="none")
    assert r["kills"] == 4 and r["lost_rows_events"] == 0
    assert r["sequence_matches"], r["mismatched"]
    # the simulated participant: its resume replays the recorded trials first, each
    # against its row (intensity and state included), then goes on
    r = kill_and_resume(2, protocol=str(JND_MINI), workdir=tmp_path / "simulated",
                        delay=(1.0, 4.0), traces="none", responder="simulated")
    assert r["kills"] == 2 and r["lost_rows_events"] == 0
    assert r["sequence_matches"], r["mismatched"]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    from app.api import analyze, simulate_study

    tmp = tmp_path_factory.mktemp("thresholds")
    s = simulate_study(JND_MINI, 3, seed=4, data=tmp / "data", traces="none", progress=None)
    assert s.complete
    report = analyze(tmp / "data", tmp / "report", formats=("json", "md"))
    return tmp, report


def _raw(tmp):
    import pandas as pd

    frames = [pd.read_csv(f, sep="\t", dtype=str, keep_default_na=False)
              for f in sorted((tmp / "data").rglob("trials.tsv"))]
    return pd.concat(frames, ignore_index=True)


def test_every_adaptive_trial_records_its_track_intensity_answer_and_state(study):
    import json

    tmp, _ = study
    d = _raw(tmp)
    adaptive = d[d["phase"].isin(["frequency", "amplitude"]) & (d["status"] == "valid")]
    assert len(adaptive) > 60
    assert (adaptive["track"] != "").all() and (adaptive["intensity"] != "").all()
    states = [json.loads(s) for s in adaptive["state"]]
    stair = [s for s, ph in zip(states, adaptive["phase"], strict=True) if ph == "frequency"]
    assert all("catch" in s or {"next", "step", "reversals"} <= set(s) for s in stair)
    quest = [s for s, ph in zip(states, adaptive["phase"], strict=True) if ph == "amplitude"]
    assert all(s["ci"][0] <= s["estimate"] <= s["ci"][1] for s in quest)
    # the answer is one of the two samples felt, right when it is the larger rendering
    for r in adaptive.itertuples():
        a, b = r.sample.split("+")
        assert r.answer in (a, b) and r.correct in ("0", "1")


def _box(lo, hi):
    """A flat prior within [lo, hi] (psignifit's MAP is then the maximum likelihood)."""
    import numpy as np

    return lambda v: ((np.asarray(v) >= lo) & (np.asarray(v) <= hi)).astype(float)


def test_the_report_fits_what_the_files_hold(study):
    """Each participant's threshold is psignifit's on the raw rows of trials.tsv (read with
    pandas alone; psignifit's MAP under flat priors, the call in
    tests/analysis/test_psychometric.py), and every threshold carries its criterion."""
    import numpy as np

    from analysis.psychometric import psi, psychometric_fit

    psignifit = pytest.importorskip("psignifit")
    tmp, report = study
    (a,) = [x for x in report["analyses"] if x["id"] == "jnd_mini/frequency"]
    assert a["type"] == "threshold" and a["criterion"] == 0.75 and a["n_subjects"] == 3
    assert {g["track"] for g in a["group"]} == {"wood-up", "wood-down"}
    assert all(g["criterion"] == 0.75 for g in a["group"])
    d = _raw(tmp)
    for f in a["fits"]:
        assert f["criterion"] == 0.75
        rows = d[(d["participant"] == f["participant"]) & (d["phase"] == "frequency")
                 & (d["status"] == "valid") & (d["track"] == f["track"])]
        x = rows["intensity"].astype(float).to_numpy()
        k = rows["correct"].astype(float).to_numpy()
        lv = np.unique(x)
        kk = np.array([k[x == v].sum() for v in lv])
        nn = np.array([(x == v).sum() for v in lv])
        u = np.log(lv)
        span = float(u.max() - u.min())

        ref = psignifit.psignifit(
            np.c_[u, kk, nn], sigmoid="weibull", experiment_type="2AFC",
            fixed_parameters={"eta": 0.0}, bounds={"lambda": (0.0, 0.06)},
            priors={"threshold": _box(u.min() - span, u.max() + span),
                    "width": _box(1e-9, 20 * span), "lambda": _box(0.0, 0.06)},
            estimate_type="MAP", verbose=False)
        t = float(np.exp(ref.threshold(0.75, return_ci=False)))
        est = ref.get_parameter_estimate()
        p = np.clip(psi("weibull", lv, est["threshold"], est["width"], 0.5, est["lambda"]),
                    1e-12, 1 - 1e-12)
        theirs = float(np.sum(kk * np.log(p) + (nn - kk) * np.log1p(-p)))
        ours = psychometric_fit(x, k, criterion=0.75, gof_samples=0)
        assert ours["loglik"] >= theirs - 1e-6  # ours is the maximum
        assert ours["threshold"] == pytest.approx(f["threshold"], rel=1e-9)
        assert ours["threshold_ml"] == pytest.approx(f["threshold_ml"], rel=1e-9)
        assert f["ci_low"] is None or f["ci_low"] < f["threshold"]
        assert f["ci_high"] is None or f["threshold"] < f["ci_high"]
        # the same threshold within 1 % where the likelihood has one peak (a width above
        # the finest step between the intensities tested; below it the answers flip
        # between two neighbouring intensities and any threshold between them is as
        # likely). 30 trials of a staircase leave a flat top: psignifit's optimizer stops
        # up to 0.6 % away on these, at a lower likelihood than ours (asserted above)
        if f["width"] > float(np.min(np.diff(u))):
            assert f["threshold_ml"] == pytest.approx(t, rel=1e-2), f
        assert f["n_trials"] == len(rows)
    md = (tmp / "report" / "report.md").read_text()
    assert "at 75 % correct" in md and "reversal average" in md and "QUEST+ estimate" in md
    for phase in ("frequency", "amplitude"):  # each track's staircase, the fitted functions
        for fig in ("tracks", "psychometric"):
            name = f"jnd_mini-{phase}_{fig}.png"
            assert (tmp / "report" / name).stat().st_size > 5000 and name in md


def test_exports_carry_the_procedure(study, tmp_path):
    import pandas as pd

    from analysis.bids import export_bids
    from analysis.export import export

    tmp, report = study
    long = pd.read_csv(export(tmp / "data", tmp_path / "l", "long-csv")[1],
                       keep_default_na=False, na_values=[""])
    adaptive = long[long["phase"].isin(["frequency", "amplitude"])]
    assert adaptive[["track", "intensity", "state", "answer", "correct"]].notna().all().all()
    files = export(tmp / "data", tmp_path / "w", "wide-csv")
    wide = pd.read_csv(next(f for f in files if f.name == "wide_jnd_mini_frequency.csv"))
    (a,) = [x for x in report["analyses"] if x["id"] == "jnd_mini/frequency"]
    for f in a["fits"]:  # the wide file's thresholds are the report's
        got = wide.set_index("participant").loc[f["participant"], f["track"]]
        assert got == pytest.approx(f["threshold"], rel=1e-9)
    assert any(f.name == "trials_jnd_mini_frequency.csv" for f in files)
    book = pd.read_csv(tmp_path / "w" / "codebook.csv", keep_default_na=False)
    assert "threshold of track wood-up at 75 % correct" in set(book["meaning"])
    export_bids(tmp / "data", tmp_path / "b")
    beh = pd.read_csv(next((tmp_path / "b").rglob("*_beh.tsv")), sep="\t")
    assert {"track", "intensity", "state"} <= set(beh.columns)
    import pyreadstat

    sav, _ = pyreadstat.read_sav(str(export(tmp / "data", tmp_path / "s", "spss")[-2]))
    assert {"track", "intensity", "state"} <= set(sav.columns)


def test_measured_jnds_replace_the_assumed_ones_and_a_resume_keeps_them(tmp_path):
    """`simulate --jnd report.json`: the simulated participants draw their JNDs around a
    report's measured Weber fractions. Measured at 5 % (a quarter of the 20 % assumed),
    the fitted thresholds fall accordingly; session.json records them, and a session
    resumed from its first rows answers as the uninterrupted one did."""
    import json
    import shutil
    import subprocess
    import sys

    report = {"analyses": [{"type": "threshold", "group": [
        {"parameter": "frequency", "criterion": 0.75, "weber_geomean": 0.05},
        {"parameter": "slope", "criterion": 0.75, "weber_geomean": 0.05}]}]}
    (tmp_path / "measured.json").write_text(json.dumps(report))
    cli = [sys.executable, "-m", "app"]
    out = subprocess.run([*cli, "simulate", str(JND_MINI), "--participants", "3", "--seed",
                          "4", "--data", str(tmp_path / "data"), "--traces", "none",
                          "--jnd", str(tmp_path / "measured.json")],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "frequency 5.0 %" in out.stderr
    folder = tmp_path / "data" / "sub-sim01" / "ses-1"
    meta = json.loads((folder / "session.json").read_text())
    assert meta["discrimination"] == {"frequency": pytest.approx(0.05),
                                      "slope": pytest.approx(0.05)}
    out = subprocess.run([*cli, "analyze", str(tmp_path / "data"), "--out",
                          str(tmp_path / "r"), "--format", "json"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    rep = json.loads((tmp_path / "r" / "report.json").read_text())
    (a,) = [x for x in rep["analyses"] if x["id"] == "jnd_mini/frequency"]
    up = next(g for g in a["group"] if g["track"] == "wood-up")
    assert up["weber_geomean"] < 0.12  # not the ~20 % the assumed JNDs give
    full = (folder / "trials.tsv").read_text()
    copy = tmp_path / "resumed" / "sub-sim01" / "ses-1"
    shutil.copytree(folder, copy)
    lines = full.splitlines(keepends=True)
    (copy / "trials.tsv").write_text("".join(lines[:20]))
    meta["status"] = "interrupted"
    (copy / "session.json").write_text(json.dumps(meta))
    out = subprocess.run([*cli, "resume", str(copy), "--quiet"], capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr

    def key(text):
        return [[c for i, c in enumerate(ln.split("\t")) if i in (4, 16, 17, 22, 23, 24)]
                for ln in text.splitlines()]

    assert key((copy / "trials.tsv").read_text()) == key(full)


def test_a_phase_of_two_surfaces_runs_as_identification_runs(tmp_path):
    """`presentation = "surfaces"`: the simulated participant taps each surface (each a
    window, its trace kept), then answers; the rows are as an interval phase's."""
    text = JND_MINI.read_text().replace('directions = ["up", "down"]',
                                        'directions = ["up", "down"]\npresentation = "surfaces"')
    f = tmp_path / "surfaces.toml"
    f.write_text(text)
    from app.api import simulate_study

    s = simulate_study(f, 1, seed=2, data=tmp_path / "data", traces="full", progress=None)
    assert s.complete
    import pandas as pd

    folder = tmp_path / "data" / "sub-sim01" / "ses-1"
    d = pd.read_csv(folder / "trials.tsv", sep="\t", dtype=str, keep_default_na=False)
    rows = d[(d["phase"] == "frequency") & (d["status"] == "valid")]
    assert len(rows) > 10 and (rows["placement"] == "").all()  # the surfaces are virtual
    for r in rows.itertuples():
        assert len(list(folder.glob(r.trace_file))) >= 2  # a window a surface at least
        assert r.answer in r.sample.split("+")
