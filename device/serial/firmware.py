"""The reference firmware (``firmware/``) as a device on a pseudo-terminal.

Six builds serve the protocol with the firmware's simulated plant: ``host`` (the C code
compiled for this machine, paced to its clock), ``host-board`` (the same with the
STM32F405's resources and its 1-Mbaud link as LIMITS: what a lab's board offers a host, at
any speed), ``host-san`` (that under ASan and UBSan) and ``qemu`` (the Cortex-M build on
an emulated STM32F405, netduinoplus2, its USART on a pty), and the bridges to commercial
devices over hapticlab's stand-ins for their SDKs, ``dhd-stub`` (Force Dimension, 4 kHz) and
``hd-stub`` (OpenHaptics, 1 kHz: :data:`BRIDGE_STUBS`). :func:`host_command` and
:func:`qemu_command` say how to start each, building it with ``make -C firmware`` when the
binary is missing; the caller
(``hapticlab device emulate --firmware``) prints the port as its first line.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from ..errors import DeviceError, DeviceSpecError

__all__ = ["FIRMWARE_DIR", "HOST_BUILDS", "CONFORMANCE_TARGETS", "BUILDS", "binary",
           "check_options", "host_command", "qemu_command", "serve", "QEMU_PTY"]

FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware"
#: the builds, by name; ``board-qemu`` is the papers' board I/O built for QEMU (its peripheral
#: traffic is what the tests check; it has no plant, so it serves no session)
_TARGETS = {"host": "build/hlfw-host", "host-board": "build/hlfw-host-board",
            "host-san": "build/hlfw-host-san",
            "dhd-stub": "build/hlfw-dhd-stub", "hd-stub": "build/hlfw-hd-stub",
            "hd-stub-tsan": "build/hlfw-hd-stub-tsan",
            "qemu": "build/hlfw-stm32.elf", "board-qemu": "build/hlfw-board-qemu.elf"}
_ARM = ("arm-none-eabi-gcc", "gcc-arm-none-eabi")
_CC = ("cc", "build-essential")
_TOOLS = {"host": _CC, "host-board": _CC, "host-san": _CC, "dhd-stub": _CC, "hd-stub": _CC,
          "hd-stub-tsan": _CC, "qemu": _ARM, "board-qemu": _ARM}
#: the builds that run on this machine (paced to its clock; at any speed but ``hd-stub``)
HOST_BUILDS = ("host", "host-board", "host-san", "dhd-stub", "hd-stub", "hd-stub-tsan")
#: every device a host can open over the serial link for a session (``hapticlab device
#: emulate --firmware BUILD``): the Python emulator, then each build that serves sessions
#: (not the ThreadSanitizer build, a check of the OpenHaptics one; QEMU's boards are
#: opened the same way but boot for seconds, and the tests that can afford it add them).
#: The conformance suite, the state table and the field ranges run on each.
CONFORMANCE_TARGETS = ("python", *(k for k in HOST_BUILDS if not k.endswith("-tsan")))
#: the bridges to commercial devices, built over hapticlab's stand-ins for their SDKs: the
#: Force Dimension bridge (its own 4-kHz servo loop through libdhd) and the OpenHaptics
#: one (the servo tick in the HD scheduler's 1-kHz callback, real time only). Neither
#: device has an accelerometer on the stylus, so neither records an accel trace.
BRIDGE_STUBS = ("dhd-stub", "hd-stub")
#: the builds whose device runs in real time only (the HD scheduler's clock); the second is
#: the first under ThreadSanitizer (its tick and its link run in two threads)
REAL_TIME_ONLY = ("hd-stub", "hd-stub-tsan")
#: QEMU's clock for the Cortex-M builds: it counts the emulated board's instructions, 8 ns
#: each (2**3; the STM32F405 runs ~130 M instructions/s at 168 MHz), and runs at wall-clock
#: pace while the board sleeps (WFI). Without it the emulated clock is this computer's, so
#: a QEMU thread descheduled between two of the board's instructions let servo ticks pass
#: that the board never had: CI measured an e-stop 4 ticks after its frame on a path of a
#: few hundred instructions. With it a busy computer slows the emulated board down (0.72x
#: wall time while it streams 7 channels at decimation 4, 0.4-0.6x beside two CPU-bound
#: processes) instead of taking its time away.
QEMU_ICOUNT = "shift=3,sleep=on"
#: what qemu-system-arm prints when it puts a serial port on a pty
QEMU_PTY = re.compile(r"char device redirected to (/dev/pts/\d+)")


#: what can emulate a device, and the servo rate each runs at [Hz] (None: the Python
#: emulator's ``rate``, 10,000 Hz by default): the Python emulator, the C firmware built for
#: this machine (``host``; ``host-board`` with the STM32F405's buffers and 1-Mbaud link;
#: ``host-san``, that under ASan and UBSan), run on an emulated STM32F405 under QEMU
#: (``qemu``), and the bridges to commercial devices over hapticlab's stand-ins for their
#: SDKs (``dhd-stub``: Force Dimension; ``hd-stub``: OpenHaptics, real time only;
#: ``hd-stub-tsan``: that under ThreadSanitizer)
BUILDS = {"python": None, "host": 10_000.0, "host-board": 10_000.0, "host-san": 10_000.0,
          "qemu": 10_000.0, "dhd-stub": 4_000.0, "hd-stub": 1_000.0, "hd-stub-tsan": 1_000.0}


def check_options(build: str, rate: float | None = None, speed: float = 1.0) -> None:
    """Whether emulator ``build`` can run at servo ``rate`` [Hz] and ``speed`` (device
    seconds per wall second).

    Raises
    ------
    DeviceSpecError
        No such build, or an option it cannot honour, named.
    """
    if build not in BUILDS:
        raise DeviceSpecError(f"no emulator named {build!r}; one of {', '.join(BUILDS)}")
    if not 0 < speed <= 20:
        raise DeviceSpecError(f"--speed must be in (0, 20] (device seconds per wall second), "
                              f"got {speed:g}")
    if BUILDS[build] is None:
        if rate is not None and not 1_000 <= rate <= 20_000:
            raise DeviceSpecError(f"--rate must be 1,000–20,000 Hz, got {rate:g}")
        return
    if rate is not None:
        raise DeviceSpecError(f"the firmware's servo runs at its build's own rate "
                              f"({BUILDS[build]:,.0f} Hz for {build}): --rate applies to "
                              "--firmware python only")
    if build == "qemu" and speed != 1.0:
        raise DeviceSpecError("the firmware under QEMU runs at the pace of its counted "
                              "instructions and its sleeps: --speed applies to --firmware "
                              "python, host, host-board, host-san and dhd-stub")
    if build in REAL_TIME_ONLY and speed != 1.0:
        raise DeviceSpecError(f"--firmware {build} runs in real time, in the HD scheduler's "
                              "clock: --speed must be 1")


def binary(build: str) -> Path:
    """The firmware build ``build`` (``host``, ``host-board``, ``qemu`` or ``board-qemu``),
    brought up to date by ``make`` (used as it is where there is no compiler).

    Raises
    ------
    DeviceError
        No such build, no compiler (the message names the Debian package), or the build
        failed (with the compiler's last lines).
    """
    if build not in _TARGETS:
        raise DeviceError(f"firmware build '{build}' does not exist; choose "
                          f"{', '.join(_TARGETS)}")
    path = FIRMWARE_DIR / _TARGETS[build]
    tool, package = _TOOLS[build]
    if shutil.which(tool) is None or shutil.which("make") is None:
        if path.exists():
            return path  # built before, on a machine with the compiler
        raise DeviceError(f"the {build} firmware is not built and {tool} or make is missing: "
                          f"install Debian's {package} and make (`make test` does), then "
                          f"`make -C firmware {_TARGETS[build]}`")
    # make rebuilds only what changed, so an edited source never runs as a stale binary
    run = subprocess.run(["make", "-C", str(FIRMWARE_DIR), _TARGETS[build]],
                         capture_output=True, text=True)
    if run.returncode != 0 or not path.exists():
        tail = "\n".join((run.stdout + run.stderr).strip().splitlines()[-8:])
        raise DeviceError(f"building the {build} firmware failed:\n{tail}")
    return path


def host_command(seed: int = 0, speed: float = 1.0, build: str = "host") -> list[str]:
    """The command line of host build ``build`` (``host``; ``host-board`` with the
    STM32F405's resources and link width; ``host-san``, the board's, under ASan and UBSan,
    which stop it at the first error), paced at ``speed`` × real time; it prints its pty
    as its first line."""
    return [str(binary(build)), "--seed", str(int(seed)), "--speed", repr(float(speed))]


def qemu_command(build: str = "qemu", *extra: str) -> list[str]:
    """qemu-system-arm running Cortex-M build ``build`` with its USART1 on a new pty (QEMU
    prints the pty's path: :data:`QEMU_PTY`); ``extra`` options go before the kernel."""
    if shutil.which("qemu-system-arm") is None:
        raise DeviceError("qemu-system-arm is missing: install Debian's qemu-system-arm "
                          "(`make test` does)")
    monitor = () if "-monitor" in extra else ("-monitor", "none")
    return ["qemu-system-arm", "-M", "netduinoplus2", "-accel", "tcg,thread=single",
            "-icount", QEMU_ICOUNT, "-nographic", *monitor, "-serial", "pty", *extra,
            "-kernel", str(binary(build))]


def serve(build: str, seed: int = 0, speed: float = 1.0) -> int:
    """Run firmware build ``build`` until SIGINT/SIGTERM, printing its pty first (the host
    build at ``speed`` × real time; QEMU at the pace of its counted instructions and its
    sleeps, :data:`QEMU_ICOUNT`)."""
    import os
    import signal
    import sys

    if build in HOST_BUILDS:
        cmd = host_command(seed, speed, build)
        sys.stdout.flush()
        os.execv(cmd[0], cmd)  # the binary prints its port and handles the signals itself
    proc = subprocess.Popen(qemu_command(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, text=True)
    stop = lambda *_: proc.terminate()  # noqa: E731
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    held = None
    for line in proc.stdout:
        m = QEMU_PTY.search(line)
        if m:
            # the pty's device end held open here for QEMU's life: QEMU stops reading a pty
            # whose last client closed and looks again only once a second, so every host
            # that connected after another waited up to 1 s for its HELLO to be read. What
            # the board writes while no host is there (about 45 B/s) now waits in the pty
            # for the next host, which counts from its HELLO_ACK
            held = os.open(m.group(1), os.O_RDWR | os.O_NOCTTY)
            print(m.group(1), flush=True)
            print(f"reference firmware on an emulated STM32F405 (QEMU netduinoplus2) at "
                  f"{m.group(1)}; stop with Ctrl-C", file=sys.stderr, flush=True)
            break
        print(line.rstrip(), file=sys.stderr, flush=True)
    for line in proc.stdout:  # QEMU's own complaints, if any
        print(line.rstrip(), file=sys.stderr, flush=True)
    code = proc.wait()
    if held is not None:
        os.close(held)
    return code
