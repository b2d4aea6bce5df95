"""Participant ids that look like numbers (001, 1e5) stay text in every export: pandas told
the codebook's types, R through load.R, SPSS; ids that read as a missing value are refused."""

import json
import sys

import pytest

from ..app.sim_sessions import run_six

pytestmark = [pytest.mark.integration, pytest.mark.r, pytest.mark.slow]


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
        assert run_six(tmp_path, pid, "sim").status == "complete"
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
