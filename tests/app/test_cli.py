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


def test_fit_grasp_json():
    out = run("device", "fit-grasp", "--simulated", "--impacts", "100", "--seed", "3",
              "--json")
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    for p in ("m", "c", "k"):
        assert set(r[p]) == {"intercept", "slope"}
    # published intercepts within 3 % (the least-squares estimate; see tests/device/test_grasp)
    assert abs(r["m"]["intercept"] / 0.023 - 1) < 0.03
    assert abs(r["k"]["intercept"] / 75_000 - 1) < 0.03
    assert r["fit_percent"]["median"] > 80


def test_sysid_json_and_plot(artifacts):
    png = artifacts / "sysid_sim.png"
    out = run("device", "sysid", "--device", "sim", "--json", "--png", str(png))
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert r["model"]["order"] == 7 and r["model"]["relative_degree"] == 4
    assert 120 < r["resonance_hz"] < 136
    assert png.stat().st_size > 10_000


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
