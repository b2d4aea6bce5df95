"""Protocols a lab has copied and edited: each is simulated and analysed as its design
declares, end to end, and the report's numbers agree with an independent computation
(statsmodels' AnovaRM, scipy's ttest_rel and statsmodels' multipletests on the raw
trials.tsv files read with pandas alone)."""

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from statsmodels.stats.anova import AnovaRM
from statsmodels.stats.multitest import multipletests

from app.api import analyze, simulate_study

pytestmark = [pytest.mark.slow]

VARIANTS = Path(__file__).resolve().parents[1] / "data" / "protocols"
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("variants")
    renamed = tmp / "realism_pilot.toml"  # a copy of realism.toml, renamed
    renamed.write_text((ROOT / "protocols" / "realism.toml").read_text()
                       .replace('name = "realism"', 'name = "realism_pilot"'))
    data = tmp / "data"
    for i, proto in enumerate([renamed, *sorted(VARIANTS.glob("*.toml"))]):
        s = simulate_study(proto, 5, seed=10 + i, data=data, prefix=proto.stem[:4],
                           traces="none", progress=None)
        assert s.complete
    report = analyze(data, tmp / "report", formats=("json", "md", "html"))
    return data, report, tmp / "report"


def _raw(data: Path) -> pd.DataFrame:
    """Every row of every trials.tsv, read with pandas alone (not through analysis)."""
    import json

    frames = []
    for f in sorted(data.rglob("trials.tsv")):
        d = pd.read_csv(f, sep="\t", dtype=str, keep_default_na=False)
        d["protocol"] = json.loads((f.parent / "session.json").read_text())["protocol"]["name"]
        frames.append(d)
    d = pd.concat(frames, ignore_index=True)
    d = d[d["status"] == "valid"]
    return d.assign(rating=pd.to_numeric(d["rating"]))


def _by_id(report):
    return {a["id"]: a for a in report["analyses"]}


def test_every_variant_gets_the_analysis_its_design_declares(study):
    _data, report, out = study
    a = _by_id(report)
    assert sorted(a) == ["realism_pilot/testing", "six_on_nine/main", "six_with_practice/main",
                         "two_by_three/rating"]
    assert {k: v["type"] for k, v in a.items()} == {
        "realism_pilot/testing": "oneway", "six_on_nine/main": "oneway",
        "six_with_practice/main": "oneway", "two_by_three/rating": "factorial"}
    # the methods are written from the data: scale, counts and pairs of each design
    assert "rated 6 samples on a 1–9 scale, 2 time(s)" in a["six_on_nine/main"]["methods"]
    assert "all 15 pairs" in a["six_on_nine/main"]["methods"]
    assert "rated 11 samples on a 1–7 scale, 3 time(s)" in a["realism_pilot/testing"]["methods"]
    assert "2 × 3 repeated-measures ANOVA (spring, transient" in \
        a["two_by_three/rating"]["methods"]
    # the practice phase is rated but not analysed, and none of its ratings are pooled
    assert not any(k.endswith("/practice") for k in a)
    md = (out / "report.md").read_text()
    assert "six_with_practice/practice" not in md and "## two_by_three/rating" in md
    for f in ("six_on_nine-main_means.png", "two_by_three-rating_all.png",
              "realism_pilot-testing_pvalues.png"):
        assert (out / f).stat().st_size > 1000, f


@pytest.mark.parametrize("aid, protocol, phase", [
    ("realism_pilot/testing", "realism_pilot", "testing"),
    ("six_on_nine/main", "six_on_nine", "main"),
    ("six_with_practice/main", "six_with_practice", "main"),
])
def test_oneway_numbers_match_statsmodels_and_scipy(study, aid, protocol, phase):
    data, report, _ = study
    a = _by_id(report)[aid]
    raw = _raw(data)
    d = raw[(raw["protocol"] == protocol) & (raw["phase"] == phase)]
    means = d.groupby(["participant", "sample"])["rating"].mean().reset_index()
    wide = means.pivot(index="participant", columns="sample", values="rating").dropna()
    ref = AnovaRM(means[means["participant"].isin(wide.index)], "rating", "participant",
                  within=["sample"]).fit().anova_table  # statsmodels, independent of ours
    row = a["anova"][0]
    assert row["F"] == pytest.approx(ref["F Value"].iloc[0], rel=1e-9)
    assert row["p_unc"] == pytest.approx(ref["Pr > F"].iloc[0], rel=1e-9)
    assert row["DF"] == ref["Num DF"].iloc[0] and row["DF_err"] == ref["Den DF"].iloc[0]
    # every pair: scipy's paired t-test, then Holm over the tested pairs (statsmodels)
    got = {(p["A"], p["B"]): p for p in a["pairwise"]}
    const = {tuple(c[:2]) for c in a["constant_pairs"]}
    assert len(got) + len(const) == len(list(itertools.combinations(wide.columns, 2)))
    full = means.pivot(index="participant", columns="sample", values="rating")
    keys, ps = [], []
    for (x, y), p in got.items():
        # listwise (the methods say so): the participants with every sample, as the ANOVA
        pair = full.loc[wide.index, [x, y]]
        t = stats.ttest_rel(pair[x], pair[y])
        keys.append((x, y))
        ps.append(t.pvalue)
        assert p["n"] == len(pair)
        assert p["t"] == pytest.approx(t.statistic, rel=1e-9)
        assert p["p_unc"] == pytest.approx(t.pvalue, rel=1e-9)
        assert p["mean_diff"] == pytest.approx((pair[x] - pair[y]).mean(), abs=1e-11)  # 12 digits
    holm = multipletests(ps, method="holm")[1]
    for k, h in zip(keys, holm, strict=True):
        assert got[k]["p_holm"] == pytest.approx(h, rel=1e-9)
    # sample means over participants, as numpy computes them
    for s in a["samples"]:
        assert s["mean"] == pytest.approx(means[means["sample"] == s["sample"]]["rating"]
                                          .mean(), rel=1e-11)


def test_two_by_three_matches_statsmodels(study):
    data, report, _ = study
    a = _by_id(report)["two_by_three/rating"]
    raw = _raw(data)
    d = raw[(raw["protocol"] == "two_by_three") & (raw["phase"] == "rating")].copy()
    levels = d["factors"].str.split(";").map(lambda kv: dict(x.split("=") for x in kv))
    d["spring"] = levels.map(lambda x: x["spring"])
    d["transient"] = levels.map(lambda x: x["transient"])
    ref = AnovaRM(d, "rating", "participant", within=["spring", "transient"],
                  aggregate_func="mean").fit().anova_table
    rows = {r["Source"]: r for r in a["groups"]["all"]["anova"]}
    for src, ref_src in (("spring", "spring"), ("transient", "transient"),
                         ("spring * transient", "spring:transient")):
        assert rows[src]["F"] == pytest.approx(ref.loc[ref_src, "F Value"], rel=1e-9), src
        assert rows[src]["p_unc"] == pytest.approx(ref.loc[ref_src, "Pr > F"], rel=1e-9), src
    eff = {e["factor"]: e for e in a["groups"]["all"]["main_effects"]}
    assert set(eff["transient"]["level_means"]) == {"none", "pulse", "ring"}
    per = d.groupby(["participant", "transient"])["rating"].mean().unstack()
    for lv in ("none", "pulse", "ring"):
        assert eff["transient"]["level_means"][lv] == pytest.approx(per[lv].mean(), rel=1e-11)
    assert np.isfinite([r["F"] for r in rows.values()]).all()
