"""The device a session ran on is on the record (report, exports, the selection table), and a
person's session on the simulated device is left out of a human analysis unless asked."""

import json
import sys

import pytest

from ..app.sim_sessions import run_six

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def test_the_device_is_on_the_record_and_a_person_on_sim_is_not_pooled(tmp_path):
    """The report and every export carry the device backend, id and firmware; a person's
    session on the simulated device is left out of a human analysis unless asked."""
    import pandas as pd

    from analysis import load_sessions, select_sessions
    from app.api import export

    for pid in ("S01", "P01"):
        assert run_six(tmp_path, pid, "sim").status == "complete"
    meta_path = tmp_path / "data" / "sub-P01" / "ses-1" / "session.json"
    meta = json.loads(meta_path.read_text())
    # P01 stands for a person on a serial device, S01 for a person on the simulator
    meta.update(kind="human", responder="person")
    meta["device"].update(backend="serial", model="hapticlab stylus", serial_number="0042",
                          firmware="hl-2.1", simulated_contact=False, seeded=False,
                          virtual_time=False)  # what the lab's device says of itself
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
