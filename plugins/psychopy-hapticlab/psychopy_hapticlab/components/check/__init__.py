"""Builder's Haptic device check component: hapticlab's preflight or self-test of the device
in the routine it sits in (the experiment's first, usually), its verdict in the data.

On a device whose contact is physical the self-test asks the operator to tap the stylus in
five of its checks: the prompts are drawn at the foot of the experiment's window and logged
(a full-screen experiment hides the terminal the command-line self-test prints to); *Device
alone* runs only the checks nobody has to tap for, the five reported as not run.

The code it writes drives :class:`psychopy_hapticlab.check.HapticCheck`.
"""

from __future__ import annotations

from pathlib import Path

from psychopy.experiment.components import Param, getInitVals
from psychopy.localization import _translate

from ...check import CHECKS
from ..base import HapticComponent

__all__ = ["HapticCheckComponent"]


class HapticCheckComponent(HapticComponent):
    """A check of the hapticlab device before any trial: the preflight (who it is, no
    latched fault) or the full self-test; the routine ends when it has its verdict."""

    categories = ["Responses", "Custom"]
    hidden = False
    iconFile = Path(__file__).parent / "hapticCheck.png"
    tooltip = _translate("Haptic device check: hapticlab's preflight or self-test of the "
                         "device, its verdict in the data")
    library = ("HapticCheck", "psychopy_hapticlab.check")
    endRoutine = ("End routine when done", "End the routine when the check has its verdict")

    def __init__(self, exp, parentName, name="hapticCheck", startType="time (s)",
                 startVal=0.0, stopType="duration (s)", stopVal="", startEstim="",
                 durationEstim="", deviceLabel="haptic", check="preflight", stopOnFail=True,
                 deviceAlone=False, tapWait=30.0, forceEndRoutine=True, saveStartStop=True,
                 syncScreenRefresh=False, disabled=False):
        super().__init__(exp, parentName, name=name, startType=startType, startVal=startVal,
                         stopType=stopType, stopVal=stopVal, startEstim=startEstim,
                         durationEstim=durationEstim, deviceLabel=deviceLabel,
                         forceEndRoutine=forceEndRoutine, saveStartStop=saveStartStop,
                         syncScreenRefresh=syncScreenRefresh, disabled=disabled)
        p = self.params
        p["check"] = Param(check, valType="str", inputType="choice", allowedVals=list(CHECKS),
                           allowedLabels=[_translate("Preflight (about 1 s, nothing moves)"),
                                          _translate("Self-test (every check, the stylus "
                                                     "moves)")],
                           categ="Basic", label=_translate("Check"),
                           hint=_translate("preflight: the device answers and has no latched "
                                           "fault; selftest: hapticlab's device self-test "
                                           "(spring law, transients, saturation, e-stop, "
                                           "watchdog, ramp…)"))
        p["stopOnFail"] = Param(stopOnFail, valType="bool", inputType="bool", categ="Basic",
                                label=_translate("Stop the experiment unless it passes"),
                                hint=_translate("A check that failed, or a self-test with checks "
                                                "not run (device alone), ends the experiment "
                                                "before any trial, naming them (the verdict is "
                                                "saved first)"))
        p["deviceAlone"] = Param(deviceAlone, valType="bool", inputType="bool", categ="Basic",
                                 label=_translate("Device alone (physical device)"),
                                 hint=_translate("Self-test of a device whose contact is "
                                                 "physical: run only the checks nobody has to "
                                                 "tap the stylus for; the five others are "
                                                 "recorded as not run, so the verdict is "
                                                 "'incomplete', never 'pass'. Unticked, the "
                                                 "operator is asked on screen when to tap. A "
                                                 "simulated device runs every check either "
                                                 "way"))
        p["tapWait"] = Param(tapWait, valType="num", inputType="single", categ="Basic",
                             label=_translate("Wait for a tap [s]"),
                             hint=_translate("Self-test of a device whose contact is physical: "
                                             "how long each check that needs a tap waits for "
                                             "the stylus after asking; nobody tapping fails "
                                             "that check"))
        self.depends += [{"dependsOn": "check", "condition": "=='selftest'", "param": param,
                          "true": "show", "false": "hide"} for param in ("deviceAlone",
                                                                          "tapWait")]
        self.order += ["check", "stopOnFail", "deviceAlone", "tapWait"]

    def problems(self) -> list[str]:
        return super().problems() + self.positive("tapWait")

    def writeInitCode(self, buff):
        code = (
            "# hapticlab: %(name)s checks the device labelled %(deviceLabel)s\n"
            "%(name)s = HapticCheck(\n"
            "    device=%(deviceLabel)s, name='%(name)s', check=%(check)s,\n"
            "    stopOnFail=%(stopOnFail)s, deviceAlone=%(deviceAlone)s, tapWait=%(tapWait)s,\n"
            "    win=win,\n"
            ")\n"
        )
        buff.writeIndentedLines(code % getInitVals(self.params))

    def writeFrameCode(self, buff):
        # the check begins at the start, in its own thread; done when it has its verdict.
        # Meanwhile what the self-test asks of the operator (a physical device) is drawn
        self.writeEndCode(buff, f"{self.params['name']}.poll()")
        buff.writeIndentedLines(f"{self.params['name']}.draw()\n")

    def writeRoutineEndCode(self, buff):
        code = (
            "# %(name)s's verdict into the data (a failure stops the experiment here)\n"
            "%(name)s.record(thisExp)\n"
        )
        buff.writeIndentedLines(code % self.params)
        super().writeRoutineEndCode(buff)


