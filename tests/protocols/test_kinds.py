"""Phase kinds are declared once (protocols/kinds.py) and looked up by name."""

from pathlib import Path

import pytest

from protocols import ProtocolError, SessionEngine, load_protocol, parse_protocol
from protocols.kinds import (
    COMPARISON,
    FREE,
    IDENTIFICATION,
    RATED,
    PhaseKind,
    phase_kind,
    phase_kinds,
    register,
)


def test_the_three_kinds_of_the_papers_and_the_comparison_are_declared():
    assert phase_kinds()[:4] == ("rated", "free", "identification", "comparison")
    assert phase_kind("rated") is RATED
    assert (RATED.windows, RATED.response, RATED.columns) == (
        "each_sample", "rating", ("rating", "response_time"))
    assert (FREE.windows, FREE.response, FREE.dv, FREE.columns) == ("until_done", None, "none", ())
    assert not FREE.redraws_saturated and not FREE.references
    assert IDENTIFICATION.surfaces and IDENTIFICATION.default_references == "start"
    assert IDENTIFICATION.columns == ("answer", "response_time", "correct")


def test_an_unknown_kind_names_the_declared_ones():
    with pytest.raises(KeyError, match="rated, free, identification"):
        phase_kind("2afc")


def test_a_declaration_is_checked_and_made_once():
    with pytest.raises(ValueError, match="windows must be one of"):
        PhaseKind("x", "", windows="twice", response=None, instructions="")
    with pytest.raises(ValueError, match="response must be one of"):
        PhaseKind("x", "", windows="each_sample", response="sigh", instructions="")
    with pytest.raises(ValueError, match="declared already"):
        register(PhaseKind("free", "", windows="each_sample", response=None, instructions=""))
    with pytest.raises(ValueError, match="declared already"):  # the runner's trial kind
        register(PhaseKind("reference", "", windows="each_sample", response=None,
                           instructions=""))


#: the session tests' mini protocol, its phase of the kind under test
MINI = (Path(__file__).parents[1] / "data" / "mini.toml").read_text().replace(
    'name = "testing"\n', 'name = "testing"\nkind = "{kind}"\n')
SCALE = '[rating]\nmin = 1\nmax = 7\nquestion = "How real?"\n'


def test_the_loader_offers_the_declared_kinds_and_asks_for_what_a_kind_needs():
    with pytest.raises(ProtocolError, match=r"phases\[0\]\.kind.*rated.*free.*identification"):
        parse_protocol(MINI.replace("{kind}", "psi"))
    with pytest.raises(ProtocolError, match="an identification phase needs an \\[answer\\]"):
        parse_protocol(MINI.replace("{kind}", "identification"))
    assert SCALE in MINI
    no_scale = MINI.replace(SCALE, '[answer]\nkind = "identify"\nchoices = ["firm", "wood"]\n')
    with pytest.raises(ProtocolError, match="a rated phase needs a \\[rating\\] scale"):
        parse_protocol(no_scale.replace("{kind}", "rated"))
    assert parse_protocol(no_scale.replace("{kind}", "free")).phases[0].kind == "free"


def test_a_comparison_felt_both_orders_of_every_pair_once_per_repetition():
    """The new kind end to end starts here: its items are ordered pairs."""
    assert (COMPARISON.items, COMPARISON.windows, COMPARISON.response, COMPARISON.needs) == (
        "pairs", "each_sample", "choice", None)
    p = load_protocol("comparison")
    phase = next(ph for ph in p.phases if ph.kind == "comparison")
    items = [i for i in SessionEngine(p, 7, "P01").plan() if i.phase == phase.name]
    pairs = [i.samples for i in items]
    k = len(phase.samples)
    assert len(pairs) == k * (k - 1) == 20 and len(set(pairs)) == 20
    assert {tuple(sorted(x)) for x in pairs} == {
        (a, b) for a in phase.samples for b in phase.samples if a < b}
    assert pairs != sorted(pairs)  # drawn, not as written
    assert pairs == [i.samples for i in SessionEngine(p, 7, "P01").plan()
                     if i.phase == phase.name]  # the same seed, the same order
    assert {i.key.split("#")[1] for i in items} == {"1"}


PAIRS = MINI.replace("{kind}", "comparison").replace(
    'id = "wood"\nscene.material', 'id = "wood"\nrated = false\nscene.material')


@pytest.mark.parametrize("change, message", [
    (('samples = "all"', 'samples = ["firm"]'), r"pairs its samples: it needs two at least"),
    (('samples = "all"', 'samples = ["firm", "wood"]'), r"\['wood'\]: a comparison phase "
                                                       r"compares renderings"),
    (('repetitions = 2', 'repetitions = 2\nno_repeat = true'), r"a comparison trial has two"),
    (('repetitions = 2', 'repetitions = 2\nanalysis.within = ["sample"]'),
     r"analysed by its pairs"),
])
def test_what_a_comparison_phase_cannot_be_is_named(change, message):
    assert change[0] in PAIRS
    with pytest.raises(ProtocolError, match=message):
        parse_protocol(PAIRS.replace(*change))


def test_a_protocol_of_choices_needs_no_scale():
    text = PAIRS.replace(SCALE, "").replace('samples = "all"', 'samples = ["firm", "pulse"]')
    assert parse_protocol(text).phases[0].kind == "comparison"
    with pytest.raises(ProtocolError, match="a \\[rating\\] scale, an \\[answer\\] table or a "
                                            "phase that asks for a choice"):
        parse_protocol(MINI.replace(SCALE, "").replace("{kind}", "free"))
