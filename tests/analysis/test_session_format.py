"""session.json: one typed record (SessionRecord) with statuses as named values, the scale
written once, values of the wrong type named, older formats read through one upgrade step
(analysis/session_format.py)."""

import json
import re

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


def _written():
    """session.json as the recorder writes it: every key of the record present."""
    m = _meta()
    m["protocol"].update(ref="realism", source="protocols/realism.toml", copy="protocol.toml")
    m["participant"].update(counterbalance_row=None, group="")
    m.update(app={"name": "hapticlab"}, libraries={}, rng="PCG64", device={"spec": "sim"},
             ui="none", responder="simulated", audio=False, packages={}, python="3.11",
             os="Linux", times={"created_utc": "2026-11-28T09:00:00Z", "finished_utc": None},
             resumes=[], timing={}, link={})
    return m


def test_this_format_is_read_as_written(tmp_path):
    (tmp_path / "session.json").write_text(json.dumps(_written()))
    record = read_meta(tmp_path / "session.json")
    assert record.to_json() == _written()
    assert record.status is SessionStatus.COMPLETE and record.participant.id == "P01"
    assert record.protocol.scale == DESIGN["scale"] and record.device_spec == "sim"


def test_keys_this_hapticlab_does_not_know_are_kept(tmp_path):
    """A newer minor writer's key (or a lab's own) survives a resume's write-back."""
    m = _written()
    m["lab_note"] = {"room": 3}
    m["participant"]["handedness"] = "left"
    (tmp_path / "session.json").write_text(json.dumps(m))
    assert read_meta(tmp_path / "session.json").to_json() == m


@pytest.mark.parametrize(("where", "value", "message"), [
    ("session", "two", "session is 'two'; expected a whole number"),
    ("seed", True, "seed is True; expected a whole number"),
    ("status", "paused", "status is 'paused'; expected one of running, complete, "
                         "interrupted, stopped"),
    ("device", "sim", "device is 'sim'; expected an object"),
    ("times", "today", "times is not an object"),
    ("participant", "P01", "missing key(s) participant.id"),
    ("kind", "robot", "kind is 'robot'; expected one of human, dry-run, simulated"),
])
def test_a_value_of_the_wrong_type_is_named_with_its_key(tmp_path, where, value, message):
    m = _written()
    m[where] = value
    (tmp_path / "session.json").write_text(json.dumps(m))
    with pytest.raises(SessionMetaError, match=re.escape(message)):
        read_meta(tmp_path / "session.json")


def test_a_participant_id_written_as_a_number_is_read_as_text(tmp_path):
    m = _written()
    m["participant"]["id"] = 7
    (tmp_path / "session.json").write_text(json.dumps(m))
    assert read_meta(tmp_path / "session.json").participant.id == "7"


def test_format_2_loses_its_second_copy_of_the_scale_and_choices(tmp_path):
    """Format 2 wrote the scale and the choices twice: beside the design and in it."""
    old = _meta(2, rating={"min": 1, "max": 7}, answer_choices=["rubber", "wood"])
    (tmp_path / "session.json").write_text(json.dumps(old))
    meta = read_meta(tmp_path / "session.json")
    assert meta.format_version == FORMAT_VERSION and meta.upgraded_from == 2
    assert "rating" not in meta.protocol.extra and "answer_choices" not in meta.protocol.extra
    assert meta.protocol.design == DESIGN
    assert meta.to_json()["upgraded_from"] == 2
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


def test_format_1_gets_its_kind_from_how_it_ran(tmp_path):
    old = _meta(None)
    del old["kind"]
    old["ui"] = "psychopy"
    meta = upgrade_meta(old)
    assert meta["kind"] == "human" and meta["upgraded_from"] == 1
    old["ui"], old["responder"] = "none", "simulated"
    (tmp_path / "session.json").write_text(json.dumps(old))
    assert read_meta(tmp_path / "session.json").kind == "simulated"


def test_a_newer_format_asks_for_a_newer_hapticlab(tmp_path):
    (tmp_path / "session.json").write_text(json.dumps(_meta(FORMAT_VERSION + 1)))
    with pytest.raises(SessionMetaError, match="newer than this hapticlab reads"):
        read_meta(tmp_path / "session.json")


def test_a_null_is_written_back_read_as_empty_or_refused_by_name(tmp_path):
    """A hand-edited or foreign file: a null where a key is optional comes back as null
    (a resume rewrites the file); a null where the record has a value of its own (the
    device, the libraries, the times) reads as that empty value, as the readers before the
    record took it; a null seed is refused, naming the key."""
    m = _written()
    m.update(limits=None, device=None, libraries=None, times=None)
    (tmp_path / "session.json").write_text(json.dumps(m))
    record = read_meta(tmp_path / "session.json")
    assert record.to_json()["limits"] is None
    assert record.device == {} and record.device_spec == "" and record.libraries == {}
    assert record.times.created_utc is None
    m = _written()
    m["seed"] = None
    (tmp_path / "session.json").write_text(json.dumps(m))
    with pytest.raises(SessionMetaError, match="seed is null; expected a whole number"):
        read_meta(tmp_path / "session.json")


@pytest.mark.parametrize("backend, firmware, simulated, virtual", [
    ("sim", "sim", True, True),                     # the simulated device
    ("serial", "emulator-2x10", True, False),       # the Python emulator at ×10
    ("serial", "hlfw-2.0 host", True, False),       # the firmware's host build
    ("serial", "hlfw-2.0 host-F4", True, False),    # host-board
    ("serial", "hlfw-2.0 stm32", True, False),      # under QEMU
    ("serial", "hlfw-2.0 dhd-stu", True, False),    # the Force Dimension bridge's stand-in
    ("serial", "hlfw-2.0 hd-stub", True, False),    # the OpenHaptics bridge's stand-in
    ("serial", "hlfw-2.0 hd-tsan", True, False),    # that under ThreadSanitizer
    ("serial", "hlfw-2.0 board", False, False),     # the papers' board
    ("serial", "hlfw-2.0 dhd", False, False),       # the bridge on the vendor's SDK
    ("serial", "hl-2.1", False, False),             # a lab's own firmware
])
def test_an_older_file_gets_its_devices_capabilities_from_what_it_recorded(
        tmp_path, backend, firmware, simulated, virtual):
    """Format 3 recorded no capabilities: they are read from the backend and firmware texts
    it did record (the bridges' stand-ins, missed before, are simulated)."""
    old = _meta(3)
    old["device"] = {"spec": "x", "backend": backend, "firmware": firmware}
    (tmp_path / "session.json").write_text(json.dumps(old))
    meta = read_meta(tmp_path / "session.json")
    assert meta.upgraded_from == 3 and meta.simulated_contact is simulated
    assert meta.device["seeded"] is simulated and meta.device["virtual_time"] is virtual
    assert meta.device["firmware"] == firmware  # what was recorded stays


def test_a_current_file_is_read_as_the_device_said_whatever_its_names(tmp_path):
    m = _meta()
    m["device"] = {"backend": "sim", "firmware": "emulator-2", "simulated_contact": False,
                   "seeded": False, "virtual_time": False}
    (tmp_path / "session.json").write_text(json.dumps(m))
    meta = read_meta(tmp_path / "session.json")
    assert meta.simulated_contact is False and meta.upgraded_from is None
