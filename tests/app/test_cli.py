"""The hapticlab command line, run as a user would."""

import json
import subprocess
import sys

import pytest

CLI = [sys.executable, "-m", "app"]


def run(*args, **kw):
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600, **kw)


def test_selftest_sim_json():
    out = run("device", "selftest", "sim", "--json")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["backend"] == "sim" and report["failed"] == 0 and report["passed"] >= 10
    assert all({"name", "ok", "detail"} <= set(c) for c in report["checks"])


@pytest.mark.parametrize("spec, fragment", [
    ("bogus", "unknown device backend 'bogus'"),
    ("sim:fast", "expected a servo rate"),
    ("sim:50", "sim servo rate must be 1,000–20,000 Hz"),
])
def test_selftest_bad_spec_is_a_clear_error(spec, fragment):
    out = run("device", "selftest", spec)
    assert out.returncode == 2
    assert fragment in out.stderr and "Traceback" not in out.stderr


def test_unknown_benchmark():
    out = run("bench", "nothing")
    assert out.returncode == 2 and "no benchmark named 'nothing'" in out.stderr


def test_demo_runs_every_available_sample():
    out = run("demo", env=None)
    assert out.returncode == 0, out.stderr
    for sample in ("wood", "wood_on_foam", "foam", "firm_spring", "soft_spring", "pulse_firm",
                   "pulse_soft", "sinusoid_firm", "sinusoid_soft", "matched_firm", "matched_soft"):
        assert sample in out.stdout
    assert "simulated 11 samples" in out.stdout


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
