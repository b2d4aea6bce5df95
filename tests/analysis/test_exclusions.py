"""Exclusions that say why (issue 53, item 7): every participant of the selection who is not
in an analysis is listed under the reason that applies — missing sets before constant
ratings, never reached the block — and the counts of the methods add up."""

import json
import shutil
import sys
from pathlib import Path

import pandas as pd
import pytest

from analysis.study import rating_factorial

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "r"))
import studies  # noqa: E402

#: the checks that leave a participant out of an analysis, in the order they are asked
LEFT_OUT = ("never_reached", "no_valid_rating", "no_valid_answer", "no_valid_choice",
            "missing_cells", "constant_ratings")


def _left_out(exclusions) -> dict[str, set[str]]:
    rows = exclusions.to_dict(orient="records") if isinstance(exclusions, pd.DataFrame) \
        else exclusions
    return {r["check"]: set(filter(None, r["subjects_excluded"].split(",")))
            for r in rows if r["check"] in LEFT_OUT}


def test_the_r_study_reaches_both_cases():
    """P11 reached only the wood block and rated 2 of its 8 sets, both the same."""
    res = rating_factorial(studies.STUDIES["factorial"](), studies.FACTORS, by="block",
                           normalize="zscore_block")
    everyone = {f"P{k:02d}" for k in range(1, 12)}
    for block, v in res.items():
        out = _left_out(v["preflight"])
        if block == "wood":  # missing sets first: 'every set the same' would be false of P11
            assert out == {"missing_cells": {"P11"}}, out
        else:
            assert out["never_reached"] == {"P11"}, out
        if block == "aluminum":
            assert out["constant_ratings"] == {"P04"}
        left = set().union(*out.values())
        assert v["n_subjects"] + len(left) == len(everyone)  # the counts add up
        assert v["n_selected"] == len(everyone)


def test_a_participant_who_reached_a_block_without_a_valid_rating_is_named():
    d = studies.STUDIES["factorial"]()
    d.loc[(d.participant == "P02") & (d.block == "rubber"), "valid"] = False
    res = rating_factorial(d, studies.FACTORS, by="block", normalize="zscore_block")
    out = _left_out(res["rubber"]["preflight"])
    assert out["no_valid_rating"] == {"P02"}
    assert "P02" not in set().union(*(_left_out(res[b]["preflight"]).get("never_reached", set())
                                      for b in res))


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """Six participants of the factorial protocol: P000001 rated 2 of the wood block's 8
    sets, both 6; P000002's session stopped before the aluminum block (interrupted)."""
    from benchmarks._study import write_study

    data = tmp_path_factory.mktemp("fac") / "data"
    write_study(data, 6, protocol="factorial", seed=3)
    t = data / "sub-P00001" / "ses-1" / "trials.tsv"
    lines = t.read_text().splitlines(keepends=True)
    out, kept = [lines[0]], 0
    for ln in lines[1:]:
        c = ln.rstrip("\n").split("\t")
        if c[7] == "wood" and c[10] == "valid":
            if kept == 2:
                continue
            kept += 1
            c[14] = "6"
            ln = "\t".join(c) + "\n"
        out.append(ln)
    t.write_text("".join(out))
    t = data / "sub-P00002" / "ses-1" / "trials.tsv"
    lines = t.read_text().splitlines(keepends=True)
    t.write_text("".join([lines[0]] + [ln for ln in lines[1:]
                                       if ln.split("\t")[7] != "aluminum"]))
    m = data / "sub-P00002" / "ses-1" / "session.json"
    meta = json.loads(m.read_text())
    meta["status"] = "interrupted"
    m.write_text(json.dumps(meta))
    return data


@pytest.mark.slow
def test_the_report_lists_everyone_left_out_of_each_block_and_the_methods_add_up(study,
                                                                                tmp_path):
    from analysis.report import analyze

    rep = analyze(study, tmp_path / "r", formats=("json", "md"), status="all")
    a = next(a for a in rep["analyses"] if a["id"] == "factorial/rating")
    groups = a["groups"]
    assert _left_out(groups["wood"]["exclusions"]) == {"missing_cells": {"P00001"}}
    assert _left_out(groups["aluminum"]["exclusions"]) == {"never_reached": {"P00002"}}
    assert _left_out(groups["rubber"]["exclusions"]) == {}
    for g, v in groups.items():
        left = set().union(*_left_out(v["exclusions"]).values())
        assert v["n_subjects"] + len(left) == 6, g
    methods = a["methods"]
    assert "Of 6 participants" in methods
    assert "5 in aluminum, 6 in rubber, 5 in wood" in methods
    md = (tmp_path / "r" / "report.md").read_text()
    assert "never reached this block" in md and "P00002" in md
    assert "gave every set in this block the same rating" not in md


def test_a_copy_of_the_study_keeps_its_shape(study, tmp_path):
    """The hostile edits above are what the report test reads (a guard on the fixture)."""
    from analysis import load_sessions

    d = load_sessions(shutil.copytree(study, tmp_path / "c"))
    p1 = d[(d.participant == "P00001") & (d.block == "wood") & d.valid]
    assert len(p1) == 2 and set(p1["rating"]) == {6.0}
    assert "aluminum" not in set(d.loc[d.participant == "P00002", "block"])


def test_the_oneway_analysis_names_who_never_reached_its_phase():
    from analysis.analyses.oneway import ONEWAY
    from analysis.study import rating_oneway

    d = studies.STUDIES["oneway_small"]()
    d = pd.concat([d, pd.DataFrame([{"participant": "P98", "sample": "s01", "rating": None,
                                     "valid": False, "group": "", "block": "",
                                     "repetition": 1}])], ignore_index=True)
    d.attrs["participants"] = sorted({*d["participant"], "P99"})
    res = rating_oneway(d)
    out = _left_out(res["preflight"])
    assert out == {"never_reached": {"P99"}, "no_valid_rating": {"P98"}}
    assert res["n_subjects"] + 2 == len(d.attrs["participants"])
    methods = ONEWAY.methods(res, {}, {"scale": {"min": 1, "max": 7}})
    assert "2 participant(s) of the selected sessions left no valid rating" in methods


def _phase(rows: list[dict], everyone: list[str]) -> pd.DataFrame:
    """A phase's rows, answering for ``everyone`` (as :func:`analysis.study.phase_rows`)."""
    d = pd.DataFrame(rows)
    d.attrs["participants"] = everyone
    return d


@pytest.mark.parametrize("kind", ["identification", "comparison"])
def test_identification_and_comparison_name_everyone_they_leave_out(kind):
    """P1–P3 answered; P4 reached the phase with every attempt invalid; P5's session stopped
    before it. Both are listed, each under its reason; the methods' counts add up to the
    five selected; the report's entry and Markdown carry the list."""
    from analysis.analyses.base import report_entry
    from analysis.analyses.comparison import COMPARISON
    from analysis.analyses.identification import IDENTIFICATION
    from analysis.report import _clean
    from analysis.study import answer_scores, choice_scores

    everyone = ["P1", "P2", "P3", "P4", "P5"]
    rows = []
    for p in everyone[:4]:
        for rep in (1, 2):
            if kind == "identification":
                answer = "wood,rubber" if p != "P2" or rep == 1 else "rubber,wood"
                rows.append({"participant": p, "sample": "wood+rubber", "answer": answer,
                             "correct": int(answer == "wood,rubber"), "repetition": rep,
                             "group": "", "valid": p != "P4"})
            else:
                for first, second in (("a", "b"), ("b", "a")):
                    rows.append({"participant": p, "sample": f"{first}+{second}",
                                 "answer": "a" if p != "P3" else second, "repetition": rep,
                                 "group": "", "valid": p != "P4"})
    d = _phase(rows, everyone)
    kind_, res = ((IDENTIFICATION, answer_scores(d)) if kind == "identification" else
                  (COMPARISON, choice_scores(d, ["a", "b"])))
    what = {"identification": "answer", "comparison": "choice"}[kind]
    assert _left_out(res["exclusions"]) == {"never_reached": {"P5"},
                                            f"no_valid_{what}": {"P4"}}
    assert res["n_subjects"] == 3 and res["n_selected"] == 5  # 3 + 2 left out
    entry, methods = report_entry(kind_, res, {}, {})
    assert methods.startswith("3 participants ")
    assert (f"Of the 5 participants of the selected sessions, 2 gave no valid {what} in this "
            "phase") in methods
    assert entry["exclusions"] == res["exclusions"] and entry["n_selected"] == 5
    md = "".join(kind_.markdown(_clean({"id": kind, **entry}))[0])  # as the report does
    assert "#### Exclusions" in md and "P4" in md and "P5" in md
