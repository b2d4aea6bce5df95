"""The Builder components under PsychoPy's own component tests (the suite PsychoPy runs on
its components and its plugin template hands to plugins: syntax of the written script at
every start/stop, icons for each theme, parameters used, a set… method for each parameter
that changes every repeat), and Builder's check of hapticlab's parameters."""

import pytest
from psychopy import experiment
from psychopy.experiment.loops import TrialHandler
from psychopy.tests.test_experiment.test_components.test_base_components import (
    BaseComponentTests,
    _TestLibraryClassMixin,
)
from psychopy_hapticlab import HapticCheck, HapticContact
from psychopy_hapticlab.components.check import HapticCheckComponent
from psychopy_hapticlab.components.contact import HapticContactComponent
from psychopy_hapticlab.components.validation import ALERT

#: PsychoPy's data and experiment packages look libraries up with ldconfig (a process) as they
#: load: these in-process tests are in the integration tier
pytestmark = [pytest.mark.integration]


class TestHapticContactComponent(BaseComponentTests, _TestLibraryClassMixin):
    comp = HapticContactComponent
    libraryClass = HapticContact


class TestHapticCheckComponent(BaseComponentTests, _TestLibraryClassMixin):
    comp = HapticCheckComponent
    libraryClass = HapticCheck


def _experiment(**params):
    exp = experiment.Experiment()
    exp.name = "HapticCheckExp"
    rt = exp.addRoutine(routineName="feel")
    exp.flow.addRoutine(rt, 0)
    exp.flow.addLoop(TrialHandler(exp=exp, name="trials"), 0, 1)
    comp = HapticContactComponent(exp, "feel", name="tap")
    for k, v in params.items():
        comp.params[k].val = v
    rt.append(comp)
    return exp, comp


def _alerts(exp, capsys) -> list[str]:
    exp.integrityCheck()
    err = capsys.readouterr().err
    return [line for line in err.splitlines() if f"Alert {ALERT}" in line]


def test_builder_names_a_field_hapticlab_refuses(capsys):
    """Builder's check of the experiment (Runner's alerts panel) says which field is wrong
    in hapticlab's words; a $-value is left to the routine, which checks the row's value."""
    exp, comp = _experiment(frequency="-5", transient="q_sinusoid")
    got = _alerts(exp, capsys)
    assert got == [f"Alert {ALERT}: hapticlab component tap: scene 'tap:q_sinusoid'."
                   "transient: frequency: must be > 0, got -5"]
    comp.params["frequency"].val = "$freq"
    comp.params["windowDuration"].val = "0"
    comp.params["deviceLabel"].val = ""
    got = _alerts(exp, capsys)
    assert [g.split(": ", 1)[1] for g in got] == [
        "hapticlab component tap: Device: name the hapticlab device (its label in Device "
        "Manager)",
        "hapticlab component tap: Window duration [s]: must be a finite number > 0, got '0'"]
    exp, comp = _experiment(scene="built-in sample", sample="realism/oak")
    assert "protocol 'realism' has no sample 'oak'" in _alerts(exp, capsys)[0]
    exp, comp = _experiment()
    assert _alerts(exp, capsys) == []


def test_the_script_sets_a_conditions_column_every_repeat():
    exp, comp = _experiment(frequency="$freq")
    comp.params["frequency"].updates = "set every repeat"
    script = exp.writeScript(target="PsychoPy")
    assert "tap.setFrequency(freq)" in script
    start = script.index("tap.setFrequency(freq)")
    assert script.index("tap.arm()", start) > start  # set before the routine arms it
    assert "frequency=" not in script[script.index("tap = HapticContact("):start]
    compile(script, "haptic.py", "exec")


def test_the_backend_writes_the_device_managers_code():
    from psychopy.experiment.exports import IndentingBuffer
    from psychopy_hapticlab.components.backend import HapticlabDeviceBackend

    b = HapticlabDeviceBackend({"deviceName": "hapticlab on /dev/ttyACM0", "spec":
                                "serial:/dev/ttyACM0", "deviceClass":
                                "psychopy_hapticlab.device.HapticlabDevice"})
    b.name = "rig"
    buff = IndentingBuffer(target="PsychoPy")
    b.writeDeviceCode(buff)
    code = buff.getvalue()
    assert "deviceName='rig'" in code and "spec='serial:/dev/ttyACM0'" in code
    assert "deviceClass='psychopy_hapticlab.device.HapticlabDevice'" in code
    assert code.count("spec=") == 1  # the profile's spec is the parameter's, written once
    compile(code, "devices.py", "exec")
    template = HapticlabDeviceBackend.getTemplateJSON()
    assert template["plugin"] == "psychopy-hapticlab"
    assert list(template["params"]) == ["name", "spec", "seed", "live", "clearFault", "lsl"]


def test_the_check_writes_its_selftest_options_and_builder_checks_the_wait(capsys):
    """The self-test's options reach the script (the window too: the operator's prompts are
    drawn there every frame), and a wait for a tap Builder cannot use is an alert naming it."""
    exp, _ = _experiment()
    check = HapticCheckComponent(exp, "feel", name="deviceCheck", check="selftest",
                                 deviceAlone=True, tapWait="0")
    exp.routines["feel"].append(check)
    assert _alerts(exp, capsys) == [f"Alert {ALERT}: hapticlab component deviceCheck: Wait for "
                                    "a tap [s]: must be a finite number > 0, got '0'"]
    check.params["tapWait"].val = "12"
    assert _alerts(exp, capsys) == []
    script = exp.writeScript(target="PsychoPy")
    assert "check='selftest',\n" in script
    assert "stopOnFail=True, deviceAlone=True, tapWait=12" in script
    assert "win=win," in script and "deviceCheck.draw()" in script
    compile(script, "haptic.py", "exec")
