"""``hapticlab bench crash``: kill -9 a headless session and resume it; nothing may be lost.

``--kills N`` (random moments):

1. An uninterrupted reference session (seed S) is run.
2. The same session (seed S, another folder) is started and killed with SIGKILL after a
   random delay, then resumed with ``hapticlab resume`` and killed again, N times; then
   resumed to the end.
3. Checked: every row present after a kill is still there at the end (0 completed trials
   lost; a torn last line is set aside and its attempt run again), and the final attempt
   sequence equals the reference's, column for column.

``--points all`` (every write point, in the manner of SQLite's crash tests): the reference
session is run under :mod:`benchmarks._killpoint`, which counts every write point in the data
folder (open, write, fsync, rename, mkdir); then, for each point, a fresh session is killed
right after it (and, at each write, half way through it: a torn write), and resumed to the
end. Reported: ``points``, ``runs``, ``lost_rows`` (runs where a row seen after the kill was
gone at the end), ``headerless`` (a trials.tsv without its header at any time),
``divergent`` (a final sequence that differs from the reference) and ``failed`` (a resume
that could not complete).

``--boundaries all`` (a simulated participant's session cut after each of its rows): the
reference session is run with the simulated responder; for each row k, a copy of it is cut
to its first k rows, marked interrupted and resumed. A resumed simulated participant replays
its memory (its familiarization, the range of what it felt) from the recorded attempts, so
the final rows must equal the reference's in every column but the times (:data:`TIMES`).
Reported: ``rows``, ``resumed``, ``divergent`` and ``failed`` (the rows cut after).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from analysis.session_format import SessionStatus

from ._common import emit, print_table
from ._options import BOUNDARY_WORDS, parse_points

#: what a resumed session must repeat of the uninterrupted one (an adaptive trial's
#: intensity and its procedure's state too)
KEY = ("trial_index", "item", "attempt", "sample", "status", "rating", "answer", "n_taps",
       "tap_velocities", "track", "intensity", "state")


#: the columns a resumed simulated participant's session need not repeat: its times
TIMES = ("response_time", "t_start", "t_end")


def _rows(folder: Path, key: tuple[str, ...] | None = KEY) -> list[tuple]:
    """trials.tsv's rows as tuples of the ``key`` columns (every column but
    :data:`TIMES` when ``key`` is None)."""
    from app.recorder import read_trials

    rows, _torn = read_trials(folder / "trials.tsv")
    return [tuple(v for k, v in r.items() if k not in TIMES) if key is None
            else tuple(r[k] for k in key) for r in rows]


def _cmd(args: list[str]) -> list[str]:
    return [sys.executable, "-m", "app", *args]


def kill_and_resume(kills: int, seed: int = 1, protocol: str = "realism", rng_seed: int = 0,
                    workdir: Path | None = None, delay: tuple[float, float] = (0.4, 2.0),
                    traces: str = "contacts", responder: str = "scripted") -> dict:
    """Run the harness; returns counts and whether every final sequence matched.

    Sessions are repeated (each in its own folder, each compared with the reference) until
    ``kills`` kills have landed. ``responder``: ``scripted`` (a dry run) or ``simulated``
    (the simulated participant on the simulated device, whose resume replays what it felt).
    """
    work = Path(workdir or tempfile.mkdtemp(prefix="hapticlab-crash-"))
    who = ["--dry-run"] if responder == "scripted" else ["--device", "sim", "--responder",
                                                          responder]
    common = ["--participant", "P01", *who, "--seed", str(seed),
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
            if not (folder / "session.json").exists():
                # killed before the session was declared (a loaded machine starts slowly):
                # nothing was recorded, and the next run takes the next session number
                folder = _newest(data / "sub-P01", folder)
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


def _newest(participant: Path, default: Path) -> Path:
    """The participant's highest-numbered session folder (``default`` when none)."""
    numbered = [(int(p.name[4:]), p) for p in participant.glob("ses-*") if p.name[4:].isdigit()]
    return max(numbered)[1] if numbered else default


def _incomplete(folder: Path) -> bool:
    import json

    try:
        return json.loads((folder / "session.json").read_text())["status"] \
            != SessionStatus.COMPLETE
    except (FileNotFoundError, ValueError, KeyError):
        return True


def _launch(args: list[str], env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "benchmarks._killpoint", *args], env=env,
                          capture_output=True, text=True, timeout=600)


def _sessions(data: Path) -> list[Path]:
    return sorted((p.parent for p in data.rglob("session.json")),
                  key=lambda p: int(p.name.split("-")[1]))


def _headerless(data: Path) -> bool:
    from analysis.session_format import header_line

    head = header_line().encode()
    for ses in _sessions(data):
        t = ses / "trials.tsv"
        if t.exists() and not t.read_bytes().startswith(head[: t.stat().st_size]):
            return True
        if not t.exists() or t.stat().st_size == 0:
            return True
    return False


def _one_point(k: int, torn: bool, protocol: str, run_args: list[str], work: Path,
               reference: list[tuple]) -> dict:
    data = work / f"point-{k}{'-torn' if torn else ''}"
    env = {**os.environ, "HAPTICLAB_KILL_ROOT": str(data), "HAPTICLAB_KILL_AT": str(k),
           "HAPTICLAB_KILL_TORN": "1" if torn else "0"}
    killed = _launch(["run", protocol, "--data", str(data), *run_args], env)
    out = {"point": k, "torn": torn, "killed": killed.returncode == -9, "lost": False,
           "headerless": False, "divergent": False, "failed": "", "resumes": 0}
    seen = _rows(_sessions(data)[-1]) if _sessions(data) else []
    out["headerless"] |= bool(_sessions(data)) and _headerless(data)
    clean = {k: v for k, v in os.environ.items() if not k.startswith("HAPTICLAB_KILL")}
    for _ in range(4):
        sessions = _sessions(data)
        if sessions and not _incomplete(sessions[-1]):
            break
        if sessions:  # resume what the kill left
            r = subprocess.run(_cmd(["resume", str(sessions[-1]), "--quiet"]), env=clean,
                               capture_output=True, text=True, timeout=600)
            out["resumes"] += 1
        else:  # killed before the session was written: the operator runs it again
            r = subprocess.run(_cmd(["run", protocol, "--data", str(data), *run_args]),
                               env=clean, capture_output=True, text=True, timeout=600)
        if r.returncode not in (0,):
            out["failed"] = (r.stderr.strip().splitlines() or ["?"])[-1][:200]
            break
    sessions = _sessions(data)
    final = _rows(sessions[-1]) if sessions else []
    out["headerless"] |= _headerless(data)
    out["lost"] = final[: len(seen)] != seen
    out["divergent"] = final != reference
    return out


def sample_points(log: list[tuple[str, str]]) -> list[int]:
    """The write points (1-based) of a sample that meets every way the session writes:
    the first point of each kind at each file (a temporary file's random name and a trial's
    number aside: ``.session.json.x8k2….tmp`` and ``trial-0002-0`` are one file each); the
    first row's append to trials.tsv (the same kinds at the same file as its header, but
    the write a resume must find whole or set aside as torn); and the last update of
    session.json, its write and its rename (every row is in, the status not yet complete).
    ``log`` is the reference run's ``(kind, path)`` per point, in order."""
    seen, chosen, trials_opened = set(), [], 0
    for k, (kind, path) in enumerate(log, start=1):
        name = re.sub(r"\d{4}", "N", re.sub(r"\.[^./]+\.tmp$", ".tmp", path))
        trials_opened += path.endswith("trials.tsv") and kind == "open"
        first_row = path.endswith("trials.tsv") and trials_opened == 2
        if (kind, name) not in seen or first_row:
            seen.add((kind, name))
            chosen.append(k)
    for kind, file in (("write", "session.json"), ("rename", "session.json")):
        last = max((k for k, (kd, path) in enumerate(log, start=1)
                    if kd == kind and file in path.rsplit("/", 1)[-1]), default=None)
        if last is not None:  # a session.json written in place has no rename
            chosen.append(last)
    return sorted(set(chosen))


def kill_at_points(protocol: str = "realism", seed: int = 1, points: str = "all",
                   workdir: Path | None = None, traces: str = "contacts", workers: int = 2,
                   torn: bool = True) -> dict:
    """Kill a session after each of its write points (``points``: ``all``, ``sample`` for
    :func:`sample_points`, or a comma list of point numbers), resume it, and check what
    :mod:`this module <benchmarks.crash>`'s docstring lists."""
    from concurrent.futures import ThreadPoolExecutor

    work = Path(workdir or tempfile.mkdtemp(prefix="hapticlab-points-"))
    work.mkdir(parents=True, exist_ok=True)
    run_args = ["--participant", "P01", "--dry-run", "--seed", str(seed), "--no-audio",
                "--quiet", "--traces", traces]
    ref = work / "reference"
    log = work / "points.log"
    env = {**os.environ, "HAPTICLAB_KILL_ROOT": str(ref), "HAPTICLAB_KILL_LOG": str(log)}
    r = _launch(["run", protocol, "--data", str(ref), *run_args], env)
    if r.returncode != 0:
        raise RuntimeError(f"the reference session failed: {r.stderr}")
    logged = [tuple(line.split("\t", 1)) for line in log.read_text().splitlines()]
    kinds = [kind for kind, _ in logged]
    reference = _rows(_sessions(ref)[-1])
    chosen = (sample_points(logged) if points == "sample"
              else parse_points(points, len(kinds)) or range(1, len(kinds) + 1))
    jobs = [(k, False) for k in chosen] + [(k, True) for k in chosen
                                           if torn and kinds[k - 1] == "write"]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(lambda j: _one_point(j[0], j[1], protocol, run_args, work,
                                                     reference), jobs))
    bad = [x for x in results if x["lost"] or x["headerless"] or x["divergent"] or x["failed"]
           or not x["killed"]]
    return {"points": len(kinds), "runs": len(results),
            "by_kind": {k: kinds.count(k) for k in sorted(set(kinds))},
            "killed_at": {k: kinds[k - 1] for k in chosen},
            "lost_rows": sum(x["lost"] for x in results),
            "headerless": sum(x["headerless"] for x in results),
            "divergent": sum(x["divergent"] for x in results),
            "failed": sum(bool(x["failed"]) for x in results),
            "not_killed": sum(not x["killed"] for x in results),
            "reference_rows": len(reference), "problems": bad[:20]}


def sample_boundaries(phases: list[str]) -> list[int]:
    """The rows (1-based: cut after row k) of a sample that meets each way a resume replays
    a simulated participant: after its first row, after the row before each later phase and
    that phase's first row (the phase's own memory begins), half way, and before the last
    row. ``phases`` is each row's phase, in order."""
    n = len(phases)
    chosen = {1, n // 2, n - 1}
    for k in range(1, n):
        if phases[k] != phases[k - 1]:
            chosen |= {k, k + 1}
    return sorted(k for k in chosen if 1 <= k < n)


def _resume_cut(src: Path, k: int, work: Path, reference: list[tuple]) -> dict:
    """A copy of the finished session ``src`` cut after row ``k`` (its first ``k`` rows,
    marked interrupted), resumed."""
    import shutil

    from analysis.session_format import read_meta
    from app.recorder import SessionFiles

    folder = work / f"after-{k}" / src.name
    shutil.copytree(src, folder)
    lines = (folder / "trials.tsv").read_text(encoding="utf-8").splitlines(keepends=True)
    (folder / "trials.tsv").write_text("".join(lines[: 1 + k]), encoding="utf-8")
    record = read_meta(folder / "session.json")
    record.interrupted(f"benchmarks.crash: cut after row {k}")
    SessionFiles(folder).write_meta(record)
    r = subprocess.run(_cmd(["resume", str(folder), "--quiet"]), capture_output=True,
                       text=True, timeout=600)
    failed = "" if r.returncode == 0 else (r.stderr.strip().splitlines() or ["?"])[-1][:200]
    return {"after": k, "failed": failed,
            "divergent": not failed and _rows(folder, None) != reference}


def resume_after_rows(protocol: str = "realism", seed: int = 5, rows: str = "all",
                      workdir: Path | None = None, workers: int = 2) -> dict:
    """Cut a simulated participant's session after each of its rows (``rows``: ``all``,
    ``sample`` for :func:`sample_boundaries`, or a comma list of row numbers), resume each
    cut, and check what :mod:`this module <benchmarks.crash>`'s docstring lists.

    Parameters
    ----------
    protocol : str
        A protocol name or TOML file.
    seed : int
        The session's seed.
    rows : str
        Which cuts (``all``, ``sample``, or row numbers such as ``1,12``).
    workdir : Path, optional
        Where the sessions go (a new temporary folder by default).
    workers : int
        Resumes run at once.

    Returns
    -------
    dict
        ``rows`` (the uninterrupted session's), ``resumed``, ``after`` (the rows cut after),
        ``divergent`` (those whose rows differ from it in any column but :data:`TIMES`)
        and ``failed`` ((row, the resume's last line of error) pairs).

    Raises
    ------
    UsageError
        A row number the session does not have, or a session of fewer than two rows
        (nothing to cut between).
    """
    from concurrent.futures import ThreadPoolExecutor

    from app.recorder import read_trials

    work = Path(workdir or tempfile.mkdtemp(prefix="hapticlab-boundaries-"))
    work.mkdir(parents=True, exist_ok=True)
    ref = work / "reference"
    r = subprocess.run(_cmd(["run", protocol, "--participant", "S01", "--seed", str(seed),
                             "--data", str(ref), "--responder", "simulated", "--no-audio",
                             "--quiet", "--traces", "none"]),
                       capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        raise RuntimeError(f"the reference session failed: {r.stderr}")
    src = _sessions(ref)[-1]
    recorded, _torn = read_trials(src / "trials.tsv")
    n = len(recorded)
    if n < 2:
        from app.errors import UsageError

        raise UsageError(f"{protocol}: its session has {n} row(s); a cut needs two or more")
    chosen = (sample_boundaries([row["phase"] for row in recorded]) if rows == "sample"
              else parse_points(rows, n - 1, **BOUNDARY_WORDS)
              or range(1, n))
    reference = _rows(src, None)
    with ThreadPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(lambda k: _resume_cut(src, k, work, reference), chosen))
    return {"rows": n, "resumed": len(results), "after": list(chosen),
            "divergent": [x["after"] for x in results if x["divergent"]],
            "failed": [(x["after"], x["failed"]) for x in results if x["failed"]]}


def _report(r: dict, t0: float, as_json: bool, title: str, columns: list[str], row: tuple,
            ok: bool) -> int:
    """Print ``r`` (its table, or JSON) with the wall time since ``t0``; the exit status."""
    r["wall_s"] = time.perf_counter() - t0
    if as_json:
        emit(r, True)
    else:
        print_table(f"{title} ({r['wall_s']:.0f} s)", columns, [row])
    return 0 if ok else 1


def main(args) -> int:
    t0 = time.perf_counter()
    if getattr(args, "boundaries", None):
        r = resume_after_rows(rows=args.boundaries)
        return _report(r, t0, args.json, "crash: a simulated participant's session cut after "
                       "each row, then resumed", ["rows", "resumed", "divergent",
                                                  "resumes failed"],
                       (r["rows"], r["resumed"], len(r["divergent"]), len(r["failed"])),
                       not (r["divergent"] or r["failed"]))
    if getattr(args, "points", None):
        r = kill_at_points(points=args.points)
        return _report(r, t0, args.json, "crash: kill -9 after every write point, then resume",
                       ["points", "runs", "rows lost", "headerless", "divergent",
                        "resumes failed"],
                       (r["points"], r["runs"], r["lost_rows"], r["headerless"],
                        r["divergent"], r["failed"]),
                       not (r["lost_rows"] or r["headerless"] or r["divergent"] or r["failed"]
                            or r["not_killed"]))
    r = kill_and_resume(getattr(args, "kills", 1000))
    return _report(r, t0, args.json, "crash: kill -9 at random moments, then resume",
                   ["kills", "sessions", "rows per session", "rows lost",
                    "torn lines set aside", "every sequence = uninterrupted"],
                   (r["kills"], r["sessions"], r["reference_rows"], r["lost_rows_events"],
                    r["torn_lines_set_aside"], "yes" if r["sequence_matches"] else "NO"),
                   r["sequence_matches"] and r["lost_rows_events"] == 0)
