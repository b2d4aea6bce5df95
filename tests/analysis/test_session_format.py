"""session.json: statuses as named values, the scale written once, older formats read
through one upgrade step (analysis/session_format.py)."""

import json

import pytest

from analysis.session_format import (
    FORMAT_VERSION,
    SessionMetaError,
    SessionStatus,
    read_meta,
    upgrade_meta,
)

DESIGN = {"scale": {"min": 1, "max": 7, "question": "How real?"},
          "answer_choices": ["rubber", "wood"], "phases": []}


def _meta(version=FORMAT_VERSION, **protocol):
    m = {"protocol": {"name": "p", "sha256": "ab", "design": DESIGN, **protocol},
         "seed": 1, "participant": {"id": "P01"}, "session": 1, "status": "complete",
         "kind": "human"}
    if version is not None:
        m["format_version"] = version
    return m


def test_a_status_is_a_named_value_written_as_its_text():
    assert json.dumps({"status": SessionStatus.INTERRUPTED}) == '{"status": "interrupted"}'
    assert SessionStatus("complete") is SessionStatus.COMPLETE
    assert [s.value for s in SessionStatus] == ["running", "complete", "interrupted", "stopped"]


def test_this_format_is_read_as_written(tmp_path):
    (tmp_path / "session.json").write_text(json.dumps(_meta()))
    assert read_meta(tmp_path / "session.json") == _meta()


def test_format_2_loses_its_second_copy_of_the_scale_and_choices(tmp_path):
    """Format 2 wrote the scale and the choices twice: beside the design and in it."""
    old = _meta(2, rating={"min": 1, "max": 7}, answer_choices=["rubber", "wood"])
    (tmp_path / "session.json").write_text(json.dumps(old))
    meta = read_meta(tmp_path / "session.json")
    assert meta["format_version"] == FORMAT_VERSION and meta["upgraded_from"] == 2
    assert "rating" not in meta["protocol"] and "answer_choices" not in meta["protocol"]
    assert meta["protocol"]["design"] == DESIGN
    assert old["protocol"]["rating"] == {"min": 1, "max": 7}  # the caller's dict is kept
    # a protocol without a scale wrote rating = null, which says nothing either way
    assert "rating" not in upgrade_meta(_meta(2, rating=None))["protocol"]


def test_two_copies_that_disagree_are_named_not_chosen_between(tmp_path):
    (tmp_path / "session.json").write_text(json.dumps(_meta(2, rating={"min": 1, "max": 10})))
    with pytest.raises(SessionMetaError, match=r"protocol\.rating \{'min': 1, 'max': 10\} "
                                               r"disagrees with the design's scale"):
        read_meta(tmp_path / "session.json")
    with pytest.raises(SessionMetaError, match="answer_choices"):
        upgrade_meta(_meta(2, answer_choices=["wood", "rubber"]))


def test_format_1_gets_its_kind_from_how_it_ran():
    old = _meta(None)
    del old["kind"]
    old["ui"] = "psychopy"
    meta = upgrade_meta(old)
    assert meta["kind"] == "human" and meta["upgraded_from"] == 1


def test_a_newer_format_asks_for_a_newer_hapticlab(tmp_path):
    (tmp_path / "session.json").write_text(json.dumps(_meta(FORMAT_VERSION + 1)))
    with pytest.raises(SessionMetaError, match="newer than this hapticlab reads"):
        read_meta(tmp_path / "session.json")
