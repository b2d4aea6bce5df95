"""What a session tells the participant and the operator: every saturation and whether its
sample comes back, the attempt counter, and the operator's panel at each placing, which says
what to remove and never cues a scene's answer."""

from pathlib import Path

from app.participants import ScriptedResponder
from protocols import load_protocol

from .sim_sessions import (
    DATA,
    AsksForTheThirdBlock,
    SeenByTheOperator,
    identification,
    sim_session,
)


def _items_in(protocol) -> int:
    """Items in the plan of a protocol of rated phases (samples × repetitions)."""
    return sum(len(ph.samples) * ph.repetitions for ph in protocol.phases)


class SeesTheNotice(ScriptedResponder):
    """Records what the 'please wait' screen is told after each saturated attempt."""

    def __init__(self):
        self.notices: list[tuple[str, bool]] = []

    def saturated(self, trial, comes_back=True):
        self.notices.append((trial.item, comes_back))


def test_the_participant_is_told_of_every_saturation_and_whether_it_comes_back(tmp_path):
    """Issue 30 (8): without sound the participant saw nothing when a tap saturated; the
    screen says so on the next 'please wait', and at the protocol's cap (here the second
    saturation of an item) it no longer says 'this sample comes back later', since the
    item is left out. One notice per saturated row, in order, each matching its status."""
    ui, con = SeesTheNotice(), SeenByTheOperator()
    hard = load_protocol(str(DATA.parent / "two_springs_low_current.toml"))  # not a variant
    folder, rows = sim_session(tmp_path, hard, ui, 2, con)
    sat = [(r["item"], r["status"] == "saturated") for r in rows
           if r["status"] in ("saturated", "excluded_saturated")]
    assert ui.notices == sat
    assert any(back for _, back in sat) and any(not back for _, back in sat), sat
    # item 7's counter, from the runner: attempts outnumber items, the count of items done
    # never reaches past them ('item done+1 of n' in the live view)
    assert max(t for *_, t in con.counts) > _items_in(hard)
    assert all(done < total == _items_in(hard) for done, total, _ in con.counts), con.counts
    from protocols.texts import DEFAULT_TEXTS

    assert "comes back" in DEFAULT_TEXTS["saturated"]
    assert "comes back" not in DEFAULT_TEXTS["saturated_last"]


def test_the_operator_panel_says_what_to_remove_and_never_cues_the_scene():
    """Issue 30 (7): in identification the panel said 'PLACE real rubber block', then
    'block — its real block: real aluminum block' (surface 1's block, the scene's answer),
    and 'PLACE nothing' where the real block had to come off. A scene now says to remove the
    block tapped just before it (and 'nothing' after a scene), and names no block."""
    import tempfile

    con = SeenByTheOperator()
    with tempfile.TemporaryDirectory() as tmp:
        sim_session(Path(tmp), identification(repetitions=2), AsksForTheThirdBlock(), 5, con)
    is_ref = [p[1].startswith("real reference block") for p in con.panels]
    assert sum(is_ref) == 5  # three at the start, one asked for before each scene
    for k, (what, detail, block) in enumerate(con.panels):
        if is_ref[k]:
            assert block == f"real reference block: {what}"
            continue
        # after a real block: take it off; after a scene: nothing is on the device
        assert what == ("nothing: remove the real aluminum block (the scene's surfaces are "
                        "virtual)" if is_ref[k - 1] else "nothing (the scene's surfaces are "
                        "virtual)"), (k, what)
        assert block == "" and "real" not in detail  # names the surfaces, never a block
