"""Set up a computer's Device Manager and compile an experiment, as Builder does (a test
helper, run in a process whose HOME is the test's own, so PsychoPy's preferences are).

usage: builder_helper.py DEVICE-LABEL SPEC LIVE IN.psyexp OUT.py

Writes DEVICE-LABEL into this HOME's devices.json (the hapticlab backend, SPEC, LIVE for a
simulated device), activates the plugins as the Builder app does at its start, then compiles
IN.psyexp with PsychoPy's compiler (psychopy.scripts.psyexpCompile.compileScript).
"""

import sys


def main(label: str, spec: str, live: str, psyexp: str, out: str) -> int:
    from psychopy import plugins

    plugins.activatePlugins()
    from psychopy import prefs
    from psychopy.scripts.psyexpCompile import compileScript
    from psychopy_hapticlab.components.backend import HapticlabDeviceBackend

    profile = next(p for p in HapticlabDeviceBackend.getAvailableDevices()
                   if p["spec"] == "sim")  # the profile Device Manager offers
    b = HapticlabDeviceBackend(profile)
    b.name = label
    b.params["spec"].val = spec
    b.params["live"].val = live == "live"
    prefs.devices[label] = b
    prefs.devices.save()
    compileScript(psyexp, None, out)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
