"""Shared test settings."""

import os
import signal
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("ci", deadline=None, max_examples=60,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci")

ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    """Build transient libraries into a fresh library store per run (subprocesses inherit
    it)."""
    if "HAPTICLAB_LIBRARIES" not in os.environ:
        os.environ["HAPTICLAB_LIBRARIES"] = tempfile.mkdtemp(prefix="hapticlab-libraries-")


@pytest.fixture(scope="session")
def artifacts() -> Path:
    """Folder for files tests leave behind for people to look at (screenshots, plots)."""
    path = ROOT / "tests" / "artifacts"
    path.mkdir(parents=True, exist_ok=True)
    return path

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





@pytest.fixture
def emulator_factory():
    """Start emulators on demand (``emulator_factory(seed, *extra_args)``); all are stopped
    afterwards."""
    started = []

    def start(seed: int = 9, *extra: str) -> Emulated:
        emu = start_emulator("--seed", str(seed), *extra)
        started.append(emu)
        return emu

    yield start
    for emu in started:
        stop_emulator(emu)


@pytest.fixture(scope="session")
def xdisplay():
    """A virtual X server (Xvfb) for PsychoPy windows; sets DISPLAY for the session."""
    import shutil
    import time

    if shutil.which("Xvfb") is None:
        pytest.fail("Xvfb is missing: `make test` installs it from Debian's packages")
    for n in range(90, 130):
        if not os.path.exists(f"/tmp/.X{n}-lock"):
            break
    proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "1280x1024x24", "-nolisten",
                             "tcp"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(100):
        if os.path.exists(f"/tmp/.X11-unix/X{n}"):
            break
        time.sleep(0.05)
    old = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = f":{n}"
    yield f":{n}"
    if old is None:
        os.environ.pop("DISPLAY", None)
    else:
        os.environ["DISPLAY"] = old
    proc.terminate()
    proc.wait(timeout=5)
