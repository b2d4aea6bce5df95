"""The Haptic device check in self-test mode, in an experiment PsychoPy compiles and runs in
a real window under Xvfb: on the simulated device every check passes, the verdict and its
counts are in the data file and the experiment goes on; on a lab's rig without an output
ramp (a backend installed as another distribution installs one) the ramp check fails, the
data file names it, and the experiment stops before its next routine, saying why.

In process (no window, a few checks), the part that needs a person at a physical device:
what the self-test asks of the operator reaches PsychoPy's log and the component's text, and
device-alone checks are counted as not run, never as passed, and stop the experiment.
"""

import io
import os

import pytest

from device import suite

from ..device.test_registry import _install
from ..device.test_selftest_operator import PhysicalSim
from .test_builder_runs import _compiled, _data, _run

#: a lab's rig whose amplifier switches output on at full scale, without the ramp hapticlab
#: asks of every device (ramp check): the simulated device with its ramp set to zero, saying
#: its contact is physical (its simulated hand taps, as an operator asked to would)
RIG = """
    from dataclasses import replace

    from device.sim.backend import SimDevice
    from device.sim.params import DeviceParams


    class StepRig(SimDevice):
        def __init__(self, **options):
            super().__init__(device=DeviceParams(ramp_s=0.0), **options)
            self._info = replace(self._info, backend="steprig", model="a rig without a ramp",
                                 simulated_contact=False, seeded=False)

        @classmethod
        def available(cls):
            return []
"""

#: the checks that need someone to tap the stylus, as the data file names them
TAPPED = ";".join(suite.TAPPED)


def _experiment(tmp, **check):
    """A Haptic device check (self-test, the device labelled 'haptic') in the first
    routine, then a routine of one short text: reached only when the check lets the
    experiment go on."""
    from psychopy import experiment, plugins
    from psychopy.experiment.components.text import TextComponent

    plugins.activatePlugins()
    from psychopy_hapticlab.components.check import HapticCheckComponent

    exp = experiment.Experiment()
    exp.name = exp.settings.params["expName"].val = "selftest"
    exp.settings.params["Show info dlg"].val = False
    exp.settings.params["Window size (pixels)"].val = "[640, 480]"
    exp.settings.params["logging level"].val = "exp"
    first = exp.addRoutine("check")
    first.addComponent(HapticCheckComponent(exp, "check", name="deviceCheck",
                                            check="selftest", **check))
    after = exp.addRoutine("after")
    after.addComponent(TextComponent(exp, "after", name="go", text="the trials",
                                     stopVal=0.1))
    exp.flow.addRoutine(first, 0)
    exp.flow.addRoutine(after, 1)
    exp.saveToXML(str(tmp / "selftest.psyexp"), makeLegacy=False)
    return tmp / "selftest.psyexp"


@pytest.mark.screen
@pytest.mark.integration
@pytest.mark.slow
def test_the_selftest_passes_on_the_simulated_device_and_the_experiment_goes_on(
        tmp_path, xdisplay):
    script, env = _compiled(tmp_path, _experiment(tmp_path), "sim")
    out = _run(script, env, xdisplay)
    assert out.returncode == 0, out.stderr[-3000:]
    d, log = _data(tmp_path)
    row = d[d["deviceCheck.verdict"].notna()].iloc[0]
    assert (row["deviceCheck.check"], row["deviceCheck.verdict"]) == ("selftest", "pass")
    assert (row["deviceCheck.passed"], row["deviceCheck.failed"],
            row["deviceCheck.not_run"]) == (13, 0, 0)
    assert not bool(row["deviceCheck.physical_contact"])
    assert row["deviceCheck.checks"].count(": ok (") == 13
    assert d["go.started"].notna().any()  # the routine after the check ran
    # a simulated hand taps by itself: nothing asked of anyone
    assert "tap the stylus" not in log + out.stdout + out.stderr
    assert "selftest of haptic: pass (selftest: 13 passed, 0 failed, 0 not run)" in log


@pytest.mark.screen
@pytest.mark.integration
@pytest.mark.slow
def test_a_rig_that_fails_a_check_stops_the_experiment_naming_it(tmp_path, xdisplay):
    """Device alone on a physical device (the eight checks nobody taps for): the ramp
    check fails on the rig that steps its output on, the five others are not run, and
    the experiment stops before the next routine, its verdict in the data file."""
    _install(tmp_path / "rig", "lab_steprig", {"steprig": "lab_steprig:StepRig"},
             {"lab_steprig": RIG})
    psyexp = _experiment(tmp_path, deviceAlone=True, tapWait=5.0)
    script, env = _compiled(tmp_path, psyexp, "steprig")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, (str(tmp_path / "rig"),
                                                      env.get("PYTHONPATH"))))
    out = _run(script, env, xdisplay)
    assert out.returncode != 0
    assert ("HapticFaultError: haptic (steprig) did not pass its selftest: failed ramp; did "
            f"not run {TAPPED.replace(';', ', ')} (they need someone to tap the stylus: "
            "untick Device alone)") in out.stderr, out.stderr[-3000:]
    d, log = _data(tmp_path)
    row = d[d["deviceCheck.verdict"].notna()].iloc[0]
    assert row["deviceCheck.verdict"] == "fail"
    assert (row["deviceCheck.passed"], row["deviceCheck.failed"],
            row["deviceCheck.not_run"]) == (7, 1, 5)
    assert row["deviceCheck.failed_checks"] == "ramp"
    assert row["deviceCheck.not_run_checks"] == TAPPED
    assert bool(row["deviceCheck.physical_contact"]) and bool(row["deviceCheck.device_alone"])
    assert "ramp: FAIL (CheckFailed: no output ramp after enabling)" in row["deviceCheck.checks"]
    assert "go.started" not in d or d["go.started"].isna().all()  # stopped before it
    # the operator was told which checks needed a tap (PsychoPy's log file and its console)
    plan = "5 need someone to tap the stylus (" + TAPPED.replace(";", ", ") + "): not run"
    assert plan in log and plan in out.stdout + out.stderr, out.stdout[-2000:]
    assert "hapticlab haptic: closed steprig (output 0 N)" in log


# ---------------------------------------------------------------- in process: the operator

#: two checks the device does alone, two that need the stylus tapped (cheap ones of each)
SOME = ("ramp", "bad_input", "spring_law", "window_length")


@pytest.fixture
def bench(monkeypatch):
    """'bench', a device that says its contact is physical (the simulated device underneath:
    its hand taps when asked), open as PsychoPy opens it, with a few of the checks; and the
    lines PsychoPy logs at warning and above."""
    from psychopy import logging
    from psychopy_hapticlab import HapticlabDevice

    import device.registry

    monkeypatch.setitem(device.registry._REGISTERED, "bench", PhysicalSim)
    monkeypatch.setattr(suite, "CHECKS", {n: suite.CHECKS[n] for n in SOME})
    log = io.StringIO()
    target = logging.LogFile(log, level=logging.WARNING)
    dev = HapticlabDevice("bench", live=False, label="rig")
    yield dev, log
    dev.close()
    logging.root.removeTarget(target)


def _check(dev, **kw):
    from psychopy.data import ExperimentHandler
    from psychopy_hapticlab import HapticCheck

    exp = ExperimentHandler(name="bench", savePickle=False, saveWideText=False)
    return HapticCheck(dev, name="deviceCheck", check="selftest", **kw), exp


@pytest.mark.integration  # PsychoPy's data package runs ldconfig as it loads
def test_the_operator_is_asked_to_tap_in_the_log_and_the_components_text(bench):
    """What the self-test says goes to PsychoPy's log (warnings: the Runner's console shows
    them) and is the check's text as it is said (what draw() shows on the window); at the
    end the text is the verdict's counts."""
    from psychopy import logging

    dev, log = bench
    check, exp = _check(dev, tapWait=10.0)
    texts = []
    say = check._say
    check._say = lambda line: (say(line), texts.append(check.text))
    check.wait()
    assert check.verdict == "pass" and check.result["passed"] == 4
    logging.flush()
    said = log.getvalue()
    plan = ("2 need someone to tap the stylus (spring_law, window_length): you will be asked "
            "at each")
    assert plan in said and plan in texts[0], said
    for name in ("spring_law", "window_length"):
        prompt = f"[{name}] tap the stylus down onto the virtual surface now"
        assert f"hapticlab deviceCheck: {prompt}" in said
        assert any(t.startswith(prompt) for t in texts), texts
    assert check.text == "selftest: 4 passed, 0 failed, 0 not run"
    data = check.record(exp)
    assert (data["verdict"], data["physical_contact"], data["device_alone"]) == \
        ("pass", True, False)


@pytest.mark.integration
def test_device_alone_counts_not_run_apart_and_stops_the_experiment(bench):
    from psychopy_hapticlab import HapticFaultError

    dev, log = bench
    check, exp = _check(dev, deviceAlone=True)
    check.wait()
    assert check.verdict == "incomplete"
    with pytest.raises(HapticFaultError, match=r"rig \(bench\) did not pass its selftest: did "
                       r"not run spring_law, window_length \(they need someone to tap"):
        check.record(exp)
    row = exp.thisEntry  # recorded before it stopped
    assert (row["deviceCheck.verdict"], row["deviceCheck.passed"], row["deviceCheck.failed"],
            row["deviceCheck.not_run"]) == ("incomplete", 2, 0, 2)
    assert row["deviceCheck.not_run_checks"] == "spring_law;window_length"
    assert row["deviceCheck.failed_checks"] == ""
    assert "spring_law: not run (needs someone to tap" in row["deviceCheck.checks"]
    check.stopOnFail = False  # recorded, and the experiment goes on
    assert check.record(exp)["verdict"] == "incomplete"
