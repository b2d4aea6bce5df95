"""Builder experiments with the hapticlab components, compiled by PsychoPy's compiler and run
by PsychoPy in a real window under Xvfb: the shipped demo on the simulated device and, the
same experiment compiled on a computer whose Device Manager names a serial port, on the
emulator over a pseudo-terminal; and the device closed with zero output on every way
PsychoPy ends (escape, an e-stop from the keyboard, an error)."""

import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from ..conftest import ROOT

pytestmark = [pytest.mark.screen, pytest.mark.integration, pytest.mark.slow]

PLUGIN = ROOT / "plugins" / "psychopy-hapticlab" / "psychopy_hapticlab"
DEMO = PLUGIN / "demos" / "haptic2afc"
HELPER = Path(__file__).with_name("builder_helper.py")


def _shrunk(src: Path, dst: Path, reps: int = 1, window: float = 1.0, **contact) -> Path:
    """``src`` as a test runs it: no info dialog, a small window, ``reps`` repeats of its
    conditions, ``window``-s tapping windows, and any other Haptic contact parameters."""
    from psychopy import experiment, plugins

    plugins.activatePlugins()
    exp = experiment.Experiment()
    exp.loadFromXML(str(src))
    s = exp.settings.params
    s["Show info dlg"].val = False
    s["Window size (pixels)"].val = "[640, 480]"
    for e in exp.flow:
        if e.getType() == "LoopInitiator":
            e.loop.params["nReps"].val = reps
    for rt in exp.routines.values():
        for c in rt:
            if c.type == "HapticContact":
                c.params["windowDuration"].val = window
                for k, v in contact.items():
                    c.params[k].val = v
    exp.saveToXML(str(dst), makeLegacy=False)
    return dst


def _compiled(tmp: Path, psyexp: Path, spec: str, live: bool = False) -> tuple[Path, dict]:
    """``psyexp`` compiled on a computer (HOME) whose Device Manager has 'haptic' = spec."""
    env = {**os.environ, "HOME": str(tmp / "home")}
    (tmp / "home").mkdir(exist_ok=True)
    script = psyexp.with_suffix(".py")
    out = subprocess.run([sys.executable, str(HELPER), "haptic", spec,
                          "live" if live else "virtual", str(psyexp), str(script)],
                         capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    return script, env


def _run(script: Path, env: dict, display: str, keys: tuple[str, ...] = (),
         timeout: float = 900.0) -> subprocess.CompletedProcess:
    """Run a compiled experiment; ``keys`` pressed into its window (X events, xdotool)
    every quarter second until it exits (a routine waiting for one takes it; a key nobody
    waits for is dropped when the next routine starts)."""
    env = {**env, "DISPLAY": display}
    proc = subprocess.Popen([sys.executable, script.name], cwd=script.parent, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def press():
        while proc.poll() is None:
            for k in keys:
                subprocess.run(["xdotool", "key", k], env=env, capture_output=True)
            time.sleep(0.25)

    presser = threading.Thread(target=press, daemon=True)
    presser.start()
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    presser.join()
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


def _data(folder: Path) -> tuple[pd.DataFrame, str]:
    csv = sorted((folder / "data").glob("*.csv"))
    log = sorted((folder / "data").glob("*.log"))
    assert len(csv) == 1 and len(log) == 1, sorted((folder / "data").iterdir())
    return pd.read_csv(csv[0]), log[0].read_text()


def _copy_demo(tmp: Path) -> Path:
    for f in DEMO.iterdir():
        shutil.copy(f, tmp)
    return tmp / "haptic2afc.psyexp"


def _check_rows(folder: Path, d: pd.DataFrame, n_trials: int) -> pd.DataFrame:
    """The trial rows of the 2AFC: both taps valid, their trace files on disk holding the
    contacts the row lists, both orders of the conditions, a choice each."""
    trials = d[d["first"].notna()]
    assert len(trials) == n_trials
    assert sorted(trials["first"]) == sorted(trials["second"])  # both orders
    assert set(trials["choice.keys"].astype(int)) == {1}
    for which in ("tap_first", "tap_second"):
        assert (trials[f"{which}.status"] == "valid").all()
        assert (trials[f"{which}.trial_id"] == trials.index).all()  # the row's own index
        for _, row in trials.iterrows():
            trace = np.load(folder / "data" / row[f"{which}.trace_file"])
            speeds = [float(v) for v in row[f"{which}.speeds"].strip("[]").split(",")]
            assert len(speeds) == row[f"{which}.n_contacts"] >= 1
            assert np.allclose(trace["contacts_v"], speeds, atol=1e-5)
            freq = row["freq_first" if which == "tap_first" else "freq_second"]
            assert f"transient.frequency={freq}" in row[f"{which}.scene_fields"]
    assert d["deviceCheck.verdict"].dropna().tolist() == ["pass"]
    return trials


def test_the_demo_compiled_by_psychopy_runs_on_the_simulated_device(tmp_path, xdisplay):
    script, env = _compiled(tmp_path, _shrunk(_copy_demo(tmp_path), tmp_path / "demo.psyexp"),
                            "sim")
    out = _run(script, env, xdisplay, keys=("space", "1"))
    assert out.returncode == 0, out.stderr[-3000:]
    d, log = _data(tmp_path)
    trials = _check_rows(tmp_path, d, 2)
    # in virtual time the simulated device has no clock on this computer: said, not invented
    assert trials["tap_first.clock_offset_s"].isna().all()
    assert "hapticlab haptic: opened sim" in log
    assert "hapticlab haptic: closed sim (output 0 N)" in log  # DeviceManager at exit


def test_the_same_experiment_on_the_emulator_over_a_pty_puts_contacts_in_their_routine(
        tmp_path, xdisplay, emulator):
    """Compiled on a computer whose Device Manager says 'haptic' is the emulator's port: the
    device's clock, mapped onto the experiment's, puts every contact inside the routine
    that felt it (globalClock, the clock of PsychoPy's own .started/.stopped columns)."""
    psyexp = _shrunk(_copy_demo(tmp_path), tmp_path / "demo.psyexp")
    script, env = _compiled(tmp_path, psyexp, f"serial:{emulator.port}")
    assert f"spec='serial:{emulator.port}'" in script.read_text()
    out = _run(script, env, xdisplay, keys=("space", "1"))
    assert out.returncode == 0, out.stderr[-3000:]
    d, log = _data(tmp_path)
    trials = _check_rows(tmp_path, d, 2)
    for which, routine in (("tap_first", "feel_first"), ("tap_second", "feel_second")):
        for _, row in trials.iterrows():
            # the Python emulator's device seconds run slow on a busy host: the mapping's
            # rate says by how much, its uncertainty how well it is known, and the contacts
            # land in their routine within it
            assert row[f"{which}.clock_rate"] >= 0.999
            unc = row[f"{which}.clock_uncertainty_s"]
            assert 0 < unc < row[f"{routine}.stopped"] - row[f"{routine}.started"]
            times = [float(v) for v in row[f"{which}.contact_times"].strip("[]").split(",")]
            assert row[f"{routine}.started"] - unc < times[0]
            assert times[-1] < row[f"{routine}.stopped"] + unc
            dev = [float(v) for v in row[f"{which}.contact_times_device"].strip("[]").split(",")]
            mapped = row[f"{which}.clock_offset_s"] + np.array(dev) * row[f"{which}.clock_rate"]
            assert np.allclose(mapped, times, atol=1e-5)
    assert f"closed serial:{emulator.port} (output 0 N)" in log


def _one_routine(tmp: Path, freqs: list[str], window: float, mode: str) -> Path:
    """An experiment of one routine in a loop over ``freqs``: a Haptic contact (``mode``
    window of ``window`` s, e-stop key e) and a text."""
    from psychopy import experiment, plugins
    from psychopy.experiment.components.text import TextComponent
    from psychopy.experiment.loops import TrialHandler

    plugins.activatePlugins()
    from psychopy_hapticlab.components.contact import HapticContactComponent

    (tmp / "rows.csv").write_text("freq\n" + "\n".join(freqs) + "\n")
    exp = experiment.Experiment()
    exp.name = "exits"
    exp.settings.params["expName"].val = "exits"
    exp.settings.params["Show info dlg"].val = False
    exp.settings.params["Window size (pixels)"].val = "[640, 480]"
    exp.settings.params["logging level"].val = "exp"
    rt = exp.addRoutine("feel")
    rt.addComponent(TextComponent(exp, "feel", name="say", text="Tap the surface"))
    tap = HapticContactComponent(exp, "feel", name="tap", window=mode, windowDuration=window)
    tap.params["frequency"].val = "$freq"
    tap.params["frequency"].updates = "set every repeat"
    rt.addComponent(tap)
    exp.flow.addRoutine(rt, 0)
    exp.flow.addLoop(TrialHandler(exp, name="rows", loopType="sequential", nReps=1,
                                  conditionsFile="rows.csv"), 0, 1)
    exp.saveToXML(str(tmp / "exits.psyexp"), makeLegacy=False)
    return tmp / "exits.psyexp"


@pytest.mark.parametrize("how", ["escape", "estop key", "bad row"])
def test_every_way_psychopy_ends_closes_the_device_with_zero_output(tmp_path, xdisplay, how):
    """Escape mid-window, the e-stop key mid-window (the experiment stops with a PsychoPy
    error naming the e-stop, the window's row saved), and a conditions row hapticlab
    refuses (an error naming the field and value, the earlier row saved): each time the
    device is closed with zero output, and the data file is there."""
    if how == "bad row":
        psyexp, live, keys = _one_routine(tmp_path, ["100", "-5"], 1.0, "from first contact"), \
            False, ()
    else:  # a long fixed window in real time: the key ends it
        psyexp, live = _one_routine(tmp_path, ["100", "100"], 30.0, "fixed"), True
        keys = ("Escape",) if how == "escape" else ("e",)
    script, env = _compiled(tmp_path, psyexp, "sim", live=live)
    out = _run(script, env, xdisplay, keys=keys)
    d, log = _data(tmp_path)
    assert "hapticlab haptic: closed sim (output 0 N)" in log, log[-2000:]
    rows = d[d["tap.status"].notna()]
    if how != "bad row":  # the key ended the 30-s window: its trace is shorter (device time)
        trace = np.load(tmp_path / "data" / rows["tap.trace_file"].iloc[0])
        assert len(trace["flags"]) / float(trace["rate_hz"]) < 29.0
    if how == "escape":  # the window's row recorded as the experiment ended: nothing lost
        assert out.returncode == 0, out.stderr[-2000:]
        assert rows["tap.status"].tolist() == ["interrupted"]
        assert log.index("window started") < log.index("closed sim")
    elif how == "estop key":
        assert out.returncode != 0
        assert "HapticFaultError: haptic (sim): an e-stop latched output at zero (estop:" \
            in out.stderr, out.stderr[-2000:]
        row = rows.iloc[0]
        assert row["tap.status"] == "estop" and row["tap.reason"].startswith("estop:")
        assert log.index("window started") < log.index("E-STOP latched (e-stop key pressed")
    else:
        assert out.returncode != 0
        assert "SceneError: scene 'tap:q_sinusoid'.transient: frequency: must be > 0, got " \
            "-5" in out.stderr, out.stderr[-2000:]
        assert rows["tap.status"].tolist() == ["valid"]  # the first row, kept


def test_builder_shows_the_components_dialog_and_the_device_manager(tmp_path, xdisplay,
                                                                    artifacts):
    """PsychoPy's Builder app (psychopy-app, on Debian's wxPython) opens the demo with the
    plugin active: the Haptic contact's dialog on its Scene page and the Device Manager with
    the hapticlab device, as screenshots in tests/artifacts/screens/ (look at them)."""
    app = ROOT / ".venv" / "psychopy-app"
    wx = Path("/usr/lib/python3/dist-packages/wx")
    if not (app / "psychopy_app").is_dir() or not (wx / "html2.py").is_file():
        pytest.fail("Builder is missing: `make test` installs Debian's python3-wxgtk4.0 and "
                    "python3-wxgtk-webview4.0, and psychopy-app into .venv/psychopy-app")
    (tmp_path / "wxpath").mkdir()
    (tmp_path / "wxpath" / "wx").symlink_to(wx)  # wx alone, not Debian's other packages
    psyexp = _shrunk(_copy_demo(tmp_path), tmp_path / "demo.psyexp")
    _, env = _compiled(tmp_path, psyexp, "sim")  # a Device Manager that names 'haptic'
    shots = artifacts / "screens"
    shots.mkdir(parents=True, exist_ok=True)
    names = ("builder-haptic-contact.png", "builder-device-manager.png")
    for name in names:
        (shots / name).unlink(missing_ok=True)
    out = subprocess.run([sys.executable, str(HELPER.with_name("builder_dialog.py")),
                          str(psyexp), "tap_first", str(shots)], capture_output=True,
                         text=True, timeout=300,
                         env={**env, "DISPLAY": xdisplay,
                              "PYTHONPATH": f"{tmp_path / 'wxpath'}{os.pathsep}{app}"})
    assert out.returncode == 0, out.stderr[-3000:]
    from PIL import Image

    for name in names:  # written by this run (the Builder app keeps stdout to itself)
        img = Image.open(shots / name).convert("L")
        assert img.size[0] > 400 and img.size[1] > 300
        assert len(set(img.getdata())) > 20  # drawn controls and text, not a blank window
