"""The reference firmware's servo tick on the Cortex-M4, in instructions.

``hapticlab bench tick [--json]`` boots ``firmware/build/hlfw-tickbench.elf`` on QEMU's
netduinoplus2 (STM32F405) with ``-icount shift=0``: the virtual clock advances 1 ns per
executed instruction and the firmware reads it through SysTick (168 MHz, 5.95
instructions a count). The firmware drives its own device code through a scripted
session (firmware/stm32/tickbench.c) and prints, per device state, the median, 99th
percentile and maximum instructions of one servo tick; a calibration loop of 120,000
instructions checks the scale first. The counts are deterministic: one run is the figure.

The 100-µs tick at 168 MHz has 16,800 cycles. Instructions are not cycles: a Cortex-M4
takes 1 cycle for most, 2 for loads, 2–4 for a taken branch, 14 for VDIV/VSQRT, plus
flash wait states when the ART cache misses. The table gives the budget's share at an
assumed 3 cycles per instruction as well, as a pessimistic reading; a board with the DWT
cycle counter (``hl_device_peek().max_tick_cycles``) gives the real one.
"""

from __future__ import annotations

import re
import shutil
import subprocess

from ._common import emit, print_table

BUDGET_CYCLES = 168_000_000 // 10_000
PESSIMISTIC_CPI = 3


def run_tickbench(timeout: float = 300.0) -> dict:
    """Boot the tick bench under QEMU and parse what it prints.

    Returns
    -------
    dict
        ``calibration`` (instructions counted for a 120,000-instruction loop), ``states``
        (name → ticks, median, p99, max [instructions]) and ``events`` (name → count).
    """
    from device.errors import DeviceError
    from device.serial.firmware import FIRMWARE_DIR

    if shutil.which("qemu-system-arm") is None:
        raise DeviceError("qemu-system-arm is missing: install Debian's qemu-system-arm "
                          "(`make test` does)")
    elf = FIRMWARE_DIR / "build" / "hlfw-tickbench.elf"
    if not elf.exists():
        run = subprocess.run(["make", "-C", str(FIRMWARE_DIR), "build/hlfw-tickbench.elf"],
                             capture_output=True, text=True)
        if run.returncode != 0:
            raise DeviceError(f"building the tick bench failed:\n{run.stderr[-800:]}")
    proc = subprocess.Popen(["qemu-system-arm", "-M", "netduinoplus2", "-icount", "shift=0",
                             "-nographic", "-monitor", "none", "-serial", "stdio",
                             "-kernel", str(elf)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, text=True)
    lines: list[str] = []
    try:
        for line in proc.stdout:
            lines.append(line.strip())
            if line.startswith("end"):
                break
    finally:
        proc.kill()
        proc.wait(timeout=10)
    text = "\n".join(lines)
    if not lines or lines[-1] != "end":
        raise DeviceError(f"the tick bench did not finish under QEMU:\n{text[-800:]}")
    out: dict = {"calibration": int(re.search(r"120000 instructions counted as (\d+)",
                                               text).group(1)),
                 "states": {}, "events": {}}
    for m in re.finditer(r"^(idle|homed|window|playing|fault) (\d+) (\d+) (\d+) (\d+)$",
                         text, re.M):
        out["states"][m.group(1)] = dict(zip(("ticks", "median", "p99", "max"),
                                             map(int, m.groups()[1:]), strict=True))
    for m in re.finditer(r"([a-z_]+) (\d+)", text.split("instructions per servo tick)")[1]):
        if m.group(1) not in out["states"]:
            out["events"][m.group(1)] = int(m.group(2))
    return out


def main(args) -> int:
    res = run_tickbench()
    base = res["states"]["idle"]["median"]
    rows = []
    for name, s in res["states"].items():
        rows.append((name, s["ticks"], s["median"], s["p99"], s["max"],
                     f"{s['max'] / base:.2f}×",
                     f"{100 * s['max'] / BUDGET_CYCLES:.1f} %",
                     f"{100 * PESSIMISTIC_CPI * s['max'] / BUDGET_CYCLES:.1f} %"))
    payload = {"benchmark": "tick", "calibration_of_120000": res["calibration"],
               "budget_cycles": BUDGET_CYCLES, "states": res["states"],
               "events": res["events"]}
    if args.json:
        emit(payload, True)
        return 0
    print(f"calibration: a 120,000-instruction loop counted as {res['calibration']:,}")
    print_table("servo tick on the Cortex-M4 (QEMU netduinoplus2, -icount shift=0), "
                "instructions; ratio against the idle tick's median in the same run",
                ("state", "ticks", "median", "p99", "max", "max / idle",
                 "of 16,800 cycles at 1 CPI", f"at {PESSIMISTIC_CPI} CPI"), rows)
    print("scenario: " + ", ".join(f"{k} {v}" for k, v in res["events"].items()))
    return 0
