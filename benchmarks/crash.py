"""``hapticlab bench crash --kills N``: kill -9 a headless session at random moments, resume it.

1. An uninterrupted reference session (seed S) is run.
2. The same session (seed S, another folder) is started and killed with SIGKILL after a
   random delay, then resumed with ``hapticlab resume`` and killed again, N times; then
   resumed to the end.
3. Checked: every row present after a kill is still there at the end (0 completed trials
   lost; a torn last line is set aside and its attempt run again), and the final attempt
   sequence equals the reference's, column for column.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ._common import emit, print_table

KEY = ("trial_index", "item", "attempt", "sample", "status", "rating", "answer", "n_taps",
       "tap_velocities")


def _rows(folder: Path) -> list[tuple]:
    from app.recorder import read_trials

    rows, _torn = read_trials(folder / "trials.tsv")
    return [tuple(r[k] for k in KEY) for r in rows]


def _cmd(args: list[str]) -> list[str]:
    return [sys.executable, "-m", "app", *args]


def kill_and_resume(kills: int, seed: int = 1, protocol: str = "realism", rng_seed: int = 0,
                    workdir: Path | None = None, delay: tuple[float, float] = (0.4, 2.0),
                    traces: str = "contacts") -> dict:
    """Run the harness; returns counts and whether every final sequence matched.

    Sessions are repeated (each in its own folder, each compared with the reference) until
    ``kills`` kills have landed.
    """
    work = Path(workdir or tempfile.mkdtemp(prefix="hapticlab-crash-"))
    common = ["--participant", "P01", "--dry-run", "--seed", str(seed),
              "--no-audio", "--quiet", "--traces", traces]
    ref_dir = work / "reference"
    subprocess.run(_cmd(["run", protocol, "--data", str(ref_dir), *common]), check=True,
                   capture_output=True)
    reference = _rows(ref_dir / "sub-P01" / "ses-1")
    rng = np.random.default_rng(rng_seed)
    lost = torn = killed = sessions = 0
    mismatched = []
    while killed < kills:
        sessions += 1
        data = work / f"killed-{sessions}"
        folder = data / "sub-P01" / "ses-1"
        snapshot: list[tuple] = []
        while _incomplete(folder):
            if (folder / "session.json").exists():
                args = ["resume", str(folder), "--quiet"]
            else:
                args = ["run", protocol, "--data", str(data), *common]
            proc = subprocess.Popen(_cmd(args), stdout=subprocess.DEVNULL,
                                    stderr=subprocess.PIPE, text=True)
            try:
                if killed < kills:
                    proc.wait(timeout=float(rng.uniform(*delay)))
                else:
                    proc.wait(timeout=300)
            except subprocess.TimeoutExpired:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait()
                killed += 1
            err = proc.stderr.read() if proc.stderr else ""
            torn += "torn last line" in err
            if folder.exists():
                now = _rows(folder)
                if now[: len(snapshot)] != snapshot:  # a row seen before has gone
                    lost += 1
                snapshot = now
        if _rows(folder) != reference:
            mismatched.append(str(folder))
    return {"kills": killed, "sessions": sessions, "lost_rows_events": lost,
            "torn_lines_set_aside": torn, "reference_rows": len(reference),
            "sequence_matches": not mismatched, "mismatched": mismatched}


def _incomplete(folder: Path) -> bool:
    import json

    try:
        return json.loads((folder / "session.json").read_text())["status"] != "complete"
    except (FileNotFoundError, ValueError, KeyError):
        return True


def main(args) -> int:
    t0 = time.perf_counter()
    kills = getattr(args, "kills", 1000)
    r = kill_and_resume(kills)
    r["wall_s"] = time.perf_counter() - t0
    if args.json:
        emit(r, True)
        return 0
    print_table(f"crash: kill -9 at random moments, then resume ({r['wall_s']:.0f} s)",
                ["kills", "sessions", "rows per session", "rows lost", "torn lines set aside",
                 "every sequence = uninterrupted"],
                [(r["kills"], r["sessions"], r["reference_rows"], r["lost_rows_events"],
                  r["torn_lines_set_aside"], "yes" if r["sequence_matches"] else "NO")])
    return 0 if r["sequence_matches"] and r["lost_rows_events"] == 0 else 1
