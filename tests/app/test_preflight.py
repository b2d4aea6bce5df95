"""Each preflight check, passing and failing on the thing it names (the whole command over the
serial emulator is in test_test_day.py)."""

import dataclasses
import os
import subprocess
import sys

import pytest

from app.preflight import (
    check_answers,
    check_data_folder,
    check_device,
    check_display,
    check_limit,
    check_protocol_on,
    check_terminal,
    expected_session_bytes,
)
from device import Scene, open_device
from protocols import BUILTIN, load_protocol, protocol_text
from protocols.model import Answer, RatingScale

PY = [sys.executable, "-m", "app"]


@pytest.mark.parametrize("name", BUILTIN)
def test_the_built_in_protocols_can_be_answered(name):
    c = check_answers(load_protocol(name))
    assert c.ok, c.line()


def test_a_scale_with_points_no_key_gives_fails_and_names_them():
    p = load_protocol("factorial")  # 1–10; one key per point cannot give 10
    bad = dataclasses.replace(p, rating=dataclasses.replace(p.rating, entry="keys"))
    c = check_answers(bad)
    assert not c.ok and "ratings [10] have no key" in c.detail and "typed" in c.fix
    typed = dataclasses.replace(p, rating=dataclasses.replace(p.rating, entry="typed"))
    assert check_answers(typed).ok
    assert "digits typed, then ENTER" in check_answers(typed).detail


def test_one_key_entry_maps_every_single_digit_point_to_top_row_and_keypad():
    scale = RatingScale(0, 9, "q", entry="keys")
    km = scale.key_map()
    assert sorted(set(km.values())) == list(range(10))
    assert km["0"] == 0 and km["num_7"] == 7 and len(km) == 20


def test_more_choices_than_number_keys_fail():
    p = load_protocol("identification")
    ten = Answer(p.answer.kind, tuple(f"m{i}" for i in range(10)))
    c = check_answers(dataclasses.replace(p, answer=ten))
    assert not c.ok and "['m9'] have no number key" in c.detail
    ok = check_answers(p)
    assert "1 = rubber" in ok.detail and "num_" not in ok.detail


def test_data_folder_checks_name_the_problem(tmp_path):
    a_file = tmp_path / "f"
    a_file.write_text("x")
    c = check_data_folder(a_file / "d")
    assert not c.ok and "is not a folder" in c.detail
    c = check_data_folder(tmp_path / "new" / "deeper", need_bytes=10**18)  # an exabyte
    assert not c.ok and "free some space" in c.detail
    assert not (tmp_path / "new").exists()  # a preflight creates nothing
    c = check_data_folder(tmp_path, expected_session_bytes(load_protocol("realism")))
    assert c.ok and "writable" in c.detail


@pytest.mark.integration
def test_terminal_and_display_checks_fail_without_them():
    code = ("from app.preflight import check_terminal, check_display as d; "
            "t = check_terminal(); print(t.ok, t.fix); print(d().ok)")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         stdin=subprocess.DEVNULL, env=env, timeout=60)
    first, second = out.stdout.splitlines()
    assert first.startswith("False run hapticlab from a terminal") and second == "False"
    assert check_display().ok == bool(os.environ.get("DISPLAY")
                                       or os.environ.get("WAYLAND_DISPLAY"))
    assert check_terminal().ok == sys.stdin.isatty()


def test_a_latched_fault_and_an_unplayable_protocol_fail(tmp_path):
    with open_device("sim") as dev:
        assert check_device(dev, "sim").ok
        dev.load_scene(Scene("s", spring=100.0))
        dev.estop()
        c = check_device(dev, "sim")
        assert not c.ok and "latched estop fault" in c.detail and "--clear-fault" in c.fix
    source, text = protocol_text("realism")
    fast = text.replace("decay_time = 0.055, frequency = 36.2", "decay_time = 0.055, "
                        "frequency = 700.0")  # above a 1-kHz servo's Nyquist frequency
    assert fast != text
    with open_device("sim:1000") as slow:
        assert check_protocol_on(text, source, slow).ok
        c = check_protocol_on(fast, source, slow)
        assert not c.ok and "700" in c.detail, c.line()
    with open_device("sim") as dev:  # 10 kHz plays it
        assert check_protocol_on(fast, source, dev).ok


def test_a_limit_above_the_rating_fails_and_one_below_is_applied():
    p = load_protocol("realism")
    with open_device("sim") as dev:
        rating = dev.info.current_limit
        high = dataclasses.replace(p, limits=dataclasses.replace(p.limits,
                                                                 max_current=rating * 1.5))
        c = check_limit(high, dev)
        assert not c.ok and "above this device's rating" in c.detail
        low = dataclasses.replace(p, limits=dataclasses.replace(p.limits,
                                                                max_current=rating / 2))
        c = check_limit(low, dev)
        assert c.ok and abs(dev.current_limit - rating / 2) <= 1e-9 * rating


@pytest.mark.integration
@pytest.mark.slow
def test_the_command_prints_one_line_per_check_and_exits_one_on_a_failure(tmp_path):
    out = subprocess.run([*PY, "preflight", "factorial", "--device", "sim", "--no-audio",
                          "--data", str(tmp_path / "d"), "--responder", "scripted"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    lines = out.stdout.splitlines()
    assert all(ln.startswith(("ok   ", "FAIL ")) for ln in lines[:-1])
    assert lines[-1].endswith("0 failed: ready to run")
    person = subprocess.run([*PY, "preflight", "factorial", "--device", "sim", "--no-audio",
                             "--data", str(tmp_path / "d")], capture_output=True, text=True,
                            timeout=120, stdin=subprocess.DEVNULL)
    assert person.returncode == 1
    assert any(ln.startswith("FAIL operator keys: no terminal") for ln in
               person.stdout.splitlines())
    assert not (tmp_path / "d").exists()
