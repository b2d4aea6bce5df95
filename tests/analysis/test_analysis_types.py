"""Each analysis type is one module behind a small registry (analysis/analyses), and none
of its results can vanish on the way to report.json."""

import pandas as pd
import pytest

from analysis.analyses import (
    TYPES,
    AnalysisType,
    ResultNotReported,
    analysis_for,
    analysis_type,
    report_entry,
)
from analysis.stats import StatsError


def test_a_phase_design_finds_its_type():
    assert analysis_for({"dv": "answer", "scoring": "all_correct"}).name == "identification"
    assert analysis_for({"dv": "rating", "within": ["sample"]}).name == "oneway"
    assert analysis_for({"dv": "rating", "within": ["frequency", "decay"]}).name == "factorial"
    assert analysis_for({"dv": "choice", "within": []}).name == "comparison"
    assert analysis_for({"dv": "forced_choice", "within": []}).name == "threshold"
    assert [t.name for t in TYPES][:4] == ["identification", "oneway", "factorial",
                                           "comparison"]
    with pytest.raises(KeyError, match="identification, oneway, factorial"):
        analysis_type("staircase")


def test_a_design_no_type_analyses_is_named():
    with pytest.raises(StatsError, match="no analysis type for a phase with dv 'rating' and "
                                         "factors \\[\\]"):
        analysis_for({"dv": "rating", "within": []})
    with pytest.raises(StatsError, match="dv 'none'"):  # familiarization: nothing to analyse
        analysis_for({"dv": "none", "within": []})


def _kind(entry, internal=()):
    return AnalysisType(
        name="probe", matches=lambda p: True, analyse=lambda r, p, a: {},
        entry=entry, methods=lambda res, phase, design: f"{res['n']} people",
        summary=lambda a: "", markdown=lambda a: ([], []), figures=lambda a, d, o: [],
        internal=internal)


RESULT = {"n": 3, "table": pd.DataFrame({"x": [1.0]}), "groups": {"a": {"mean": 1.0, "sd": 0.5},
                                                                   "b": {"mean": 2.0, "sd": 0.1}},
          "scratch": [1, 2]}


def test_a_result_key_left_out_of_the_entry_stops_the_report_with_its_name():
    """What a hand whitelist of keys did silently (issue 33): a key the type's entry forgot
    disappeared from report.json. Here it stops the report, named by its dotted path."""
    forgot = _kind(lambda r: {"table": r["table"],
                              "groups": {g: {"mean": v["mean"]} for g, v in r["groups"].items()}})
    with pytest.raises(ResultNotReported, match=r"'probe': groups\.a\.sd, groups\.b\.sd, "
                                                r"scratch of its result"):
        report_entry(forgot, RESULT, {}, {})


def test_keys_read_by_the_methods_passed_whole_or_declared_internal_are_reported():
    whole = _kind(lambda r: {"table": r["table"], "groups": r["groups"]}, internal=("scratch",))
    entry, methods = report_entry(whole, RESULT, {}, {})
    assert methods == "3 people"  # n reaches the report through the methods paragraph
    assert entry["groups"] == {"a": {"mean": 1.0, "sd": 0.5}, "b": {"mean": 2.0, "sd": 0.1}}
    assert type(entry["groups"]) is dict and type(entry["groups"]["a"]) is dict  # plain again
    wild = _kind(lambda r: {"table": r["table"], "n": r["n"],
                            "groups": {g: {"mean": v["mean"]} for g, v in r["groups"].items()}},
                 internal=("*.sd", "scratch"))
    assert report_entry(wild, RESULT, {}, {})[0]["groups"]["b"] == {"mean": 2.0}


def test_each_registered_type_declares_everything_the_report_asks_of_it():
    for t in TYPES:
        for f in (t.matches, t.analyse, t.entry, t.methods, t.summary, t.markdown, t.figures):
            assert callable(f), (t.name, f)
        assert all(isinstance(v, str) for v in t.captions.values()), t.name
