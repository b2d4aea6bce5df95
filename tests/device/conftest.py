"""Device-test fixtures: an emulator process serving the wire protocol on a pty."""


import signal
import subprocess
import sys
import threading
from dataclasses import dataclass, field

import pytest


@dataclass
class Emulated:
    proc: subprocess.Popen
    port: str
    stderr_lines: list = field(default_factory=list)

    def stderr(self) -> str:
        return "".join(self.stderr_lines)


def start_emulator(*extra: str) -> Emulated:
    proc = subprocess.Popen([sys.executable, "-m", "app", "device", "emulate", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    port = proc.stdout.readline().strip()
    if not port.startswith("/dev/"):
        proc.kill()
        raise RuntimeError(f"emulator did not announce a port: {port!r} {proc.stderr.read()}")
    emu = Emulated(proc, port)

    def pump():
        for line in proc.stderr:
            emu.stderr_lines.append(line)

    threading.Thread(target=pump, daemon=True).start()
    return emu


def stop_emulator(emu: Emulated) -> None:
    if emu.proc.poll() is None:
        emu.proc.send_signal(signal.SIGTERM)
        try:
            emu.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            emu.proc.kill()


@pytest.fixture(scope="session")
def emulator():
    """One emulator for the tests that leave it running."""
    emu = start_emulator("--seed", "5")
    yield emu
    stop_emulator(emu)


@pytest.fixture
def own_emulator():
    """An emulator a test may kill."""
    emu = start_emulator("--seed", "6")
    yield emu
    stop_emulator(emu)



