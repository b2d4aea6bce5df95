"""Responses are declared once (protocols/responses.py) and read everywhere else: the
runner, the responders, the texts, the loader, and the analysis, which reads the rules a
session recorded with its design (analysis/cells.py)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.cells import LEGACY, cell_problem, column_meanings, row_problem
from protocols import load_protocol
from protocols.kinds import phase_kind, phase_kinds
from protocols.responses import (
    ANSWER,
    CHOICE,
    RATING,
    Cell,
    Question,
    Response,
    Wide,
    response,
    responses,
)
from protocols.texts import DEFAULT_TEXTS


def test_every_kind_asks_a_declared_response_or_nothing():
    for name in phase_kinds():
        k = phase_kind(name)
        assert k.response is None or response(k.response) is k.asks
        assert k.columns == (k.asks.columns if k.asks else ())
    with pytest.raises(KeyError, match="the responses are " + ", ".join(responses())):
        response("sigh")


def test_older_sessions_read_as_the_three_responses_record_themselves_now():
    """A session recorded before responses recorded themselves carries only its phase's dv;
    the analysis reads it by LEGACY, which must say what the declarations say (a
    declaration that changes its rules changes what new sessions record, and this test
    then asks whether older files keep their old meaning)."""
    for r in (RATING, ANSWER, CHOICE):
        assert LEGACY[r.dv] == r.record(), r.name


def test_each_response_brings_its_texts_and_a_text_is_declared_once():
    seen = {}
    for name in responses():
        for key in response(name).texts:
            assert key not in seen, f"{key} is declared by {seen.get(key)} and {name}"
            seen[key] = name
            assert key in DEFAULT_TEXTS
    assert DEFAULT_TEXTS["choice_keys"] == CHOICE.texts["choice_keys"]


def test_a_declaration_is_checked():
    rt = RATING.cell("response_time")
    with pytest.raises(ValueError, match="response_time among them"):
        Response("x", "", "x", (Cell("answer", "", ""),), RATING.wide, RATING.ask,
                 RATING.row, RATING.scripted, RATING.simulated)
    with pytest.raises(ValueError, match="type must be one of"):
        Cell("answer", "", "", type="colour")
    with pytest.raises(ValueError, match="among must be"):
        Cell("answer", "", "", among="everyone")
    with pytest.raises(ValueError, match="must be one of"):
        Wide("answer", "person", "", "")
    with pytest.raises(ValueError, match="shown_when names texts"):
        Response("x", "", "x", (rt,), RATING.wide, RATING.ask, RATING.row, RATING.scripted,
                 RATING.simulated, shown_when={"nowhere": "keys"})


REALISM = load_protocol("realism")
IDENT = load_protocol("identification")
TRIAL = type("T", (), {"samples": ("firm_spring",), "sample": "firm_spring"})()
SURFACES = type("T", (), {"samples": ("rubber", "wood", "aluminum"),
                          "sample": "rubber+wood+aluminum"})()


def _analysed(r: Response, row: dict, trial, protocol) -> str:
    """The analysis's verdict on a recorded row: the text trials.tsv holds, the rules the
    session recorded."""
    text = {c: "" if v is None else str(v) for c, v in row.items()}
    return row_problem({**text, "status": "valid", "sample": trial.sample},
                       {"response": r.record()}, protocol.design())


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.integers(-3, 12), st.floats(allow_nan=True), st.booleans(),
                 st.text(max_size=3)), st.floats(0, 30))
def test_a_rating_the_runner_records_is_one_the_analysis_counts(value, rt):
    """The declaration turns the responder's value into the row (or refuses it, saying
    why), and what it lets through passes the rule the analysis applies: a session never
    records a rating its analysis would set aside, and what it refuses is off the scale."""
    q = Question(TRIAL, REALISM, [None])
    try:
        row = RATING.answer_row(value, rt, q)
    except ValueError as exc:
        assert "not a point of the scale 1–7" in str(exc)
        assert not (isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 7)
        return
    assert _analysed(RATING, row, TRIAL, REALISM) == ""
    assert row["rating"] in range(1, 8) and row["response_time"] == round(rt, 3)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.sampled_from(["rubber", "wood", "aluminum", "glass"]), max_size=4))
def test_names_for_the_surfaces_are_recorded_only_when_the_analysis_counts_them(names):
    q = Question(SURFACES, IDENT, [None, None, None])
    try:
        row = ANSWER.answer_row(names, 2.0, q)
    except ValueError:
        assert len(names) != 3
        return
    why = _analysed(ANSWER, row, SURFACES, IDENT)
    assert (why == "") == ("glass" not in names), why
    assert row["correct"] == int(names == ["rubber", "wood", "aluminum"])


def test_a_choice_is_an_index_of_the_samples_felt():
    pair = type("T", (), {"samples": ("a", "b"), "sample": "a+b"})()
    q = Question(pair, REALISM, [None, None])
    assert CHOICE.answer_row(1, 0.5, q) == {"answer": "b", "response_time": 0.5}
    for bad in (2, -1, True, 0.0, "a"):
        with pytest.raises(ValueError, match="not one of the 2 samples felt"):
            CHOICE.answer_row(bad, 0.5, q)
    with pytest.raises(ValueError, match="response time"):
        CHOICE.answer_row(0, math.nan, q)


@pytest.mark.parametrize("column, text, why", [
    ("rating", "99", "rating 99 is outside the scale 1–7"),
    ("rating", "inf", "rating inf is not a finite number"),
    ("rating", "", "a valid trial without a rating"),
    ("rating", "x", "rating 'x' is not a number"),
    ("rating", "2.5", "rating 2.5 is not a point of the scale"),
    ("response_time", "-1", "response time -1 is outside at least 0"),
    ("response_time", "", ""),
])
def test_the_rules_say_why_in_words(column, text, why):
    cell = RATING.record()["cells"][column]
    got = cell_problem(text, column, cell, {"sample": "firm"}, REALISM.design())
    assert got == why


def test_names_and_choices_are_checked_against_the_trial_and_the_design():
    cells = ANSWER.record()["cells"]
    d = IDENT.design()
    row = {"sample": "rubber+wood+aluminum"}
    assert cell_problem("rubber,wood", "answer", cells["answer"], row, d) == \
        "answer 'rubber,wood' names 2 surfaces, the trial had 3"
    assert cell_problem("rubber,wood,glass", "answer", cells["answer"], row, d) == \
        "answer names glass, not among rubber, wood, aluminum"
    assert cell_problem("2", "correct", cells["correct"], row, d) == "correct is '2', not 0 or 1"
    c = CHOICE.record()["cells"]["answer"]
    assert cell_problem("c", "answer", c, {"sample": "a+b"}, d) == \
        "the choice 'c' is not one of the samples felt (a, b)"
    assert cell_problem("b", "answer", c, {"sample": "a+b"}, d) == ""


def test_a_codebook_says_each_kind_s_meaning_of_a_shared_column():
    phases = [*IDENT.design()["phases"], *load_protocol("comparison").design()["phases"]]
    meanings, labels = column_meanings(phases)
    assert meanings["answer"] == ("", "identification: the names given to the surfaces, in "
                                      "order; comparison: the sample chosen as more like real "
                                      "contact")
    assert meanings["correct"][0] == "0/1" and labels["correct"]["1"] == "all named right"
    # an older session's phase (no record, a dv) reads the same
    old = [{k: v for k, v in p.items() if k != "response"} for p in phases]
    assert column_meanings(old) == (meanings, labels)


def test_the_scripted_and_simulated_answers_come_from_the_declaration():
    """The scripted responder has no answer of its own: it asks the declaration; so does
    the simulated participant, from what it perceives (here: nothing felt, a coin)."""
    from app.participant_model import SimulatedParticipant
    from app.participants import ScriptedResponder

    pair = type("T", (), {"samples": ("firm_spring", "soft_spring"), "phase": "testing",
                          "kind": "comparison", "repetition": 1})()
    q = Question(pair, REALISM, [])
    a = ScriptedResponder().answer(CHOICE, q, np.random.default_rng(1))
    b = CHOICE.scripted(q, np.random.default_rng(1))
    assert a == b
    sim = SimulatedParticipant(REALISM, seed=3)
    nothing = type("R", (), {"contacts": [], "traces": {}})()
    k, rt = sim.answer(CHOICE, Question(pair, REALISM, [nothing, nothing]),
                       np.random.default_rng(2))
    assert k in (0, 1) and rt > 0
