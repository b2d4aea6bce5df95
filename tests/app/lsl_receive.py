"""Receive hapticlab's LSL markers with a pylsl inlet while a command runs (a test helper,
run inside tools/private_net.py).

usage: lsl_receive.py OUT.json COMMAND [ARG...]

Starts COMMAND, resolves the stream ``hapticlab markers``, pulls every marker until one with
event ``session_end`` arrives and COMMAND has exited, and writes to OUT.json: the markers
(stamp [s], text, receipt [s] on pylsl.local_clock), the inlet's time correction [s], and
COMMAND's exit status and output.
"""

import json
import subprocess
import sys

from app.markers import private_network_problem


def main(out: str, cmd: list[str]) -> int:
    if (why := private_network_problem()) is not None:  # before liblsl is loaded
        print(f"lsl_receive: not in a private network: {why}", file=sys.stderr)
        return 2
    import pylsl

    out_f, err_f = open(f"{out}.stdout", "w+"), open(f"{out}.stderr", "w+")  # never a full pipe
    proc = subprocess.Popen(cmd, stdout=out_f, stderr=err_f, text=True)
    found = []
    while not found and proc.poll() is None:
        found = pylsl.resolve_byprop("name", "hapticlab markers", timeout=1.0)
    markers, correction = [], None
    if found:
        inlet = pylsl.StreamInlet(found[0], max_buflen=360)
        inlet.open_stream(timeout=60)
        correction = inlet.time_correction(timeout=10)  # while the outlet is there
        while True:
            sample, stamp = inlet.pull_sample(timeout=1.0)
            if sample is not None:
                markers.append([stamp, sample[0], pylsl.local_clock()])
                if json.loads(sample[0])["event"] == "session_end":
                    break
            elif proc.poll() is not None:
                break
    proc.wait(timeout=600)
    stdout, stderr = (f.seek(0) or f.read() for f in (out_f, err_f))
    with open(out, "w") as f:
        json.dump({"markers": markers, "time_correction_s": correction,
                   "returncode": proc.returncode, "stdout": stdout, "stderr": stderr}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2:]))
