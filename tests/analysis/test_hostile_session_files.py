"""Hostile session folders meet the one reader of the format (analysis/session_format.py):
statuses that are not the recorder's, whole-number columns that are not whole, and links
that lead out of the session folder — each a named error, never a traceback, and nothing
read through a link that leaves the folder."""

import json

import pytest

from analysis import session_format as sf
from analysis.session_format import (
    COLUMNS,
    SessionMetaError,
    TrialsFileError,
    format_row,
    header_line,
    read_meta,
    read_trials,
)

ROW = {"participant": "P01", "session": 1, "phase": "testing", "trial_index": 1,
       "item": "testing/wood#1", "attempt": 1, "sample": "wood", "status": "valid",
       "n_taps": 3, "rating": 5}
META = {"protocol": {"name": "p", "sha256": "ab"}, "seed": 1, "participant": {"id": "P01"},
        "session": 1, "status": "complete", "kind": "human"}


def _trials(folder, *rows):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "trials.tsv").write_text(header_line() + "".join(format_row({**ROW, **r})
                                                               for r in rows))
    return folder / "trials.tsv"


def test_the_format_names_the_engines_statuses():
    """analysis imports nothing of ours: the format keeps its own list of the values of the
    engine's named statuses (protocols.TrialStatus), held equal here, in order."""
    from protocols import TrialStatus

    assert sf.ROW_STATUSES == tuple(s.value for s in TrialStatus)


@pytest.mark.parametrize("status", ["VALID", "Valid", "valid ", "done"])
def test_a_status_the_recorder_never_writes_is_named_with_file_line_and_the_statuses(
        tmp_path, status):
    path = _trials(tmp_path / "ses-1", {}, {"status": status, "trial_index": 2}, {})
    with pytest.raises(TrialsFileError) as err:
        read_trials(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}:3: status {status!r} is not one of valid, saturated")
    assert "reference" in msg  # every accepted value is listed
    if status.lower() != "done":  # the spreadsheet's capitals: said what happened
        assert "the recorder writes 'valid' (lower case, no spaces)" in msg
    else:
        assert "the recorder writes" not in msg


def test_a_torn_last_line_is_still_torn_whatever_its_status(tmp_path):
    path = _trials(tmp_path / "ses-1", {})
    with open(path, "a") as f:
        line = format_row({**ROW, "trial_index": 2})
        f.write(line[:line.index("\tvalid\t") + 4])  # killed mid-line, in the status
    rows, torn = read_trials(path)
    assert len(rows) == 1 and torn is not None and torn.line == 3


@pytest.mark.parametrize("column, value", [("session", "one"), ("n_taps", "2.5"),
                                           ("n_taps", "-1")])
def test_a_whole_number_column_that_is_not_one_is_named(tmp_path, column, value):
    path = _trials(tmp_path / "ses-1", {})
    lines = path.read_text().splitlines()
    cells = lines[1].split("\t")
    cells[COLUMNS.index(column)] = value
    path.write_text("\n".join([lines[0], "\t".join(cells)]) + "\n")
    with pytest.raises(TrialsFileError, match=rf"trials.tsv:2: {column} '{value}' is not a "
                                              "whole number"):
        read_trials(path)


def test_trials_through_a_link_out_of_the_folder_are_not_read(tmp_path):
    outside = _trials(tmp_path / "elsewhere", {"participant": "P99"})
    folder = tmp_path / "sub-P01" / "ses-1"
    folder.mkdir(parents=True)
    (folder / "trials.tsv").symlink_to(outside)
    with pytest.raises(TrialsFileError) as err:
        read_trials(folder / "trials.tsv")
    msg = str(err.value)
    assert f"{folder / 'trials.tsv'}: is a link to {outside.resolve()}" in msg
    assert "outside the session folder" in msg and "copy the file into the folder" in msg


def test_a_link_that_stays_in_the_folder_is_followed(tmp_path):
    folder = tmp_path / "ses-1"
    _trials(folder / "kept", {})
    (folder / "trials.tsv").symlink_to("kept/trials.tsv")
    rows, _ = read_trials(folder / "trials.tsv")
    assert [r["participant"] for r in rows] == ["P01"]


def test_the_session_folder_itself_may_be_reached_through_a_link(tmp_path):
    _trials(tmp_path / "disk2" / "ses-1", {})
    (tmp_path / "sub-P01").symlink_to(tmp_path / "disk2")
    rows, _ = read_trials(tmp_path / "sub-P01" / "ses-1" / "trials.tsv")
    assert len(rows) == 1


def test_session_json_through_a_link_out_of_the_folder_is_not_read(tmp_path):
    (tmp_path / "other.json").write_text(json.dumps(META))
    folder = tmp_path / "ses-1"
    folder.mkdir()
    (folder / "session.json").symlink_to(tmp_path / "other.json")
    with pytest.raises(SessionMetaError, match="is a link to .*other.json, outside the "
                                               "session folder"):
        read_meta(folder / "session.json")


@pytest.mark.parametrize("name, words", [("../x.npz", "names"), ("/etc/passwd", "names"),
                                         ("traces/t.npz", "goes through the link")])
def test_a_name_that_leaves_the_folder_is_refused(tmp_path, name, words):
    folder = tmp_path / "ses-1"
    folder.mkdir()
    (tmp_path / "out").mkdir()
    (folder / "traces").symlink_to(tmp_path / "out")
    with pytest.raises(sf.SessionPathError, match=f"{words} .*outside the session folder"):
        sf.inside_session(folder, name)
    assert sf.inside_session(folder, "trials.tsv") == folder / "trials.tsv"


# ---------------------------------------------------------------- analyze, export, BIDS
def _dataset(tmp_path):
    """A copy of the packaged example sessions (three simulated realism sessions)."""
    import shutil

    from analysis.datasets import sessions_path

    data = tmp_path / "data"
    shutil.copytree(sessions_path(), data)
    return data


@pytest.mark.parametrize("what", ["analyze", "export", "bids"])
def test_analyze_export_and_bids_refuse_a_trials_file_linked_out_of_its_folder(tmp_path,
                                                                                what):
    import shutil

    from analysis import LoadError
    from analysis.bids import export_bids
    from analysis.export import export
    from analysis.report import analyze

    data = _dataset(tmp_path)
    t = data / "sub-P02" / "ses-1" / "trials.tsv"
    other = tmp_path / "someone-elses.tsv"
    shutil.move(t, other)
    t.symlink_to(other)
    call = {"analyze": lambda: analyze(data, tmp_path / "out"),
            "export": lambda: export(data, tmp_path / "out"),
            "bids": lambda: export_bids(data, tmp_path / "out")}[what]
    with pytest.raises(LoadError, match=f"{t}: is a link to {other}, outside the session"):
        call()


def test_a_trace_linked_out_of_the_folder_is_not_exported_to_bids(tmp_path):
    from analysis import LoadError
    from analysis.bids import export_bids

    data = _dataset(tmp_path)
    folder = data / "sub-P01" / "ses-1"
    t = folder / "trials.tsv"
    lines = t.read_text().splitlines(keepends=True)
    cells = lines[1].rstrip("\n").split("\t")
    cells[COLUMNS.index("trace_file")] = "traces/trial-1.npz"
    t.write_text("".join([lines[0], "\t".join(cells) + "\n", *lines[2:]]))
    (folder / "traces").mkdir()
    (tmp_path / "private.npz").write_bytes(b"not the session's")
    (folder / "traces" / "trial-1.npz").symlink_to(tmp_path / "private.npz")
    with pytest.raises(LoadError, match=r"trials.tsv:2: .*trial-1.npz: is a link to "
                                        r".*private.npz, outside the session folder"):
        export_bids(data, tmp_path / "bids")


def test_a_trace_name_that_climbs_out_of_the_folder_is_named(tmp_path):
    folder = tmp_path / "ses-1"
    path = _trials(folder, {"trace_file": "traces/../../x.npz"})
    with pytest.raises(TrialsFileError, match=r"trials.tsv:2: trace_file "
                                              r"'traces/../../x.npz' names a file outside"):
        read_trials(path)


def test_a_session_folder_kept_on_another_disk_is_read_once(tmp_path):
    """A link to a folder outside the data folder is followed (it was skipped without a
    word); a link to a folder inside it is an alias, not a second copy of its sessions."""
    import shutil

    from analysis import load_sessions

    data = _dataset(tmp_path)
    disk2 = tmp_path / "disk2"
    shutil.move(data / "sub-P03", disk2)
    (data / "sub-P03").symlink_to(disk2)
    (data / "latest").symlink_to(data / "sub-P02")  # an alias inside the data folder
    d = load_sessions(data)
    t = d.attrs["session_table"]
    assert sorted(t["participant"]) == ["P01", "P02", "P03"]
    assert str(data / "sub-P03" / "ses-1") in set(t["session_dir"])
