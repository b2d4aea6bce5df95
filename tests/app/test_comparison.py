"""The comparison kind end to end (issue 33: a new phase kind through the registry): the
built-in comparison protocol run by simulated participants on the simulated device, its
trials recorded, analysed, and the report's numbers checked against the raw trials.tsv
read with pandas alone, scipy's binomtest and statsmodels' Holm correction."""

import json

import pandas as pd
import pytest
from scipy import stats
from statsmodels.stats.multitest import multipletests

from app.api import analyze, simulate_study

pytestmark = [pytest.mark.slow]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("comparison")
    s = simulate_study("comparison", 4, seed=21, data=tmp / "data", traces="none",
                       progress=None)
    assert s.complete
    report = analyze(tmp / "data", tmp / "report", formats=("json", "md"))
    return tmp, report


def test_the_sessions_record_one_choice_of_the_two_samples_felt(study):
    tmp, _ = study
    for f in sorted((tmp / "data").rglob("trials.tsv")):
        d = pd.read_csv(f, sep="\t", dtype=str, keep_default_na=False)
        pairs = d[(d["phase"] == "pairs") & (d["status"] == "valid")]
        left_out = d[(d["phase"] == "pairs") & d["status"].str.startswith("excluded")]
        # both orders of the 10 pairs of 5 samples: chosen, or left out after saturating
        # the drive as often as the protocol allows (a hard tapper and the firm sinusoid)
        assert len(pairs) + len(left_out) == 20
        assert set(pairs["item"]).isdisjoint(left_out["item"])
        felt = pairs["sample"].str.split("+")
        assert all(a in f for a, f in zip(pairs["answer"], felt, strict=True))
        assert (pairs["rating"] == "").all() and (pairs["correct"] == "").all()
        meta = json.loads((f.parent / "session.json").read_text())
        phase = next(p for p in meta["protocol"]["design"]["phases"] if p["name"] == "pairs")
        assert (phase["kind"], phase["dv"]) == ("comparison", "choice")


def test_the_report_agrees_with_the_raw_files(study):
    tmp, report = study
    (a,) = [x for x in report["analyses"] if x["id"] == "comparison/pairs"]
    assert a["type"] == "comparison" and a["n_subjects"] == 4
    rows = []
    for f in sorted((tmp / "data").rglob("trials.tsv")):
        d = pd.read_csv(f, sep="\t", dtype=str, keep_default_na=False)
        rows.append(d[(d["phase"] == "pairs") & (d["status"] == "valid")])
    d = pd.concat(rows)
    assert a["n_choices"] == len(d) > 40
    first, second = d["sample"].str.split("+").str[0], d["sample"].str.split("+").str[1]
    order = ["firm_spring", "soft_spring", "pulse_firm", "sinusoid_firm", "sinusoid_soft"]
    p_unc = []
    for r in a["pairs"]:
        mine = ((first == r["A"]) & (second == r["B"])) | ((first == r["B"]) & (second == r["A"]))
        assert order.index(r["A"]) < order.index(r["B"])
        assert r["n"] == mine.sum() <= 8  # 4 people × 2 orders, less what was left out
        assert r["chose_A"] == (d.loc[mine, "answer"] == r["A"]).sum()
        p = stats.binomtest(r["chose_A"], r["n"], 0.5).pvalue
        assert r["p_unc"] == pytest.approx(p, rel=1e-12)
        p_unc.append(p)
    holm = multipletests(p_unc, method="holm")[1]
    assert [r["p_corr"] for r in a["pairs"]] == pytest.approx(list(holm), rel=1e-12)
    o = a["order"][0]
    assert o["chose_first"] == (d["answer"] == first).sum() and o["n"] == len(d)
    assert o["p_unc"] == pytest.approx(stats.binomtest(o["chose_first"], len(d), 0.5).pvalue)
    won = d["answer"].value_counts()
    assert {r["sample"]: r["wins"] for r in a["samples"]} == {s: int(won.get(s, 0))
                                                                for s in order}
    md = (tmp / "report" / "report.md").read_text()
    assert "## comparison/pairs" in md and "exact binomial against 1/2" in md


def test_the_wide_export_gives_each_person_each_samples_share_of_wins(study):
    """JASP's wide table of a comparison phase: one row per person, per sample the share of
    its comparisons it won (a Friedman test on these columns is JASP's own next step)."""
    from app.api import export

    tmp, _ = study
    export(tmp / "data", tmp / "jasp", "jasp")
    wide = pd.read_csv(tmp / "jasp" / "wide_comparison_pairs.csv", dtype={"participant": str})
    for f in sorted((tmp / "data").rglob("trials.tsv")):
        d = pd.read_csv(f, sep="\t", dtype=str, keep_default_na=False)
        d = d[(d["phase"] == "pairs") & (d["status"] == "valid")]
        who = d["participant"].iloc[0]
        row = wide[wide["participant"] == who].iloc[0]
        for s in ("firm_spring", "pulse_firm", "sinusoid_soft"):
            felt = d["sample"].str.split("+").apply(lambda x, s=s: s in x)
            assert row[s] == pytest.approx((d.loc[felt, "answer"] == s).mean()), (who, s)
