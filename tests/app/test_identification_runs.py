"""Identification sessions: every real block's taps recorded apiece, the real block the
participant asks for, moving on to another surface mid-window and going back to one, an
e-stop during a reference tap, and a stray trace set aside before a resume."""

from pathlib import Path

import numpy as np
import pytest

from app.participants import ScriptedResponder
from app.recorder import SessionFiles
from protocols import Attempt, SessionEngine, reference_item

from .sim_sessions import AsksForTheThirdBlock, identification, sim_session


@pytest.fixture(scope="module")
def identification_session(tmp_path_factory):
    ui = AsksForTheThirdBlock()
    folder, rows = sim_session(tmp_path_factory.mktemp("ident"), identification(), ui, 5)
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
    folder, rows = sim_session(tmp_path, identification(duration=3.0, repetitions=1), MovesOn(), 7)
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
    folder, rows = sim_session(tmp_path, identification(duration=1.0, repetitions=1), ui, 3)
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
    p = identification()
    eng = SessionEngine(p, 5, "P01")
    first = eng.next_trial([])
    log = [Attempt(reference_item(first.phase, "wood-real"), "estop", "estop: operator"),
           Attempt(reference_item(first.phase, "wood-real"), "reference", "")]
    again = eng.next_trial(log)
    assert again.item == first.item and again.trial_index == first.trial_index
