"""PsychoPy data files read into hapticlab's analyses where the design fits, and a design
that does not is refused by name."""

import pytest

from analysis.load import LoadError
from analysis.psychopy_data import WHY_NOT, analyse_psychopy, load_psychopy

#: the columns of a PsychoPy CSV as the demo writes them (a non-trial row first, as
#: PsychoPy writes one for each routine outside the loop; lists quoted, nothing escaped)
HEAD = ("first,second,choice.keys,tap_first.status,tap_first.speeds,tap_second.status,"
        "tap_second.speeds,participant\n")


def _csv(tmp_path, name, rows):
    f = tmp_path / name
    f.write_text(HEAD + ",,,,,,,P\n" + "".join(rows), encoding="utf-8-sig")
    return f


def test_a_2afc_is_read_as_hapticlabs_paired_comparison(tmp_path):
    a = _csv(tmp_path, "P01.csv", [
        'w100,w67,1,valid,"[0.1, 0.12]",valid,[0.09],P01\n',
        'w67,w100,2,valid,[0.11],valid,[0.1],P01\n',
        'w100,w67,1,saturated,[0.3],valid,[0.1],P01\n',
        "w67,w100,,valid,[0.11],valid,[0.1],P01\n"])
    b = _csv(tmp_path, "P02.csv", ['w100,w67,2,valid,[0.1],valid,[0.1],P02\n',
                                   'w67,w100,1,valid,[0.1],valid,[0.1],P02\n'])
    d = load_psychopy([a, b], "comparison")
    assert d["sample"].tolist()[:2] == ["w100+w67", "w67+w100"]
    assert d["answer"].tolist() == ["w100", "w100", "w100", "", "w67", "w67"]
    assert d["status"].tolist() == ["valid", "valid", "saturated", "no_response", "valid",
                                    "valid"]
    assert d["tap_velocities"].iloc[0] == "0.10000;0.12000;0.09000"
    assert d["trial_index"].tolist()[:2] == [1, 2]  # the rows of the file, as trial_id says
    res = analyse_psychopy(d, "comparison")
    assert res["type"] == "comparison"
    r = res["result"]
    assert (r["n_subjects"], r["n_choices"]) == (2, 4)
    # w100 chosen in 2 of the 4 valid pairs; the first felt chosen in 2 of 4
    won = {s["sample"]: (s["wins"], s["n"]) for s in r["samples"]}
    assert won == {"w100": (2, 4), "w67": (2, 4)}
    assert r["order"]["prop_first"].iloc[0] == pytest.approx(0.5)
    assert res["device"]["n_taps"] == 9  # the valid trials' taps, both windows


def test_designs_hapticlab_cannot_read_from_psychopy_data_are_refused_by_name(tmp_path):
    f = _csv(tmp_path, "P01.csv", ['w100,w67,1,valid,[0.1],valid,[0.1],P01\n'])
    for design in WHY_NOT:
        with pytest.raises(LoadError, match=f"cannot be analysed as {design}: "):
            load_psychopy(f, design)
    with pytest.raises(LoadError, match="needs the column.s. sample, rating"):
        load_psychopy(f, "oneway")
    with pytest.raises(LoadError, match=r"choice.keys: keys 3 are neither 1"):
        load_psychopy(_csv(tmp_path, "P02.csv", ['w100,w67,3,valid,[0.1],valid,[0.1],P\n']),
                      "comparison")
    (tmp_path / "empty").mkdir()
    with pytest.raises(LoadError, match="no PsychoPy data files"):
        load_psychopy(tmp_path / "empty", "comparison")
