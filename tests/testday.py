"""A test day: realism, factorial and identification end to end on the C host firmware, as
a lab runs them: the operator at the console in tmux, a person at the PsychoPy window under
Xvfb (xdotool key events), a library built first with the command the preflight names.
Screenshots, the data, a report and a log go to $TESTDAY_OUT (/tmp/hapticlab-testday). Not
part of the suite (about 15 min); run it by hand::

    .venv/bin/python tests/testday.py [realism] [factorial] [identification]

An interrupted session of a protocol is continued with ``hapticlab resume``.

The person is a small state machine that reads the operator's live view (state, trial) and
acts as a participant would: SPACE on instructions, ENTER to end familiarization, a rating
with a correction (another digit) before ENTER, R once to ask for the real block, surfaces
1, 2, 3 then N in identification, a debrief with punctuation.
"""

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
from conftest import Participant, Terminal, start_emulator, stop_emulator  # noqa: E402

OUT = Path(os.environ.get("TESTDAY_OUT", "/tmp/hapticlab-testday"))
only = sys.argv[1:] or ["realism", "factorial", "identification"]
if only == ["realism", "factorial", "identification"]:  # a new day: the last one's folder goes
    if OUT.exists() and any(OUT.iterdir()) and not (OUT / "log.txt").exists():
        sys.exit(f"{OUT} holds something that is not a test day's: set TESTDAY_OUT")
    shutil.rmtree(OUT, ignore_errors=True)
SHOTS = OUT / "shots"
SHOTS.mkdir(parents=True, exist_ok=True)
DATA = OUT / "data"
LIBS = OUT / "libs"
n = 152
xvfb = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "1920x1200x24", "-nolisten", "tcp"],
                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
time.sleep(1.0)
disp = f":{n}"
person = Participant(disp)
emu = start_emulator("--firmware", "host")
spec = f"serial:{emu.port}"
env = {k: os.environ[k] for k in ("PATH", "HOME", "TERM") if k in os.environ}
env.update(DISPLAY=disp, HAPTICLAB_LIBRARIES=str(LIBS))
PY = [sys.executable, "-m", "app"]
rng = np.random.default_rng(2026)
log: list[str] = []
shot_k = len(list(SHOTS.glob("*.png")))


def note(what: str) -> None:
    log.append(f"{time.strftime('%H:%M:%S')} {what}")
    print(log[-1], flush=True)
    with open(OUT / "log.txt", "a") as f:
        f.write(log[-1] + "\n")


def cli(*args: str, timeout: float = 1800) -> subprocess.CompletedProcess:
    t0 = time.monotonic()
    out = subprocess.run([*PY, *args], capture_output=True, text=True, timeout=timeout,
                         env={**os.environ, **env})
    note(f"$ hapticlab {' '.join(args)}  → exit {out.returncode} in "
         f"{time.monotonic() - t0:.0f} s\n{out.stdout[-3000:]}{out.stderr[-3000:]}")
    return out


def state_of(screen: str) -> tuple[str | None, str | None, str]:
    """(state, trial and what is placed — a real block tapped before a scene shares the
    scene's trial number, phase)."""
    m = re.search(r"keys\s+(\w+):", screen)
    t = re.search(r"\(trial #(\d+)\)", screen)
    ph = re.search(r"trial\s+(\w+) ·", screen)
    place = re.search(r"PLACE\s+(.*?)\s{3}", screen)
    trial = f"{t.group(1)}:{place.group(1) if place else ''}" if t else None
    return (m.group(1) if m else None, trial, ph.group(1) if ph else "")


class Day:
    def __init__(self, name: str, args: list[str]):
        self.name = name
        self.t = Terminal(f"td4{name[:3]}", [*PY, *args], env, cwd=str(OUT))
        self.seen: dict[str, int] = {}

    def shot(self, what: str, operator: bool = True, limit: int = 2) -> None:
        """At most ``limit`` screenshots of each kind of moment."""
        global shot_k
        self.seen[what] = self.seen.get(what, 0) + 1
        if self.seen[what] > limit:
            return
        shot_k += 1
        stem = f"{shot_k:03d}-{self.name}-{what}"
        try:
            person.screenshot(SHOTS / f"{stem}.png")
        except Exception as exc:  # noqa: BLE001
            note(f"screenshot failed: {exc}")
        if operator:
            self.t.save_png(SHOTS / f"{stem}-operator.png", f"operator — {self.name}: {what}")


def run(day: Day, rating: tuple[int, int] | None, ask_ref_at: str, limit_s: float) -> int:
    t, end = day.t, time.monotonic() + limit_s
    acted: set = set()
    acted_at: dict = {}  # (state, trial) → when the operator or person last acted on it
    trial_since: dict = {}
    last_space = 0.0
    while time.monotonic() < end:
        s = t.screen()
        if "EXIT=" in s:
            return int(re.search(r"EXIT=(\d+)", s).group(1))
        state, trial, phase = state_of(s)
        key = (state, trial)
        now = time.monotonic()
        if "answering the debrief" in s and "debrief" not in acted:
            acted.add("debrief")
            time.sleep(1.0)
            day.shot("debrief")
            person.press("shift+t", "h", "e", "space", "m", "e", "t", "a", "l", "space", "r",
                         "a", "n", "g", "space", "l", "o", "n", "g", "e", "r", "space",
                         "parenleft", "9", "0", "percent", "parenright", "exclam", "Return")
            continue
        if "debrief" in acted:
            pass  # the session is ending: nothing more to press
        elif state == "fault" and key not in acted:
            acted.add(key)
            note(f"{day.name}: FAULT on the operator's screen:\n{s}")
            day.shot("fault", limit=5)
            t.keys("c")
        elif state in ("placing", "reference", "rating") and key in acted \
                and now - acted_at.get(key, now) > 10:
            note(f"{day.name}: still {state} on trial {trial} 10 s after acting: again")
            acted.discard(key)
            day.shot(f"stuck-{state}", limit=3)
        elif state in ("placing", "reference") and key not in acted:
            acted.add(key)
            acted_at[key] = now
            time.sleep(0.6)
            if state == "placing" and trial.split(":")[0] == ask_ref_at and "asked" not in acted:
                acted.add("asked")  # the participant asks for the real block again
                person.press("r")
                time.sleep(1.0)
                day.shot("participant-asks-reference")
                if day.name == "identification":
                    person.press("2")
                    time.sleep(0.5)
                acted.discard(key)
                continue
            day.shot(state)
            t.keys("r")
        elif state == "trial":
            first = trial_since.setdefault(key, now)
            if now - last_space > 2.0 and now - first < 8:
                person.press("space")  # instructions, when a phase begins (ignored elsewhere)
                last_space = now
                if now - first < 2.5:
                    time.sleep(0.8)
                    day.shot(f"trial-{phase or 'x'}", operator=False, limit=1)
            if phase == "familiarization" and now - first > 6 and \
                    now - acted_at.get(("fam", key), 0) > 5:
                acted_at[("fam", key)] = now  # ENTER ends familiarization after this window
                person.press("Return")
            if day.name == "identification":
                plan = [(3, "1"), (9, "2"), (15, "3"), (21, "n")]
                for at, k in plan:
                    if now - first > at and ("id", key, k) not in acted:
                        acted.add(("id", key, k))
                        person.press(k)
                        time.sleep(1.5)
                        day.shot(f"surface-{k}", operator=k == "2", limit=1)
        elif state == "rating" and key not in acted:
            acted.add(key)
            acted_at[key] = now
            time.sleep(0.7)
            if day.name == "identification":
                day.shot("naming")
                for k in rng.permutation(["1", "2", "3"]):
                    person.press(str(k))
            else:
                lo, hi = rating
                v = int(rng.integers(lo, hi + 1))
                digits = list(str(v))
                if hi <= 9 and len(acted) % 5 == 0:  # a correction: another digit first
                    person.press(str(lo))
                    time.sleep(0.3)
                    day.shot("rating-chosen")
                day.shot("rating")
                person.press(*digits, "Return")
        time.sleep(0.25)
    note(f"{day.name}: gave up after {limit_s:.0f} s; operator screen:\n{t.screen()}")
    return -1


def protocol(name: str, rating, ask_ref_at: str, limit_s: float, seed: str) -> None:
    common = ["--device", spec, "--no-audio", "--data", str(DATA)]
    pre = cli("preflight", name, *common)
    fail = [ln for ln in pre.stdout.splitlines() if ln.startswith("FAIL libraries")]
    if fail:
        command = fail[0].split("build it with: ")[1].split(";")[0].strip()
        note(f"{name}: preflight names: {command}")
        cli(*shlex.split(command)[1:])
        cli("preflight", name, *common)
    folder = DATA / "sub-T04"
    metas = {f: json.loads((f / "session.json").read_text())
             for f in sorted(folder.glob("ses-*"))} if folder.exists() else {}
    left = [f for f, m in metas.items() if m.get("status") == "interrupted"
            and m.get("protocol", {}).get("name") == name]
    if left:  # as a lab continues a session that stopped: resume it
        note(f"{name}: resuming {left[-1]}")
        day = Day(name, ["resume", str(left[-1]), "--device", spec, "--no-audio"])
    else:
        day = Day(name, ["run", name, "--participant", "T04", *common, "--seed", seed])
    t0 = time.monotonic()
    code = run(day, rating, ask_ref_at, limit_s)
    note(f"{name}: exit {code} after {time.monotonic() - t0:.0f} s")
    day.t.save_png(SHOTS / f"{name}-end-operator.png", f"operator — {name}: end")
    (OUT / f"{name}-operator-end.txt").write_text(day.t.screen())
    day.t.close()
    folder = max((DATA / "sub-T04").glob("ses-*"), key=lambda p: p.stat().st_mtime)
    meta = json.loads((folder / "session.json").read_text())
    note(f"{name}: {folder.name}: status {meta.get('status')} summary {meta.get('summary')}")


try:
    if "realism" in only:
        protocol("realism", (1, 7), "5", 3600, "31")
    if "factorial" in only:
        protocol("factorial", (1, 10), "6", 1800, "32")
    if "identification" in only:
        protocol("identification", None, "3", 1800, "33")
    # the host firmware simulates its plant: its people are analysed when asked
    cli("analyze", str(DATA), "--out", str(OUT / "report"), "--sim-device")
finally:
    stop_emulator(emu)
    (OUT / "emulator.txt").write_text(emu.stderr() if hasattr(emu, "stderr") else "")
    xvfb.terminate()
