"""Builder's Haptic contact component: a scene armed when the routine starts, one tapping
window, and the routine's data (contacts, speeds, peak acceleration, saturation, the trace
file and the device's clock) through the experiment handler.

The code it writes drives :class:`psychopy_hapticlab.contact.HapticContact`.
"""

from __future__ import annotations

from pathlib import Path

from psychopy.experiment.components import Param, getInitVals
from psychopy.localization import _translate

from ...contact import SCENE_DEFAULTS, TRACE_MODES, WINDOW_MODES
from ...scenes import SOURCES, TRANSIENT_FIELDS, TRANSIENTS
from ..base import VARIES, HapticComponent, constant

__all__ = ["HapticContactComponent"]

#: the scene's Builder parameters: (label, hint, value type)
_SCENE_PARAMS = {
    "scene": ("Scene from", "Where the scene comes from: its parameters here (each may be "
              "$column of a conditions file), a built-in sample of hapticlab's protocols, or "
              "a scene file (TOML or JSON)", "str"),
    "sample": ("Built-in sample", "protocol/sample, e.g. realism/sinusoid_firm or "
               "factorial/wood_fhigh_dhigh_shigh (hapticlab protocol show NAME lists them)",
               "str"),
    "sceneFile": ("Scene file", "A TOML or JSON file with one scene table: name, spring "
                  "[N/m], transient = {kind, …} or material = {…}", "file"),
    "surfaceHeight": ("Surface height [m]", "Height of the virtual surface in device "
                      "coordinates", "num"),
    "spring": ("Spring [N/m]", "Penetration spring of the virtual surface", "num"),
    "transient": ("Transient", "What plays at each contact: " + ", ".join(TRANSIENTS) +
                  " (q_sinusoid: Q(t) = A·v·exp(−B·t)·sin(2πft), the decaying sinusoid of "
                  "the vibration-parameter study)", "str"),
    "slope": ("Slope A [1/s]", "Amplitude slope of the decaying sinusoid (negative in the "
              "papers' tables)", "num"),
    "decay": ("Decay B [1/s]", "Decay rate of the decaying sinusoid", "num"),
    "frequency": ("Frequency [Hz]", "Frequency of the decaying sinusoid", "num"),
    "gain": ("Gain [N·s/m]", "Force per unit incoming speed (sinusoid in force, pulse)",
             "num"),
    "decayTime": ("Decay time [s]", "Time constant of a sinusoid in force", "num"),
    "pulseDuration": ("Pulse duration [s]", "Length of the force pulse", "num"),
    "librarySource": ("Library source", "The real sample whose taps the library built on "
                      "this device reproduces (hapticlab library build)", "str"),
    "attenuation": ("Attenuation", "Factor on the library's transients, in (0, 2]", "num"),
}


class HapticContactComponent(HapticComponent):
    """A haptic contact: a scene rendered by a hapticlab device during one tapping window
    per routine, with its data in the experiment's rows."""

    categories = ["Stimuli", "Responses"]
    hidden = False
    iconFile = Path(__file__).parent / "hapticContact.png"
    tooltip = _translate("Haptic contact: a scene on a hapticlab force-feedback device, "
                         "tapped during one window")
    library = ("HapticContact", "psychopy_hapticlab.contact")
    endRoutine = ("End routine with window", "End the routine when the window ends")

    def __init__(self, exp, parentName, name="hapticContact", startType="time (s)",
                 startVal=0.0, stopType="duration (s)", stopVal="", startEstim="",
                 durationEstim="", deviceLabel="haptic", window=WINDOW_MODES[0],
                 windowDuration=4.0, timeout=30.0, forceEndRoutine=True, estopKeys="'e'",
                 traces="full", saveStartStop=True, syncScreenRefresh=False, disabled=False,
                 **scene):
        super().__init__(exp, parentName, name=name, startType=startType, startVal=startVal,
                         stopType=stopType, stopVal=stopVal, startEstim=startEstim,
                         durationEstim=durationEstim, deviceLabel=deviceLabel,
                         forceEndRoutine=forceEndRoutine, saveStartStop=saveStartStop,
                         syncScreenRefresh=syncScreenRefresh, disabled=disabled)
        p = self.params
        values = {**SCENE_DEFAULTS, **scene}
        for key, (label, hint, vtype) in _SCENE_PARAMS.items():
            if key == "scene":
                p[key] = Param(values[key], valType="str", inputType="choice",
                               allowedVals=list(SOURCES), categ="Scene",
                               label=_translate(label), hint=_translate(hint))
                continue
            # numbers as code: a conditions column is named as $column, as in Builder's
            # own numeric fields
            p[key] = Param(values[key], valType="code" if vtype == "num" else vtype,
                           inputType="file" if vtype == "file" else "single", categ="Scene",
                           updates="constant",
                           allowedUpdates=["constant", "set every repeat"],
                           label=_translate(label), hint=_translate(hint))
        self.order += list(_SCENE_PARAMS)
        # which fields show, by the scene's source and the transient's kind
        for key in ("sample",):
            self.depends.append({"dependsOn": "scene", "condition": "=='built-in sample'",
                                 "param": key, "true": "show", "false": "hide"})
        self.depends.append({"dependsOn": "scene", "condition": "=='scene file'",
                             "param": "sceneFile", "true": "show", "false": "hide"})
        fields = ("surfaceHeight", "spring", "transient", *(
            k for k in _SCENE_PARAMS if k not in ("scene", "sample", "sceneFile",
                                                  "surfaceHeight", "spring", "transient")))
        for key in fields:
            self.depends.append({"dependsOn": "scene", "condition": "=='parameters'",
                                 "param": key, "true": "show", "false": "hide"})

        p["window"] = Param(window, valType="str", inputType="choice",
                            allowedVals=list(WINDOW_MODES), categ="Basic",
                            label=_translate("Window"),
                            hint=_translate("Count the window's duration from the first "
                                            "contact (waiting up to the timeout for it), or "
                                            "from the component's start"))
        p["windowDuration"] = Param(windowDuration, valType="num", inputType="single",
                                    categ="Basic", label=_translate("Window duration [s]"),
                                    hint=_translate("How long the participant taps"))
        p["timeout"] = Param(timeout, valType="num", inputType="single", categ="Basic",
                             label=_translate("Wait for a first contact [s]"),
                             hint=_translate("Longest wait for the first contact; the row "
                                             "then says timed_out"))
        self.order += ["window", "windowDuration", "timeout"]
        p["estopKeys"] = Param(estopKeys, valType="list", inputType="single", categ="Device",
                               label=_translate("E-stop keys"),
                               hint=_translate("Keys that latch the e-stop during the window "
                                               "(output zero, the experiment stops, its data "
                                               "saved); blank for none. The device's own "
                                               "button always works."))
        p["traces"] = Param(traces, valType="str", inputType="choice",
                            allowedVals=list(TRACE_MODES), categ="Data",
                            label=_translate("Trace files"),
                            hint=_translate("Keep the device's streams of each window: every "
                                            "tick, the taps alone, or none (the file's name "
                                            "goes in the row)"))
        self.order += ["estopKeys", "traces"]

    # ------------------------------------------------------------------ checks
    def problems(self) -> list[str]:
        """What is wrong with the constant parameters, in words (empty when nothing):
        $-values and values set every repeat are checked when the routine runs."""
        from device import SceneError

        from ...contact import HapticContact

        p = self.params
        out = super().problems()
        out += self.positive("windowDuration", "timeout")
        fields = {k: constant(p[k]) for k in SCENE_DEFAULTS}
        source = fields["scene"]
        used = {"built-in sample": ("sample",), "scene file": ("sceneFile",)}.get(
            source, ("surfaceHeight", "spring", "transient",
                     *TRANSIENT_FIELDS.get(str(fields["transient"]), {}).values()))
        if any(fields[k] is VARIES for k in used):
            return out  # a $-value: the routine checks the scene it makes
        probe = object.__new__(HapticContact)
        probe.name = p["name"].val
        probe.fields = fields
        try:
            probe.makeScene()
        except SceneError as exc:
            out.append(str(exc))
        return out

    # ------------------------------------------------------------------ code
    def writeInitCode(self, buff):
        inits = getInitVals(self.params)
        constants = ", ".join(f"{k}={inits[k]}" for k in SCENE_DEFAULTS
                              if self.params[k].updates in ("constant", None))
        code = (
            "# hapticlab: %(name)s on the device labelled %(deviceLabel)s\n"
            "%(name)s = HapticContact(\n"
            "    device=%(deviceLabel)s, name='%(name)s', experiment=thisExp,\n"
            "    window=%(window)s, windowDuration=%(windowDuration)s, timeout=%(timeout)s,\n"
            "    traces=%(traces)s, traceFolder=filename + '_%(name)s',\n"
            "    estopKeys=%(estopKeys)s, forceEndRoutine=%(forceEndRoutine)s,\n"
        )
        tail = (
            "# the experiment ending mid-window (escape) still records the window's row\n"
            "runAtExit.append(%(name)s.rescue)\n"
        )
        buff.writeIndentedLines(code % inits)
        if constants:
            buff.writeIndentedLines(f"    {constants},\n")
        buff.writeIndentedLines(")\n" + tail % inits)

    def writeRoutineStartCode(self, buff):
        self.writeParamUpdates(buff, "set every repeat")
        code = (
            "# arm %(name)s: its scene made and loaded, the stylus homed, output on\n"
            "%(name)s.arm()\n"
        )
        buff.writeIndentedLines(code % self.params)

    def writeFrameCode(self, buff):
        # the window begins at the start; contacts dispatched and e-stop keys read each
        # frame until it ends; a stop that comes first ends it
        name = self.params["name"]
        self.writeEndCode(buff, f"{name}.poll()",
                          f"# the component's stop came first: end the window\n{name}.stop()\n")

    def writeRoutineEndCode(self, buff):
        code = (
            "# %(name)s's row: contacts, speeds, peak acceleration, saturation, trace file,\n"
            "# the device's clock on globalClock (a latched fault stops the experiment here)\n"
            "%(name)s.record(thisExp, clock=globalClock)\n"
        )
        buff.writeIndentedLines(code % self.params)
        super().writeRoutineEndCode(buff)
