"""Protocol files: the built-ins load, and every kind of bad input is a named error."""

import re
import subprocess
import sys

import pytest

from device.sim.backend import SimDevice
from protocols import ProtocolError, load_protocol, parse_protocol, protocol_text

MINIMAL = """\
[protocol]
name = "mini"

[rating]
min = 1
max = 7
question = "How real?"

[[samples]]
id = "wood"
scene.material = { stiffness = 70000.0, damping = 40.0 }

[[samples]]
id = "spring"
scene.spring = 680.0
scene.transient = { kind = "pulse", gain = 5.7, duration = 0.02 }

[[phases]]
name = "testing"
samples = "all"
repetitions = 3
"""


def test_minimal_protocol_loads():
    p = parse_protocol(MINIMAL, "mini.toml")
    assert list(p.samples) == ["wood", "spring"]
    assert p.samples["wood"].placement == "wood" and p.samples["spring"].placement is None
    assert p.phases[0].repetitions == 3 and p.saturation.max_attempts == 3
    assert len(p.sha256) == 64


def test_factorial_expands_to_eight_sets_per_material():
    p = load_protocol("factorial", device=SimDevice().info)
    rated = [s for s in p.samples.values() if s.rated]
    assert len(rated) == 24
    for m in ("rubber", "wood", "aluminum"):
        sets = [s for s in rated if s.block == m]
        assert len(sets) == 8
        assert {tuple(s.factors.values()) for s in sets} == {
            (a, b, c) for a in ("low", "high") for b in ("low", "high") for c in ("low", "high")}
        assert p.samples[f"{m}-real"].scene.is_real and not p.samples[f"{m}-real"].rated
    # the best sets of Table 2 are vertices: rubber −240 1/s, 60 1/s, 30 Hz
    best = {"rubber": (-240.0, 60.0, 30.0), "wood": (-150.0, 80.0, 100.0),
            "aluminum": (-300.0, 90.0, 300.0)}
    for m, (a, b, f) in best.items():
        assert any(s.params == {"frequency": f, "decay": b, "slope": a}
                   for s in rated if s.block == m), m
    # levels are ordered by magnitude: low is the smaller |value|
    r = p.samples["rubber-LLL"].params
    assert (r["frequency"], r["decay"], r["slope"]) == (30.0, 60.0, -240.0)


def test_identification_protocol():
    p = load_protocol("identification")
    assert p.answer.choices == ("rubber", "wood", "aluminum")
    assert p.phases[0].kind == "identification" and p.phases[0].repetitions == 3
    assert p.cursor


def _mutate(old: str, new: str) -> str:
    assert old in MINIMAL, old
    return MINIMAL.replace(old, new, 1)


BAD = [
    ("", None, "", "the file is empty"),
    ("[protocol\nname = 1", 1, "", "not valid TOML"),
    (_mutate('name = "mini"', 'name = "mini"\ntitel = "x"'), 3, "protocol.titel",
     "did you mean 'title'"),
    (_mutate("[[phases]]", "[[phase]]"), 18, "phase", "did you mean 'phases'"),
    (_mutate('question = "How real?"\n', ""), 4, "rating.question",
     "missing (required: max, min, question)"),
    (_mutate("max = 7", "max = 1"), 6, "rating.max", "must be greater than min"),
    (_mutate("max = 7", "max = 0"), 6, "rating.max", "must be greater than min"),
    (_mutate("repetitions = 3", "repetitions = 0"), 21, "phases[0].repetitions", "must be >= 1"),
    (_mutate("repetitions = 3", "repetitions = 2.5"), 21, "phases[0].repetitions",
     "must be an integer"),
    (_mutate("stiffness = 70000.0", "stiffness = -70000.0"), 11,
     "samples[0].scene.material.stiffness", "must be > 0"),
    (_mutate("scene.spring = 680.0", "scene.spring = -680.0"), 15, "samples[1].scene.spring",
     "must be >= 0"),
    (_mutate("scene.spring = 680.0", "scene.spring = nan"), 15, "samples[1].scene.spring",
     "must be finite"),
    (_mutate("gain = 5.7", "gain = inf"), 16, "samples[1].scene.transient.gain", "must be finite"),
    (_mutate('id = "spring"', 'id = "wood"'), 14, "samples[1].id", "duplicate sample id 'wood'"),
    (_mutate('samples = "all"', 'samples = ["wood", "sprng"]'), 20, "phases[0].samples[1]",
     "did you mean 'spring'"),
    # a list where a sample id goes (was a TypeError: unhashable type 'list')
    (_mutate('samples = "all"', 'samples = ["wood", ["spring"]]'), 20, "phases[0].samples[1]",
     "unknown sample ['spring']"),
    (_mutate("[[phases]]", "[saturation]\nmax_attempts = 0\n\n[[phases]]"), 19,
     "saturation.max_attempts", "a redraw cap of 0"),
    (_mutate("[[phases]]", "[limits]\nmax_current = 2.0\n\n[[phases]]"), 19, "limits.max_current",
     "exceeds the rating of the device 'sim' (1.4 A)"),
    (_mutate("gain = 5.7", "gain = 50.0"), 16, "samples[1].scene.transient",
     "transient peak 5.50 N at 0.11 m/s exceeds the 3.01 N"),
    (_mutate("kind = \"pulse\"", "kind = \"wobble\""), 16, "samples[1].scene.transient.kind",
     "transient kind 'wobble' is not available"),
    (_mutate('scene.material = { stiffness = 70000.0, damping = 40.0 }',
             'scene.spring = 100.0\nscene.material = { stiffness = 7.0 }'), 11,
     "samples[0].scene.spring", "cannot also have"),
    (_mutate("[[phases]]", "[window]\nduration = 0\n\n[[phases]]"), 19, "window.duration",
     "must be > 0"),
    (_mutate("[[phases]]", "[operator]\nplaceholders = [\"A\"]\n\n[[phases]]"), 19,
     "operator.placeholders", "at least two distinct"),
    (_mutate('id = "wood"', 'id = "wo od"'), 10, "samples[0].id", "must be letters"),
    (_mutate('[rating]\nmin = 1\nmax = 7\nquestion = "How real?"\n', ""), 14,
     "phases[0].kind", "a rated phase needs a [rating] scale"),
]


@pytest.mark.parametrize("text, line, field, fragment", BAD,
                         ids=[f"{i}:{b[3][:30]}" for i, b in enumerate(BAD)])
def test_bad_input_names_file_line_field_and_value(text, line, field, fragment):
    with pytest.raises(ProtocolError) as err:
        parse_protocol(text, "mini.toml", device=SimDevice().info)
    e = err.value
    assert fragment in str(e)
    assert str(e).startswith("mini.toml")
    assert e.line == line, str(e)
    assert e.field.startswith(field), str(e)
    assert "scene 'spring'" not in str(e)  # the place is said once, by the loader


def test_missing_file_is_a_clear_error():
    with pytest.raises(ProtocolError, match="no such protocol file; built-in protocols: realism"):
        protocol_text("realismm")


def test_non_utf8_file(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_bytes(b"\xff\xfe[protocol]")
    with pytest.raises(ProtocolError, match="not a UTF-8 text file"):
        load_protocol(f)


def test_williams_needs_a_row(tmp_path):
    text = protocol_text("factorial")[1].replace('block_order = "random"',
                                                 'block_order = "williams"')
    p = parse_protocol(text, "f.toml")
    from protocols import SessionEngine

    with pytest.raises(ValueError, match="counterbalance row"):
        SessionEngine(p, 1, "P01")


CLI = [sys.executable, "-m", "app"]


@pytest.mark.integration
@pytest.mark.slow
def test_cli_validate_and_errors(tmp_path):
    ok = subprocess.run([*CLI, "protocol", "validate", "factorial", "--device", "sim"],
                        capture_output=True, text=True)
    assert ok.returncode == 0 and "valid protocol 'factorial'" in ok.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text(_mutate("repetitions = 3", "repetitions = 0"))
    out = subprocess.run([*CLI, "protocol", "validate", str(bad)], capture_output=True, text=True)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert re.search(r"bad\.toml:21: phases\[0\]\.repetitions: must be >= 1", out.stderr)


def test_a_folder_or_named_pipe_is_named_for_what_it_is(tmp_path):
    """They were called missing ('no such protocol file'); a named pipe must not block."""
    import os

    (tmp_path / "folder.toml").mkdir()
    os.mkfifo(tmp_path / "pipe.toml")
    for name, kind in (("folder.toml", "a directory"), ("pipe.toml", "a named pipe")):
        with pytest.raises(ProtocolError, match=rf"{name}: not a regular file \({kind}\)"):
            protocol_text(tmp_path / name)
