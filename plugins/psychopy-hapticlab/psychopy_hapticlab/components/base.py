"""What both hapticlab components share: the device parameter, the end of the routine, the
library class their code drives, and Builder's check of their parameters."""

from __future__ import annotations

import math

from psychopy.alerts import alert
from psychopy.experiment.components import BaseDeviceComponent, Param
from psychopy.localization import _translate

from .backend import PLUGIN, HapticlabDeviceBackend
from .validation import ALERT, register_alert

__all__ = ["HapticComponent", "VARIES", "constant"]


class HapticComponent(BaseDeviceComponent):
    """Base of the hapticlab components (not itself in Builder's panel)."""

    targets = ["PsychoPy"]
    plugin = PLUGIN
    version = "2026.2.0"
    beta = True
    hidden = True
    #: the device class the component talks to (PsychoPy's tests resolve it)
    deviceClasses = ["psychopy_hapticlab.device.HapticlabDevice"]
    #: the library class the written code drives: (its name, its module)
    library = ("", "")
    #: the label and hint of "End routine …"
    endRoutine = ("End routine when done", "End the routine when this component is done")

    def __init__(self, exp, parentName, name, deviceLabel="haptic", forceEndRoutine=True,
                 **base):
        super().__init__(exp, parentName, name=name, deviceLabel=deviceLabel, **base)
        self.type = type(self).__name__.removesuffix("Component")
        self.exp.requireImport(importName=self.library[0], importFrom=self.library[1])
        register_alert()
        self.params["forceEndRoutine"] = Param(
            forceEndRoutine, valType="bool", inputType="bool", categ="Basic",
            label=_translate(self.endRoutine[0]), hint=_translate(self.endRoutine[1]))
        self.order += ["forceEndRoutine"]

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        if not cls.__dict__.get("hidden", False):
            cls.registerBackend(HapticlabDeviceBackend)

    def integrityCheck(self):
        """Builder's check of the experiment: each problem :meth:`problems` finds is an
        alert naming the component and what is wrong (Builder's alerts panel)."""
        super().integrityCheck()
        for problem in self.problems():
            alert(ALERT, obj=self, strFields={"name": self.params["name"].val,
                                              "problem": problem})

    def problems(self) -> list[str]:
        """What is wrong with the constant parameters, in words (empty when nothing)."""
        if str(self.params["deviceLabel"].val).strip() in ("", "None"):
            return ["Device: name the hapticlab device (its label in Device Manager)"]
        return []

    def positive(self, *keys: str) -> list[str]:
        """A problem for each constant parameter of ``keys`` that is not a finite number
        > 0 (durations, waits [s]); $-values are checked when the routine runs."""
        out = []
        for key in keys:
            p = self.params[key]
            v = constant(p)
            if v is not VARIES and not (isinstance(v, (int, float)) and math.isfinite(v)
                                        and v > 0):
                out.append(f"{p.label}: must be a finite number > 0, got {p.val!r}")
        return out

    def writeEndCode(self, buff, poll: str, after: str = "") -> None:
        """Each frame: the start test (``start()``), then while active ``poll`` until it
        says done (the routine ends when asked), then the stop test (``after``)."""
        name = self.params["name"]
        buff.writeIndentedLines(f"\n# *{name}* updates\n")
        indented = self.writeStartTestCode(buff)
        if indented:
            buff.writeIndentedLines(f"{name}.start()\n")
            buff.setIndentLevel(-indented, relative=True)
        indented = self.writeActiveTestCode(buff)
        if indented:
            code = f"if {poll}:\n    {name}.tStop = t\n    {name}.tStopRefresh = tThisFlipGlobal\n"
            if self.params["saveStartStop"].val:
                code += f"    thisExp.addData('{name}.stopped', t)\n"
            if self.params["forceEndRoutine"].val:
                code += "    continueRoutine = False\n"
            buff.writeIndentedLines(code)
            buff.setIndentLevel(-indented, relative=True)
        indented = self.writeStopTestCode(buff)
        if indented:
            if after:
                buff.writeIndentedLines(after)
            buff.setIndentLevel(-indented, relative=True)


class _Varies:
    """A parameter whose value is known only when the experiment runs."""


VARIES = _Varies()


def constant(param):
    """A constant parameter's value (a number as a float), or :data:`VARIES` for a
    $-value or one set every repeat."""
    val = param.val
    if param.updates not in ("constant", None) or (isinstance(val, str)
                                                    and val.strip().startswith("$")):
        return VARIES
    if param.valType in ("num", "code") and isinstance(val, str):
        try:
            return float(val)
        except ValueError:
            return val
    return val
