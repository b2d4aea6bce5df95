"""A new kind of answer is its declaration, its screen and its tests (issue 54, item 3).

Here one is declared in the test alone — magnitude estimation: a positive number for how far
a sample felt from real contact — with a phase kind that asks it, and a session runs,
records, reloads and exports it through code that never heard of it: the runner asks the
responder by the declaration, the simulated participant answers from its perception, the
loader checks the rows by the rules the session recorded, the export's codebook and wide
cells come from that record. (Its screen would be one PsychoPy method; a person is not
asked here.)"""

import math
from pathlib import Path

import pandas as pd
import pytest

from protocols import kinds, parse_protocol, responses
from protocols.kinds import PhaseKind
from protocols.responses import Cell, Response, Wide

pytestmark = [pytest.mark.integration, pytest.mark.slow]  # two short simulated sessions (git)


def _row(value, q):
    if isinstance(value, bool) or not isinstance(value, int | float) \
            or not (math.isfinite(value) and value > 0):
        raise ValueError(f"magnitude {value!r}, not a positive number")
    return {"answer": f"{value:.4g}"}


MAGNITUDE = Response(
    name="magnitude", dv="magnitude", summary="a positive number: how far from real contact",
    cells=(Cell("answer", "", "the number given: how far the sample felt from real contact",
                type="number", noun="magnitude", range=(1e-9, None)),
           Cell("response_time", "s", "from the question to the answer", type="number",
                range=(0.0, None), required=False)),
    wide=Wide("answer", "sample", "number", "mean magnitude of sample {cell}"),
    ask=lambda r, q, rng: r.estimate(q.trial, q.results[0], rng),
    row=_row,
    scripted=lambda q, rng: (float(rng.lognormal(2.0, 0.5)), 1.0),
    # ten for a sample one JND from what it remembers of real contact, ratio-scaled
    simulated=lambda m, q, rng: (10.0 * math.exp(0.3 * (m.distances(q.trial, q.results,
                                                                     rng)[0] - 1.0)),
                                 m.response_time(2.0, rng)),
    texts={"magnitude": "How far from real contact? A number, then ENTER."},
    marker=("answer",))


@pytest.fixture
def declared():
    responses.register_response(MAGNITUDE)
    kind = kinds.register(PhaseKind(name="magnitude", summary="a number per sample",
                                    windows="each_sample", response="magnitude",
                                    instructions="Give each sample a number."))
    yield kind
    del kinds._KINDS["magnitude"], responses._RESPONSES["magnitude"]


def test_a_response_declared_here_runs_records_and_exports(declared, tmp_path):
    from analysis import load_sessions
    from analysis.export import export
    from app.api import simulate_study

    mini = (Path(__file__).parents[1] / "data" / "mini.toml").read_text()
    # familiarization on the real block first: what the participant remembers of real contact
    proto = mini.replace('[[phases]]\nname = "testing"\n', '[[phases]]\nname = "familiar"\n'
                         'kind = "free"\nsamples = ["wood"]\n[[phases]]\nname = "testing"\n'
                         'kind = "magnitude"\n') \
        .replace('samples = "all"', 'samples = ["firm", "pulse"]') \
        .replace("repetitions = 2", "repetitions = 1")
    f = tmp_path / "magnitude.toml"
    f.write_text(proto)
    assert parse_protocol(proto).phases[1].kind == "magnitude"
    s = simulate_study(f, 2, seed=5, data=tmp_path / "data", traces="none", progress=None)
    assert s.complete
    d = load_sessions(tmp_path / "data")
    v = d[d["valid"] & (d["phase"] == "testing")]
    assert len(v) == 4 and (pd.to_numeric(v["answer"]) > 0).all()
    files = export(tmp_path / "data", tmp_path / "x", "wide-csv")
    wide = pd.read_csv(next(p for p in files if p.name.startswith("wide_")))
    assert {"firm", "pulse"} <= set(wide.columns)
    book = pd.read_csv(tmp_path / "x" / "codebook.csv", keep_default_na=False)
    assert "mean magnitude of sample firm" in set(book["meaning"])
    # a row the rules refuse is named when loaded: the number the session recorded, edited
    tsv = next((tmp_path / "data").rglob("trials.tsv"))
    rows = tsv.read_text().splitlines()
    i = next(k for k, r in enumerate(rows) if "\tvalid\t" in r and "\ttesting\t" in r)
    cells = rows[i].split("\t")
    col = rows[0].split("\t").index("answer")
    cells[col] = "-3"
    rows[i] = "\t".join(cells)
    tsv.write_text("\n".join(rows) + "\n")
    with pytest.raises(Exception, match="magnitude -3 is outside at least 1e-09"):
        load_sessions(tmp_path / "data")
