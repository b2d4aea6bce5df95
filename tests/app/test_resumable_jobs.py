"""A fault costs one measurement, never a job's work: library builds keep every finished
measurement and resume; a person at the terminal clears a fault and the build measures
again; every command the program suggests exists.

The device is the reference firmware built for this machine (at ×10), over pyserial on its
pty; its e-stop button is pressed with SIGUSR1 and released with SIGUSR2. Waits end as soon
as what they wait for happens; nothing depends on the host keeping a deadline.
"""

from __future__ import annotations

import ast
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from app.cli import build_parser

from ..conftest import ROOT, start_emulator, stop_emulator, wait_for


def _lines(stream, into: list[str]) -> threading.Thread:
    def pump():
        for line in stream:
            into.append(line)

    t = threading.Thread(target=pump, daemon=True)
    t.start()
    return t


def _cli(command_line: str) -> list[str]:
    """A suggested `hapticlab …` line as this interpreter runs it."""
    words = shlex.split(command_line)
    assert words[0] == "hapticlab"
    return [sys.executable, "-m", "app", *words[1:]]


@pytest.fixture
def firmware():
    emu = start_emulator("--firmware", "host", "--seed", "4", "--speed", "10")
    yield emu
    stop_emulator(emu)


def _stopped(firmware, cmd: list[str], step: str, env=None) -> str:
    """Run ``cmd`` with no terminal until its progress shows ``step``, press the device's
    e-stop button (SIGUSR1) and return what it said as it stopped (exit status 2)."""
    err: list[str] = []
    job = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, env=env)
    pump = _lines(job.stderr, err)
    wait_for(lambda: any(step in ln for ln in err), 120, step)
    firmware.proc.send_signal(signal.SIGUSR1)  # the device's e-stop button
    assert job.wait(timeout=120) == 2
    pump.join(timeout=10)
    return "".join(err)


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.slow
def test_a_library_build_stopped_by_a_fault_keeps_its_work_and_resumes(firmware, tmp_path):
    out = tmp_path / "wood.npz"
    text = _stopped(firmware, [sys.executable, "-m", "app", "library", "build", "--device",
                               f"serial:{firmware.port}", "--windows", "2", "--out", str(out)],
                    "[ 5/14]")
    done = max(int(m) for m in re.findall(r"\[\s*(\d+)/14\]", text))
    m = re.search(r"estop fault during (.+?) \(.*?\)\. (\d+) finished measurements are kept "
                  r"in (\S+); once it is safe, continue with: (hapticlab library build .+)$",
                  text, re.M)
    assert m, text
    assert int(m.group(2)) == done and Path(m.group(3)).exists() and not out.exists()
    firmware.proc.send_signal(signal.SIGUSR2)  # released

    # the command it names runs as it is, resumes from what was kept and finishes
    again = subprocess.run(_cli(m.group(4)), capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert f"resuming: {done} measurements kept" in again.stderr
    steps = [int(x) for x in re.findall(r"\[\s*(\d+)/14\]", again.stderr)]
    assert steps == list(range(done + 1, 15))  # nothing measured twice
    assert out.exists() and not Path(m.group(3)).exists()
    # then it taps the matched sample and its spring alone and says how close each came
    assert re.search(r"with the library [\d.]+ dB — (close|fair|far) .*; the spring alone, the "
                     r"baseline, [\d.]+ dB \(\d+ and \d+ taps\)", again.stdout), again.stdout


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.slow
def test_an_identification_stopped_by_a_fault_keeps_its_sweeps_and_resumes(firmware, tmp_path):
    """`device sysid` kept nothing across a fault without a terminal (an audit of issue
    29); its finished sweeps now wait in the library store until the model is fitted."""
    env = {**os.environ, "HAPTICLAB_LIBRARIES": str(tmp_path / "store")}
    text = _stopped(firmware, [sys.executable, "-m", "app", "device", "sysid", "--device",
                               f"serial:{firmware.port}", "--json"], "[ 2/12]", env)
    done = max(int(m) for m in re.findall(r"\[\s*(\d+)/12\]", text))
    m = re.search(r"estop fault during sweep at .+?; (\d+) of 12 sweeps are kept in (\S+)\. "
                  r"Once it is safe, continue with: (hapticlab device sysid .+)$", text, re.M)
    assert m, text
    assert int(m.group(1)) == done >= 2 and Path(m.group(2)).exists()
    firmware.proc.send_signal(signal.SIGUSR2)  # released

    again = subprocess.run(_cli(m.group(3)), capture_output=True, text=True, timeout=300,
                           env=env)
    assert again.returncode == 0, again.stderr
    assert f"resuming: {done} of 12 sweeps kept" in again.stderr
    steps = [int(x) for x in re.findall(r"\[\s*(\d+)/12\]", again.stderr)]
    assert steps == list(range(done + 1, 13))  # nothing measured twice
    assert json.loads(again.stdout)["repeats"] == 4
    assert not Path(m.group(2)).exists()  # fitted: the record is gone


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.slow
def test_a_person_clears_a_fault_and_the_build_measures_again(firmware, terminal, tmp_path,
                                                             artifacts):
    out = tmp_path / "wood.npz"
    t = terminal("build", ["hapticlab", "library", "build", "--device",
                           f"serial:{firmware.port}", "--windows", "2", "--verify", "0",
                           "--out", str(out)],  # its verification: the test above
                 env={"PATH": str(Path(sys.executable).parent) + ":/usr/bin:/bin"})
    t.wait("[ 3/14]", 120)
    firmware.proc.send_signal(signal.SIGUSR1)  # pressed, and held
    screen = t.wait("c + ENTER clears the fault", 120)
    assert re.search(r"ESTOP during (sweep|tapping)", screen), screen
    t.keys("c\n")  # still held: refused in words, the build waits on
    t.wait("not cleared", 60)
    (artifacts / "screens").mkdir(exist_ok=True)
    t.save_png(artifacts / "screens" / "library-build-fault.png", "library build: a fault")
    firmware.proc.send_signal(signal.SIGUSR2)
    t.keys("c\n")
    t.wait("fault cleared; measuring again", 60)
    assert t.exit_code(300) == 0, t.screen()
    assert out.exists()
    assert "[14/14]" in t.screen()


# ------------------------------------------------------------------ suggested commands
SOURCES = [p for pkg in ("app", "device", "protocols", "analysis") for p in
           (ROOT / pkg).rglob("*.py")]
#: a command line suggested in a message ends where the sentence does, or where its quote
#: (a backtick, as in "a file that `hapticlab library build` writes") closes
_END = re.compile(r"\s*(?:[;)`\n]|\. |\.$| \(|$)")


def _strings(path: Path):
    """Every string constant and f-string of a module, f-string fields as 'X'."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    parts = {id(v) for n in ast.walk(tree) if isinstance(n, ast.JoinedStr) for v in n.values}
    docs = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr)}  # documentation
    for node in ast.walk(tree):
        if id(node) in parts or id(node) in docs:
            continue  # a piece of an f-string (seen whole below), or a docstring
        if isinstance(node, ast.JoinedStr):
            yield node.lineno, "".join(v.value if isinstance(v, ast.Constant) else "X"
                                       for v in node.values)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.lineno, node.value


def suggested_commands(sources=SOURCES, root: Path = ROOT) -> list[tuple[str, str]]:
    found = []
    for path in sources:
        for line, text in _strings(path):
            for m in re.finditer(r"hapticlab ((?:library|device|protocol|run|resume|preflight|"
                                 r"simulate|analyze|export|power|bench|demo)\b.*)", text):
                cmd = _END.split(m.group(1), maxsplit=1)[0]
                found.append((f"{path.relative_to(root)}:{line}", cmd))
    return found


def unparsable(cmds: list[tuple[str, str]]) -> list[str]:
    """The suggested command lines the command line's own parser refuses."""
    parser = build_parser()
    bad = []
    for where, cmd in cmds:
        try:
            parser.parse_args(shlex.split(cmd.replace("…", "")))
        except (SystemExit, ValueError):
            bad.append(f"{where}: hapticlab {cmd}")
    return bad


def test_every_suggested_command_line_parses():
    """Messages name commands the operator can type: each one the program suggests parses
    with the command line's own parser (an option that does not exist fails)."""
    cmds = suggested_commands()
    assert len(cmds) >= 6  # the scan finds them (resume, library build, preflight, …)
    bad = unparsable(cmds)
    assert not bad, "suggested commands that do not parse:\n" + "\n".join(bad)


def test_the_scan_would_see_a_command_that_does_not_exist(tmp_path, capsys):
    bad = tmp_path / "m.py"
    bad.write_text('MSG = f"continue with: hapticlab library build --device {x} --resume"\n'
                   'OK = "resume with: hapticlab resume data/sub-P1/ses-1 --clear-fault"\n'
                   'QUOTED = "a .npz file that `hapticlab library build` writes"\n')
    cmds = suggested_commands([bad], tmp_path)
    assert [c for _, c in cmds] == ["library build --device X --resume",
                                    "resume data/sub-P1/ses-1 --clear-fault",
                                    "library build"]  # a quoted command ends at its quote
    assert unparsable(cmds) == ["m.py:1: hapticlab library build --device X --resume"]


def test_every_command_that_opens_a_device_can_clear_its_fault():
    parser = build_parser()
    for line in ("preflight realism --device sim", "device selftest sim",
                 "device check realism", "device sysid", "library build",
                 "library show f.npz --device sim", "protocol validate realism --device sim",
                 "run realism --participant P1 --dry-run", "resume d", "simulate realism"):
        args = parser.parse_args([*line.split(), "--clear-fault"])
        assert args.clear_fault is True, line


@pytest.mark.integration
def test_commands_built_from_values_parse_with_spaces_in_them():
    """The scan above sees string constants only; these commands are built from the user's
    own values (a data folder or a plot path may hold a space, which an unquoted
    suggestion split in two). Each parses back to the values it was built from, and the
    identification's keeps every option the user gave (it kept only --device)."""
    from types import SimpleNamespace

    from app.api import preflight_line
    from app.libraries import build_line
    from app.matching_cli import _sysid_again
    from app.runner import SessionRunner

    parser = build_parser()
    folder = "/lab data/sub-P1/ses-1"
    line = SessionRunner._resume_line(SimpleNamespace(files=SimpleNamespace(folder=folder)))
    args = parser.parse_args(shlex.split(line)[1:])
    assert args.session_dir == folder and args.clear_fault

    given = parser.parse_args(["preflight", "my protocols/r.toml", "--device", "serial:/dev/x",
                               "--data", "/lab data", "--responder", "scripted", "--traces",
                               "none", "--no-audio"])
    again = parser.parse_args(shlex.split(preflight_line(
        given.protocol, device=given.device, data=given.data, responder=given.responder,
        traces=given.traces, audio=not given.no_audio))[1:])
    keep = ("protocol", "device", "data", "responder", "traces", "no_audio")
    assert {k: getattr(again, k) for k in keep} == {k: getattr(given, k) for k in keep}
    assert again.clear_fault

    built = parser.parse_args(shlex.split(build_line("serial:/dev/ttyACM0", "my r.toml",
                                                     "wood_on_foam"))[1:])
    assert (built.device, built.protocol, built.source) == ("serial:/dev/ttyACM0",
                                                            "my r.toml", "wood_on_foam")

    given = parser.parse_args(["device", "sysid", "--device", "serial:/dev/x", "--levels",
                               "0.5", "2", "--repeats", "3", "--order", "5", "--delay", "1.5",
                               "--png", "/tmp/my plots/fit.png", "--json"])
    again = parser.parse_args(shlex.split(_sysid_again(given))[1:])
    keep = ("device", "levels", "repeats", "order", "relative_degree", "delay", "png", "json")
    assert {k: getattr(again, k) for k in keep} == {k: getattr(given, k) for k in keep}
    assert again.clear_fault and not given.clear_fault
