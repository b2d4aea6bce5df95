"""Shared test settings."""

import os
import signal
import subprocess
import sys
import tempfile
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from .hostwatch import HostWatch, busiest, cpu_by_process
from .tiers import TierGuard

settings.register_profile("ci", deadline=None, max_examples=60,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci")

ROOT = Path(__file__).resolve().parents[1]


def wait_for(pred, limit: float = 30.0, what: str = "condition") -> None:
    """Wait until ``pred()`` holds, polling; fail after ``limit`` [s], a bound generous
    enough for a loaded machine (the wait ends as soon as it holds)."""
    import time

    end = time.monotonic() + limit
    while time.monotonic() < end:
        if pred():
            return
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def pytest_configure(config):
    """Build transient libraries into a fresh library store per run (subprocesses inherit
    it); refuse to load liblsl anywhere but in a private network (app.markers.PRIVATE_ENV:
    every process the tests start inherits it); mark the unit tier and guard it
    (tests/tiers.py)."""
    if "HAPTICLAB_LIBRARIES" not in os.environ or os.environ.get("PYTEST_XDIST_WORKER"):
        # each pytest-xdist worker its own store, as a run has: a test that finds a library
        # missing is not handed one the other worker built meanwhile
        os.environ["HAPTICLAB_LIBRARIES"] = tempfile.mkdtemp(prefix="hapticlab-libraries-")
    os.environ["HAPTICLAB_LSL_PRIVATE"] = "1"
    _adopt_orphans()
    _HOST_WATCH.start()
    config.pluginmanager.register(TierGuard(config), "tier-guard")


@dataclass(frozen=True)
class DemoStudy:
    """What ``hapticlab demo`` made: its folder (``data/``, ``report/``), exit code and
    output."""

    out: Path
    returncode: int
    stdout: str
    stderr: str


#: a test that asks for the demo study may wait for the whole demo (made in its setup, or by
#: another worker while it waits on the lock): minutes on a loaded machine [s]
_DEMO_TIMEOUT_S = 900


@pytest.fixture(scope="session")
def demo_study(tmp_path_factory) -> DemoStudy:
    """One ``hapticlab demo`` for the whole run (32 simulated sessions and their report),
    made by the first test that asks and shared by every later one, in this process or
    another pytest-xdist worker (a lock in the run's common temporary folder). Tests read
    it and never write into it."""
    import fcntl
    import json

    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the workers' common folder
    out, done = root / "demo-study", root / "demo-study.json"
    with open(root / "demo-study.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            run = subprocess.run([sys.executable, "-m", "app", "demo", "--out", str(out)],
                                 capture_output=True, text=True, timeout=900)
            done.write_text(json.dumps({"returncode": run.returncode, "stdout": run.stdout,
                                        "stderr": run.stderr}))
    return DemoStudy(out, **json.loads(done.read_text()))


#: what makes a test real-time besides its own ``realtime`` marker: the tiers that run a
#: device or a window, and the fixtures here that start a device, a terminal or a display
_REALTIME_TIERS = ("firmware", "qemu", "screen")
_REALTIME_FIXTURES = {"emulator", "own_emulator", "emulator_factory", "xdisplay", "participant",
                      "terminal"}


def is_realtime(item) -> bool:
    """Whether ``item`` meets deadlines in real time (see ``realtime`` in pyproject.toml):
    ``@pytest.mark.realtime(False)`` says a test of those tiers has none (a headless
    browser's screenshot, which keeps its own virtual time); a test on one of the fixtures
    above is real-time whatever it says."""
    if _REALTIME_FIXTURES & set(getattr(item, "fixturenames", ())):
        return True
    own = item.get_closest_marker("realtime")
    if own is not None:
        return not (own.args and own.args[0] is False)
    return any(item.get_closest_marker(m) for m in _REALTIME_TIERS)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """How pytest-xdist shares the suite between its workers (``make test``,
    ``--dist loadgroup``). Every real-time test (:func:`is_realtime`) goes to one group,
    run by one worker one test after another as in a serial run: none runs beside another
    (each was made to pass beside two CPU-bound processes; the other worker yields its core
    to them, :func:`_yield_to_realtime`). Every other test goes with its module, so that a
    module's shared fixture (a study, an identified plant) is made once."""
    for item in items:  # the demo a test waits for is part of its time (demo_study)
        if "demo_study" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.timeout(_DEMO_TIMEOUT_S), append=False)
    if not config.pluginmanager.hasplugin("xdist"):
        return
    for item in items:
        group = "realtime" if is_realtime(item) else item.nodeid.split("::", 1)[0]
        item.add_marker(pytest.mark.xdist_group(group))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadgroup`` giving out the real-time group before every other unit, so that
    the worker it goes to runs it first, at its own priority (:func:`_yield_to_realtime`):
    pytest-xdist orders units by size, and a subset run can make the group a small one."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    class RealtimeFirst(LoadGroupScheduling):
        def _assign_work_unit(self, node):
            if "realtime" in self.workqueue:
                self.workqueue.move_to_end("realtime", last=False)
            super()._assign_work_unit(node)

    return RealtimeFirst(config, log)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node, ids):
    """Stop a run whose workers lost the groups (on the controller, which schedules by
    them): pytest-xdist marks a test's group in its id (``…@realtime``), and pytest 9.2's
    structured ids drop that mark silently (pytest-xdist issue #1386), so real-time tests
    would run side by side. Every test has a group (pytest_collection_modifyitems)."""
    def grouped(nodeid: str) -> bool:  # the groups pytest_collection_modifyitems gives
        return nodeid.endswith(("@realtime", "@" + nodeid.split("::", 1)[0]))

    if ids and node.config.getvalue("dist") == "loadgroup" and not any(map(grouped, ids)):
        pytest.exit(f"--dist loadgroup: pytest-xdist grouped none of the {len(ids)} tests "
                    f"{node.gateway.id} collected: pytest {pytest.__version__} with this "
                    "pytest-xdist loses the groups (pytest-xdist issue #1386); install pytest "
                    "below 9.2, as pyproject.toml asks", returncode=3)


#: what the machine did while each test ran (tests/hostwatch.py), told when one fails
_HOST_WATCH = HostWatch()


#: each test's CPU-by-process snapshot from before its call (hostwatch.cpu_by_process)
_CPU_BEFORE = pytest.StashKey[dict]()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    item.stash[_CPU_BEFORE] = cpu_by_process()  # a few ms: read back only when it fails
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if report.failed:
        import time

        to_monotonic = time.monotonic() - time.time()
        watch = _HOST_WATCH.summary(call.start + to_monotonic, call.stop + to_monotonic)
        if call.when == "call" and _CPU_BEFORE in item.stash:
            watch += "; " + busiest(item.stash[_CPU_BEFORE], cpu_by_process(),
                                    call.stop - call.start)
        report.sections.append(("host during this test", watch))


#: processes meant to outlive a test (session fixtures': the shared emulator, Xvfb)
_LONG_LIVED: set[int] = set()


def _adopt_orphans() -> None:
    """Make this process a child subreaper (prctl PR_SET_CHILD_SUBREAPER): a process whose
    parent exits (a daemon that forks away, a child of a killed emulator) becomes this
    process's child rather than init's, so it stays in this process's tree and
    :func:`_processes` finds it, whichever pytest worker started it."""
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):  # not Linux: orphans go to init, unseen
        pass


def _processes() -> dict[int, tuple[int, str, str]]:
    """Every process descended from this one (this run's, or with pytest-xdist this
    worker's: not the machine's other work, nor the other worker's): pid → (parent pid,
    state, command line)."""
    table = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat", "rb") as f:
                stat = f.read().decode(errors="replace")
        except OSError:  # gone meanwhile
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # state, ppid, …
        table[int(d)] = (int(fields[1]), fields[0])
    me, out = os.getpid(), {}
    for pid, (ppid, state) in table.items():
        up = ppid
        for _ in range(64):
            if up == me or up not in table:
                break
            up = table[up][0]
        if up != me:
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        out[pid] = (ppid, state, cmd)
    return out


def _descends_from_long_lived(pid: int, procs: dict) -> bool:
    for _ in range(64):
        if pid in _LONG_LIVED:
            return True
        if pid not in procs:
            return False
        pid = procs[pid][0]
    return False


@pytest.fixture(autouse=True)
def _no_process_left_behind(request):
    """A test leaves no process of its own running: one left spinning (an emulator, a
    firmware build, QEMU) loads every later test, which on a 2-core machine is what
    fails timing-sensitive ones far from their cause. Written down in
    tests/artifacts/leftover-processes.txt with the test that left it."""
    before = set(_processes())
    yield
    import time

    for _ in range(50):  # what is stopping is given 1 s
        now = _processes()
        left = {pid: now[pid] for pid in now
                if pid not in before and now[pid][1] != "Z" and now[pid][2]
                and not _descends_from_long_lived(pid, now)}
        if not left:
            return
        time.sleep(0.02)
    (ROOT / "tests" / "artifacts").mkdir(parents=True, exist_ok=True)
    with open(ROOT / "tests" / "artifacts" / "leftover-processes.txt", "a") as f:
        for pid, (ppid, state, cmd) in sorted(left.items()):
            f.write(f"{request.node.nodeid}: pid {pid} (parent {ppid}, {state}) {cmd}\n")


#: a command's prefix that runs it in a network namespace with loopback alone, liblsl
#: configured to stay on this machine (tools/private_net.py)
PRIVATE_NET = [sys.executable, str(ROOT / "tools" / "private_net.py")]
_private: list[str | None] = []


def private_net_problem() -> str | None:
    """Why no private network namespace can be made here (the wrapper's own words), or
    None; asked once per run."""
    if not _private:
        out = subprocess.run([*PRIVATE_NET, sys.executable, "-c", "pass"],
                             capture_output=True, text=True, timeout=60)
        _private.append(None if out.returncode == 0 else
                        (out.stderr.strip() or f"exit status {out.returncode}"))
    return _private[0]


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
    #: the thread that collects stderr's lines: joined once the emulator has stopped, so
    #: that its last words (a host build's account at exit) are in :meth:`stderr`
    pump: threading.Thread | None = None

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

    emu.pump = threading.Thread(target=pump, daemon=True)
    emu.pump.start()
    return emu


def stop_emulator(emu: Emulated) -> None:
    if emu.proc.poll() is None:
        emu.proc.send_signal(signal.SIGCONT)  # a test may have frozen it
        emu.proc.send_signal(signal.SIGTERM)
        try:
            emu.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            emu.proc.kill()
            emu.proc.wait()
    if emu.pump is not None:
        emu.pump.join(timeout=10)  # stderr's end comes with the process's; a child it left
        #                            holding the pipe is waited for no longer


@pytest.fixture(scope="session")
def _shared_emulator():
    emu = start_emulator("--seed", "5")
    _LONG_LIVED.add(emu.proc.pid)
    yield emu
    stop_emulator(emu)


@pytest.fixture
def emulator(_shared_emulator):
    """One emulator for the tests that leave it running, handed to each test without a
    latched fault (a device keeps one across connections: a test that ends with an e-stop
    or a watchdog fault must not fail the next test's preflight)."""
    from device import open_device

    with open_device(f"serial:{_shared_emulator.port}") as dev:
        if dev.fault is not None:
            dev.clear_fault()
    return _shared_emulator


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

    if shutil.which("Xvfb") is None:
        pytest.fail("Xvfb is missing: `make test` installs it from Debian's packages")
    # -displayfd: the server takes the first free display and writes its number here (two
    # pytest workers, or another run on this machine, never race for one)
    rfd, wfd = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(wfd), "-screen", "0", "1920x1200x24",
                             "-nolisten", "tcp"], pass_fds=(wfd,),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(wfd)
    _LONG_LIVED.add(proc.pid)
    with os.fdopen(rfd) as said:
        line = said.readline().strip()  # once it listens; empty if it died
    if not line.isdigit():
        pytest.fail(f"Xvfb did not start (exit status {proc.poll()})")
    n = int(line)
    old = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = f":{n}"
    yield f":{n}"
    if old is None:
        os.environ.pop("DISPLAY", None)
    else:
        os.environ["DISPLAY"] = old
    proc.terminate()
    proc.wait(timeout=5)


class Terminal:
    """A program in a real terminal (a tmux pane): keys typed in, the screen read back."""

    def __init__(self, name: str, command: list[str], env: dict, size=(160, 48), cwd=None):
        import shlex

        if shutil_which("tmux") is None:
            pytest.fail("tmux is missing: `make test` installs it from Debian's packages")
        self.sock = f"hl-{name}-{os.getpid()}"
        exports = " ".join(f"{k}={shlex.quote(str(v))}" for k, v in env.items())
        line = (f"cd {shlex.quote(str(cwd or os.getcwd()))}; env {exports} "
                f"{' '.join(shlex.quote(c) for c in command)}; echo EXIT=$?; sleep 3600")
        self._tmux("new-session", "-d", "-s", "t", "-x", str(size[0]), "-y", str(size[1]),
                   "bash", "-c", line)

    def _tmux(self, *args: str) -> str:
        # the pane's size is the terminal's: no COLUMNS/LINES inherited from pytest
        env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
        out = subprocess.run(["tmux", "-L", self.sock, *args], capture_output=True, text=True,
                             env=env)
        return out.stdout

    def keys(self, text: str) -> None:
        """Type ``text`` (literally)."""
        self._tmux("send-keys", "-t", "t", "-l", text)

    def screen(self) -> str:
        return self._tmux("capture-pane", "-p", "-t", "t")

    def wait(self, text: str, timeout: float = 60.0) -> str:
        import time

        end = time.monotonic() + timeout
        while time.monotonic() < end:
            s = self.screen()
            if text in s:
                return s
            time.sleep(0.1)
        raise AssertionError(f"'{text}' did not appear in the terminal:\n{self.screen()}")

    def exit_code(self, timeout: float = 120.0) -> int:
        import re

        s = self.wait("EXIT=", timeout)
        return int(re.search(r"EXIT=(\d+)", s).group(1))

    def close(self) -> None:
        self._tmux("kill-server")

    def save_png(self, path: Path, title: str = "operator terminal") -> None:
        """The terminal's screen as an image (DejaVu Sans Mono, light on dark)."""
        from PIL import Image, ImageDraw, ImageFont

        lines = self.screen().splitlines() or [""]
        font = ImageFont.truetype("/usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf", 15)
        cw, ch = font.getbbox("M")[2], 19
        img = Image.new("RGB", (max(len(ln) for ln in lines) * cw + 24, len(lines) * ch + 44),
                        (24, 26, 30))
        d = ImageDraw.Draw(img)
        d.text((12, 8), title, fill=(140, 150, 160), font=font)
        for i, ln in enumerate(lines):
            d.text((12, 32 + i * ch), ln, fill=(220, 225, 230), font=font)
        img.save(path)


def shutil_which(name):
    import shutil

    return shutil.which(name)


@pytest.fixture
def terminal():
    """Start programs in real terminals (tmux panes); all are closed afterwards."""
    made = []

    def start(name, command, env, **kw):
        t = Terminal(name, command, env, **kw)
        made.append(t)
        return t

    yield start
    for t in made:
        t.close()


class Participant:
    """A person at the PsychoPy window: real X key events (xdotool) and screenshots, and
    the screen log (``HAPTICLAB_SCREEN_LOG``, app/screen.py) to wait on: a screen's line
    is there once it is up and counts the keys pressed from then on."""

    def __init__(self, display: str, log: Path | None = None):
        self.display = display
        self.env = {**os.environ, "DISPLAY": display}
        self.log = log
        self._seen = 0  # screen-log lines already waited past

    def app_env(self) -> dict:
        """What the application's environment needs to write this person's screen log."""
        return {"HAPTICLAB_SCREEN_LOG": str(self.log)} if self.log is not None else {}

    def screens(self) -> list[str]:
        """The screen log's lines so far (each: time, a tab, the screen's texts)."""
        if self.log is None or not self.log.exists():
            return []
        return self.log.read_text(encoding="utf-8").splitlines()

    def mark(self) -> None:
        """What was shown so far is waited past: :meth:`sees` looks at newer screens."""
        self._seen = len(self.screens())

    def showing(self, text: str, limit: float = 180.0) -> str:
        """Wait until the screen up now (the log's last line) says ``text``; its line."""
        import time

        end = time.monotonic() + limit
        while time.monotonic() < end:
            lines = self.screens()
            if lines and text in lines[-1]:
                self._seen = len(lines)
                return lines[-1]
            time.sleep(0.05)
        raise AssertionError(f"the screen up is not one saying {text!r} after {limit:g} s; "
                             f"the last screens: {self.screens()[-5:]}")

    def sees(self, text: str, limit: float = 180.0) -> str:
        """Wait until a screen shown after the last one waited for says ``text``; that
        screen's line. ``limit`` [s] bounds an application that died, it is no deadline."""
        import time

        end = time.monotonic() + limit
        while time.monotonic() < end:
            lines = self.screens()
            for i in range(self._seen, len(lines)):
                if text in lines[i]:
                    self._seen = i + 1
                    return lines[i]
            time.sleep(0.05)
        raise AssertionError(f"no screen saying {text!r} within {limit:g} s; the screens "
                             f"since the last one waited for: {self.screens()[self._seen:]}")

    def window(self, timeout: float = 30.0) -> str:
        import time

        end = time.monotonic() + timeout
        while time.monotonic() < end:
            out = subprocess.run(["xdotool", "search", "--onlyvisible", "--name", "PsychoPy"],
                                 capture_output=True, text=True, env=self.env).stdout.split()
            if out:
                return out[-1]
            time.sleep(0.1)
        raise AssertionError("no PsychoPy window appeared")

    def press(self, *keys: str) -> None:
        """Press keys (X keysym names: 1, Return, space, r …) into the participant's window."""
        import time

        wid = self.window()
        subprocess.run(["xdotool", "windowfocus", "--sync", wid], env=self.env,
                       capture_output=True)
        for k in keys:
            subprocess.run(["xdotool", "key", "--clearmodifiers", k], env=self.env, check=True)
            time.sleep(0.15)

    def screenshot(self, path: Path, window: bool = True) -> Path:
        from PIL import ImageGrab

        img = ImageGrab.grab(xdisplay=self.display)
        if window:
            geo = subprocess.run(["xdotool", "getwindowgeometry", "--shell", self.window()],
                                 capture_output=True, text=True, env=self.env).stdout
            g = dict(line.split("=") for line in geo.split())
            x, y, w, h = (int(g[k]) for k in ("X", "Y", "WIDTH", "HEIGHT"))
            img = img.crop((x, y, x + w, y + h))
        img.save(path)
        return path


@pytest.fixture
def participant(xdisplay, tmp_path):
    import shutil

    if shutil.which("xdotool") is None:
        pytest.fail("xdotool is missing: `make test` installs it from Debian's packages")
    return Participant(xdisplay, tmp_path / "screens.log")


_FIRMWARE_READY: list[bool] = []


def _firmware_builds() -> None:
    """Every firmware build (``make -C firmware all``) once per run, before the first test
    that needs one: the tests' own ``make`` calls then find them current, and two pytest
    workers never compile the same binary at once (the lock). What cannot be built here (a
    compiler missing) is left to the test that needs it, which says why (firmware.binary)."""
    import fcntl

    from device.serial.firmware import FIRMWARE_DIR

    (FIRMWARE_DIR / "build").mkdir(exist_ok=True)
    with open(FIRMWARE_DIR / "build" / ".tests.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        subprocess.run(["make", "-s", "-k", "-j2", "-C", str(FIRMWARE_DIR), "all"],
                       capture_output=True)
    _FIRMWARE_READY.append(True)


#: the niceness a worker of a two-worker run takes for the tests that meet no deadline
_YIELDING_NICE = 10
#: whether this process has taken it (a process cannot take it back unprivileged)
_YIELDING: list[bool] = []


def _yield_to_realtime(item) -> None:
    """On a worker of a run on two workers or more with the real-time group
    (``make test``, ``--dist loadgroup``): before its first test that meets no
    deadline, lower this process's priority (and its children's) by :data:`_YIELDING_NICE`,
    so that the real-time lane, with its devices and windows, takes a core first and the
    machine's other work competes with it as in a one-process run. The real-time group is
    given out first (:func:`pytest_xdist_make_scheduler`), so its worker runs it before
    anything else; a real-time test that still meets a yielding worker (after a worker
    crashed) is warned of."""
    if (not hasattr(item.config, "workerinput") or item.config.getvalue("dist") != "loadgroup"
            or int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) < 2):
        return
    if is_realtime(item):
        if _YIELDING:
            warnings.warn(f"{item.nodeid}: a real-time test on a worker that yields its core "
                          f"(niceness {os.getpriority(os.PRIO_PROCESS, 0)})", stacklevel=1)
        return
    if not _YIELDING:
        os.nice(_YIELDING_NICE)
        _YIELDING.append(True)


def pytest_runtest_setup(item):
    _yield_to_realtime(item)
    if not _FIRMWARE_READY and (item.get_closest_marker("firmware")
                                or item.get_closest_marker("qemu")):
        _firmware_builds()
