"""The session engine: a pure function of (protocol, seed, participant, attempt log).

It has no UI, no device and no clock. :meth:`SessionEngine.next_trial` replays the
log from the start every time, so the state of a session is its log alone: resuming
after a crash is the same computation as continuing, and for every prefix of a log the
remaining order equals that of the uninterrupted run.

Randomness comes from two ``numpy.random.Generator`` streams spawned from the
session seed: one draws the plan (block order, item order, surface order of
identification trials), the other the positions at which redrawn items go back.

Statuses of an attempt
----------------------
``valid``
    done; the item leaves the queue.
``saturated``
    the participant exceeded the current limit: the item goes back among the remaining
    items of its block at a random position.
``excluded_saturated``
    the saturated attempt that reached the protocol's cap: the item leaves the queue.
``requeued``
    the operator sent the item back (with a reason): random position, like a redraw,
    not counted against any cap.
``timed_out``
    nobody tapped before the window's timeout: the item goes back at a random position,
    counted against the protocol's ``[attempts] max_timeouts``.
``excluded_timeout``
    the timed-out attempt that reached that cap: the item leaves the queue.
``aborted_device``
    the device failed mid-trial: the item stays first in the queue and is retried,
    counted against ``[attempts] max_device_failures``.
``excluded_device``
    the device failure that reached that cap: the item leaves the queue.
``skipped``
    the operator skipped the item: it leaves the queue.

Every count is capped, so a session always ends: a device that saturates, times out or
fails on every attempt still reaches the end of the plan.

``estop``
    the operator's e-stop (or the device's watchdog) stopped the attempt: the item stays
    first and is retried once the fault is cleared, not counted against any cap.

Operator pauses are log entries with status ``paused`` / ``resumed``; while paused,
:meth:`SessionEngine.next_trial` returns :data:`PAUSED`. A ``reference`` entry (a real block
tapped for comparison) does not change the order.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from device.errors import HapticlabError

from .adaptive import Stimulus, Tracks, comparison_sample, value_at
from .kinds import phase_kind
from .model import Phase, Protocol, Sample
from .statuses import CAPPED, FINAL_STATUSES, STATUSES, TrialStatus
from .williams import williams_square

__all__ = ["SessionEngine", "Trial", "Attempt", "Done", "Paused", "DONE", "PAUSED",
           "LogMismatch", "ResumeMismatch", "SessionSetupError", "STATUSES", "FINAL_STATUSES",
           "TrialStatus",
           "SATURATION_SAFETY_CAP", "reference_item", "is_reference"]

#: a real reference block's row in trials.tsv: item ``<phase>/ref:<sample>``
_REF = "/ref:"


def reference_item(phase: str, sample: str) -> str:
    """The item of a row where the real block ``sample`` was tapped before a trial of
    ``phase`` (not an item of the session's plan)."""
    return f"{phase}{_REF}{sample}"


def is_reference(item: str) -> bool:
    """Whether a row's item is a real reference block's (see :func:`reference_item`)."""
    return _REF in item

#: saturations of one item after which it is excluded even with ``max_attempts = "none"``
#: (the paper redrew without a cap; no participant saturates one sample this often, and a
#: device that saturates on every attempt must still let the session end)
SATURATION_SAFETY_CAP = 20
RNG_ALGORITHM = ("numpy PCG64 via SeedSequence(seed).spawn(2): [plan, redraw]; an adaptive "
                 "phase's trial k: SeedSequence([seed, 57, phase index, k])")
#: the key's end of an adaptive phase's place in the plan
_ADAPTIVE = "/*adaptive"


class SessionSetupError(HapticlabError, ValueError):
    """A session cannot be set up as asked (a seed, a counterbalance row)."""


class LogMismatch(HapticlabError, ValueError):
    """The attempt log does not fit this protocol/seed (an entry names the wrong item)."""


class ResumeMismatch(HapticlabError, ValueError):
    """Resuming with a different protocol, seed or participant than the session recorded."""


@dataclass(frozen=True)
class Item:
    """One queued unit of work: a sample's repetition, an identification's (all the samples)
    or a comparison's (an ordered pair)."""

    key: str
    phase: str
    kind: str
    samples: tuple[str, ...]
    block: str | None
    repetition: int
    #: an adaptive phase's trial: its track, intensity and comparison (None otherwise)
    stimulus: Stimulus | None = None
    #: how its windows run when not as its kind's (an adaptive phase's presentation)
    windows: str | None = None

    @property
    def marker(self) -> bool:
        """The place of an adaptive phase in the plan, not a trial: its trials are made
        one at a time, from the answers so far, when it comes first."""
        return self.key.endswith(_ADAPTIVE)


@dataclass(frozen=True)
class Trial:
    """What the runner should do next.

    Attributes
    ----------
    item : str
        Stable key of the queued item (``phase/sample#repetition``); log attempts by it.
    phase, kind : str
        Phase name and kind (a :func:`~protocols.kinds.phase_kind` name, or ``reference``).
    trial_index : int
        1-based position of this attempt in the session.
    attempt : int
        1-based attempt number of this item.
    samples : tuple of str
        The sample (one) or the surfaces in order (identification).
    block : str or None
        Block (factorial material) of the item.
    placement : str or None
        What the operator places: a real sample, a placeholder block, or None.
    repetition : int
        1-based repetition of the sample within its phase.
    stimulus : Stimulus or None
        An adaptive phase's trial: its track, intensity, the comparison and which of the
        two samples is the larger (:class:`~protocols.adaptive.Stimulus`).
    windows : str
        How its windows run (:data:`protocols.kinds.WINDOWS`): its kind's, or an adaptive
        phase's presentation (``each_sample`` for intervals, ``surfaces`` for two surfaces
        the participant goes between); '' for a reference block's trial.
    """

    item: str
    phase: str
    kind: str
    trial_index: int
    attempt: int
    samples: tuple[str, ...]
    block: str | None
    placement: str | None
    repetition: int
    stimulus: Stimulus | None = None
    windows: str = ""

    @property
    def surfaces(self) -> bool:
        """Its samples are surfaces of one scene that the participant goes between."""
        return self.windows == "surfaces"

    def sample_of(self, protocol: Protocol, sample_id: str) -> Sample:
        """The sample ``sample_id`` of this trial: the protocol's, or the comparison an
        adaptive trial made."""
        if self.stimulus is not None and sample_id == self.stimulus.comparison.id:
            return self.stimulus.comparison
        return protocol.samples[sample_id]

    @property
    def sample(self) -> str:
        """The single sample of a non-identification trial."""
        return self.samples[0] if len(self.samples) == 1 else "+".join(self.samples)


@dataclass(frozen=True)
class Attempt:
    """One log entry: the outcome of an attempt at ``item``, or a pause/resume marker;
    ``correct``: a valid trial of an adaptive phase, whether its answer was right (what its
    procedure takes)."""

    item: str
    status: str
    reason: str = ""
    correct: bool | None = None

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "status", TrialStatus(self.status))
        except ValueError:
            raise ValueError(f"attempt status must be one of "
                             f"{', '.join(s.value for s in TrialStatus)}; got "
                             f"{self.status!r}") from None


@dataclass(frozen=True)
class Done:
    """The session is complete."""


@dataclass(frozen=True)
class Paused:
    """The operator paused the session."""


DONE, PAUSED = Done(), Paused()


@dataclass
class _State:
    queue: list[Item]
    attempts: dict[str, int] = field(default_factory=dict)
    #: (counted failure, item) → how many times
    failures: dict[tuple[TrialStatus, str], int] = field(default_factory=dict)
    n_attempts: int = 0
    paused: bool = False
    last_placement: str | None = None
    finished: dict[str, str] = field(default_factory=dict)
    tracks: dict[str, Tracks] = field(default_factory=dict)  # adaptive phase → its tracks
    rng: np.random.Generator | None = None  # where redrawn items go back
    entries: int = 0  # log entries taken


def _can_spread(counts: Mapping[str, int], prev: str | None) -> bool:
    """Whether items with ``counts`` per sample can follow one another with no sample twice
    in a row, the first not ``prev``: no sample may fill more than every other place, and
    one that fills exactly every other place of an odd count must come first."""
    n = sum(counts.values())
    if n == 0:
        return True
    half = (n + 1) // 2
    if max(counts.values()) > half:
        return False
    return not (n % 2 and prev is not None and counts.get(prev, 0) == half)


def no_repeat_order(items: Sequence[Item], rng: np.random.Generator,
                    prev: str | None = None) -> list[Item]:
    """``items`` (one sample each) in a random order with no sample on two in a row and the
    first not ``prev`` (ignored when that cannot be met).

    Each place is drawn among the samples that leave the rest an order (:func:`_can_spread`),
    in proportion to how many of each are left, the lowest repetition of a sample first: a
    sequential draw, not uniform over all admissible orders.

    Raises
    ------
    ValueError
        When no such order exists (one sample fills more than every other place).
    """
    by_sample: dict[str, list[Item]] = {}
    for it in items:
        by_sample.setdefault(it.samples[0], []).append(it)
    counts = {s: len(v) for s, v in by_sample.items()}
    if not _can_spread(counts, None):
        raise ValueError(f"no order without repeats: counts per sample {counts}")
    if not _can_spread(counts, prev):
        prev = None
    out: list[Item] = []
    while len(out) < len(items):
        ok = [s for s, c in counts.items() if c and s != prev
              and _can_spread({**counts, s: c - 1}, s)]
        weights = np.array([counts[s] for s in ok], dtype=float)
        prev = ok[int(rng.choice(len(ok), p=weights / weights.sum()))]
        counts[prev] -= 1
        out.append(by_sample[prev].pop(0))
    return out


class SessionEngine:
    """Sequences the trials of one session.

    Parameters
    ----------
    protocol : Protocol
    seed : int
        Session seed (recorded); every random choice derives from it.
    participant : str
        Participant id (part of the session identity checked on resume).
    counterbalance_row : int, optional
        Row of the Williams square for phases with ``block_order = "williams"``
        (typically the participant's 0-based enrolment number; taken modulo the rows).
    """

    def __init__(self, protocol: Protocol, seed: int, participant: str,
                 counterbalance_row: int | None = None):
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise SessionSetupError(f"seed must be a non-negative integer, got {seed!r}")
        self.protocol = protocol
        self.seed = int(seed)
        self.participant = participant
        self.counterbalance_row = counterbalance_row
        williams = [p for p in protocol.phases if p.block_order == "williams"]
        if williams and counterbalance_row is None:
            raise SessionSetupError(f"protocol '{protocol.name}' counterbalances block order "
                                    "with a Williams square: give the participant's "
                                    "counterbalance row (--row)")
        for p in williams:
            n = len(self.williams_rows(p))
            if not isinstance(counterbalance_row, int) or not 0 <= counterbalance_row < n:
                raise SessionSetupError(f"counterbalance row {counterbalance_row!r} is not a "
                                        f"row of phase {p.name!r}'s Williams square: rows "
                                        f"0–{n - 1} ({n} orders; a row beyond them would "
                                        "repeat one silently)")
        self._no_repeat = {ph.name: ph.no_repeat for ph in protocol.phases}
        self._phases = {ph.name: (i, ph) for i, ph in enumerate(protocol.phases)}
        self._states: dict[tuple, object] = {}  # (phase, track, answers) → procedure state
        self._last: tuple[list, _State] | None = None  # the last replay: its log and state
        self._plan = self._build_plan()

    # ------------------------------------------------------------------ identity
    @property
    def identity(self) -> dict:
        """What a resumed session must match: protocol hash, seed, participant, row."""
        return {"protocol_sha256": self.protocol.sha256, "seed": self.seed,
                "participant": self.participant, "counterbalance_row": self.counterbalance_row}

    def check_resume(self, recorded: Mapping) -> None:
        """Refuse to resume a session recorded under a different identity.

        Raises
        ------
        ResumeMismatch
            Naming each field that differs, with both values.
        """
        diffs = [f"{k}: session has {recorded.get(k)!r}, now {v!r}"
                 for k, v in self.identity.items() if recorded.get(k) != v]
        if diffs:
            raise ResumeMismatch("cannot resume: the session was recorded with a different "
                                 + "; ".join(diffs))

    # ------------------------------------------------------------------ plan
    def _build_plan(self) -> list[Item]:
        plan_ss, _ = np.random.SeedSequence(self.seed).spawn(2)
        rng = np.random.default_rng(plan_ss)
        items: list[Item] = []
        for phase in self.protocol.phases:
            items.extend(self._phase_items(phase, rng, items[-1] if items else None))
        return items

    def _phase_items(self, phase: Phase, rng: np.random.Generator,
                     before: Item | None) -> list[Item]:
        samples = self.protocol.samples
        items = phase_kind(phase.kind).items
        if items == "adaptive":  # made one trial at a time from the answers (_fill)
            return [Item(f"{phase.name}{_ADAPTIVE}", phase.name, phase.kind, (), None, 0)]
        if items == "pairs":  # both orders of every pair, each repetition, in a drawn order
            pairs = [(a, b) for a in phase.samples for b in phase.samples if a != b]
            out = []
            for rep in range(1, phase.repetitions + 1):
                order = [pairs[i] for i in rng.permutation(len(pairs))] \
                    if phase.order == "random" else pairs
                out += [Item(f"{phase.name}/{a}+{b}#{rep}", phase.name, phase.kind, (a, b),
                             None, rep) for a, b in order]
            return out
        if items == "all":  # one item of all the samples, drawn in order
            out = []
            for rep in range(1, phase.repetitions + 1):
                order = [phase.samples[i] for i in rng.permutation(len(phase.samples))]
                out.append(Item(f"{phase.name}/#{rep}", phase.name, phase.kind, tuple(order),
                                None, rep))
            return out
        if phase.blocks:
            names: list[str | None] = list(dict.fromkeys(samples[s].block for s in phase.samples))
        else:
            names = [None]
        if phase.block_order == "random":
            names = [names[i] for i in rng.permutation(len(names))]
        elif phase.block_order == "williams":
            rows = self.williams_rows(phase)
            names = [names[i] for i in rows[self.counterbalance_row]]
        out = []
        for block in names:
            members = [s for s in phase.samples if block is None or samples[s].block == block]
            block_items = [Item(f"{phase.name}/{s}#{rep}", phase.name, phase.kind, (s,), block, rep)
                           for rep in range(1, phase.repetitions + 1) for s in members]
            if phase.order == "random" and phase.no_repeat:
                last = out[-1] if out else before
                block_items = no_repeat_order(block_items, rng,
                                              last.samples[0] if last is not None else None)
            elif phase.order == "random":
                block_items = [block_items[i] for i in rng.permutation(len(block_items))]
            out.extend(block_items)
        return out

    def williams_rows(self, phase: Phase) -> list[list[int]]:
        """The Williams square of ``phase``'s blocks (its rows are the counterbalance rows)."""
        blocks = {self.protocol.samples[s].block for s in phase.samples} if phase.blocks \
            else {None}
        return williams_square(len(blocks))

    def plan(self) -> list[Item]:
        """The uninterrupted order of items (no saturations, no operator actions)."""
        return list(self._plan)

    def placements(self) -> list[str | None]:
        """What the operator places for each item of :meth:`plan` (None: nothing, or an
        adaptive phase's place, whose trials are not planned)."""
        out, previous = [], None
        for item in self._plan:
            if not item.marker:
                previous = self._placement(item, previous)
            out.append(None if item.marker else previous)
        return out

    def max_trials(self) -> int:
        """The trials of the plan, an adaptive phase counted at its most (its tracks' cap
        and its catch trials)."""
        return sum(self._phases[i.phase][1].adaptive.max_total() if i.marker else 1
                   for i in self._plan)

    # ------------------------------------------------------------------ replay
    def _fresh(self) -> _State:
        _, redraw_ss = np.random.SeedSequence(self.seed).spawn(2)
        return _State(queue=list(self._plan), rng=np.random.default_rng(redraw_ss),
                      tracks={ph.name: Tracks.of(ph.adaptive) for ph in self.protocol.phases
                              if ph.adaptive is not None})

    @staticmethod
    def _copy(st: _State) -> _State:
        rng = np.random.Generator(type(st.rng.bit_generator)())
        rng.bit_generator.state = st.rng.bit_generator.state
        return dataclasses.replace(
            st, queue=list(st.queue), attempts=dict(st.attempts), failures=dict(st.failures),
            finished=dict(st.finished), tracks={k: v.copy() for k, v in st.tracks.items()},
            rng=rng)

    def _replay(self, log: Iterable[Attempt]) -> _State:
        """The session's state after ``log``. The state after the last log replayed is kept,
        so a log that extends it continues from there (the same result as replaying from
        the start: an adaptive procedure is not run again for every trial)."""
        log = list(log)
        last = self._last
        if last is not None and len(last[0]) <= len(log) and log[:len(last[0])] == last[0]:
            st = self._copy(last[1])
        else:
            st = self._fresh()
        for n in range(st.entries, len(log)):
            self._take(st, n, log[n])
        self._fill(st)
        st.entries = len(log)
        self._last = (log, st)  # the callers only read it; a longer log continues a copy
        return st

    def _take(self, st: _State, n: int, entry: Attempt) -> None:
        """Log entry ``n`` into the state."""
        failure_of = {v: k for k, v in CAPPED.items()}  # an exclusion → the failure it caps
        if not isinstance(entry, Attempt):
            raise LogMismatch(f"log entry {n + 1}: expected an Attempt, got {entry!r}")
        if entry.status == TrialStatus.PAUSED:
            st.paused = True
            return
        if entry.status == TrialStatus.RESUMED:
            st.paused = False
            return
        if entry.status == TrialStatus.REFERENCE or is_reference(entry.item):
            return  # a real block tapped (or an e-stop while it was): not a plan item
        self._fill(st)
        if not st.queue:
            raise LogMismatch(f"log entry {n + 1} ({entry.item}, {entry.status}) comes after "
                              "the session was complete")
        head = st.queue[0]
        if entry.item != head.key:
            raise LogMismatch(f"log entry {n + 1} is for item {entry.item!r} but the session's "
                              f"order has {head.key!r} next: the log does not belong to this "
                              "protocol, seed and participant, or was edited")
        st.n_attempts += 1
        st.attempts[head.key] = st.attempts.get(head.key, 0) + 1
        st.last_placement = self._placement(head, st.last_placement)
        status = entry.status
        failure = status if status in CAPPED else failure_of.get(status)
        if failure is not None:
            key = (failure, head.key)
            st.failures[key] = st.failures.get(key, 0) + 1
            if status == failure and st.failures[key] >= self.cap(failure):
                raise LogMismatch(f"log entry {n + 1}: attempt {st.failures[key]} of "
                                  f"{head.key!r} is {status} at the cap of "
                                  f"{self.cap(failure)}; it must be logged "
                                  f"'{CAPPED[failure]}'")
        if status.final:
            st.queue.pop(0)
            st.finished[head.key] = status
            if head.stimulus is not None:
                self._ended(st, head, entry, n)
        elif status in (TrialStatus.SATURATED, TrialStatus.REQUEUED, TrialStatus.TIMED_OUT) \
                and head.stimulus is None:
            st.queue.pop(0)
            self._reinsert(st.queue, head, st.rng, self._no_repeat[head.phase])
        else:
            # aborted_device, estop: the item stays first and is retried; an adaptive
            # trial that saturated, timed out or was sent back is repeated at once, its
            # procedure unchanged
            return
        self._spread_rest(st.queue, head, st.rng)

    # ------------------------------------------------------------------ adaptive phases
    def _fill(self, st: _State) -> None:
        """While an adaptive phase's place is first: make its next trial from the answers
        so far, or, when its tracks are done, go past it."""
        while st.queue and st.queue[0].marker:
            item = self._next_adaptive(st, st.queue[0].phase)
            if item is None:
                st.queue.pop(0)
            else:
                st.queue.insert(0, item)
                return

    def procedure_state(self, phase: str, track: str, answers: tuple[bool, ...]):
        """The procedure of ``track`` in ``phase`` after ``answers`` (kept: each state is
        made once per engine)."""
        proc = self._phases[phase][1].adaptive.procedure
        n = len(answers)
        while n > 0 and (phase, track, answers[:n]) not in self._states:
            n -= 1
        if n == 0 and (phase, track, ()) not in self._states:
            self._states[(phase, track, ())] = proc.begin()
        state = self._states[(phase, track, answers[:n])]
        for k in range(n, len(answers)):
            state = proc.update(state, answers[k])
            self._states[(phase, track, answers[:k + 1])] = state
        return state

    def _track_done(self, phase: Phase, tracks: Tracks, track: str) -> bool:
        a = phase.adaptive
        return tracks.ended[track] >= a.max_trials or a.procedure.done(
            self.procedure_state(phase.name, track, tracks.answers[track]))

    def _next_adaptive(self, st: _State, name: str) -> Item | None:
        index, phase = self._phases[name]
        a, tracks = phase.adaptive, st.tracks[name]
        open_ = [t for t in a.tracks if not self._track_done(phase, tracks, t.name)]
        if not open_:
            return None
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 57, index,
                                                            tracks.made]))
        track = open_[int(rng.integers(len(open_)))]
        catch = bool(tracks.catch_done < a.max_catch() and rng.random() < a.catch)
        first = int(rng.integers(2))  # the interval of the comparison
        tracks.made += 1
        answers = tracks.answers[track.name]
        x = a.catch_intensity if catch else \
            self.procedure_state(name, track.name, answers).x
        standard = self.protocol.samples[track.standard]
        value = value_at(getattr(standard.scene.transient, a.parameter), x, a.units,
                         track.direction)
        comparison = comparison_sample(standard, a.parameter, value)
        pair = (comparison.id, standard.id) if first == 0 else (standard.id, comparison.id)
        larger = first if track.direction == "up" else 1 - first
        n = (f"c{tracks.catch_done + 1}" if catch else str(tracks.ended[track.name] + 1))
        stim = Stimulus(track=track.name, intensity=float(x), catch=catch,
                        standard=standard.id, comparison=comparison, larger=larger,
                        answers=answers)
        return Item(f"{name}/{track.name}#{n}", name, phase.kind, pair, standard.block, 0,
                    stim, "surfaces" if a.presentation == "surfaces" else None)

    def _ended(self, st: _State, head: Item, entry: Attempt, n: int) -> None:
        """An adaptive trial ended: a valid answer goes to its track's procedure (a catch
        trial's to none); any ending counts against the track's cap."""
        s, tracks = head.stimulus, st.tracks[head.phase]
        if s.catch:
            tracks.catch_done += 1
            return
        tracks.ended[s.track] += 1
        if entry.status == TrialStatus.VALID:
            if entry.correct is None:
                raise LogMismatch(f"log entry {n + 1}: a valid trial of the adaptive phase "
                                  f"{head.phase!r} without its answer (correct 0 or 1)")
            tracks.answers[s.track] = (*tracks.answers[s.track], bool(entry.correct))

    def state_after(self, trial: Trial, correct: bool) -> dict:
        """What the trial row of an adaptive ``trial`` records of its procedure after the
        answer ``correct``: the next intensity, step, reversals … (a catch trial: that it
        was one)."""
        s = trial.stimulus
        if s is None:
            raise ValueError(f"trial {trial.item} is not an adaptive phase's")
        if s.catch:
            return {"catch": True}
        phase = self._phases[trial.phase][1]
        state = self.procedure_state(trial.phase, s.track, (*s.answers, bool(correct)))
        return state.summary(phase.adaptive.procedure)

    def _spread_rest(self, queue: list[Item], last: Item, rng: np.random.Generator) -> None:
        """With no_repeat, a next trial of the sample just tried (redraws and what the
        participant finished moved things: the block's own next item, or the first of the
        next block) is avoided by drawing the rest of its block again, where the items left
        allow an order that begins with another sample."""
        if not queue or not self._no_repeat[queue[0].phase] \
                or queue[0].samples[0] != last.samples[0]:
            return
        span = 0
        while span < len(queue) and (queue[span].phase, queue[span].block) == \
                (queue[0].phase, queue[0].block):
            span += 1
        counts = Counter(it.samples[0] for it in queue[:span])
        if _can_spread(counts, last.samples[0]):
            queue[:span] = no_repeat_order(queue[:span], rng, last.samples[0])

    def cap(self, failure: str) -> int:
        """How many counted failures (``saturated``, ``timed_out``, ``aborted_device``) of
        one item end it."""
        if failure == TrialStatus.SATURATED:
            cap = self.protocol.saturation.max_attempts
            return SATURATION_SAFETY_CAP if cap is None else cap
        if failure == TrialStatus.TIMED_OUT:
            return self.protocol.attempts.max_timeouts
        return self.protocol.attempts.max_device_failures

    @staticmethod
    def _reinsert(queue: list[Item], item: Item, rng: np.random.Generator,
                  no_repeat: bool = False) -> None:
        """Put ``item`` back at a random position among the remaining items of its block;
        with ``no_repeat``, at a position with another sample on either side (the first
        position follows the attempt just made, of this very sample), where there is one,
        else one with another sample before it."""
        span = 0
        while span < len(queue) and queue[span].phase == item.phase \
                and queue[span].block == item.block:
            span += 1
        places = list(range(span + 1))
        if no_repeat:
            s = item.samples[0]
            # not straight back, nor after its own sample; then, where it can, not before it
            # either (the block's end counts as apart: a next block that would begin with
            # this sample is drawn again when it comes, _spread_rest)
            after = [i for i in places if i > 0 and queue[i - 1].samples[0] != s]
            apart = [i for i in after if i == span or queue[i].samples[0] != s]
            places = apart or after or places
        queue.insert(places[int(rng.integers(0, len(places)))], item)

    def _placement(self, item: Item, previous: str | None) -> str | None:
        if (item.windows or phase_kind(item.kind).windows) == "surfaces":  # all virtual
            return None
        s = self.protocol.samples[item.stimulus.standard if item.stimulus else item.samples[0]]
        if s.placement is not None:
            return s.placement
        blocks = self.protocol.placeholders
        if not blocks:
            return None
        # a different placeholder from what is on the stand, so every trial is a swap
        return blocks[1] if previous == blocks[0] else blocks[0]

    # ------------------------------------------------------------------ API
    def next_trial(self, log: Sequence[Attempt]) -> Trial | Done | Paused:
        """The next trial given everything logged so far, or :data:`DONE` / :data:`PAUSED`."""
        st = self._replay(log)
        if st.paused:
            return PAUSED
        if not st.queue:
            return DONE
        head = st.queue[0]
        return Trial(item=head.key, phase=head.phase, kind=head.kind,
                     trial_index=st.n_attempts + 1, attempt=st.attempts.get(head.key, 0) + 1,
                     samples=head.samples, block=head.block,
                     placement=self._placement(head, st.last_placement),
                     repetition=head.repetition, stimulus=head.stimulus,
                     windows=head.windows or phase_kind(head.kind).windows)

    def failure_status(self, failure: str, trial: Trial, log: Sequence[Attempt]
                       ) -> TrialStatus:
        """Status to log for a failed attempt (``failure``: ``saturated``, ``timed_out``,
        ``aborted_device``): the failure itself or, when it reaches its cap, the exclusion."""
        failure = TrialStatus(failure)
        n = self._replay(log).failures.get((failure, trial.item), 0) + 1
        return CAPPED[failure] if n >= self.cap(failure) else failure

    def saturated_status(self, trial: Trial, log: Sequence[Attempt]) -> TrialStatus:
        """Status to log for a saturated attempt: ``saturated`` or, at the cap, the exclusion."""
        if self.protocol.saturation.action == "keep":
            return TrialStatus.VALID
        return self.failure_status(TrialStatus.SATURATED, trial, log)

    def outcomes(self, log: Sequence[Attempt]) -> dict[str, TrialStatus]:
        """Final status of every finished item (``valid``, ``skipped`` or an exclusion)."""
        return dict(self._replay(log).finished)

    def remaining(self, log: Sequence[Attempt]) -> list[Item]:
        """Items still to do, in order."""
        return list(self._replay(log).queue)


def seed_from_entropy() -> int:
    """A fresh session seed (recorded in the session; 63 bits so JSON and TSV keep it exact)."""
    return int(np.random.SeedSequence().entropy % (2**63))

