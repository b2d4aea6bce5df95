"""Write the demo experiment (``demos/haptic2afc/haptic2afc.psyexp``) with PsychoPy's own
experiment classes, as Builder saves it:

    .venv/bin/python -m psychopy_hapticlab.demos.make_haptic2afc

A two-alternative forced choice between two decaying sinusoids: wood's best vibration set of
the factorial study (SPEC §2, Table 2: A = −150 1/s, B = 80 1/s, 100 Hz) and the same at
66.7 Hz (the study's other frequency level for wood, a factor 1.5 away), on its one 400-N/m
spring. Each trial: tap the first, tap the second, say which felt more like tapping wood
(1 or 2). conditions.csv holds both orders; the loop repeats them three times at random.
"""

from pathlib import Path

from psychopy import plugins

plugins.activatePlugins()

from psychopy import experiment  # noqa: E402 - after the plugins, as Builder loads them
from psychopy.experiment.components.keyboard import KeyboardComponent  # noqa: E402
from psychopy.experiment.components.text import TextComponent  # noqa: E402
from psychopy.experiment.loops import TrialHandler  # noqa: E402

from psychopy_hapticlab.components.check import HapticCheckComponent  # noqa: E402
from psychopy_hapticlab.components.contact import HapticContactComponent  # noqa: E402

HERE = Path(__file__).resolve().parent / "haptic2afc"


def text(exp, routine, name, words, stop=""):
    return TextComponent(exp, routine, name=name, text=words, stopVal=stop,
                         letterHeight=0.05)


def build() -> experiment.Experiment:
    exp = experiment.Experiment()
    exp.name = "haptic2afc"
    s = exp.settings.params
    s["expName"].val = "haptic2afc"
    s["Full-screen window"].val = False
    s["Window size (pixels)"].val = "[1024, 768]"
    s["Units"].val = "height"
    s["logging level"].val = "exp"
    s["Experiment info"].val = "{'participant': 'P01', 'session': '001'}"

    check = exp.addRoutine("check")
    check.addComponent(text(exp, "check", "checking", "Checking the haptic device…"))
    check.addComponent(HapticCheckComponent(exp, "check", name="deviceCheck"))

    intro = exp.addRoutine("instructions")
    intro.addComponent(text(exp, "instructions", "intro",
                            "You will tap two surfaces with the stylus, one after the other.\n"
                            "Then say which felt more like tapping wood:\n"
                            "1 = the first, 2 = the second.\n\nPress space to begin."))
    intro.addComponent(KeyboardComponent(exp, "instructions", name="begin",
                                         allowedKeys="'space'"))

    fields = {"transient": "q_sinusoid", "slope": -150.0, "decay": 80.0, "spring": 400.0}
    for k, (which, col) in enumerate((("first", "freq_first"), ("second", "freq_second"))):
        rname = f"feel_{which}"
        rt = exp.addRoutine(rname)
        rt.addComponent(text(exp, rname, f"{rname}_text",
                             f"Tap the {which} surface ({k + 1} of 2)"))
        contact = HapticContactComponent(exp, rname, name=f"tap_{which}",
                                         windowDuration=3.0, **fields)
        contact.params["frequency"].val = f"${col}"
        contact.params["frequency"].updates = "set every repeat"
        rt.addComponent(contact)

    choose = exp.addRoutine("choose")
    choose.addComponent(text(exp, "choose", "question",
                             "Which felt more like tapping wood?\n1 = the first, "
                             "2 = the second"))
    choose.addComponent(KeyboardComponent(exp, "choose", name="choice",
                                          allowedKeys="'1','2'"))

    bye = exp.addRoutine("thanks")
    bye.addComponent(text(exp, "thanks", "bye", "Thank you.", stop="1.0"))

    for pos, rt in enumerate((check, intro, exp.routines["feel_first"],
                              exp.routines["feel_second"], choose, bye)):
        exp.flow.addRoutine(rt, pos)
    trials = TrialHandler(exp, name="trials", loopType="random", nReps=3,
                          conditionsFile="conditions.csv")
    exp.flow.addLoop(trials, 2, 5)
    return exp


if __name__ == "__main__":
    exp = build()
    exp.saveToXML(str(HERE / "haptic2afc.psyexp"), makeLegacy=False)
    print(HERE / "haptic2afc.psyexp")
