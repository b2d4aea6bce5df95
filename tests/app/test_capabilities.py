"""A session asks its device what it is and can do (DeviceInfo), never its name: the sound a
session on a physical device cannot go without, the library built on demand, the record in
session.json (issue 54)."""

import dataclasses
import json
from pathlib import Path

import pytest

import device.registry
from app.errors import UsageError
from app.libraries import builds_on_demand
from device.sim.backend import SimDevice

MINI = Path(__file__).resolve().parents[1] / "data" / "mini.toml"


class PhysicalStandIn(SimDevice):
    """A device that says its contact is physical (a lab's own device would), simulated
    underneath so that a session can run here."""

    def __init__(self, **options):
        super().__init__(**options)
        self._info = dataclasses.replace(self._info, backend="bench", simulated_contact=False,
                                         seeded=False, virtual_time=False)


@pytest.fixture
def bench(monkeypatch):
    """``bench`` registered for this test only."""
    monkeypatch.setitem(device.registry._REGISTERED, "bench", PhysicalStandIn)
    return "bench"


@pytest.fixture
def no_audio(monkeypatch):
    from app import audio

    def unavailable():
        raise audio.AudioUnavailable("no output device (this test's)")

    monkeypatch.setattr(audio, "Audio", unavailable)


def _run(tmp_path, dev, **kw):
    from app.api import run_session

    said = []
    r = run_session(MINI, "P01", device=dev, data=tmp_path, responder="scripted", seed=2,
                    traces="none", quiet=True, operator_keys=False, say=said.append, **kw)
    return r, said


@pytest.mark.integration  # a session in process: it records its provenance with git
def test_without_sound_a_physical_device_is_refused_and_a_simulated_one_goes_on(
        tmp_path, bench, no_audio):
    """The masking noise hides a real sample's own sound: a device that says its contact is
    physical does not run without it (whatever its backend is called); on a simulated contact
    there is nothing to hide, so the session runs and says so."""
    with pytest.raises(UsageError, match="no audio device .* a real session needs masking "
                                         "noise"):
        _run(tmp_path / "a", bench)
    assert not list((tmp_path / "a").rglob("trials.tsv"))  # nothing started
    r, said = _run(tmp_path / "b", "sim")
    assert r.status == "complete"
    assert any("warning: no audio" in s and "simulated device" in s for s in said), said


@pytest.mark.integration  # two sessions in process: their provenance with git
def test_session_json_records_what_the_device_said_it_is(tmp_path, bench):
    for pid, dev in (("sim", "sim"), ("bench", bench)):
        from app.api import run_session

        r = run_session(MINI, pid.upper(), device=dev, data=tmp_path, responder="scripted",
                        seed=2, traces="none", quiet=True, operator_keys=False, audio=False)
        meta = json.loads((r.folder / "session.json").read_text())
        d = meta["device"]
        expected = dev == "sim"
        assert (d["simulated_contact"], d["seeded"], d["virtual_time"]) == (expected,) * 3
        assert meta["format_version"] >= 4
    from analysis import load_sessions

    table = load_sessions(tmp_path).attrs["session_table"].set_index("participant")
    assert table.loc["SIM", "simulated_plant"] == 1 and table.loc["BENCH", "simulated_plant"] == 0


@pytest.mark.parametrize("simulated, virtual, built", [
    (True, True, True),     # the simulated device: a build takes seconds, nobody taps
    (True, False, False),   # the emulator, a firmware build: real time, the operator's step
    (False, False, False),  # a physical device: an experiment of its own
])
def test_a_missing_library_is_built_on_demand_only_where_it_costs_seconds(simulated, virtual,
                                                                          built):
    info = dataclasses.replace(SimDevice().info, backend="any", simulated_contact=simulated,
                               virtual_time=virtual)
    assert builds_on_demand(info) is built


class PacedStandIn(SimDevice):
    """A simulated device that keeps the pace each open asked for (as an emulator runs at
    its ``speed``)."""

    opened: list = []

    @classmethod
    def from_spec(cls, arg=None, **options):
        cls.opened.append(options.get("speed"))
        return super().from_spec(arg, **options)


@pytest.mark.integration  # a session in process: it records its provenance with git
def test_a_resumed_session_runs_at_the_speed_it_was_recorded_at(tmp_path, monkeypatch):
    """A session on a paced device (an emulator at --speed 3) records its speed beside the
    spec; its resume opens the device at it, not at 1 (follow-up 6). A speed session.json
    cannot hold is refused naming the file and the key, before the device opens."""
    from app.api import resume_session
    from app.errors import SessionFileError

    monkeypatch.setitem(device.registry._REGISTERED, "paced", PacedStandIn)
    monkeypatch.setattr(PacedStandIn, "opened", [])
    r, _ = _run(tmp_path, "paced", audio=False, speed=3.0)
    meta_path = r.folder / "session.json"
    meta = json.loads(meta_path.read_text())
    assert meta["device"]["spec"] == "paced" and meta["device"]["speed"] == 3.0
    trials = r.folder / "trials.tsv"
    trials.write_text("".join(trials.read_text().splitlines(keepends=True)[:3]))
    for bad in ("fast", 0, 25.0):
        meta["device"]["speed"], meta["status"] = bad, "interrupted"
        meta_path.write_text(json.dumps(meta))
        with pytest.raises(SessionFileError, match=rf"session\.json: device\.speed: .*{bad!r}"):
            resume_session(r.folder, quiet=True, operator_keys=False)
    meta["device"]["speed"] = 3.0
    meta_path.write_text(json.dumps(meta))
    done = resume_session(r.folder, quiet=True, operator_keys=False)
    assert done.status == "complete", done.message
    assert PacedStandIn.opened == [3.0, 3.0]
