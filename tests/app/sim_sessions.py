"""Sessions on the simulated device, run in this process, for the tests that look at what a
session recorded or said: a short identification protocol, a session with full traces, the
participant who asks for a real block, the operator's panel as shown, and a dry run of a
six-sample protocol through the public function."""

import io
from pathlib import Path

from app.console import PlainConsole
from app.participants import ScriptedResponder
from app.recorder import SessionFiles, new_session_dir, read_trials
from app.runner import SessionRunner
from device import open_device
from protocols import SessionEngine, parse_protocol, protocol_text

DATA = Path(__file__).resolve().parents[1] / "data" / "protocols"
#: six samples rated on a 1–9 scale
SIX = DATA / "six_on_nine.toml"


def identification(duration: float = 1.0, repetitions: int = 2):
    """The built-in identification protocol with windows of ``duration`` [s] and
    ``repetitions`` of each set."""
    source, text = protocol_text("identification")
    text = (text.replace("duration = 20.0", f"duration = {duration}")
            .replace("repetitions = 3", f"repetitions = {repetitions}"))
    return parse_protocol(text, source)


def sim_session(tmp: Path, p, ui, seed: int, console=None) -> tuple[Path, list[dict]]:
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


def run_six(tmp_path, pid, device_spec, **kw):
    """A scripted dry run of :data:`SIX` for ``pid`` into ``tmp_path/data`` through
    ``app.api.run_session`` (``kw`` overrides its arguments)."""
    from app.api import run_session

    args = dict(device=device_spec, data=tmp_path / "data", responder="scripted", seed=3,
                traces="none", audio=False, quiet=True)
    return run_session(SIX, pid, **{**args, **kw})
