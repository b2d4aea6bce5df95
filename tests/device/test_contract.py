"""The wire contract written once (device/serial/contract.py): the files generated from it
are current, the host's messages take their layouts from it, its range check refuses exactly
what it should, and every device target answers every bounded field, at and beyond its
range ends, as the contract says (over raw frames on a pty)."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from device.serial import contract as C
from device.serial import messages as M
from device.serial.firmware import CONFORMANCE_TARGETS

from ..conftest import start_emulator, stop_emulator
from .test_state_table import Host

ROOT = Path(__file__).resolve().parents[2]


def test_generated_files_are_current():
    """`make contract` was run after the contract last changed."""
    assert (ROOT / C.HEADER).read_text() == C.render_header(), "run `make contract`"
    doc = (ROOT / C.DOC).read_text()
    assert C.render_doc(doc) == doc, "run `make contract`"


#: the shared core that reads every command and writes every report
FIRMWARE_CORE = ("firmware/src/device.c", "firmware/src/wire.c")


def test_the_firmware_handles_every_field_of_the_newest_version():
    """Issue 54 item 2: a field added to the contract and not handled by the firmware fails
    here, by name. The firmware reads a command's fields and writes a report's through the
    accessors hl_contract.h generates (hl_<message>_<field>, hl_<message>_set_<field>), so
    a field it handles is one whose accessor it calls; a field it may leave alone says why
    in the contract (``Field.unused``)."""
    code = "".join((ROOT / f).read_text() for f in FIRMWARE_CORE)
    missing = []
    for spec in C.SPECS:
        if C.PROTOCOL not in spec.versions:
            continue
        fields = [f for f in spec.fields if not f.unused] + \
            ([spec.items] if spec.items else [])
        for f in fields:
            name = "item" if f is spec.items else f.name
            call = (f"hl_{spec.name.lower()}_{name}(" if spec.sender == "host" else
                    f"hl_{spec.name.lower()}_set_{name}(")
            if call not in code:
                missing.append(f"{spec.name}.{f.name} ({call}…) ")
    assert not missing, "the firmware never handles " + ", ".join(missing)


def test_the_documents_hand_written_tables_say_what_the_contract_says():
    """Issue 54 item 2: the tables of sections 5 and 6 that stay written by hand (their
    prose is the document's) list each message's fields with the contract's types in the
    contract's order, the SCENE_BEGIN table its offsets and size, and the title the one
    protocol version (contract.PROTOCOL)."""
    import re

    doc = (ROOT / C.DOC).read_text()
    assert doc.splitlines()[0] == f"# hapticlab wire protocol, version {C.PROTOCOL}"
    wrong, seen = [], set()
    for line in doc.splitlines():
        m = re.match(r"\| 0x([0-9a-f]{2}) \| ([A-Z_]+) \| (.*?) \|", line)
        if not m or m[2] not in C.BY_NAME or m[2] in seen or m[3].strip().isdigit():
            continue  # not a body row, or the generated table of §5a (offsets)
        spec = C.BY_NAME[m[2]]
        seen.add(m[2])
        if m[3].startswith("see below"):
            continue
        said = [t for t in re.findall(r"`([uif]\d+)(?:\[[^\]]*\])? ?[^`]*`", m[3])]
        want = [f.type if not f.type.startswith("bytes") else "u8" for f in spec.fields]
        want += [spec.items.type] if spec.items else []
        if said != want:
            wrong.append(f"{m[2]}: the table says {said}, the contract {want}")
    assert seen == set(C.BY_NAME), set(C.BY_NAME) - seen
    begin = C.BY_NAME["SCENE_BEGIN"]
    rows = re.findall(r"^\| (\d+) \| ([uif]\d+) \| (\w+) \|", doc, re.M)
    assert [(int(o), t) for o, t, _ in rows] == [(o, f.type) for f, o in C._offsets(begin)]
    assert f"**SCENE_BEGIN** body ({begin.fixed_size} bytes)" in doc
    assert not wrong, "\n".join(wrong)


def test_no_literal_offset_or_size_in_the_firmware_core():
    """The executor and the C tests take offsets and sizes from hl_contract.h: no `b + 36`,
    no SCENE_BEGIN size 43 written out."""
    import re

    for f in (*FIRMWARE_CORE, "firmware/tests/device_test.c", "firmware/tests/hl_test.c"):
        text = (ROOT / f).read_text()
        literal = re.findall(r"\b(?:b|c|h|l|p|t|v|ch|sw|tc|body)\s*\+\s*\d+\b"  # b + 36
                             r"|\b(?:b|c|t|sw|tc|lim|body|f\.body)\[\d+\]"  # b[35]
                             r"|last_body\[[^\]]+\]\s*(?:\+\s*\d+|\[\d+\])"
                             r"|(?<![.\d])43\b", text)  # SCENE_BEGIN's size
        assert not literal, (f, literal)


def test_every_message_class_is_its_contract_entry():
    assert {cls.NAME for cls in M.MESSAGES.values()} == set(C.BY_NAME)
    for cls in M.MESSAGES.values():
        spec = C.BY_NAME[cls.NAME]
        names = [f.name for f in dataclasses.fields(cls)]
        expect = [f.name for f in spec.fields] + (["items"] if spec.items else [])
        assert names == expect, cls.__name__
        assert cls.TYPE == spec.type and cls.FMT == spec.fmt


def test_the_state_table_gate_reads_the_documented_cells():
    s = M.Status
    assert C.gate("START_WINDOW", C.STATES.index("IDLE")) == s.BAD_STATE
    assert C.gate("HOME", C.STATES.index("FAULT")) == s.FAULT_LATCHED
    assert C.gate("SCENE_CHUNK", C.STATES.index("PLAYING")) == s.BUSY
    assert C.gate("ESTOP", C.STATES.index("WINDOW")) == s.OK
    assert C.gate("TRACE_REQUEST", 0) == C.gate("ACK", 4) == s.BAD_MESSAGE


LIMITS = {"table_items": 16_384, "play_items": 37_888, "channels": 0x7F, "max_decimation": 100,
          "current_limit_ma": 1400}


def _bounded():
    """(message, field) of every host → device field with a stated bound."""
    for spec in C.SPECS:
        if spec.sender != "host" or spec.versions == (1,):
            continue
        for f in spec.fields + ((spec.items,) if spec.items else ()):
            if f.lo is not None or f.hi is not None or f.subset or f.type == "f32":
                yield spec, f


def _limit(v, limits=LIMITS):
    return limits[v] if isinstance(v, str) else v


def _beyond(f: C.Field, limits=LIMITS) -> list:
    """Values just outside the field's range (and, for f32, the non-finite ones)."""
    out = []
    if f.subset:
        return [0, _limit(f.subset, limits) + 1]
    lo, hi = _limit(f.lo, limits), _limit(f.hi, limits)
    if f.type == "f32":
        out += [math.nan, math.inf, -math.inf]
        if lo is not None:
            out.append(float(np.nextafter(np.float32(C.f32(lo)), np.float32(-np.inf))))
        if hi is not None:
            out.append(float(np.nextafter(np.float32(C.f32(hi)), np.float32(np.inf))))
        return out
    tlo, thi = {"u8": (0, 255), "u16": (0, 65535), "u32": (0, 2**32 - 1),
                "i32": (-2**31, 2**31 - 1)}[f.type]
    if lo is not None and lo > tlo:
        out.append(int(lo) - 1)
    if hi is not None and hi < thi:
        out.append(int(hi) + 1)
    return out


def _ends(f: C.Field, limits=LIMITS) -> list:
    if f.subset:
        return [1, _limit(f.subset, limits)]
    return [x for x in (_limit(f.lo, limits), _limit(f.hi, limits)) if x is not None]


@pytest.mark.parametrize(("spec", "f"), list(_bounded()), ids=lambda x: getattr(x, "name", ""))
def test_check_refuses_just_beyond_and_accepts_the_ends(spec, f):
    base = BASE[spec.name]
    for x in _beyond(f):
        with pytest.raises(C.RangeError, match=rf"{spec.name}\.{f.name}"):
            _with(base, f, x).check(LIMITS)
    for x in _ends(f):
        _with(base, f, x).check(LIMITS)


@given(surface=st.integers(-2**31, 2**31 - 1), spring=st.floats(width=32))
def test_check_is_the_range_for_any_value(surface, spring):
    msg = dataclasses.replace(BASE["SCENE_BEGIN"], surface_um=surface, spring=spring)
    inside = abs(surface) <= C.MAX_SURFACE_UM and 0.0 <= spring <= 1e6  # NaN: False
    try:
        msg.check()
        ok = True
    except C.RangeError:
        ok = False
    assert ok == inside


#: one valid instance of each host → device command (a real sample, kind 0: a
#: SCENE_SUPPORT for it is valid; a chunk of no items fits any table)
BASE = {
    "HELLO": M.Hello(C.PROTOCOL),
    "SCENE_BEGIN": M.SceneBegin(1, 0, 0, 0.0, 1000.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0, 1.0),
    "SCENE_VELOCITIES": M.SceneVelocities(1, ()),
    "SCENE_CHUNK": M.SceneChunk(1, 0, 0, ()),
    "SCENE_SUPPORT": M.SceneSupport(1, 500.0, 1.0),
    "SCENE_COMMIT": M.SceneCommit(1, 0),
    "HOME": M.Home(20_000),
    "START_WINDOW": M.StartWindow(3, 100, 100, 0),
    "PLAY_CHUNK": M.PlayChunk(0, 0, ()),
    "PLAY_START": M.PlayStart(4, 10),
    "SET_LIMIT": M.SetLimit(1000),
    "TRACE_CONFIG": M.TraceConfig(0x7F, 1),
    "LINK_QUERY": M.LinkQuery(0),
}


def _with(base: M.Message, f: C.Field, x) -> M.Message:
    """``base`` with field ``f`` = x (an array item: one item of value x, counted; a count:
    that many items)."""
    spec = C.BY_NAME[base.NAME]
    if f.name == spec.count:
        return dataclasses.replace(base, **{f.name: x, "items": (0,) * x})
    if f is spec.items:
        changes = {"items": (x,)}
        if spec.count:
            changes[spec.count] = 1
        return dataclasses.replace(base, **changes)
    return dataclasses.replace(base, **{f.name: x})


#: ends a target refuses by a rule between fields (the document's "and" rows)
STATEFUL = {("SCENE_BEGIN", "kind", 2),  # a table scene needs rows; the base has none
            ("SCENE_BEGIN", "rows", 0)}  # and the rows' test uses a table scene


def _table(items: int) -> tuple[int, int]:
    """(rows, row_len) of a table of exactly ``items`` (a device's whole table)."""
    for rows in range(1, C.MAX_ROWS + 1):
        if items % rows == 0 and items // rows <= 0xFFFF:
            return rows, items // rows
    raise AssertionError(f"no table shape holds exactly {items} items")


def _setup(spec: C.Spec, f: C.Field, limits: dict) -> tuple[M.Message | None, M.Message]:
    """(the scene to begin first, the base command) for testing field ``f``, chosen so that
    no other rule refuses the command: only the field's own range can."""
    base = BASE[spec.name]
    if spec.name == "SCENE_BEGIN" and f.name == "rows":  # a table scene: rows x 1 item
        return None, dataclasses.replace(base, kind=2, rows=1, row_len=1)
    if spec.name == "SCENE_VELOCITIES":  # a one-row table scene takes one speed
        return M.SceneBegin(1, 2, 0, 680.0, 0, 0, 0, 0, 0, 0, 1, 1, 0, 1.0), base
    if spec.name == "SCENE_CHUNK":  # a table scene as large as the device's table
        rows, row_len = _table(limits["table_items"])
        return M.SceneBegin(1, 2, 0, 680.0, 0, 0, 0, 0, 0, 0, rows, row_len, 0, 1.0), base
    if spec.name == "TRACE_CONFIG":  # the base channels the device records (no accel on a
        return None, dataclasses.replace(base, channels=limits["channels"] & 0x7F)  # bridge)
    return None, base


#: under QEMU (an emulated board on a busy computer) a shorter subset: the fields behind the
#: safety findings, and one of each kind (i32, f32, u32, u16, a count, a bit mask)
QEMU_FIELDS = {("SCENE_BEGIN", "surface_um"), ("SCENE_BEGIN", "spring"),
               ("SCENE_BEGIN", "attenuation"), ("HOME", "clearance_um"), ("SCENE_CHUNK", "n"),
               ("SET_LIMIT", "current_ma"), ("TRACE_CONFIG", "channels")}


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.slow
@pytest.mark.parametrize("firmware", [*CONFORMANCE_TARGETS,
                                      pytest.param("qemu", marks=pytest.mark.qemu)])
def test_every_target_refuses_every_field_beyond_its_range(firmware):
    """Each bounded field of each command, in IDLE with a real sample committed: just
    beyond its range (NaN and ±inf for every f32) BAD_MESSAGE and nothing changes; at its
    ends, anything but BAD_MESSAGE (unless a rule between fields forbids that end). The
    same suite on every target: the Python emulator, the firmware built for this machine
    (as is, with the board's resources, and those under ASan and UBSan), and the Cortex-M
    build under QEMU (a subset)."""
    emu = start_emulator("--firmware", firmware, "--seed", "3")
    host = Host(emu.port)
    wrong = []
    try:
        assert host.ask(M.Hello(C.PROTOCOL)) == "hello"
        lim = host.limits
        limits = {"table_items": lim.table_items, "play_items": lim.play_items,
                  "channels": lim.channels, "max_decimation": lim.max_decimation,
                  "current_limit_ma": host.rating_ma}
        moved = True  # the device may not be in IDLE yet: wait for a STATUS to say it is
        for spec, f in _bounded():
            if firmware == "qemu" and (spec.name, f.name) not in QEMU_FIELDS:
                continue
            scene, base = _setup(spec, f, limits)
            for x in _beyond(f, limits):
                _ready(host, scene, settle=moved)
                got = host.ask(_with(base, f, x))
                state = host.settled_state()
                moved = got != M.Status.BAD_MESSAGE or state != "IDLE"
                if moved:
                    wrong.append(f"{spec.name}.{f.name} = {x}: {got}, then {state}")
            for x in _ends(f, limits):
                if (spec.name, f.name, x) in STATEFUL:
                    continue
                _ready(host, scene, settle=moved)
                got = host.ask(_with(base, f, x))
                moved = True  # an accepted HOME, START_WINDOW or PLAY_START leaves IDLE
                if got == M.Status.BAD_MESSAGE:
                    wrong.append(f"{spec.name}.{f.name} = {x} (an end of its range): "
                                 "BAD_MESSAGE")
    finally:
        host.close()
        stop_emulator(emu)
        print(emu.stderr())  # shown when the test fails: the target's own account at exit
    assert not wrong, "\n".join(wrong)
    sanitizer = [line for line in emu.stderr_lines if "runtime error" in line
                 or "Sanitizer" in line]
    assert not sanitizer, "".join(sanitizer)


def _ready(host: Host, scene: M.Message | None, settle: bool = True) -> None:
    """IDLE, a real sample begun and committed (ids 1), the rating and trace defaults; then
    ``scene`` begun (id 1), when given. ``settle``: wait for STATUS reports to say IDLE
    after the ZERO (the last command may have left IDLE); without it the device is known
    to be in IDLE (a STATUS said so after the last command, which was refused)."""
    host.clear()
    host.ask(M.Zero())
    host.ask(M.Hello(C.PROTOCOL))
    if settle:
        end = time.monotonic() + 5  # a playback the ZERO ended may take a moment to end
        while (state := host.settled_state()) != "IDLE" and time.monotonic() < end:
            pass
        assert state == "IDLE", f"still {state} 5 s after ZERO"
    assert host.ask(BASE["SCENE_BEGIN"]) == M.Status.OK
    assert host.ask(BASE["SCENE_COMMIT"]) == M.Status.OK
    if scene is not None:
        assert host.ask(scene) == M.Status.OK


def test_range_errors_name_the_field_before_anything_is_sent():
    msg = dataclasses.replace(BASE["SCENE_BEGIN"], surface_um=-2**31)
    with pytest.raises(C.RangeError, match=r"SCENE_BEGIN\.surface_um = -2147483648 outside "
                                           r"-500,000 … 500,000 µm"):
        msg.check()
    with pytest.raises(C.RangeError, match=r"SET_LIMIT\.current_ma = 1401 outside 1 … "
                                           r"HELLO_ACK\.current_limit mA"):
        M.SetLimit(1401).check(LIMITS)
