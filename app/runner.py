"""Running a session: engine + device + participant (screen or simulated) + recorder.

The session's only state is its files: every attempt is a row of trials.tsv, fsynced
before the next trial starts, and the engine replays those rows to decide what comes
next. A crash at any moment loses at most the attempt in progress; ``hapticlab resume``
continues with exactly the order the uninterrupted session would have had.

Randomness: the engine draws from the session seed; the simulated device's tapping and a
simulated participant's answers for an attempt come from
``SeedSequence([seed, trial_index, attempt])``, so a resumed attempt repeats exactly.

Size: over 700 lines on purpose. :class:`SessionRunner` is one state machine — the wait
for the operator's placing, pauses and faults, the real reference blocks, an attempt's
windows as its phase kind declares them, the row of each — whose steps share the runner's
state (device, console, log, markers, files) and read best in their order in one place.
What has a job of its own lives beside it: the record a session starts with
(:mod:`app.session_record`), who answers (:mod:`app.participants`), the files
(:mod:`app.recorder`), the run's set-up (:mod:`app.api._new_session`).
"""

from __future__ import annotations

import dataclasses
import shlex
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.cells import row_problem
from analysis.session_format import (
    SessionRecord,
    SessionStatus,
    format_cell,
)
from device import DeviceError, DeviceFaultError, HapticDevice
from protocols import (
    DONE,
    PAUSED,
    REFERENCE,
    Attempt,
    Protocol,
    SessionEngine,
    Trial,
    TrialStatus,
    is_reference,
    phase_kind,
    reference_item,
)
from protocols.responses import Question, Response

from .console import PlainConsole
from .errors import DataFolderError, SessionFileError
from .markers import MarkerSink
from .participants import Responder
from .recorder import SessionFiles
from .session_record import session_meta, utc_now

__all__ = ["SessionRunner", "SessionInterrupted", "session_meta", "utc_now", "trace_payload"]


class _FaultStop(Exception):
    """A latched fault stopped a trial while an operator is at the keys: pause, not end."""

    def __init__(self, fault):
        super().__init__(fault.code)
        self.fault = fault


class SessionInterrupted(Exception):
    """The session stopped before the end (device gone, operator abort); it can be resumed."""


@dataclass(kw_only=True)
class SessionRunner:
    """Runs trials until the engine says done. Built with keywords.

    Parameters
    ----------
    protocol, engine : the protocol and its session engine
    device : HapticDevice
    files : SessionFiles
    responder : Responder
        Who answers (a person's screen, a scripted or simulated participant).
    markers : MarkerSink
        Where the session's events go as markers (:mod:`app.markers`; default: nowhere).
    """

    protocol: Protocol
    engine: SessionEngine
    device: HapticDevice
    files: SessionFiles
    responder: Responder
    participant: str
    session: int
    seed: int
    console: PlainConsole = field(default_factory=PlainConsole)
    audio: Any = None
    traces: str = "full"
    log: list[Attempt] = field(default_factory=list)
    timing: list[dict] = field(default_factory=list)
    #: what the device could not do as asked (a simulated contact that chattered), by its
    #: first words: each is said to the operator once and kept in session.json
    warnings: dict[str, str] = field(default_factory=dict)
    meta: SessionRecord | None = None  # session.json's record (notes are added to it)
    markers: MarkerSink = field(default_factory=MarkerSink)
    _expected: list[dict] | None = None  # while replaying: the recorded rows still to meet
    _durations: list[float] = field(default_factory=list)
    _windows_in_attempt: int = 0
    _on_device: str | None = None  # the real block last placed on the device, if any
    #: (window result, file or None, peak current [A]) of the attempt's windows whose traces
    #: left memory when they ended; _record names the files, and what no row named is set
    #: aside when the attempt ends
    _spilled: list = field(default_factory=list)

    def load_log(self) -> None:
        rows, torn = self.files.read_rows()
        if torn is not None:
            raise RuntimeError("set the torn line aside before loading the log")
        self.log = [Attempt(r["item"], r["status"], r["reason"], correct=_correct(r))
                    for r in rows]

    def _rng(self, trial: Trial) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence([self.seed, trial.trial_index,
                                                             trial.attempt]))

    def _total(self) -> int:
        return self.engine.max_trials()  # an adaptive phase at its most

    def run(self) -> str:
        """Run to the end; returns "complete". Raises SessionInterrupted to stop early —
        also when the data folder fails (full, read-only): what was recorded is kept."""
        try:
            return self._run()
        except DataFolderError as exc:
            raise SessionInterrupted(f"{exc}. Everything recorded before is kept; fix this, "
                                     "then resume") from exc

    # columns a replayed attempt must reproduce (and its response's, but its time)
    _REPLAYED = ("item", "attempt", "status", "n_taps", "tap_velocities")

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
        markers, self.markers = self.markers, MarkerSink()  # nor anything to mark
        try:
            while self._expected:
                row = self._expected[0]
                status = TrialStatus(row["status"])
                # what the operator, the participant or the device decided: taken as logged
                if status.control or status in (TrialStatus.ESTOP, TrialStatus.ABORTED_DEVICE,
                                                TrialStatus.EXCLUDED_DEVICE) \
                        or row["reason"].startswith(("operator", "participant asked")):
                    self._expected.pop(0)
                    self.log.append(Attempt(row["item"], row["status"], row["reason"],
                                            correct=_correct(row)))
                    continue
                trial = self.engine.next_trial(self.log)
                if trial is DONE or trial is PAUSED:
                    raise SessionFileError(f"{self.files.trials}:{row['_line']}: the replayed "
                                           "session ended before its rows did")
                self._references_due(trial)
                if self._expected:
                    self._attempt(trial)
        finally:
            self._expected = None
            self.console = console
            self.markers = markers

    def _run(self) -> str:
        v = self.console.view
        v.title = f"{self.protocol.title} · {self.participant} · session {self.session}"
        while True:
            self._save_notes()
            trial = self.engine.next_trial(self.log)
            if trial is DONE:
                return SessionStatus.COMPLETE
            if trial is PAUSED:  # a pause recorded in the log (older sessions)
                time.sleep(0.05)
                continue
            self._references_due(trial)
            action = self._wait_placed(trial)
            if action in ("skip", "requeue"):
                status = TrialStatus.SKIPPED if action == "skip" else TrialStatus.REQUEUED
                self._record(trial, status, reason=f"operator {action}", t_start=utc_now())
                self.console.say(f"{'s: skipped' if action == 'skip' else 'u: re-queued'} trial "
                                 f"{trial.trial_index} ({trial.item})")
                continue
            if action == "abort":
                self.console.say(f"q: stopped before trial {trial.trial_index}; everything so "
                                 "far is saved")
                raise SessionInterrupted("stopped by the operator; everything so far is saved")
            t0 = time.monotonic()
            try:
                self._attempt(trial)
            except _FaultStop as stop:
                self._fault_pause(stop.fault)
                continue
            finally:
                self.console.set_state("idle")
            self._durations.append(time.monotonic() - t0)

    # ------------------------------------------------------------------ between trials
    def _placement(self, trial: Trial) -> tuple[str, str]:
        """What the operator places for ``trial``, and what it is (never on the participant's
        screen)."""
        clear = f"nothing: remove the {self._on_device}" if self._on_device else "nothing"
        if trial.surfaces:
            return f"{clear} (the scene's surfaces are virtual)", " / ".join(trial.samples)
        sample = trial.sample_of(self.protocol, trial.samples[0])
        what = trial.placement or clear
        detail = "real sample" if sample.is_real else f"virtual: {', then '.join(trial.samples)}"
        return what, detail

    def _block_line(self, trial: Trial) -> str:
        if trial.kind == REFERENCE:
            return f"real reference block: {trial.placement}"
        if trial.surfaces:  # surface 1's block is not the scene's
            return ""
        sample = trial.sample_of(self.protocol, trial.samples[0])
        block = trial.block or sample.block
        if block is None and sample.reference is None:
            return ""
        ref = self.protocol.samples.get(sample.reference) if sample.reference else None
        return (f"{block or ''}" + (f" — its real block: {ref.placement or ref.id}"
                                    if ref is not None else ""))

    def _wait_placed(self, trial: Trial) -> str:
        """Until the operator has placed the item and pressed r (or chose another action);
        meanwhile the participant sees 'please wait' and may ask for the real block."""
        done = len(self.engine.outcomes(self.log))
        what, detail = self._placement(trial)
        v = self.console.view
        v.block = self._block_line(trial)
        rest = len(self.engine.remaining(self.log))
        v.left_s = (float(np.median(self._durations)) * rest) if self._durations else None
        self.responder.waiting(trial)
        self.console.place(trial, self._total(), done, what, detail)
        self.console.set_state("placing")
        while True:
            self._save_notes()
            if self.console.interactive and self.device.fault is not None:
                self._fault_pause(self.device.fault)  # an e-stop pressed between trials
                self.responder.waiting(trial)
                self.console.place(trial, self._total(), done, what, detail)
                self.console.set_state("placing")
            if self.responder.poll() == "reference":
                ref = self.responder.choose_reference(trial, self._real_blocks(trial))
                if ref is not None:
                    self.console.say(f"the participant asks for the real block: {ref}")
                    self._reference(trial, ref, asked=True)
                    what, detail = self._placement(trial)  # the real block is on it now
                    v.block = self._block_line(trial)
                    self.console.place(trial, self._total(), done, what, detail)
                    self.console.set_state("placing")
                self.responder.waiting(trial)
            action = self.console.poll(0.03)
            if action is None:
                continue
            if action == "pause":
                action = self._paused(trial)
                if action == "resume":  # back to placing: r starts the trial, nothing else
                    self.responder.waiting(trial)
                    self.console.set_state("placing")
                    self.console.say(f"p: resumed; trial {trial.trial_index} starts with r")
                    continue
            return action

    def _paused(self, trial: Trial) -> str:
        self.console.set_state("paused")
        self.console.say(f"p: paused before trial {trial.trial_index} — p resumes, q stops")
        self.responder.pause()
        while True:
            self._save_notes()
            a = self.console.poll(0.03)
            if a in ("resume", "abort"):
                return a

    def _fault_pause(self, fault) -> None:
        """An e-stop or the watchdog latched the device: the participant's window stays up,
        the session waits for the operator to make it safe and clear the fault (c)."""
        self.markers.fault(fault)  # unless its window's markers carried it
        self.console.set_state("fault")
        self.console.say(f"{fault.code.upper()}: output is off and latched ({fault.message}). "
                         "Make it safe, then press c to clear it and continue, or q to stop and "
                         "save")
        self.responder.pause(fault=True)
        while True:
            self._save_notes()
            a = self.console.poll(0.03)
            if a == "clear":
                try:
                    why = self.console.clear_fault(self.device)
                except DeviceFaultError as exc:  # the device keeps it (its button is held)
                    why = str(exc)
                if why:
                    self.console.set_state("fault")
                    self.console.say(f"c: not cleared: {why}. Press c again once it is "
                                     "safe, or q to stop and save")
                    continue
                self.console.say("c: fault cleared by the operator; the trial runs again")
                return
            if a == "abort":
                raise SessionInterrupted(f"stopped by the operator after a {fault.code}; "
                                         "everything so far is saved")

    def _resume_line(self) -> str:
        """The command that continues this session after a fault, once it is safe."""
        return shlex.join(["hapticlab", "resume", str(self.files.folder), "--clear-fault"])

    def _save_notes(self) -> None:
        notes = self.console.take_notes()
        if notes and self.meta is not None:
            self.meta.add_notes(notes)
            self.files.write_meta(self.meta)

    # ------------------------------------------------------------------ reference blocks
    def _referenced(self, item: str) -> bool:
        return any(a.item == item and a.status == TrialStatus.REFERENCE for a in self.log)

    def _references_due(self, trial: Trial) -> None:
        """The real blocks the protocol calls for before this trial: the block's own at the
        start of each block, or all the phase's at its start."""
        phase = next(p for p in self.protocol.phases if p.name == trial.phase)
        declared = phase_kind(trial.kind)  # the phase kind's declaration (trial.kind: its name)
        if phase.references == "none" or not declared.references:
            return
        if phase.references == "block" and not trial.surfaces:
            refs = [trial.sample_of(self.protocol, trial.samples[0]).reference]
        else:
            refs = list(dict.fromkeys(self.protocol.samples[s].reference
                                      for s in phase.samples))
        for ref in refs:
            if ref is not None and not self._referenced(reference_item(trial.phase, ref)):
                self._reference(trial, ref)

    def _real_blocks(self, trial: Trial) -> list[tuple[str, str]]:
        """The real blocks a participant may ask for before ``trial``: (sample id, what it
        is called). A rated trial's own block; in identification every real block of the
        phase, in the protocol's order — never one that follows from the scene (surface 1's
        block would be its answer)."""
        if not trial.surfaces:
            ref = trial.sample_of(self.protocol, trial.samples[0]).reference
            return [] if ref is None else [(ref, self.protocol.samples[ref].placement or ref)]
        phase = next(p for p in self.protocol.phases if p.name == trial.phase)
        refs = dict.fromkeys(self.protocol.samples[s].reference for s in phase.samples)
        return [(r, self.protocol.samples[r].placement or r) for r in refs if r is not None]

    def _reference(self, trial: Trial, ref_id: str, asked: bool = False) -> None:
        """The operator places a real reference block; the participant taps it (one window);
        the taps are recorded as their own row (status ``reference``). An e-stop while it is
        placed or tapped pauses the session like any trial; the block is tapped again."""
        ref = self.protocol.samples[ref_id]
        k = sum(a.status == TrialStatus.REFERENCE for a in self.log)
        rtrial = dataclasses.replace(trial, item=reference_item(trial.phase, ref_id),
                                     kind=REFERENCE,
                                     samples=(ref_id,), placement=ref.placement or ref_id,
                                     attempt=0, block=trial.block)
        reason = "participant asked" if asked else ""
        while True:
            self.responder.waiting(rtrial)
            self.console.view.block = self._block_line(rtrial)
            self.console.place(rtrial, self._total(), len(self.engine.outcomes(self.log)),
                               ref.placement or ref_id, "real reference block (compare with it)")
            self.console.set_state("reference")
            while self.console.poll(0.03) != "go":
                self._save_notes()
                self.responder.poll()
                if self.console.interactive and self.device.fault is not None:
                    self._fault_pause(self.device.fault)
                    self.responder.waiting(rtrial)
                    self.console.set_state("reference")
            self.console.set_state("trial")
            self._on_device = ref.placement or ref_id
            self.responder.reference(rtrial, ref)
            t_start = utc_now()
            self.markers.trial(rtrial)
            self.markers.send("trial_start", sample=ref_id, kind=REFERENCE)
            self._windows_in_attempt = 0
            try:
                rng = np.random.default_rng(np.random.SeedSequence(
                    [self.seed, trial.trial_index, 10_000 + k]))
                res = self._window(rtrial, ref_id, rng,
                                   reseed=[self.seed, trial.trial_index, 0, k])
            except DeviceError as exc:
                self.markers.unfinished(str(exc)[:200])
                if not (isinstance(exc, DeviceFaultError) and self.console.interactive
                        and self.device.fault is not None):
                    raise SessionInterrupted(f"device error while tapping the real block "
                                             f"{ref_id}: {exc}") from exc
                self._fault_pause(self.device.fault)
                continue
            if res.faults:
                f = res.faults[0]
                self._record(rtrial, TrialStatus.ESTOP, reason=f"{f.code}: {f.message}",
                             t_start=t_start, result=res)
                if not self.console.interactive:
                    raise SessionInterrupted(f"{f.code} while tapping the real block {ref_id}: "
                                             "output is off and latched; once it is safe: "
                                             f"{self._resume_line()}")
                self._fault_pause(f)
                continue
            self._record(rtrial, TrialStatus.REFERENCE, t_start=t_start, result=res, reason=reason)
            self.console.result(TrialStatus.REFERENCE, len(res.contacts), ref_id)
            return

    # ------------------------------------------------------------------ the end
    def summary(self, seconds: float) -> str:
        """One line for the operator: what the session recorded."""
        rows, _ = self.files.read_rows()
        c = {}
        for r in rows:
            c[r["status"]] = c.get(r["status"], 0) + 1
        excluded = sum(v for k, v in c.items() if k.startswith("excluded"))
        sat = c.get(TrialStatus.SATURATED, 0) + c.get(TrialStatus.EXCLUDED_SATURATED, 0)
        return (f"{c.get('valid', 0)} valid, {sat} saturated, {excluded} excluded, "
                f"{c.get('skipped', 0)} skipped, {c.get('timed_out', 0)} timed out, "
                f"{c.get('reference', 0)} reference taps; "
                f"{int(seconds // 60)} min {int(seconds % 60)} s")

    # ------------------------------------------------------------------ one attempt
    def _attempt(self, trial: Trial) -> None:
        self._windows_in_attempt = 0
        try:
            self._attempt_windows(trial)
        except BaseException as exc:  # an attempt that ends without its row says so
            self.markers.unfinished(str(exc)[:200] or type(exc).__name__)
            raise
        finally:  # what the attempt wrote early and no row names goes aside, never reused
            if self._spilled:
                self.files.set_aside([name for _, name, _ in self._spilled if name])
                self._spilled.clear()

    def _attempt_windows(self, trial: Trial) -> None:
        declared = phase_kind(trial.kind)  # the phase kind's declaration (trial.kind: its name)
        self._on_device = None if trial.surfaces else trial.placement
        rng = self._rng(trial)
        t_start = utc_now()
        self.responder.ready(trial)
        self.markers.trial(trial)
        self.markers.send("trial_start", sample=trial.sample, kind=trial.kind)
        self.console.set_state("trial")
        if self.audio is not None:
            self.audio.tap_cue()
        # the sample of each window begun (one more than results while a window runs, so a
        # window a device error cut short is named too), and each finished window's result
        results, played = [], []
        try:
            # the windows the participant is judged on (a surface's last)
            judged = self._WINDOWS[trial.windows](self, trial, rng, results, played)
        except DeviceFaultError as exc:  # latched before the window (an e-stop between trials)
            fault = self.device.fault
            if fault is not None:
                self.markers.fault(fault)
            if not self.console.interactive or fault is None:
                raise SessionInterrupted(f"trial {trial.trial_index}: {exc}; once it is safe: "
                                         f"{self._resume_line()}") from exc
            raise _FaultStop(fault) from exc
        except DeviceError as exc:
            status = self.engine.failure_status(TrialStatus.ABORTED_DEVICE, trial, self.log)
            cut = [exc.partial] if exc.partial is not None else []  # the window it cut short
            self._record(trial, status, reason=str(exc)[:200], t_start=t_start,
                         results=[*results, *cut], played=played)
            excluded = (f"; item {trial.item} failed {self.engine.cap('aborted_device')} times "
                        "and is left out" if status == TrialStatus.EXCLUDED_DEVICE else "")
            raise SessionInterrupted(f"device error during trial {trial.trial_index}: "
                                     f"{exc}{excluded}") from exc
        res = results[0]
        velocities = np.concatenate([r.velocities for r in results]) if results else []
        if any(r.faults for r in results):  # an e-stop or the watchdog during the window
            f = next(r.faults[0] for r in results if r.faults)
            if self.console.interactive:  # the operator is there: pause until it is cleared
                self._record(trial, TrialStatus.ESTOP, reason=f"{f.code}: {f.message}",
                             t_start=t_start, result=res, results=results, played=played)
                raise _FaultStop(f)
            status = self.engine.failure_status(TrialStatus.ABORTED_DEVICE, trial, self.log)
            self._record(trial, status, reason=f"{f.code}: {f.message}",
                         t_start=t_start, result=res, results=results, played=played)
            raise SessionInterrupted(f"{f.code} during trial {trial.trial_index}: output is off "
                                     f"and latched; once it is safe: {self._resume_line()}")
        # a surface left without a tap, then tapped on a later visit, did not time out
        if any(r.timed_out for r in judged):
            status = self.engine.failure_status(TrialStatus.TIMED_OUT, trial, self.log)
            self._record(trial, status, reason="no contact before the timeout",
                         t_start=t_start, result=res, results=results, played=played)
            self.console.say(f"  no contact within {self.protocol.window.timeout:g} s: "
                             + ("left out (timed out too often)"
                                if status == TrialStatus.EXCLUDED_TIMEOUT
                                else "the item goes back into the pool"))
            return
        if any(r.saturated for r in results) and self.protocol.saturation.action == "redraw" \
                and declared.redraws_saturated:
            if self.audio is not None and self.protocol.saturation.tone:
                self.audio.low_tone()
            self.console.saturated()
            status = self.engine.saturated_status(trial, self.log)
            self.responder.saturated(trial, comes_back=status == TrialStatus.SATURATED)
            self._record(trial, status, t_start=t_start, result=res, results=results,
                         played=played)
            return
        row: dict[str, Any] = {}
        if declared.asks is not None:
            row = self._respond(declared.asks, trial, judged, rng)
        self._record(trial, TrialStatus.VALID, t_start=t_start, result=res, results=results,
                     played=played, **row)
        self.console.result(TrialStatus.VALID, len(velocities), ", ".join(
            f"{c} {row[c]}" for c in (declared.asks.marker if declared.asks else ())))

    # ------------------------------------------------------------------ a kind's windows
    # each appends every window it begins to ``played`` and each it finishes to
    # ``results`` as it goes (a device error keeps what came before), and returns the
    # windows the participant is judged on

    def _each_sample(self, trial: Trial, rng, results: list, played: list) -> list:
        for sid in trial.samples:
            played.append(sid)
            results.append(self._window(trial, sid, rng))
        return results

    def _until_done(self, trial: Trial, rng, results: list, played: list) -> list:
        # familiarization: windows on the sample until the participant is done, each
        # window's traces on disk as it ends (held in memory, a long familiarization grew
        # by megabytes a window)
        while True:
            played.append(trial.samples[0])
            results.append(self._spill(trial, len(results),
                                       self._window(trial, trial.samples[0], rng)))
            if results[-1].faults or not self.responder.keep_tapping():
                return results  # a fault ends it: the e-stop's row names its windows

    def _surfaces(self, trial: Trial, rng, results: list, played: list) -> list:
        # the participant switches between the surfaces before naming them; every window
        # is kept (a surface tapped again adds one); the naming is of each surface's last
        visited: set[int] = set()
        last: dict[int, Any] = {}
        while (k := self.responder.choose_surface(trial, visited)) is not None:
            self.console.say(f"  surface {k + 1} of {len(trial.samples)}: tapping")
            played.append(trial.samples[k])
            results.append(self._window(trial, trial.samples[k], rng))
            last[k] = results[-1]
            visited.add(k)
        return [last[k] for k in sorted(last)]

    _WINDOWS = {"each_sample": _each_sample, "until_done": _until_done, "surfaces": _surfaces}

    # ------------------------------------------------------------------ the response
    def _respond(self, asks: Response, trial: Trial, judged: list, rng) -> dict[str, Any]:
        """Ask the responder for ``asks`` and return the row's response cells (its
        declaration's columns), checked by the rules the analysis applies to them."""
        self.console.set_state("rating")  # answering: the operator's e acts
        self.markers.send("rating_onset")
        question = Question(trial=trial, protocol=self.protocol, results=judged,
                            after=None if trial.stimulus is None else
                            (lambda right: self.engine.state_after(trial, right)))
        value, rt = self.responder.answer(asks, question, rng)
        try:
            row = asks.answer_row(value, rt, question)
        except ValueError as exc:
            why = str(exc)
        else:
            why = cell_problems(row, asks, trial, self.protocol)
        if why:
            raise SessionInterrupted(f"the responder's {asks.name}: {why}; nothing was "
                                     "recorded for this trial")
        self.markers.send("response", **{c: row[c] for c in asks.marker},
                          response_time_s=row["response_time"])
        return row

    def _spill(self, trial: Trial, k: int, res):
        """Window ``k`` of ``trial`` with its traces written now when the session records
        them (as ``_record`` would name them) and dropped from memory either way; its peak
        current is kept for the row."""
        if not res.traces:
            return res
        name = None
        if self._expected is None and self.traces != "none":
            name = self.files.save_trace(
                f"trial-{trial.trial_index:04d}-{k}.npz",
                trace_payload(res, self.traces, self.device.info, trial.samples[0]),
                res.contacts)
        kept = dataclasses.replace(res, traces={})
        self._spilled.append((kept, name, res.peak_current))
        return kept

    def _window(self, trial: Trial, sample_id: str, rng: np.random.Generator,
                reseed: list | None = None):
        sample = trial.sample_of(self.protocol, sample_id)
        dev = self.device
        dev.load_scene(sample.scene)
        # each window of an attempt its own stream (familiarization's several windows, a
        # surface tapped twice): the same attempt repeats exactly, its windows differ
        k = self._windows_in_attempt
        self._windows_in_attempt += 1
        dev.reseed([*(reseed or [self.seed, trial.trial_index, trial.attempt,
                                 trial.samples.index(sample_id)]), k])
        self.responder.before_window(trial, sample_id, dev, rng)
        dev.home()
        self.markers.send("homed", sample=sample_id, window=k)
        w = self.protocol.window

        shown = 0
        ended = False
        surfaces = trial.kind != REFERENCE and trial.surfaces

        def progress(t, partial):
            nonlocal shown, ended
            for c in partial.contacts[shown:]:  # live incoming speeds for the operator
                self.console.contact(c.velocity)
            shown = len(partial.contacts)
            self.responder.progress(t, partial, w.duration)
            if surfaces and not ended and self.responder.moving_on():
                ended = True  # the participant went to another surface, or to answer
                dev.end_window()

        try:
            res = dev.run_window(w.duration, timeout=w.timeout, on_progress=progress)
        except DeviceError as exc:  # what the window recorded before it was cut short
            if getattr(exc, "partial", None) is not None:
                self.markers.window(exc.partial, dev, window=k)
            raise
        try:
            # output off while the participant answers, switches surfaces or rests: only
            # a window keeps it on, and the device's watchdog then guards a host that hangs
            # (the link's lease is renewed by this loop alone: device.serial.link)
            dev.zero()
        except DeviceError as exc:
            exc.partial = res  # the window ended whole: its row names it
            raise
        finally:  # its contacts, saturations and faults, on the markers' clock
            self.markers.window(res, dev, window=k)
        if res.timing:
            self.timing.append(res.timing)
        for text in res.warnings:  # what the device could not do as asked: said once
            if (said := text.split(" (")[0]) not in self.warnings:
                self.warnings[said] = text
                self.console.say(f"warning: {text}")
        self.responder.after_window(trial, sample_id, res)  # what a simulated person felt
        return res

    # ------------------------------------------------------------------ recording
    def _record(self, trial: Trial, status: str, *, reason: str = "", t_start: str,
                result=None, results=None, played=None, **extra) -> None:
        results = results or ([result] if result is not None else [])
        played = played or [trial.samples[0]] * len(results)
        vel = [v for r in results for v in r.velocities]
        trace_file = None
        if self._expected is not None:  # replaying: compare, do not record
            self._meet(trial, status, vel, extra)
            self.log.append(Attempt(trial.item, status, reason, correct=_correct(
                {"status": status, **extra})))
            return
        spilled = {id(r): name for r, name, _ in self._spilled if name}  # alive: ids hold
        peaks = {id(r): peak for r, _, peak in self._spilled}
        if results and self.traces != "none" and any(len(r.traces) or id(r) in spilled
                                                     for r in results):
            # every recording its own name: a trial's windows by its index (unique per
            # attempt), a real block's tapping by its place among the session's references
            # (several may come before one trial); the recorder refuses to overwrite
            if trial.kind == REFERENCE:
                stem = f"reference-{sum(is_reference(a.item) for a in self.log) + 1:03d}"
            else:
                stem = f"trial-{trial.trial_index:04d}"
            for k, r in enumerate(results):
                if id(r) in spilled:  # written when its window ended: named by this row
                    trace_file = spilled[id(r)]
                    self._spilled = [e for e in self._spilled if e[0] is not r]
                elif r.traces:
                    trace_file = self.files.save_trace(
                        f"{stem}-{k}.npz", trace_payload(r, self.traces, self.device.info,
                                                          played[k]), r.contacts)
            if len(results) > 1:
                trace_file = f"traces/{stem}-*.npz"
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
            "peak_current": round(max((peaks.get(id(r), r.peak_current) for r in results),
                                      default=0.0), 4),
            "reason": reason, "t_start": t_start, "t_end": utc_now(), "trace_file": trace_file,
            **extra,
        }
        self.files.append_row(row)  # durable before anything else happens
        self.log.append(Attempt(trial.item, status, reason, correct=_correct(row)))
        self.markers.trial(trial)
        self.markers.send("trial_end", status=status, reason=reason)
        self.markers.trial(None)
        if self.markers.active and self.meta is not None:  # the windows' clocks, kept
            self.files.write_meta(self.meta)

    def _meet(self, trial: Trial, status: str, vel: list[float], extra: dict) -> None:
        """A replayed attempt against its recorded row."""
        row = self._expected.pop(0)
        asks = None if trial.kind == REFERENCE else phase_kind(trial.kind).asks
        answered = [c for c in (asks.columns if asks else ()) if c != "response_time"]
        got = {"item": trial.item, "attempt": str(trial.attempt), "status": status,
               "n_taps": str(len(vel)), "tap_velocities": ";".join(f"{v:.5f}" for v in vel),
               **{c: format_cell(c, extra.get(c)) for c in answered}}
        diff = [c for c in (*self._REPLAYED, *answered) if got[c] != row[c]]
        if diff:
            raise SessionFileError(
                f"{self.files.trials}:{row['_line']}: the replayed attempt differs from the "
                f"recorded one in {', '.join(diff)} (recorded "
                f"{', '.join(f'{c}={row[c]!r}' for c in diff)}; replayed "
                f"{', '.join(f'{c}={got[c]!r}' for c in diff)}): the session cannot be "
                "resumed exactly")


def _correct(row: dict) -> bool | None:
    """What the engine takes of a row: whether a valid answer of an adaptive trial (one
    with a track) was right; None for every other row."""
    if row.get("status") != "valid" or not row.get("track"):
        return None
    return str(row.get("correct")) in ("1", "1.0", "True")


def cell_problems(row: dict, asks: Response, trial: Trial, protocol: Protocol) -> str:
    """Why the response cells ``row`` of ``trial`` would not count when analysed ('' when
    they would): the rules of ``asks``, applied as the analysis applies them to the file
    (:func:`analysis.cells.row_problem`), so a session never records what its analysis
    would set aside."""
    design = protocol.design()
    text = {c: format_cell(c, v) for c, v in row.items()}
    return row_problem({**text, "status": "valid", "sample": trial.sample},
                       {"response": asks.record()}, design)


def trace_payload(res, mode: str, info, sample: str) -> dict:
    """The device's own streams, in the device's own units where they are quantized.

    ``t0`` [s] and ``rate_hz`` [Hz] instead of a time column; ``position_counts`` (int32,
    × ``encoder_resolution`` [m]); ``accel_counts`` (int16, × ``accel_lsb`` [m/s²]; neither
    from a device without an accelerometer); velocity, forces and current as float32; flags
    as uint8. ``mode = "contacts"`` keeps 10 ms before to 140 ms after each contact (with
    ``sample_index`` of what was kept).
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
    out = {"sample": np.str_(sample),
           "t0": np.float64(tr["t"][0] if n else 0.0), "rate_hz": np.float64(res.rate_hz),
           "encoder_resolution": np.float64(info.encoder_resolution),
           "position_counts": np.round(np.asarray(tr["position"])[keep]
                                       / info.encoder_resolution).astype(np.int32),
           "flags": np.asarray(tr["flags"])[keep].astype(np.uint8)}
    if "accel" in tr:
        out["accel_lsb"] = np.float64(lsb)
        out["accel_counts"] = np.clip(np.round(np.asarray(tr["accel"])[keep] / lsb), -32768,
                                      32767).astype(np.int16)
    for k in ("velocity", "force_cmd", "force_out", "current"):
        out[k] = np.asarray(tr[k])[keep].astype(np.float32)
    if mode == "contacts":
        out["sample_index"] = np.flatnonzero(keep).astype(np.int32)
    return out
