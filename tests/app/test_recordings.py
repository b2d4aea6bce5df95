"""Recordings keep their data: a trace never overwrites another; familiarization writes each
window as it ends, and an e-stop or a device error during it keeps what was recorded."""

from pathlib import Path

import numpy as np
import pytest

from app.errors import SessionFileError
from app.participants import ScriptedResponder
from app.recorder import SessionFiles, new_session_dir, read_trials
from app.runner import SessionRunner
from device import open_device
from protocols import SessionEngine, load_protocol

from .sim_sessions import DATA


def test_the_recorder_never_overwrites_a_recording(tmp_path):
    folder, _ = new_session_dir(tmp_path, "P01")
    files = SessionFiles(folder)
    files.save_trace("trial-0001-0.npz", {"x": np.arange(3)}, [])
    before = (folder / "traces" / "trial-0001-0.npz").read_bytes()
    with pytest.raises(SessionFileError, match="exists; a recording never overwrites"):
        files.save_trace("trial-0001-0.npz", {"x": np.arange(5)}, [])
    assert (folder / "traces" / "trial-0001-0.npz").read_bytes() == before
    assert [f.name for f in (folder / "traces").iterdir()] == ["trial-0001-0.npz"]


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
