"""The hapticlab command line, run as a user would."""

import json
import re
import subprocess
import sys

import pytest

CLI = [sys.executable, "-m", "app"]


def run(*args, **kw):
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600, **kw)


@pytest.mark.integration
def test_selftest_sim_json():
    out = run("device", "selftest", "sim", "--json")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["backend"] == "sim" and report["failed"] == 0 and report["passed"] >= 10
    assert all({"name", "ok", "detail"} <= set(c) for c in report["checks"])


@pytest.mark.integration
@pytest.mark.parametrize("spec, fragment", [
    ("bogus", "unknown device backend 'bogus'"),
    ("/dev/ttyACM0", "did you mean serial:/dev/ttyACM0?"),
    ("COM3", "did you mean serial:COM3?"),
    ("sim:fast", "expected a servo rate"),
    ("sim:50", "sim servo rate must be 1,000–20,000 Hz"),
])
def test_selftest_bad_spec_is_a_clear_error(spec, fragment):
    out = run("device", "selftest", spec)
    assert out.returncode == 2
    assert fragment in out.stderr and "Traceback" not in out.stderr


@pytest.mark.integration
def test_unknown_benchmark():
    out = run("bench", "nothing")
    assert out.returncode == 2 and "no benchmark named 'nothing'" in out.stderr


@pytest.mark.integration
@pytest.mark.slow
def test_bench_sim_json_shape():
    out = run("bench", "sim", "--json", "--repeats", "1")
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert len(data["rows"]) == 25
    row = data["rows"][0]
    assert set(row) >= {"scene", "rate_hz", "realtime_factor", "us_per_tick", "rel_error", "stable"}
    assert all(r["stable"] for r in data["rows"])
    wall = {r["rate_hz"]: r["restitution"] for r in data["restitution"]
            if r["scene"] == "wall_10kN"}
    assert wall[1_000] > 1.0 > wall[10_000]


@pytest.mark.integration
@pytest.mark.slow
def test_fit_grasp_json():
    out = run("device", "fit-grasp", "--simulated", "--rig", "published", "--impacts", "100",
              "--seed", "3", "--json")
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert r["rig"] == {"kind": "published", "tissue": None}
    for p in ("m", "c", "k"):
        assert set(r[p]) == {"intercept", "slope"}
    # published intercepts within 3 % (the least-squares estimate; see tests/device/test_grasp)
    assert abs(r["m"]["intercept"] / 0.023 - 1) < 0.03
    assert abs(r["k"]["intercept"] / 75_000 - 1) < 0.03
    assert r["fit_percent"]["median"] > 80
    # the round trip's error is reported against the paper's lines (SPEC §3, written out
    # here), within the least-squares estimate's tolerances (tests/device/test_grasp)
    paper = {"m": (0.023, -0.00032), "c": (14.0, -0.19), "k": (75_000.0, -1_000.0)}
    for p, (i_pub, s_pub) in paper.items():
        err = r["error_vs_published"][p]
        assert err["intercept"] == pytest.approx(r[p]["intercept"] / i_pub - 1, abs=1e-12)
        assert err["slope"] == pytest.approx(r[p]["slope"] / s_pub - 1, abs=1e-12)
        assert abs(err["intercept"]) < 0.03 and abs(err["slope"]) < 0.15, (p, err)


@pytest.mark.integration
@pytest.mark.slow
def test_fit_grasp_defaults_to_the_rig_with_a_mode_the_model_lacks():
    """The default rig is not a round trip: its fit % is the paper's range, not ~89 %, and
    the command says what its differences mean; too few impacts are refused by name."""
    out = run("device", "fit-grasp", "--simulated", "--impacts", "60", "--seed", "1")
    assert out.returncode == 0, out.stderr
    assert "what a second-order fit makes of such impacts" in out.stdout
    median = float(re.search(r"fit % median ([0-9.]+)", out.stdout).group(1))
    assert 69.0 < median < 84.0, out.stdout
    bad = run("device", "fit-grasp", "--simulated", "--impacts", "2")
    assert bad.returncode == 2 and "--impacts 2" in bad.stderr and "fewer than 3" in bad.stderr
    bad = run("device", "fit-grasp", "--simulated", "--seed", "-1")
    assert bad.returncode == 2 and "--seed must be >= 0, got -1" in bad.stderr


@pytest.mark.integration
@pytest.mark.slow
def test_sysid_json_and_plot(artifacts):
    png = artifacts / "sysid_sim.png"
    out = run("device", "sysid", "--device", "sim", "--json", "--png", str(png))
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert r["model"]["order"] == 7 and r["model"]["relative_degree"] == 4
    assert 120 < r["resonance_hz"] < 136
    assert png.stat().st_size > 10_000


@pytest.mark.integration
@pytest.mark.slow
def test_library_build_show_and_refusals(tmp_path, artifacts):
    lib = tmp_path / "lib.npz"
    out = run("library", "build", "--device", "sim", "--out", str(lib), "--entries", "6",
              "--windows", "4")
    assert out.returncode == 0, out.stderr
    assert "6 transients for wood_on_foam" in out.stdout
    png = artifacts / "library_wood_on_foam.png"
    show = run("library", "show", str(lib), "--png", str(png), "--device", "sim")
    assert show.returncode == 0 and "entries 6" in show.stdout and png.exists()
    other = run("library", "show", str(lib), "--device", "sim:2000")
    assert other.returncode == 2 and "build a library on this device" in other.stderr
    bad = run("library", "build", "--source", "firm_spring", "--out", str(tmp_path / "x.npz"))
    assert bad.returncode == 2 and "--source must be a real sample" in bad.stderr
    assert "Traceback" not in bad.stderr + other.stderr


@pytest.mark.integration
def test_version_and_every_option_explained():
    """`hapticlab --version` is pyproject's version; every command's every argument has help
    text (about 45 had none)."""
    import argparse
    import tomllib
    from pathlib import Path

    from app.cli import build_parser

    out = run("--version")
    root = Path(__file__).resolve().parents[2]
    want = tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"]
    assert out.returncode == 0 and out.stdout.strip() == f"hapticlab {want}"
    missing = []

    def walk(p, path):
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, sp in a.choices.items():
                    walk(sp, [*path, name])
            elif not a.help:
                missing.append(" ".join([*path, *(a.option_strings or [a.dest])]))

    walk(build_parser(), ["hapticlab"])
    assert not missing, missing


@pytest.mark.integration
def test_device_list_opens_nothing_and_names_every_backends_devices(tmp_path):
    out = run("device", "list", "--json")
    assert out.returncode == 0, out.stderr
    found = json.loads(out.stdout)
    from device import available_devices, backends

    assert found["backends"] == backends() and found["broken"] == {}
    assert found["devices"] == [d.to_dict() for d in available_devices()]
    assert {d["backend"] for d in found["devices"]} <= set(found["backends"])
    text = run("device", "list")
    assert text.returncode == 0
    for d in found["devices"]:
        assert any(ln.startswith(d["spec"]) for ln in text.stdout.splitlines()), text.stdout


def test_device_list_names_each_serial_port_as_a_spec(monkeypatch, capsys):
    """This machine has no USB serial device, so the ports pyserial finds are given: each
    is listed as the spec that opens it, with what the system says it is."""
    from serial.tools import list_ports
    from serial.tools.list_ports_common import ListPortInfo

    from app import guards
    from app.cli import main

    monkeypatch.setattr(guards, "install_signal_guards", lambda: None)  # pytest's own signals
    acm = ListPortInfo("/dev/ttyACM0", skip_link_detection=True)
    acm.description, acm.hwid = "hapticlab stylus", "USB VID:PID=0483:5740 SER=0042"
    usb = ListPortInfo("/dev/ttyUSB3", skip_link_detection=True)
    usb.description, usb.hwid = "FT232R USB UART", "USB VID:PID=0403:6001"
    monkeypatch.setattr(list_ports, "comports", lambda: [usb, acm])
    assert main(["device", "list", "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    ports = [d for d in found["devices"] if d["backend"] == "serial"]
    assert [p["spec"] for p in ports] == ["serial:/dev/ttyACM0", "serial:/dev/ttyUSB3"]
    assert ports[0]["details"].endswith("SER=0042")
    assert main(["device", "list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert any(ln.startswith("serial:/dev/ttyACM0") and "hapticlab stylus" in ln
               for ln in lines), lines
    assert lines[-1] == "check one with: hapticlab device selftest SPEC (it opens the device)"


def test_device_list_without_serial_ports_says_to_check_the_dialout_group(monkeypatch, capsys):
    """pyserial finds no port: the serial backend says what to check (the device plugged
    in, the dialout group); with a port it says nothing."""
    from serial.tools import list_ports
    from serial.tools.list_ports_common import ListPortInfo

    from app import guards
    from app.cli import main

    monkeypatch.setattr(guards, "install_signal_guards", lambda: None)  # pytest's own signals
    monkeypatch.setattr(list_ports, "comports", lambda: [])
    assert main(["device", "list", "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert "dialout group" in found["none_found"]["serial"]
    assert main(["device", "list"]) == 0
    out = capsys.readouterr().out
    assert f"backend serial: {found['none_found']['serial']}" in out.splitlines(), out
    acm = ListPortInfo("/dev/ttyACM0", skip_link_detection=True)
    monkeypatch.setattr(list_ports, "comports", lambda: [acm])
    assert main(["device", "list"]) == 0
    assert "dialout" not in capsys.readouterr().out


@pytest.mark.integration
def test_protocol_show_says_what_to_place_and_how_long():
    out = run("protocol", "show", "realism", "--seed", "3")
    assert out.returncode == 0, out.stderr
    assert "(1 trials" not in out.stdout and "(1 trial;" in out.stdout  # familiarization
    assert "place: wood" in out.stdout and "min without redraws" in out.stdout
    plan = json.loads(run("protocol", "show", "realism", "--seed", "3", "--json").stdout)
    trials = [t for ph in plan["phases"] for t in ph["trials"]]
    assert all("placement" in t for t in trials)
    est = plan["duration_estimate"]
    assert est["total_s"] == pytest.approx(est["tapping_s"] + 20.0 * len(trials))
    # the realism protocol never shows a sample twice in a row, and says so per phase
    assert [ph["no_repeat"] for ph in plan["phases"]] == [False, True, True]
    assert "(the same sample again)" not in out.stdout
    assert out.stdout.count("never the same sample twice in a row") == 2


@pytest.mark.integration
@pytest.mark.parametrize("old, new, fragment", [
    ("duration = 5.0 ", "duration = 1e9 ", "window.duration: must be <= 600"),
    ("scene.spring = 680.0", "scene.spring = 1e7", "above the stiffest spring the device"),
    ("scene.spring = 680.0", "scene.spring = 1e12", "spring: must be <= 1e+08"),
    ("timeout = 30.0", "timeout = 3600.0", "records in one window at 10000 Hz"),
])
def test_protocol_validate_refuses_what_no_session_can_run(tmp_path, old, new, fragment):
    from protocols import protocol_text

    _, text = protocol_text("realism")
    assert old in text
    f = tmp_path / "p.toml"
    f.write_text(text.replace(old, new, 1))
    out = run("protocol", "validate", str(f), "--device", "sim")
    assert out.returncode != 0 and fragment in (out.stdout + out.stderr), out


@pytest.mark.integration
@pytest.mark.slow
def test_protocol_validate_warns_of_a_transient_the_device_renders_poorly(tmp_path):
    """Issue 34: a transient near the Nyquist frequency was accepted silently. A third of
    the servo rate is played at 72 % of its peak (warned); 0.499 of it at 42 % (refused)."""
    from protocols import protocol_text

    _, text = protocol_text("realism")
    f = tmp_path / "p.toml"
    f.write_text(text.replace("frequency = 36.2 }", "frequency = 3333.0 }", 1))
    out = run("protocol", "validate", str(f), "--device", "sim")
    assert out.returncode == 0, out
    assert "warning: sample 'sinusoid_firm': a device at 10000 Hz renders 72% of its peak" \
        in out.stdout, out.stdout
    assert "sinusoid_soft" not in out.stdout  # its frequency was left alone
    assert "warning" not in run("protocol", "validate", "realism", "--device", "sim").stdout
    f.write_text(text.replace("frequency = 36.2 }", "frequency = 4990.0 }", 1))
    out = run("protocol", "validate", str(f), "--device", "sim")
    assert out.returncode != 0 and "renders only" in out.stdout + out.stderr, out


@pytest.mark.integration
def test_a_translated_protocol_is_told_which_texts_are_still_english(tmp_path):
    """Issue 30: texts added to hapticlab after a lab translated its protocol appeared in
    English beside the translation without a word. ``protocol validate`` and ``preflight``
    name them (only those the protocol's screens show); an English protocol gets no note."""
    from protocols import parse_protocol, protocol_text
    from protocols.texts import DEFAULT_TEXTS, left_in_english

    _, text = protocol_text("identification")
    german = text.replace("[saturation]", '[texts]\nlanguage = "de"\nwait = "Bitte warten"\n'
                          "switch_hint = \"andere Fläche: {keys}\"\n[texts.instructions]\n"
                          'identification = "Drei Flächen."\n\n[saturation]', 1)
    f = tmp_path / "de.toml"
    f.write_text(german)
    left = left_in_english(parse_protocol(german, str(f)))
    assert "wait" not in left and "switch_hint" not in left and "name_hint" in left
    assert "reference_which" in left  # three real blocks to choose between
    assert "rating_keys" not in left and "done_hint" not in left  # no rated or free phase
    assert not any(k.startswith("instructions.") for k in left)
    out = run("protocol", "validate", str(f))
    assert out.returncode == 0, out.stderr
    assert f"will read {len(left)} texts in English (not in its [texts]): " in out.stdout
    assert ", ".join(left) in out.stdout
    out = run("preflight", str(f), "--device", "sim", "--responder", "scripted", "--no-audio",
              "--data", str(tmp_path / "d"))
    assert f"ok   texts: the protocol is in language 'de', but its participants will read " \
           f"{len(left)} texts" in out.stdout, out.stdout + out.stderr
    # translated in full: nothing to say
    full = "\n".join(f"{k} = {json.dumps('de: ' + v)}" for k, v in DEFAULT_TEXTS.items()
                     if k != "language")
    whole = german.replace('wait = "Bitte warten"\n', "").replace(
        "switch_hint = \"andere Fläche: {keys}\"\n", full + "\n")
    assert left_in_english(parse_protocol(whole, "whole.toml")) == []
    assert left_in_english(parse_protocol(text, "en.toml")) == []
    assert left_in_english(parse_protocol(german.replace('"de"', '"en_GB"'), "gb.toml")) == []
    # only what the screens show: one-key ratings, saturations kept, no block to choose
    _, realism = protocol_text("realism")
    de = parse_protocol(realism.replace("[saturation]", '[texts]\nlanguage = "de"\n\n'
                                        "[saturation]", 1)
                        .replace('action = "redraw"', 'action = "keep"'), "r.toml")
    left = left_in_english(de)
    assert "rating_keys" in left and "rating_confirmed" in left
    assert not {"rating_typed", "rating_slider", "rating_invalid", "saturated",
                "reference_which", "switch_hint"} & set(left), left
    assert "note:" not in run("protocol", "validate", "identification").stdout
