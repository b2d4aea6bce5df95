"""The session engine: deterministic, resumable, always finishing."""

from collections import Counter
from itertools import pairwise

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from protocols import (
    DONE,
    PAUSED,
    Attempt,
    LogMismatch,
    ProtocolError,
    ResumeMismatch,
    SessionEngine,
    load_protocol,
    parse_protocol,
    protocol_text,
    williams_square,
)
from protocols.engine import _can_spread

FACTORIAL = load_protocol("factorial")
IDENT = load_protocol("identification")


def run(engine, policy=lambda t: "valid", limit=10_000):
    """Drive an engine to the end; ``policy(trial)`` gives each attempt's status."""
    log = []
    seq = []
    for _ in range(limit):
        t = engine.next_trial(log)
        if t is DONE:
            return log, seq
        status = policy(t)
        if status == "saturated":
            status = engine.saturated_status(t, log)
        seq.append(t)
        log.append(Attempt(t.item, status))
    raise AssertionError("session did not end")


def test_uninterrupted_run_is_the_plan():
    e = SessionEngine(FACTORIAL, 7, "P01")
    log, seq = run(e)
    assert [t.item for t in seq] == [i.key for i in e.plan()]
    assert [t.trial_index for t in seq] == list(range(1, 25))


def test_materials_in_blocks_and_sets_random_within():
    e = SessionEngine(FACTORIAL, 3, "P01")
    blocks = [i.block for i in e.plan()]
    runs = [blocks[i] for i in range(len(blocks)) if i == 0 or blocks[i] != blocks[i - 1]]
    assert sorted(runs) == ["aluminum", "rubber", "wood"]  # each material one contiguous block
    orders = {tuple(i.key for i in SessionEngine(FACTORIAL, s, "P01").plan()) for s in range(20)}
    assert len(orders) == 20


def test_same_seed_same_plan_different_seed_different():
    a = [i.key for i in SessionEngine(IDENT, 1, "P01").plan()]
    assert a == [i.key for i in SessionEngine(IDENT, 1, "P01").plan()]
    plans = {tuple(i.samples for i in SessionEngine(IDENT, s, "P01").plan()) for s in range(30)}
    assert len(plans) > 20


def test_identification_items_show_all_three_surfaces():
    for item in SessionEngine(IDENT, 5, "P01").plan():
        assert sorted(item.samples) == ["aluminum", "rubber", "wood"]


def test_saturation_redraws_then_excludes_at_the_cap():
    e = SessionEngine(FACTORIAL, 11, "P01")
    target = e.plan()[3].key
    log, seq = run(e, lambda t: "saturated" if t.item == target else "valid")
    tries = [a.status for a in log if a.item == target]
    assert tries == ["saturated", "saturated", "excluded_saturated"]
    assert e.outcomes(log)[target] == "excluded_saturated"
    assert sum(1 for s in e.outcomes(log).values() if s == "valid") == 23


def test_a_device_that_always_saturates_still_ends():
    e = SessionEngine(FACTORIAL, 2, "P01")
    log, seq = run(e, lambda t: "saturated")
    assert len(log) == 24 * 3
    assert set(e.outcomes(log).values()) == {"excluded_saturated"}


def test_redraws_stay_within_their_material_block():
    e = SessionEngine(FACTORIAL, 4, "P01")
    log, seq = run(e, lambda t: "saturated" if t.attempt == 1 else "valid")
    blocks = [t.block for t in seq]
    runs = [blocks[i] for i in range(len(blocks)) if i == 0 or blocks[i] != blocks[i - 1]]
    assert len(runs) == 3


def test_aborted_device_retries_the_same_item():
    e = SessionEngine(IDENT, 1, "P01")
    t1 = e.next_trial([])
    log = [Attempt(t1.item, "aborted_device")]
    t2 = e.next_trial(log)
    assert t2.item == t1.item and t2.attempt == 2 and t2.trial_index == 2


def test_operator_skip_requeue_and_pause():
    e = SessionEngine(FACTORIAL, 9, "P01")
    t = e.next_trial([])
    log = [Attempt(t.item, "skipped", "participant sneezed")]
    assert e.outcomes(log) == {t.item: "skipped"}
    t2 = e.next_trial(log)
    log.append(Attempt(t2.item, "requeued", "stylus slipped"))
    assert t2.item in [i.key for i in e.remaining(log)]
    log.append(Attempt("", "paused"))
    assert e.next_trial(log) is PAUSED
    log.append(Attempt("", "resumed"))
    assert e.next_trial(log) is not PAUSED


def test_placeholders_alternate_so_every_virtual_trial_is_a_swap():
    text = protocol_text("identification")[1]
    mini = parse_protocol("""
[protocol]
name = "p"
[rating]
min = 1
max = 7
question = "q"
[operator]
placeholders = ["block A", "block B"]
[[samples]]
id = "wood"
scene.material = { stiffness = 70000.0 }
[[samples]]
id = "v1"
scene.spring = 680.0
[[samples]]
id = "v2"
scene.spring = 340.0
[[phases]]
name = "t"
samples = "all"
repetitions = 4
""", "p.toml")
    assert text  # the identification protocol has no placeholders: its trials place nothing
    log, seq = run(SessionEngine(mini, 3, "P01"))
    placed = [t.placement for t in seq]
    virtual_pairs = [(a, b) for (ta, a), (tb, b) in pairwise(zip(seq, placed, strict=True))
                     if tb.sample != "wood"]
    assert virtual_pairs and all(a != b for a, b in virtual_pairs)
    assert {p for t, p in zip(seq, placed, strict=True) if t.sample == "wood"} == {"wood"}
    assert {p for t, p in zip(seq, placed, strict=True) if t.sample != "wood"} <= {"block A",
                                                                                  "block B"}


def test_log_from_another_seed_is_refused():
    e1, e2 = SessionEngine(FACTORIAL, 1, "P01"), SessionEngine(FACTORIAL, 2, "P01")
    log, _ = run(e1)
    with pytest.raises(LogMismatch, match="log entry 1"):
        e2.next_trial(log)


def test_saturation_at_the_cap_must_be_logged_as_exclusion():
    e = SessionEngine(IDENT, 1, "P01")
    target = e.next_trial([]).item
    log, count = [], 0
    while count < 3:
        t = e.next_trial(log)
        if t.item == target:
            count += 1
            log.append(Attempt(t.item, "saturated"))  # the third should be the exclusion
        else:
            log.append(Attempt(t.item, "valid"))
    with pytest.raises(LogMismatch, match="cap of 3"):
        e.next_trial(log)


def test_resume_identity():
    e = SessionEngine(FACTORIAL, 5, "P01")
    e.check_resume(e.identity)
    for key, value in (("seed", 6), ("participant", "P02"), ("protocol_sha256", "0" * 64)):
        with pytest.raises(ResumeMismatch, match=key):
            e.check_resume({**e.identity, key: value})


def test_bad_status_and_seed():
    with pytest.raises(ValueError, match="attempt status"):
        Attempt("x", "great")
    with pytest.raises(ValueError, match="seed"):
        SessionEngine(IDENT, -1, "P01")


@pytest.mark.parametrize("n", range(1, 9))
def test_williams_square_is_balanced(n):
    rows = williams_square(n)
    assert len(rows) == (n if n % 2 == 0 else 2 * n)
    for r in rows:
        assert sorted(r) == list(range(n))
    for col in zip(*rows, strict=True):  # each condition equally often in each position
        assert len(set(Counter(col).values())) == 1
    pairs = Counter(p for r in rows for p in pairwise(r))
    if n > 1:
        assert len(pairs) == n * (n - 1) and len(set(pairs.values())) == 1


def test_williams_rows_counterbalance_factorial_blocks():
    text = protocol_text("factorial")[1].replace('block_order = "random"',
                                                 'block_order = "williams"')
    p = parse_protocol(text, "f.toml")
    orders = []
    for row in range(6):
        blocks = [i.block for i in SessionEngine(p, 1, f"P{row}", counterbalance_row=row).plan()]
        orders.append(tuple(dict.fromkeys(blocks)))
    assert len(set(orders)) == 6  # all 3! orders, each once


STATUS = st.sampled_from(["valid", "saturated", "requeued", "timed_out", "aborted_device",
                          "skipped"])
CAPPED = ("saturated", "timed_out", "aborted_device")


class SessionMachine(RuleBasedStateMachine):
    """Complete / saturate / requeue / abort / skip / crash-and-resume in any interleaving."""

    def __init__(self):
        super().__init__()
        self.protocol = FACTORIAL
        self.engine = SessionEngine(self.protocol, 1234, "P01")
        self.log: list[Attempt] = []
        self.steps = 0

    @precondition(lambda self: self.engine.next_trial(self.log) is not DONE)
    @rule(status=STATUS)
    def attempt(self, status):
        t = self.engine.next_trial(self.log)
        if status in CAPPED:
            status = self.engine.failure_status(status, t, self.log)
        if status == "requeued" and self.steps > 200:
            status = "valid"  # operators do not re-queue forever
        self.log.append(Attempt(t.item, status))
        self.steps += 1

    @rule(cut=st.integers(0, 10_000))
    def crash_and_resume(self, cut):
        """A new engine from the recorded identity continues exactly where the log stops."""
        before = self.engine.next_trial(self.log)
        fresh = SessionEngine(self.protocol, 1234, "P01")
        fresh.check_resume(self.engine.identity)
        assert fresh.next_trial(self.log) == before
        # any prefix replays to the same remaining order as the uninterrupted replay did
        k = cut % (len(self.log) + 1)
        assert fresh.remaining(self.log[:k]) == self.engine.remaining(self.log[:k])
        self.engine = fresh

    @invariant()
    def nothing_lost_or_duplicated(self):
        keys = {i.key for i in self.engine.plan()}
        done = self.engine.outcomes(self.log)
        left = [i.key for i in self.engine.remaining(self.log)]
        assert len(left) == len(set(left))
        assert set(done).isdisjoint(left)
        assert set(done) | set(left) == keys


TestSessionMachine = SessionMachine.TestCase
TestSessionMachine.settings = settings(max_examples=40, stateful_step_count=60, deadline=None)
TestSessionMachine.pytestmark = [pytest.mark.slow]  # 40 runs of up to 60 steps: seconds


@given(seed=st.integers(0, 2**32), statuses=st.lists(STATUS, min_size=0, max_size=150))
def test_any_log_prefix_resumes_to_the_uninterrupted_order(seed, statuses):
    e = SessionEngine(IDENT, seed, "P01")
    log = []
    for s in statuses:
        t = e.next_trial(log)
        if t is DONE:
            break
        if s in CAPPED:
            s = e.failure_status(s, t, log)
        log.append(Attempt(t.item, s))
    full = e.remaining(log)
    for k in range(len(log) + 1):
        # replaying the first k entries and then the rest gives the same final state
        assert SessionEngine(IDENT, seed, "P01").remaining(log[:k]) == e.remaining(log[:k])
    assert SessionEngine(IDENT, seed, "P01").remaining(log) == full


@pytest.mark.parametrize("kind, final", [("saturated", "excluded_saturated"),
                                         ("timed_out", "excluded_timeout"),
                                         ("aborted_device", "excluded_device")])
def test_a_session_ends_even_when_every_attempt_fails(kind, final):
    """Every loop is bounded: a surface nobody can reach (always timed out), a device that
    fails on every window, or one that always saturates still reaches the end."""
    e = SessionEngine(IDENT, 3, "P01")
    log = []
    for _ in range(1000):
        t = e.next_trial(log)
        if t is DONE:
            break
        log.append(Attempt(t.item, e.failure_status(kind, t, log)))
    assert t is DONE
    outcomes = e.outcomes(log)
    assert set(outcomes.values()) == {final} and len(outcomes) == len(e.plan())
    assert len(log) == 3 * len(e.plan())  # the default cap of each [attempts]/[saturation]


def test_no_saturation_cap_is_the_papers_redraw_with_a_safety_stop():
    from protocols.engine import SATURATION_SAFETY_CAP

    text = protocol_text("identification")[1].replace("max_attempts = 3",
                                                      'max_attempts = "none"')
    e = SessionEngine(parse_protocol(text, "i.toml"), 3, "P01")
    assert e.protocol.saturation.max_attempts is None
    log = []
    target = e.next_trial(log).item
    statuses = []
    while (t := e.next_trial(log)) is not DONE:
        if t.item != target:
            log.append(Attempt(t.item, "valid"))
            continue
        statuses.append(e.saturated_status(t, log))
        log.append(Attempt(t.item, statuses[-1]))
    assert statuses == ["saturated"] * (SATURATION_SAFETY_CAP - 1) + ["excluded_saturated"]
    with pytest.raises(ProtocolError, match=r"max_attempts: must be an integer >= 1 or \"none\""):
        parse_protocol(text.replace('"none"', '"never"'), "i.toml")


# ---------------------------------------------------------------- no sample twice in a row
REALISM = load_protocol("realism")


def _repeats(items):
    return [(a.key, b.key) for a, b in pairwise(items) if a.samples == b.samples]


@settings(max_examples=200, deadline=None)
@given(counts=st.lists(st.integers(1, 5), min_size=1, max_size=6),
       prev=st.one_of(st.none(), st.integers(0, 6)), seed=st.integers(0, 2**32))
def test_no_repeat_order_is_a_permutation_without_neighbours_alike(counts, prev, seed):
    """Any counts per sample: an order with no sample twice in a row exists exactly when
    no sample fills more than every other place (checked by brute force on small cases in
    the test below); then the draw finds one, first not ``prev`` where that can be met."""
    import numpy as np

    from protocols.engine import Item, _can_spread, no_repeat_order

    items = [Item(f"p/s{k}#{r}", "p", "rated", (f"s{k}",), None, r)
             for k, c in enumerate(counts) for r in range(1, c + 1)]
    before = None if prev is None else f"s{prev}"
    n, top = sum(counts), max(counts)
    if top > (n + 1) // 2:
        with pytest.raises(ValueError, match="no order without repeats"):
            no_repeat_order(items, np.random.default_rng(seed), before)
        return
    out = no_repeat_order(items, np.random.default_rng(seed), before)
    assert sorted(i.key for i in out) == sorted(i.key for i in items)
    assert _repeats(out) == []
    if _can_spread(dict(Counter(i.samples[0] for i in items)), before):
        assert out[0].samples[0] != before
    for s in {i.samples[0] for i in out}:  # a sample's repetitions in their order
        reps = [i.repetition for i in out if i.samples[0] == s]
        assert reps == sorted(reps)


def test_the_spread_condition_matches_brute_force():
    """_can_spread against every ordering of every multiset of up to 7 items over three
    samples, with each possible sample before it (an independent enumeration)."""
    from itertools import permutations, product

    from protocols.engine import _can_spread

    for counts in product(range(4), repeat=3):
        c = {k: v for k, v in zip("abc", counts, strict=True) if v}
        items = [k for k, v in c.items() for _ in range(v)]
        for prev in (None, "a", "b", "c"):
            exists = any(all(x != y for x, y in pairwise(p)) and (not p or p[0] != prev)
                         for p in set(permutations(items)))
            assert exists == _can_spread(c, prev), (c, prev)


@pytest.mark.parametrize("seed", range(40))
def test_realism_never_shows_the_same_sample_twice_in_a_row(seed):
    """The bundled realism protocol (no_repeat in demonstration and testing): the whole
    plan, across familiarization → demonstration → testing, has no sample twice in a row
    (the test day found `protocol show` listing the same sample twice in a row)."""
    plan = SessionEngine(REALISM, seed, "P01").plan()
    assert _repeats(plan) == []
    assert Counter(i.samples[0] for i in plan if i.phase == "testing") == \
        dict.fromkeys(REALISM.phases[2].samples, 3)


@pytest.mark.slow  # 400 examples of up to 120 attempts
@settings(max_examples=400, deadline=None)  # ~1 s in all
@given(seed=st.integers(0, 2**32),
       statuses=st.lists(st.sampled_from(["valid", "valid", "saturated", "requeued",
                                          "timed_out"]), min_size=1, max_size=120))
def test_a_redrawn_trial_does_not_come_straight_back(seed, statuses):
    """Saturated, re-queued and timed-out trials go back between two other samples: the
    participant meets the same sample twice in a row only when no order of the trials left
    in its block avoids it (say wood and two of matched_soft left, matched_soft just
    tried: matched_soft, wood, matched_soft is the only order)."""
    e = SessionEngine(REALISM, seed, "P01")
    log: list[Attempt] = []
    last = None
    for s in statuses:
        t = e.next_trial(log)
        if t is DONE:
            break
        if last is not None and t.samples == last.samples:
            left = Counter(i.samples[0] for i in e.remaining(log)
                           if i.phase == t.phase and i.block == t.block)
            assert not _can_spread(left, last.samples[0]), (last.item, t.item, left)
        if s in CAPPED:
            s = e.failure_status(s, t, log)
        log.append(Attempt(t.item, s))
        last = t


def test_a_protocol_without_no_repeat_keeps_its_recorded_order():
    """Sessions recorded before no_repeat keep their protocol copy: without the key the
    draw is the old one. The plan below is the one the engine gave before this change
    (realism without no_repeat, whose text is the earlier realism.toml, seed 7), and it
    does show soft_spring twice in a row."""
    src, text = protocol_text("realism")
    old = parse_protocol("\n".join(line for line in text.splitlines()
                                   if not line.startswith("no_repeat")), src)
    plan = [i.key for i in SessionEngine(old, 7, "P01").plan()]
    assert plan[12:20] == ["testing/soft_spring#1", "testing/soft_spring#3",
                           "testing/pulse_firm#1", "testing/wood_on_foam#1", "testing/wood#3",
                           "testing/matched_soft#3", "testing/pulse_soft#1", "testing/foam#3"]


@pytest.mark.parametrize("edit, message", [
    (("order = \"random\"\nno_repeat", "order = \"fixed\"\nno_repeat"), "needs order = \"random\""),
    (("repetitions = 3\norder = \"random\"\nno_repeat = true",
      "repetitions = 3\norder = \"random\"\nno_repeat = \"yes\""), "must be true or false"),
])
def test_no_repeat_is_checked_where_it_is_written(edit, message):
    src, text = protocol_text("realism")
    assert edit[0] in text
    with pytest.raises(ProtocolError, match=message) as err:
        parse_protocol(text.replace(edit[0], edit[1], 1), src)
    assert "phases[" in str(err.value) and "no_repeat" in str(err.value)


def test_no_repeat_refuses_a_sample_with_nothing_to_put_between():
    src, text = protocol_text("realism")
    one = text.replace("name = \"testing\"\nsamples = \"all\"",
                       "name = \"testing\"\nsamples = [\"wood\"]", 1)
    with pytest.raises(ProtocolError, match="one sample \\('wood'\\) repeated 3 times"):
        parse_protocol(one, src)
    src, text = protocol_text("identification")
    phase = "kind = \"identification\"\n"
    assert phase in text
    with pytest.raises(ProtocolError, match="applies to phases of one sample a trial"):
        parse_protocol(text.replace(phase, phase + "no_repeat = true\n", 1), src)
