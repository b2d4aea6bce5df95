"""Rows that cannot be pooled under the wrong person (issue 58, item 2): a row whose
participant, session or protocol disagrees with its session's record is never pooled
silently — the session is left out and named with the reason, or the analyst chooses
whom to trust (--ids) — in analyze, export and BIDS alike."""

import json

import pandas as pd
import pytest

from analysis import load_sessions, select_sessions
from analysis.session_format import COLUMNS

PID = COLUMNS.index("participant")


def _edit(folder, column: str, value: str, only_first: bool = False) -> None:
    """Set ``column`` of the rows of ``folder``'s trials.tsv to ``value``."""
    t = folder / "trials.tsv"
    lines = t.read_text().splitlines(keepends=True)
    out = [lines[0]]
    for i, ln in enumerate(lines[1:]):
        c = ln.rstrip("\n").split("\t")
        if not only_first or i == 0:
            c[COLUMNS.index(column)] = value
        out.append("\t".join(c) + "\n")
    t.write_text("".join(out))


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """Five participants of the factorial protocol. P00003's rows name P00001 (the
    operator typed the wrong id, then renamed the folder: folder and session.json say
    P00003); P00004's rows say session 2 (session.json: 1); P00005's first row is of a
    phase its protocol does not have."""
    from benchmarks._study import write_study

    data = tmp_path_factory.mktemp("ids") / "data"
    write_study(data, 5, protocol="factorial", seed=11)
    _edit(data / "sub-P00003" / "ses-1", "participant", "P00001")
    _edit(data / "sub-P00004" / "ses-1", "session", "2", only_first=True)
    _edit(data / "sub-P00005" / "ses-1", "phase", "practice", only_first=True)
    return data


def _reasons(table) -> dict[str, str]:
    return {r.recorded_participant: r.reason for r in table.itertuples() if not r.included}


def test_a_session_whose_rows_disagree_with_its_record_is_left_out_and_named(study):
    d = load_sessions(study)
    rows, table = select_sessions(d)
    why = _reasons(table)
    assert set(why) == {"P00003", "P00004", "P00005"}
    assert "sub-P00003/ses-1/trials.tsv:2: the row names participant 'P00001', session.json " \
           "'P00003'" in why["P00003"]
    assert "--ids record (analyse as P00003) or --ids rows (as P00001)" in why["P00003"]
    assert "trials.tsv:2: the row names session '2', session.json '1'" in why["P00004"]
    assert "trials.tsv:2: phase 'practice' is not a phase of protocol 'factorial'" \
        in why["P00005"]
    assert set(rows["participant"]) == {"P00001", "P00002"}
    # P00001's own rows only: nothing of P00003's session pooled under P00001
    assert rows.groupby("participant")["session_dir"].nunique().max() == 1


def test_the_analyst_chooses_whom_to_trust(study):
    d = load_sessions(study)
    rows, table = select_sessions(d, ids="record")
    mine = rows[rows["session_dir"].str.contains("sub-P00003")]
    assert len(mine) and set(mine["participant"]) == {"P00003"}
    # a session number or protocol that disagrees is not a choice
    assert set(_reasons(table)) == {"P00004", "P00005"}
    # trusting the rows makes it P00001's second session of the design, which the design
    # does not analyse (its first complete one is): named as such, not pooled
    rows, table = select_sessions(d, ids="rows", every_session=True)
    mine = rows[rows["session_dir"].str.contains("sub-P00003")]
    assert len(mine) and set(mine["participant"]) == {"P00001"}
    _, table = select_sessions(d, ids="rows")
    assert "session of P00001" in _reasons(table)["P00003"]


def test_rows_naming_several_participants_cannot_be_trusted_as_rows(tmp_path):
    from benchmarks._study import write_study

    write_study(tmp_path / "d", 2, protocol="factorial", seed=2)
    _edit(tmp_path / "d" / "sub-P00002" / "ses-1", "participant", "P00009", only_first=True)
    d = load_sessions(tmp_path / "d")
    _, table = select_sessions(d, ids="rows")
    why = _reasons(table)["P00002"]
    assert "(the rows name 2 participants)" in why and "--ids rows cannot choose" in why
    rows, _ = select_sessions(d, ids="record")
    assert set(rows.loc[rows["session_dir"].str.contains("P00002"), "participant"]) == \
        {"P00002"}


@pytest.mark.slow
def test_analyze_export_and_bids_leave_it_out_alike(study, tmp_path):
    from analysis.bids import export_bids
    from analysis.export import export
    from analysis.report import analyze

    rep = analyze(study, tmp_path / "r", formats=("json",))
    assert rep["selection"]["included"] == 2 and rep["selection"]["excluded"] == 3
    listed = pd.read_csv(tmp_path / "r" / "sessions.tsv", sep="\t", dtype=str)
    assert "the row names participant 'P00001'" in \
        listed.set_index("participant").loc["P00003", "reason"]
    (long,) = [f for f in export(study, tmp_path / "x") if f.name == "long.csv"]
    assert set(pd.read_csv(long, dtype=str)["participant"]) == {"P00001", "P00002"}
    res = export_bids(study, tmp_path / "bids", status="complete")
    assert sorted(res["labels"]) == ["P00001", "P00002"]
    assert any("the row names participant" in why for why in res["left_out"].values())
    res = export_bids(study, tmp_path / "bids-record", ids="record")
    assert sorted(res["labels"]) == ["P00001", "P00002", "P00003"]
    part = json.loads(json.dumps(res["left_out"]))
    assert len(part) == 2
