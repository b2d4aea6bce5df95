"""An emulated device serving the wire protocol on a pseudo-terminal: in this process until a
signal (:func:`serve`, ``hapticlab device emulate``), or in a process of its own
(:class:`EmulatorProcess`, what the ``emulator`` backend and the serial backend's way into the
conformance suite start): ``python -m device.serial.serving BUILD --seed S --speed X``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile

from ..errors import DeviceError
from .firmware import BUILDS, check_options

__all__ = ["serve", "EmulatorProcess", "start_emulator"]


def serve(build: str = "python", *, rate: float | None = None, seed: int = 0,
          speed: float = 1.0) -> int:
    """Serve protocol 2 from emulator ``build`` (:data:`BUILDS`) on a new pseudo-terminal
    until SIGINT or SIGTERM, printing the port's path first; the exit status.

    Raises
    ------
    DeviceSpecError
        An option this emulator cannot honour (:func:`check_options`).
    """
    check_options(build, rate, speed)
    if BUILDS[build] is not None:
        from .firmware import serve as serve_firmware

        return serve_firmware(build, seed, speed)
    from .emulator import main as serve_python

    return serve_python(10_000.0 if rate is None else rate, seed, speed)


class EmulatorProcess:
    """An emulator serving on a pseudo-terminal in a process of its own (:func:`serve`).

    Attributes
    ----------
    port : str
        Its pseudo-terminal's path.
    proc : subprocess.Popen
    """

    def __init__(self, build: str = "python", *, seed: int = 0, speed: float = 1.0,
                 rate: float | None = None):
        check_options(build, rate, speed)
        #: what the emulator says on stderr (its faults, its timing at the end): kept in a
        #: file, so that a process nobody reads never blocks on a full pipe
        self.log = tempfile.TemporaryFile(mode="w+", prefix="hapticlab-emulator-")
        cmd = [sys.executable, "-m", "device.serial.serving", build, "--seed", str(int(seed)),
               "--speed", repr(float(speed)), *(["--rate", repr(rate)] if rate else [])]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self.log, text=True,
                                     stdin=subprocess.DEVNULL)
        self.port = self.proc.stdout.readline().strip()
        if not self.port.startswith("/"):
            self.stop()
            raise DeviceError(f"the {build} emulator did not start: {self.said()[-600:]}")

    def said(self) -> str:
        """What the emulator has written on stderr so far."""
        self.log.seek(0)
        return self.log.read()

    def stop(self) -> None:
        """Stop the emulator (SIGTERM, then SIGKILL after 10 s) and wait for it. Idempotent."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc.stdout.close()
        self.log.close()

    def __enter__(self) -> EmulatorProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def start_emulator(build: str = "python", *, seed: int = 0, speed: float = 1.0,
                   rate: float | None = None) -> EmulatorProcess:
    """A new :class:`EmulatorProcess` (a context manager that stops it)."""
    return EmulatorProcess(build, seed=seed, speed=speed, rate=rate)


def _main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m device.serial.serving",
                                description="serve an emulated device on a new pty")
    p.add_argument("build", nargs="?", default="python", choices=tuple(BUILDS))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--speed", type=float, default=1.0)
    p.add_argument("--rate", type=float, default=None)
    a = p.parse_args(argv)
    try:
        return serve(a.build, rate=a.rate, seed=a.seed, speed=a.speed)
    except DeviceError as exc:
        print(f"emulator: {exc}", file=sys.stderr, flush=True)
        return 2


if __name__ == "__main__":
    sys.exit(_main())
