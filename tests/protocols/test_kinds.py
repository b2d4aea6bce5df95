"""Phase kinds are declared once (protocols/kinds.py) and looked up by name."""

from pathlib import Path

import pytest

from protocols import ProtocolError, parse_protocol
from protocols.kinds import (
    FREE,
    IDENTIFICATION,
    RATED,
    PhaseKind,
    phase_kind,
    phase_kinds,
    register,
)


def test_the_three_kinds_of_the_papers_are_declared():
    assert phase_kinds() == ("rated", "free", "identification")
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
        parse_protocol(MINI.replace("{kind}", "staircase"))
    with pytest.raises(ProtocolError, match="an identification phase needs an \\[answer\\]"):
        parse_protocol(MINI.replace("{kind}", "identification"))
    assert SCALE in MINI
    no_scale = MINI.replace(SCALE, '[answer]\nkind = "identify"\nchoices = ["firm", "wood"]\n')
    with pytest.raises(ProtocolError, match="a rated phase needs a \\[rating\\] scale"):
        parse_protocol(no_scale.replace("{kind}", "rated"))
    assert parse_protocol(no_scale.replace("{kind}", "free")).phases[0].kind == "free"
