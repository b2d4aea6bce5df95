"""Test day, round three: recordings that keep their data, a participant who chooses which
real block to tap again, and what a session says about the device it ran on."""

import io
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from app.console import PlainConsole
from app.errors import SessionFileError
from app.participants import ScriptedResponder
from app.recorder import SessionFiles, new_session_dir, read_trials
from app.runner import SessionRunner
from device import Scene, open_device
from protocols import (
    Attempt,
    SessionEngine,
    load_protocol,
    parse_protocol,
    protocol_text,
    reference_item,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "protocols"


def _identification(duration: float = 1.0, repetitions: int = 2):
    source, text = protocol_text("identification")
    text = (text.replace("duration = 20.0", f"duration = {duration}")
            .replace("repetitions = 3", f"repetitions = {repetitions}"))
    return parse_protocol(text, source)


def _session(tmp: Path, p, ui, seed: int, console=None) -> tuple[Path, list[dict]]:
    """One session on the simulated device (its current limited as the protocol says) with
    full traces: (folder, rows)."""
    folder, n = new_session_dir(tmp, "P01")
    files = SessionFiles(folder)
    files.start("")
    dev = open_device("sim", seed=seed)
    if p.limits.max_current is not None:
        dev.set_current_limit(p.limits.max_current)
    runner = SessionRunner(protocol=p, engine=SessionEngine(p, seed, "P01"), device=dev,
                           files=files, responder=ui, participant="P01", session=n,
                           seed=seed, traces="full",
                           **({"console": console} if console else {}))
    assert runner.run() == "complete"
    rows, _ = read_trials(folder / "trials.tsv")
    return folder, rows


class AsksForTheThirdBlock(ScriptedResponder):
    """Asks for a real block once before every scene and picks the third one offered."""

    def __init__(self):
        self.offered: list[list[tuple[str, str]]] = []
        self._asked_for: set[str] = set()
        self._trial = None

    def waiting(self, trial):
        self._trial = trial

    def poll(self):
        t = self._trial
        if t is not None and t.kind == "identification" and t.item not in self._asked_for:
            self._asked_for.add(t.item)  # once per scene (a redrawn scene keeps its item)
            return "reference"
        return None

    def choose_reference(self, trial, blocks):
        self.offered.append(list(blocks))
        return blocks[2][0]


@pytest.fixture(scope="module")
def identification_session(tmp_path_factory):
    ui = AsksForTheThirdBlock()
    folder, rows = _session(tmp_path_factory.mktemp("ident"), _identification(), ui, 5)
    return folder, rows, ui


def test_every_reference_tap_has_its_own_trace(identification_session):
    """references = "start" taps all three real blocks before trial 1: each row names its
    own file (they all were traces/reference-0001-0.npz, only the last one kept), and each
    file holds that block's taps."""
    folder, rows, _ = identification_session
    refs = [r for r in rows if r["status"] == "reference"]
    assert len(refs) == 3 + 2  # three at the start, one asked for before each scene
    files = [r["trace_file"] for r in refs]
    assert len(set(files)) == len(files), files
    for r in refs:
        with np.load(folder / r["trace_file"]) as z:
            assert len(z["contacts_v"]) == int(r["n_taps"]) > 0
            speeds = ";".join(f"{v:.5f}" for v in z["contacts_v"])
            assert speeds == r["tap_velocities"]  # the file is this row's recording
    named = {r["trace_file"] for r in rows if r["trace_file"] and "*" not in r["trace_file"]}
    on_disk = {f"traces/{f.name}" for f in (folder / "traces").glob("*.npz")}
    assert named <= on_disk


def test_the_participant_chooses_which_real_block_and_it_is_recorded(identification_session):
    """R in identification offers every real block in the protocol's order — never surface
    1's block, which would be that scene's answer — and the row records the one chosen."""
    _, rows, ui = identification_session
    protocol_order = [("rubber-real", "real rubber block"), ("wood-real", "real wood block"),
                      ("aluminum-real", "real aluminum block")]
    assert ui.offered and all(o == protocol_order for o in ui.offered)
    asked = [r for r in rows if r["status"] == "reference" and r["reason"]]
    assert [r["reason"] for r in asked] == ["participant asked"] * 2
    assert [r["sample"] for r in asked] == ["aluminum-real"] * 2


class MovesOn(ScriptedResponder):
    """Taps surface 1 briefly and goes to surface 2 mid-window, taps surface 2 its whole
    window, then surface 3 briefly and goes to naming mid-window."""

    def __init__(self):
        self.asked = 0  # moving_on() calls in the window so far
        self.plan: list[int | None] = []

    def choose_surface(self, trial, visited):
        if not visited:
            self.plan = [0, 1, 2, None]
        self.asked = 0
        return self.plan.pop(0)

    def moving_on(self):
        self.asked += 1
        return self.plan[0] != 2 and self.asked >= 3  # not during surface 2's window


def test_identification_goes_to_another_surface_mid_window(tmp_path):
    """Issue 30 (9): a participant who moves on ends the surface's window at once (on the
    device: STOP_WINDOW, checked on every target by ``device selftest``'s end_window)."""
    folder, rows = _session(tmp_path, _identification(duration=3.0, repetitions=1), MovesOn(), 7)
    scenes = [r for r in rows if r["phase"] == "identification" and r["status"] != "reference"]
    assert [r["status"] for r in scenes] == ["valid"]
    for r in scenes:
        spans = []
        for k in range(3):
            with np.load(folder / "traces" / f"trial-{int(r['trial_index']):04d}-{k}.npz") as z:
                spans.append(len(z["position_counts"]) / float(z["rate_hz"]))
        # surfaces 1 and 3 ended after three progress calls (a fraction of a second of
        # device time); surface 2 ran its 3 s from its first contact
        assert spans[0] < 1.0 and spans[2] < 1.0 and spans[1] >= 3.0, spans


class GoesBack(ScriptedResponder):
    """Taps surface 1, 2, 1 again, then 3, and names them."""

    def __init__(self):
        self.plan: list[int | None] = []
        self.named_from = None

    def choose_surface(self, trial, visited):
        if not visited:
            self.plan = [0, 1, 0, 2, None]
        return self.plan.pop(0)

    def answer(self, response, question, rng):
        self.named_from = list(question.results)
        return super().answer(response, question, rng)


def test_a_surface_tapped_again_keeps_both_windows(tmp_path):
    """A surface the participant goes back to once replaced its first window: those taps
    and that trace were lost, and a saturation in them went unseen. Every window is kept,
    in the order tapped, each trace naming the sample it played; the naming is of each
    surface's last window."""
    ui = GoesBack()
    folder, rows = _session(tmp_path, _identification(duration=1.0, repetitions=1), ui, 3)
    (row,) = [r for r in rows if r["phase"] == "identification" and r["status"] != "reference"]
    surfaces = row["sample"].split("+")
    assert len(surfaces) == 3
    stem = folder / "traces" / f"trial-{int(row['trial_index']):04d}"
    played, speeds = [], []
    for k in range(4):
        with np.load(f"{stem}-{k}.npz") as z:
            played.append(str(z["sample"]))
            speeds += [f"{v:.5f}" for v in z["contacts_v"]]
    assert not Path(f"{stem}-4.npz").exists()
    assert played == [surfaces[0], surfaces[1], surfaces[0], surfaces[2]]
    assert row["trace_file"] == f"traces/trial-{int(row['trial_index']):04d}-*.npz"
    assert ";".join(speeds) == row["tap_velocities"] and len(speeds) == int(row["n_taps"])
    assert len(ui.named_from) == 3 and len(ui.named_from[0].contacts) > 0


def _items_in(protocol) -> int:
    """Items in the plan of a protocol of rated phases (samples × repetitions)."""
    return sum(len(ph.samples) * ph.repetitions for ph in protocol.phases)


class SeesTheNotice(ScriptedResponder):
    """Records what the 'please wait' screen is told after each saturated attempt."""

    def __init__(self):
        self.notices: list[tuple[str, bool]] = []

    def saturated(self, trial, comes_back=True):
        self.notices.append((trial.item, comes_back))


def test_the_participant_is_told_of_every_saturation_and_whether_it_comes_back(tmp_path):
    """Issue 30 (8): without sound the participant saw nothing when a tap saturated; the
    screen says so on the next 'please wait', and at the protocol's cap (here the second
    saturation of an item) it no longer says 'this sample comes back later', since the
    item is left out. One notice per saturated row, in order, each matching its status."""
    ui, con = SeesTheNotice(), SeenByTheOperator()
    hard = load_protocol(str(DATA.parent / "two_springs_low_current.toml"))  # not a variant
    folder, rows = _session(tmp_path, hard, ui, 2, con)
    sat = [(r["item"], r["status"] == "saturated") for r in rows
           if r["status"] in ("saturated", "excluded_saturated")]
    assert ui.notices == sat
    assert any(back for _, back in sat) and any(not back for _, back in sat), sat
    # item 7's counter, from the runner: attempts outnumber items, the count of items done
    # never reaches past them ('item done+1 of n' in the live view)
    assert max(t for *_, t in con.counts) > _items_in(hard)
    assert all(done < total == _items_in(hard) for done, total, _ in con.counts), con.counts
    from protocols.texts import DEFAULT_TEXTS

    assert "comes back" in DEFAULT_TEXTS["saturated"]
    assert "comes back" not in DEFAULT_TEXTS["saturated_last"]


class SeenByTheOperator(PlainConsole):
    """The operator's panel at every placing: (PLACE, its detail, the block line)."""

    def __init__(self):
        super().__init__(stream=io.StringIO())
        self.panels: list[tuple[str, str, str]] = []
        self.counts: list[tuple[int, int, int]] = []  # (items done, items, trial #)

    def place(self, trial, total, done, what="", detail=""):
        super().place(trial, total, done, what, detail)
        self.panels.append((what, detail, self.view.block))
        self.counts.append((done, total, trial.trial_index))


def test_the_operator_panel_says_what_to_remove_and_never_cues_the_scene():
    """Issue 30 (7): in identification the panel said 'PLACE real rubber block', then
    'block — its real block: real aluminum block' (surface 1's block, the scene's answer),
    and 'PLACE nothing' where the real block had to come off. A scene now says to remove the
    block tapped just before it (and 'nothing' after a scene), and names no block."""
    import tempfile

    con = SeenByTheOperator()
    with tempfile.TemporaryDirectory() as tmp:
        _session(Path(tmp), _identification(repetitions=2), AsksForTheThirdBlock(), 5, con)
    is_ref = [p[1].startswith("real reference block") for p in con.panels]
    assert sum(is_ref) == 5  # three at the start, one asked for before each scene
    for k, (what, detail, block) in enumerate(con.panels):
        if is_ref[k]:
            assert block == f"real reference block: {what}"
            continue
        # after a real block: take it off; after a scene: nothing is on the device
        assert what == ("nothing: remove the real aluminum block (the scene's surfaces are "
                        "virtual)" if is_ref[k - 1] else "nothing (the scene's surfaces are "
                        "virtual)"), (k, what)
        assert block == "" and "real" not in detail  # names the surfaces, never a block


def test_the_recorder_never_overwrites_a_recording(tmp_path):
    folder, _ = new_session_dir(tmp_path, "P01")
    files = SessionFiles(folder)
    files.save_trace("trial-0001-0.npz", {"x": np.arange(3)}, [])
    before = (folder / "traces" / "trial-0001-0.npz").read_bytes()
    with pytest.raises(SessionFileError, match="exists; a recording never overwrites"):
        files.save_trace("trial-0001-0.npz", {"x": np.arange(5)}, [])
    assert (folder / "traces" / "trial-0001-0.npz").read_bytes() == before
    assert [f.name for f in (folder / "traces").iterdir()] == ["trial-0001-0.npz"]


def test_a_trace_no_row_names_is_set_aside_before_a_resume(identification_session, tmp_path):
    """The process stopped after the trace, before its row: the attempt runs again and
    writes its own trace, so the old one moves to traces/unrecorded/ (never deleted)."""
    import shutil

    src, rows, _ = identification_session
    folder = tmp_path / "copy"
    shutil.copytree(src, folder)
    stray = folder / "traces" / "trial-0099-0.npz"
    stray.write_bytes(b"stray")
    done = SessionFiles(folder).repair()
    assert any("traces/unrecorded/trial-0099-0.npz" in d for d in done), done
    assert (folder / "traces" / "unrecorded" / "trial-0099-0.npz").read_bytes() == b"stray"
    assert not stray.exists()
    for r in rows:  # every recorded trace is where its row says
        if r["trace_file"] and "*" not in r["trace_file"]:
            assert (folder / r["trace_file"]).exists()


def test_an_estop_while_a_real_block_is_tapped_does_not_break_the_log():
    """An e-stop row of a reference tap (item <phase>/ref:<block>) is not an item of the
    plan: the engine skips it (it raised LogMismatch, so the session could not go on)."""
    p = _identification()
    eng = SessionEngine(p, 5, "P01")
    first = eng.next_trial([])
    log = [Attempt(reference_item(first.phase, "wood-real"), "estop", "estop: operator"),
           Attempt(reference_item(first.phase, "wood-real"), "reference", "")]
    again = eng.next_trial(log)
    assert again.item == first.item and again.trial_index == first.trial_index


SIX = DATA / "six_on_nine.toml"


def _run_with(tmp_path, pid, device_spec, **kw):
    from app.api import run_session

    args = dict(device=device_spec, data=tmp_path / "data", responder="scripted", seed=3,
                traces="none", audio=False, quiet=True)
    return run_session(SIX, pid, **{**args, **kw})


def test_ids_that_look_like_numbers_survive_every_export_as_text(tmp_path):
    """001 and 1e5 are kept as typed by pandas told the codebook's types (load.py, written
    beside every CSV export: quotes alone do not keep them), by R through load.R, and in
    the SPSS file; nan and NA are refused at entry."""
    import subprocess

    import pandas as pd

    from app.api import export
    from app.ids import ParticipantIdError, validate_participant

    for bad in ("nan", "NA", "null", "TRUE"):
        with pytest.raises(ParticipantIdError, match="missing value or a truth value"):
            validate_participant(bad)
    for pid in ("001", "1e5"):
        assert _run_with(tmp_path, pid, "sim").status == "complete"
    out = tmp_path / "r"
    export(tmp_path / "data", out, "r", kind="dry-run")
    book = pd.read_csv(out / "codebook.csv", keep_default_na=False)
    types = dict(zip(book["column"], book["type"], strict=True))
    assert types["participant"] == "text" and types["rating"] == "number"
    text_cols = [c for c, t in types.items() if t == "text"]
    long = pd.read_csv(out / "long.csv", dtype={c: str for c in text_cols},
                       keep_default_na=False)
    assert set(long["participant"]) == {"001", "1e5"}
    assert (out / "long.csv").read_text().count('"001"') > 0  # quoted on disk
    # quotes alone do not keep them: pandas reads the column as numbers
    assert set(pd.read_csv(out / "long.csv")["participant"]) == {1.0, 1e5}
    # load.py, beside every CSV export, reads each file with the codebook's types
    for fmt in ("r", "wide-csv", "jasp"):
        folder = tmp_path / f"py-{fmt}"
        export(tmp_path / "data", folder, fmt, kind="dry-run")
        read = ("import json, runpy; t = runpy.run_path('load.py')['tables']; "
                "print(json.dumps({n: sorted(set(d['participant'])) for n, d in t.items()}))")
        got = subprocess.run([sys.executable, "-c", read], cwd=folder, capture_output=True,
                             text=True, timeout=120)
        assert got.returncode == 0, got.stderr
        tables = json.loads(got.stdout)
        assert tables and all(ids == ["001", "1e5"] for ids in tables.values()), (fmt, tables)
    r = subprocess.run(["Rscript", "-e", 'source("load.R"); cat(levels(d$participant), '
                        'sep = ",")'], cwd=out, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "001,1e5"  # R's read.csv alone gives 1 and 1e+05
    sav = tmp_path / "sav"
    export(tmp_path / "data", sav, "spss", kind="dry-run")
    import pyreadstat

    df, _meta = pyreadstat.read_sav(str(sav / "long.sav"))
    assert set(df["participant"]) == {"001", "1e5"}


def test_the_device_is_on_the_record_and_a_person_on_sim_is_not_pooled(tmp_path):
    """The report and every export carry the device backend, id and firmware; a person's
    session on the simulated device is left out of a human analysis unless asked."""
    import pandas as pd

    from analysis import load_sessions, select_sessions
    from app.api import export

    for pid in ("S01", "P01"):
        assert _run_with(tmp_path, pid, "sim").status == "complete"
    meta_path = tmp_path / "data" / "sub-P01" / "ses-1" / "session.json"
    meta = json.loads(meta_path.read_text())
    # P01 stands for a person on a serial device, S01 for a person on the simulator
    meta.update(kind="human", responder="person")
    meta["device"].update(backend="serial", model="hapticlab stylus", serial_number="0042",
                          firmware="hl-2.1")
    meta_path.write_text(json.dumps(meta))
    s_path = tmp_path / "data" / "sub-S01" / "ses-1" / "session.json"
    s_meta = json.loads(s_path.read_text())
    s_meta.update(kind="human", responder="person")
    s_path.write_text(json.dumps(s_meta))
    data = load_sessions(tmp_path / "data")
    _, table = select_sessions(data, kind="human")
    by = table.set_index("participant")
    assert bool(by.loc["P01", "included"]) and not bool(by.loc["S01", "included"])
    assert "simulated device" in by.loc["S01", "reason"]
    assert by.loc["P01", "device_id"] == "hapticlab stylus #0042"
    assert by.loc["P01", "firmware"] == "hl-2.1" and by.loc["S01", "device_backend"] == "sim"
    _, both = select_sessions(data, kind="human", sim_device=True)
    assert both["included"].all()
    out = tmp_path / "x"
    export(tmp_path / "data", out, "long-csv", kind="human", sim_device=True)
    long = pd.read_csv(out / "long.csv", keep_default_na=False)
    devs = long.groupby("participant")["device_backend"].first().to_dict()
    assert devs == {"P01": "serial", "S01": "sim"}
    wide = tmp_path / "w"
    export(tmp_path / "data", wide, "wide-csv", kind="human", sim_device=True)
    w = pd.read_csv(next(wide.glob("wide_*.csv")), keep_default_na=False)
    assert dict(zip(w["participant"], w["device_backend"], strict=True)) == devs
    # the analyst's command: S01 is listed with its reason and its device, and left out
    # unless --sim-device asks for it
    import subprocess

    for extra, included in (([], {"P01"}), (["--sim-device"], {"P01", "S01"})):
        rep = tmp_path / f"rep{len(extra)}"
        out = subprocess.run([sys.executable, "-m", "app", "analyze", str(tmp_path / "data"),
                              "--out", str(rep), "--kind", "human", *extra],
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        sessions = json.loads((rep / "report.json").read_text())["selection"]["sessions"]
        got = {x["participant"]: x for x in sessions}
        assert {p for p, x in got.items() if x["included"]} == included
        assert got["P01"]["device_id"] == "hapticlab stylus #0042"
        assert got["P01"]["firmware"] == "hl-2.1" and got["S01"]["device_backend"] == "sim"
        md = (rep / "report.md").read_text()
        table = md[md.index("## Sessions included and excluded"):]
        assert "| device_backend | device_id | firmware |" in table
        assert "hapticlab stylus #0042" in table and "| sim |" in table
        assert "hapticlab stylus #0042" in (rep / "report.html").read_text()
        if not extra:
            assert "simulated device" in got["S01"]["reason"]


def test_a_persons_second_session_of_a_protocol_needs_new_session(tmp_path, monkeypatch):
    """P01's next session of the same protocol is not created silently: the error lists what
    exists and how to go on; a dry run says so and runs."""
    from app.errors import UsageError

    assert _run_with(tmp_path, "P01", "sim").status == "complete"
    said = []
    assert _run_with(tmp_path, "P01", "sim", seed=4, say=said.append).status == "complete"
    assert any("already has six_on_nine session(s): ses-1 (complete, dry-run" in s
               for s in said)
    with pytest.raises(UsageError, match=r"already has six_on_nine session\(s\).*ses-1 .*ses-2 .*"
                                         r"--new-session"):
        _run_with(tmp_path, "P01", "sim", seed=5, responder="person")
    assert sorted(f.name for f in (tmp_path / "data" / "sub-P01").iterdir()) == ["ses-1",
                                                                                  "ses-2"]
    # the command line: refused without --new-session; with it, the id check passes and the
    # next check stops (no terminal here for the operator) before anything is created
    import subprocess

    cmd = [sys.executable, "-m", "app", "run", str(SIX), "--participant", "P01", "--data",
           str(tmp_path / "data"), "--device", "sim", "--no-audio", "--seed", "5"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 2 and "--new-session" in out.stderr, out.stderr
    out = subprocess.run([*cmd, "--new-session"], capture_output=True, text=True, timeout=120,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 2 and "this one is the next" in out.stderr, out.stderr
    assert "preflight: operator keys: no terminal" in out.stderr, out.stderr
    assert len(list((tmp_path / "data" / "sub-P01").iterdir())) == 2


def test_a_person_on_the_simulated_device_is_paced_by_the_wall_clock():
    """Issue 30 (10): unpaced, a person's familiarization on `sim` produced 910 taps in 13 s.
    The session opens the simulator live when a person sits at it (its windows then report
    their pacing, which session.json keeps as `timing`), and unpaced for a program."""
    from app.api import open_device_for

    for person, paced in ((True, True), (False, False)):
        with open_device_for("sim", seed=1, person=person) as dev:
            dev.load_scene(Scene("firm", spring=680.0))
            dev.home()
            res = dev.run_window(0.1, from_first_contact=False)
            assert bool(res.timing) is paced, res.timing
            if paced:
                assert res.timing["achieved_rate_hz"] > 0


class TapsFourTimes(ScriptedResponder):
    """Familiarization: four windows; counts the trace files on disk before each."""

    def __init__(self, traces: Path | None = None):
        self.traces, self.on_disk, self.more = traces, [], 3

    def before_window(self, trial, sample_id, device, rng):
        if trial.kind == "free":
            self.on_disk.append(len(list(self.traces.glob("trial-*.npz"))))

    def keep_tapping(self):
        self.more -= 1
        return self.more >= 0


def test_familiarization_writes_each_window_as_it_ends(tmp_path):
    """Issue 30 (10): familiarization kept every window's traces in memory until the
    participant was done (megabytes a window, without bound). Each window's file is on
    disk before the next window starts, and the row names them all."""
    p = load_protocol(str(DATA.parent / "free_spring.toml"))  # on a spring: force commanded
    folder, _ = new_session_dir(tmp_path, "P01")
    ui = TapsFourTimes(folder / "traces")
    files = SessionFiles(folder)
    files.start("")
    runner = SessionRunner(protocol=p, engine=SessionEngine(p, 4, "P01"),
                           device=open_device("sim", seed=4), files=files, responder=ui,
                           participant="P01", session=1, seed=4, traces="full")
    trial = runner.engine.next_trial([])
    assert trial.kind == "free"
    runner._attempt(trial)
    assert ui.on_disk == [0, 1, 2, 3]
    rows, _ = read_trials(folder / "trials.tsv")
    assert rows[-1]["trace_file"] == f"traces/trial-{trial.trial_index:04d}-*.npz"
    speeds, peak = [], 0.0
    for k in range(4):
        with np.load(folder / "traces" / f"trial-{trial.trial_index:04d}-{k}.npz") as z:
            assert str(z["sample"]) == trial.samples[0]
            speeds += [f"{v:.5f}" for v in z["contacts_v"]]
            peak = max(peak, float(np.abs(z["current"]).max()))
    assert ";".join(speeds) == rows[-1]["tap_velocities"]
    # the row's peak current is the windows' own (it read 0 once their traces had left)
    assert float(rows[-1]["peak_current"]) == pytest.approx(peak, abs=1e-3) and peak > 0


class StopsAfterTwo(TapsFourTimes):
    """Familiarization that goes on after its second window while ``interrupt(device)``
    breaks the device (an e-stop latched, a device error during the third window)."""

    def __init__(self, traces, interrupt):
        super().__init__(traces)
        self.interrupt, self.device = interrupt, None

    def before_window(self, trial, sample_id, device, rng):
        super().before_window(trial, sample_id, device, rng)
        self.device = device

    def keep_tapping(self):
        more = super().keep_tapping()
        if self.more == 1:  # after the second window
            self.interrupt(self.device)
        return more


def _familiarization(tmp_path, ui_of):
    from app.runner import SessionInterrupted

    p = load_protocol(str(DATA / "six_with_practice.toml"))
    folder, _ = new_session_dir(tmp_path, "P01")
    files = SessionFiles(folder)
    files.start("")
    dev = open_device("sim", seed=4)
    ui = ui_of(folder / "traces")
    runner = SessionRunner(protocol=p, engine=SessionEngine(p, 4, "P01"), device=dev,
                           files=files, responder=ui, participant="P01", session=1,
                           seed=4, traces="full")
    trial = runner.engine.next_trial([])
    with pytest.raises(SessionInterrupted):
        runner._attempt(trial)
    return folder, runner, trial, dev


def test_an_estop_during_familiarization_sets_its_early_traces_aside(tmp_path):
    """Writing familiarization's windows as they end made an e-stop between two of them
    fatal: the attempt ended without a row, ran again under the same trial number and
    found its own files ('a recording never overwrites another'). What no row names goes
    to traces/unrecorded/ (kept, as a resume keeps such files) and the attempt runs again."""
    folder, runner, trial, dev = _familiarization(
        tmp_path, lambda traces: StopsAfterTwo(traces, lambda d: d.estop()))
    stem = f"trial-{trial.trial_index:04d}"
    assert sorted(f.name for f in (folder / "traces" / "unrecorded").iterdir()) == [
        f"{stem}-0.npz", f"{stem}-1.npz"]
    assert not list((folder / "traces").glob("trial-*.npz"))
    dev.clear_fault()
    runner.responder = TapsFourTimes(folder / "traces")
    runner._attempt(trial)  # the same trial again: its own files, its row
    rows, _ = read_trials(folder / "trials.tsv")
    assert rows[-1]["trace_file"] == f"traces/{stem}-*.npz" and rows[-1]["status"] == "valid"
    assert len(list((folder / "traces").glob(f"{stem}-*.npz"))) == 4


def test_a_device_error_in_familiarization_records_every_window(tmp_path):
    """A device error during the third window: the row (aborted) names the two windows on
    disk and the one cut short, each its own file; nothing collides, nothing is lost."""
    from device import DeviceError

    def break_link(dev):
        real = dev.run_window

        def failing(*a, **kw):
            err = DeviceError("the link went away")
            err.partial = real(*a, **kw)
            raise err

        dev.run_window = failing

    folder, _, trial, _ = _familiarization(
        tmp_path, lambda traces: StopsAfterTwo(traces, break_link))
    rows, _ = read_trials(folder / "trials.tsv")
    (row,) = rows
    stem = f"trial-{trial.trial_index:04d}"
    assert row["status"] == "aborted_device" and "link went away" in row["reason"]
    assert row["trace_file"] == f"traces/{stem}-*.npz"
    files = sorted(f.name for f in (folder / "traces").glob(f"{stem}-*.npz"))
    assert files == [f"{stem}-{k}.npz" for k in range(3)]
    speeds = []
    for name in files:
        with np.load(folder / "traces" / name) as z:
            speeds += [f"{v:.5f}" for v in z["contacts_v"]]
    assert ";".join(speeds) == row["tap_velocities"]
    assert not (folder / "traces" / "unrecorded").exists()


class EstopsInTheSecondWindow(TapsFourTimes):
    """Familiarization whose second window the operator e-stops (the participant would
    have gone on tapping)."""

    def __init__(self, traces):
        super().__init__(traces)
        self.windows, self.device = 0, None

    def before_window(self, trial, sample_id, device, rng):
        super().before_window(trial, sample_id, device, rng)
        self.windows, self.device = self.windows + 1, device

    def progress(self, t, partial, duration):
        if self.windows == 2 and self.device.fault is None and partial.contacts:
            self.device.estop()


def test_an_estop_in_a_familiarization_window_is_recorded_with_its_windows(tmp_path):
    """A fault during a familiarization window went on to the next window (the participant
    had not pressed ENTER), whose HOME then failed: no row, the faulted window's trace set
    aside. The fault now ends familiarization at that window, and its row names both."""
    folder, _, trial, dev = _familiarization(tmp_path, EstopsInTheSecondWindow)
    rows, _ = read_trials(folder / "trials.tsv")
    (row,) = rows
    assert row["status"] == "aborted_device" and row["reason"].startswith("estop"), row
    stem = f"trial-{trial.trial_index:04d}"
    assert row["trace_file"] == f"traces/{stem}-*.npz"
    assert sorted(f.name for f in (folder / "traces").glob("*.npz")) == [
        f"{stem}-0.npz", f"{stem}-1.npz"]
    assert not (folder / "traces" / "unrecorded").exists()
