"""The hapticlab device in Builder's Device Manager: a backend whose profiles are what
``hapticlab device list`` finds, and whose settings open it (the experiment names it by its
label; each computer's Device Manager says which device that label is here)."""

from __future__ import annotations

from psychopy.experiment.devices import DeviceBackend
from psychopy.experiment.params import Param
from psychopy.localization import _translate

__all__ = ["HapticlabDeviceBackend", "PLUGIN"]

#: the distribution the Builder elements come from (what a .psyexp names, so that a
#: computer without it says which plugin to install)
PLUGIN = "psychopy-hapticlab"


class HapticlabDeviceBackend(DeviceBackend):
    """A hapticlab haptic device (simulated, a board, an emulator or a bridge)."""

    backendLabel = "hapticlab haptic device"
    deviceClass = "psychopy_hapticlab.device.HapticlabDevice"
    icon = "contact/light/hapticContact.png"
    plugin = PLUGIN

    def getParams(self):
        params = {
            "spec": Param(
                self.profile.get("spec", "sim"), valType="str", inputType="single",
                categ="Device", label=_translate("Device spec"),
                hint=_translate("sim (the simulated device) or serial:PORT (a board, or the "
                                "pseudo-terminal of an emulator or bridge), as `hapticlab "
                                "device list` shows")),
            "seed": Param(
                0, valType="int", inputType="single", categ="Device",
                label=_translate("Simulation seed"),
                hint=_translate("The simulated device's seed (its tapping hand, its sensor "
                                "noise); hardware ignores it")),
            "live": Param(
                True, valType="bool", inputType="bool", categ="Device",
                label=_translate("Simulate in real time"),
                hint=_translate("Pace the simulated device to the wall clock, as a person "
                                "feels it; off runs it in virtual time, as fast as it "
                                "computes (dry runs)")),
            "clearFault": Param(
                False, valType="bool", inputType="bool", categ="Device",
                label=_translate("Clear a latched fault"),
                hint=_translate("Clear an e-stop or watchdog fault the device latched before "
                                "the experiment (only once the device is safe); otherwise "
                                "such a device refuses to open")),
            "lsl": Param(
                False, valType="bool", inputType="bool", categ="Device",
                label=_translate("Send LSL markers"),
                hint=_translate("hapticlab's event markers on a Lab Streaming Layer outlet, "
                                "with the trial ids of the data file (needs pylsl)")),
        }
        return params, ["spec", "seed", "live", "clearFault", "lsl"]

    def writeDeviceCode(self, buff):
        self.writeBaseDeviceCode(buff, close=False)
        code = (
            "    spec=%(spec)s,\n"
            "    seed=%(seed)s,\n"
            "    live=%(live)s,\n"
            "    clearFault=%(clearFault)s,\n"
            "    lsl=%(lsl)s,\n"
            "    label=%(name)s,\n"
            ")\n"
        )
        buff.writeIndentedLines(code % self.params)
