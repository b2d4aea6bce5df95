"""Coder example: a hapticlab device through PsychoPy's DeviceManager, two decaying
sinusoids tapped one after the other, their contacts and rows.

    python coder_contact.py                       # the simulated device, in virtual time
    python coder_contact.py --spec serial:/dev/ttyACM0 --live   # a board (hardware)
    python coder_contact.py --lsl                 # with LSL markers (a recorder must listen)
"""

import argparse
from pathlib import Path

from psychopy import core, data
from psychopy.hardware import DeviceManager

from psychopy_hapticlab import HapticContact

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--spec", default="sim", help="hapticlab device spec (default: sim)")
parser.add_argument("--live", action="store_true", help="pace a simulated device in real time")
parser.add_argument("--lsl", action="store_true", help="send LSL markers")
parser.add_argument("--data", default="data", help="folder for the data file and traces")
args = parser.parse_args()

# the device, by the alias the plugin registers; DeviceManager closes it at exit
device = DeviceManager.addDevice(deviceClass="hapticlab", deviceName="haptic", spec=args.spec,
                                 live=args.live, lsl=args.lsl, lslWait=30.0, label="haptic")
Path(args.data).mkdir(parents=True, exist_ok=True)
thisExp = data.ExperimentHandler(name="coder_contact",
                                 dataFileName=str(Path(args.data) / "coder_contact"))
clock = core.Clock()

# wood's best vibration set of the factorial study (SPEC §2, Table 2) and its 66.7-Hz level
contact = HapticContact("haptic", name="tap", experiment=thisExp, windowDuration=1.0,
                        traceFolder=Path(args.data) / "coder_contact_tap", spring=400.0,
                        transient="q_sinusoid", slope=-150.0, decay=80.0)
for frequency in (100.0, 66.7):
    contact.setFrequency(frequency)
    contact.arm()                        # scene loaded, stylus homed, output ramped on
    contact.start()                      # the window: 1 s from the first contact
    while not contact.poll():            # contacts dispatched as they come
        core.wait(0.01)
    row = contact.record(thisExp, clock=clock)   # the row; a latched fault raises here
    thisExp.nextEntry()
    print(f"{frequency:g} Hz: trial {row['trial_id']}, {row['status']}, "
          f"{row['n_contacts']} contacts at {row['speeds']} m/s, peak acceleration "
          f"{row['peak_accel']} m/s², trace {row['trace_file']}")
    for response in device.getResponses(kind="contact"):
        print("   ", response)

thisExp.saveAsWideText(str(Path(args.data) / "coder_contact.csv"), delim=",")
thisExp.abort()  # saved above; nothing more at exit
