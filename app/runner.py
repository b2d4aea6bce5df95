"""Running a session: engine + device + participant (screen or simulated) + recorder.

The session's only state is its files: every attempt is a row of trials.tsv, fsynced
before the next trial starts, and the engine replays those rows to decide what comes
next. A crash at any moment loses at most the attempt in progress; ``hapticlab resume``
continues with exactly the order the uninterrupted session would have had.

Randomness: the engine draws from the session seed; the simulated device's tapping and a
simulated participant's answers for an attempt come from
``SeedSequence([seed, trial_index, attempt])``, so a resumed attempt repeats exactly.
"""

from __future__ import annotations

import datetime as _dt
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from analysis.session_format import FORMAT_VERSION, PROTOCOL_COPY
from device import DeviceError, HapticDevice
from protocols import DONE, PAUSED, RNG_ALGORITHM, Attempt, Protocol, SessionEngine, Trial

from .console import PlainConsole
from .errors import DataFolderError, SessionFileError
from .participants import Participant
from .recorder import SessionFiles

__all__ = ["SessionRunner", "SessionInterrupted", "session_meta", "utc_now"]

APP_VERSION = "0.1.0"


class SessionInterrupted(Exception):
    """The session stopped before the end (device gone, operator abort); it can be resumed."""


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def _git_sha() -> str:
    here = Path(__file__).resolve().parents[1]
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _versions() -> dict[str, str]:
    out = {}
    for pkg in ("numpy", "scipy", "pandas", "statsmodels", "numba", "pyserial", "matplotlib",
                "psychopy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def session_meta(protocol: Protocol, protocol_ref: str, participant: str, session: int, seed: int,
                 counterbalance_row: int | None, device: HapticDevice, device_spec: str,
                 ui: str, responder: str, audio: bool, group: str = "", kind: str = "dry-run",
                 libraries: dict | None = None) -> dict:
    """The metadata DESIGN.md asks for, at session start."""
    return {
        "format_version": FORMAT_VERSION,
        "app": {"name": "hapticlab", "version": APP_VERSION, "git_sha": _git_sha()},
        "protocol": {"name": protocol.name, "ref": protocol_ref, "source": protocol.source,
                     "sha256": protocol.sha256, "copy": PROTOCOL_COPY,
                     "rating": None if protocol.rating is None else
                     {"min": protocol.rating.min, "max": protocol.rating.max},
                     "answer_choices": None if protocol.answer is None
                     else list(protocol.answer.choices),
                     "design": protocol.design()},
        "kind": kind,
        "libraries": libraries or {},
        "seed": seed,
        "rng": RNG_ALGORITHM + "; per attempt: SeedSequence([seed, trial_index, attempt])",
        "participant": {"id": participant, "counterbalance_row": counterbalance_row,
                        "group": group},
        "session": session,
        "device": {"spec": device_spec, **device.info.to_dict()},
        "ui": ui, "responder": responder, "audio": audio,
        "packages": _versions(),
        "python": sys.version.split()[0],
        "os": platform.platform(),
        "times": {"created_utc": utc_now(), "finished_utc": None},
        "resumes": [],
        "timing": {},
        "link": {},
        "status": "running",
    }


@dataclass
class SessionRunner:
    """Runs trials until the engine says done.

    Parameters
    ----------
    protocol, engine : the protocol and its session engine
    device : HapticDevice
    files : SessionFiles
    participant_ui : Participant
        Who answers (a person's screen, a scripted or simulated participant).
    """

    protocol: Protocol
    engine: SessionEngine
    device: HapticDevice
    files: SessionFiles
    participant_ui: Participant
    participant: str
    session: int
    seed: int
    console: PlainConsole = field(default_factory=PlainConsole)
    audio: Any = None
    traces: str = "full"
    log: list[Attempt] = field(default_factory=list)
    timing: list[dict] = field(default_factory=list)
    _expected: list[dict] | None = None  # while replaying: the recorded rows still to meet

    def load_log(self) -> None:
        rows, torn = self.files.read_rows()
        if torn is not None:
            raise RuntimeError("set the torn line aside before loading the log")
        self.log = [Attempt(r["item"], r["status"], r["reason"]) for r in rows]

    def _rng(self, trial: Trial) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence([self.seed, trial.trial_index,
                                                             trial.attempt]))

    def _total(self) -> int:
        return len(self.engine.plan())

    def run(self) -> str:
        """Run to the end; returns "complete". Raises SessionInterrupted to stop early —
        also when the data folder fails (full, read-only): what was recorded is kept."""
        try:
            return self._run()
        except DataFolderError as exc:
            raise SessionInterrupted(f"{exc}. Everything recorded before is kept; fix this, "
                                     "then resume") from exc

    # columns a replayed attempt must reproduce
    _REPLAYED = ("item", "attempt", "status", "n_taps", "tap_velocities", "rating", "answer")

    def replay(self, rows: list[dict]) -> None:
        """Run the recorded attempts again without recording them, so a participant whose
        answers depend on what it felt before (the simulated participant) is where it was
        when the session stopped. Each replayed attempt must reproduce its row; operator
        actions and pauses are taken from the rows.

        Raises
        ------
        SessionFileError
            A replayed attempt differs from its row (naming the line and the columns).
        """
        self.log = []
        self._expected = [dict(r, _line=i + 2) for i, r in enumerate(rows)]
        console, self.console = self.console, PlainConsole(quiet=True)  # nothing to tell
        try:
            while self._expected:
                row = self._expected[0]
                if row["status"] in ("paused", "resumed") or row["reason"].startswith(
                        "operator") or row["status"] in ("aborted_device", "excluded_device"):
                    self._expected.pop(0)
                    self.log.append(Attempt(row["item"], row["status"], row["reason"]))
                    continue
                trial = self.engine.next_trial(self.log)
                if trial is DONE or trial is PAUSED:
                    raise SessionFileError(f"{self.files.trials}:{row['_line']}: the replayed "
                                           "session ended before its rows did")
                self._attempt(trial)
        finally:
            self._expected = None
            self.console = console

    def _run(self) -> str:
        while True:
            trial = self.engine.next_trial(self.log)
            if trial is DONE:
                return "complete"
            if trial is PAUSED:  # operator pause: wait for resume
                time.sleep(0.05)
                continue
            done = len(self.engine.outcomes(self.log))
            self.participant_ui.waiting(trial)
            self.console.place(trial, self._total(), done)
            action = self.console.wait_ready()
            while action == "pause":
                self.participant_ui.pause()
                self.console.say("paused — press p to resume")
                action = self.console.wait_resume()
            if action in ("skip", "requeue"):
                status = "skipped" if action == "skip" else "requeued"
                self._record(trial, status, reason=f"operator {action}", t_start=utc_now())
                continue
            if action == "abort":
                raise SessionInterrupted("aborted by the operator; everything so far is saved")
            self._attempt(trial)

    # ------------------------------------------------------------------ one attempt
    def _attempt(self, trial: Trial) -> None:
        rng = self._rng(trial)
        t_start = utc_now()
        self.participant_ui.ready(trial)
        if self.audio is not None:
            self.audio.tap_cue()
        results = []
        try:
            if trial.kind == "identification":
                # the participant switches between the surfaces before naming them
                visited: set[int] = set()
                by_surface: dict[int, Any] = {}
                while (k := self.participant_ui.choose_surface(trial, visited)) is not None:
                    by_surface[k] = self._window(trial, trial.samples[k], rng)
                    visited.add(k)
                results = [by_surface[k] for k in sorted(by_surface)]
            elif trial.kind == "free":
                # familiarization: windows on the sample until the participant is done
                results.append(self._window(trial, trial.samples[0], rng))
                while self.participant_ui.keep_tapping():
                    results.append(self._window(trial, trial.samples[0], rng))
            else:
                for sid in trial.samples:
                    results.append(self._window(trial, sid, rng))
        except DeviceError as exc:
            status = self.engine.failure_status("aborted_device", trial, self.log)
            self._record(trial, status, reason=str(exc)[:200], t_start=t_start,
                         result=exc.partial)
            excluded = (f"; item {trial.item} failed {self.engine.cap('aborted_device')} times "
                        "and is left out" if status == "excluded_device" else "")
            raise SessionInterrupted(f"device error during trial {trial.trial_index}: "
                                     f"{exc}{excluded}") from exc
        res = results[0]
        velocities = np.concatenate([r.velocities for r in results]) if results else []
        if any(r.faults for r in results):  # an e-stop or the watchdog during the window
            f = next(r.faults[0] for r in results if r.faults)
            status = self.engine.failure_status("aborted_device", trial, self.log)
            self._record(trial, status, reason=f"{f.code}: {f.message}",
                         t_start=t_start, result=res, results=results)
            raise SessionInterrupted(f"{f.code} during trial {trial.trial_index}: output is off "
                                     "and latched; resume with --clear-fault once it is safe")
        if any(r.timed_out for r in results):
            status = self.engine.failure_status("timed_out", trial, self.log)
            self._record(trial, status, reason="no contact before the timeout",
                         t_start=t_start, result=res)
            self.console.say(f"  no contact within {self.protocol.window.timeout:g} s: "
                             + ("left out (timed out too often)" if status == "excluded_timeout"
                                else "the item goes back into the pool"))
            return
        if any(r.saturated for r in results) and self.protocol.saturation.action == "redraw" \
                and trial.kind != "free":
            if self.audio is not None and self.protocol.saturation.tone:
                self.audio.low_tone()
            self.console.saturated()
            status = self.engine.saturated_status(trial, self.log)
            self._record(trial, status, t_start=t_start, result=res, results=results)
            return
        row: dict[str, Any] = {}
        if trial.kind == "rated":
            rating, rt = self.participant_ui.rate(trial, self.protocol.rating, res, rng)
            if not self.protocol.rating.min <= rating <= self.protocol.rating.max:
                raise SessionInterrupted(f"the responder gave rating {rating!r}, outside the "
                                         f"scale {self.protocol.rating.min}–"
                                         f"{self.protocol.rating.max}; nothing was recorded "
                                         "for this trial")
            row.update(rating=int(rating), response_time=round(float(rt), 3))
        elif trial.kind == "identification":
            answers, rt = self.participant_ui.identify(trial, self.protocol.answer.choices,
                                                       results, rng)
            row.update(answer=",".join(answers), response_time=round(float(rt), 3),
                       correct=int(list(answers) == list(trial.samples)))
        self._record(trial, "valid", t_start=t_start, result=res, results=results, **row)
        self.console.result("valid", len(velocities),
                            f"rating {row['rating']}" if "rating" in row else "")

    def _window(self, trial: Trial, sample_id: str, rng: np.random.Generator):
        sample = self.protocol.samples[sample_id]
        dev = self.device
        dev.load_scene(sample.scene)
        dev.reseed([self.seed, trial.trial_index, trial.attempt, trial.samples.index(sample_id)])
        self.participant_ui.before_window(trial, sample_id, dev, rng)
        dev.home()
        w = self.protocol.window

        shown = 0

        def progress(t, partial):
            nonlocal shown
            for c in partial.contacts[shown:]:  # live incoming speeds for the operator
                self.console.contact(c.velocity)
            shown = len(partial.contacts)
            self.participant_ui.progress(t, partial, w.duration)

        res = dev.run_window(w.duration, timeout=w.timeout, on_progress=progress)
        if res.timing:
            self.timing.append(res.timing)
        self.participant_ui.after_window(trial, sample_id, res)  # what a simulated person felt
        return res

    # ------------------------------------------------------------------ recording
    def _record(self, trial: Trial, status: str, *, reason: str = "", t_start: str,
                result=None, results=None, **extra) -> None:
        results = results or ([result] if result is not None else [])
        vel = [v for r in results for v in r.velocities]
        trace_file = None
        if self._expected is not None:  # replaying: compare, do not record
            self._meet(trial, status, vel, extra)
            self.log.append(Attempt(trial.item, status, reason))
            return
        if results and self.traces != "none" and any(len(r.traces) for r in results):
            for k, r in enumerate(results):
                if not r.traces:
                    continue
                name = f"trial-{trial.trial_index:04d}-{k}.npz"
                trace_file = self.files.save_trace(
                    name, _trace_payload(r, self.traces, self.device.info), r.contacts)
            if len(results) > 1:
                trace_file = f"traces/trial-{trial.trial_index:04d}-*.npz"
        row = {
            "participant": self.participant, "session": self.session, "phase": trial.phase,
            "trial_index": trial.trial_index, "item": trial.item, "attempt": trial.attempt,
            "sample": trial.sample, "block": trial.block or "",
            "factors": ";".join(f"{k}={v}" for k, v in
                                self.protocol.samples[trial.samples[0]].factors.items())
            if len(trial.samples) == 1 else "",
            "placement": trial.placement or "",
            "status": status, "n_taps": len(vel),
            "tap_velocities": ";".join(f"{v:.5f}" for v in vel),
            "peak_current": round(max((r.peak_current for r in results), default=0.0), 4),
            "reason": reason, "t_start": t_start, "t_end": utc_now(), "trace_file": trace_file,
            **extra,
        }
        self.files.append_row(row)  # durable before anything else happens
        self.log.append(Attempt(trial.item, status, reason))

    def _meet(self, trial: Trial, status: str, vel: list[float], extra: dict) -> None:
        """A replayed attempt against its recorded row."""
        row = self._expected.pop(0)
        got = {"item": trial.item, "attempt": str(trial.attempt), "status": status,
               "n_taps": str(len(vel)), "tap_velocities": ";".join(f"{v:.5f}" for v in vel),
               "rating": str(extra.get("rating", "")), "answer": str(extra.get("answer", ""))}
        diff = [c for c in self._REPLAYED if got[c] != row[c]]
        if diff:
            raise SessionFileError(
                f"{self.files.trials}:{row['_line']}: the replayed attempt differs from the "
                f"recorded one in {', '.join(diff)} (recorded "
                f"{', '.join(f'{c}={row[c]!r}' for c in diff)}; replayed "
                f"{', '.join(f'{c}={got[c]!r}' for c in diff)}): the session cannot be "
                "resumed exactly")


def _trace_payload(res, mode: str, info) -> dict:
    """The device's own streams, in the device's own units where they are quantized.

    ``t0`` [s] and ``rate_hz`` [Hz] instead of a time column; ``position_counts`` (int32,
    × ``encoder_resolution`` [m]); ``accel_counts`` (int16, × ``accel_lsb`` [m/s²]); velocity,
    forces and current as float32; flags as uint8. ``mode = "contacts"`` keeps 10 ms before
    to 140 ms after each contact (with ``sample_index`` of what was kept).
    """
    tr = res.traces
    n = len(tr["t"])
    keep = np.ones(n, bool)
    if mode == "contacts":
        keep[:] = False
        for c in res.contacts:
            i = int(round((c.t - tr["t"][0]) * res.rate_hz))
            keep[max(0, i - int(0.01 * res.rate_hz)): i + int(0.14 * res.rate_hz)] = True
    lsb = 2 * info.accel_range / 4096
    out = {"t0": np.float64(tr["t"][0] if n else 0.0), "rate_hz": np.float64(res.rate_hz),
           "encoder_resolution": np.float64(info.encoder_resolution),
           "accel_lsb": np.float64(lsb),
           "position_counts": np.round(np.asarray(tr["position"])[keep]
                                       / info.encoder_resolution).astype(np.int32),
           "accel_counts": np.clip(np.round(np.asarray(tr["accel"])[keep] / lsb), -32768,
                                   32767).astype(np.int16),
           "flags": np.asarray(tr["flags"])[keep].astype(np.uint8)}
    for k in ("velocity", "force_cmd", "force_out", "current"):
        out[k] = np.asarray(tr[k])[keep].astype(np.float32)
    if mode == "contacts":
        out["sample_index"] = np.flatnonzero(keep).astype(np.int32)
    return out
