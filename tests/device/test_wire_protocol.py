"""The wire protocol: framing, every message, the document's examples, fuzzing."""

import dataclasses
import re
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from device.serial import contract as C
from device.serial import messages as M
from device.serial.framing import (
    MAX_PAYLOAD,
    FrameDecoder,
    FramingError,
    cobs_decode,
    cobs_encode,
    decode_payload,
    encode_frame,
)
from device.serial.fuzz import fuzz

DOC = Path(__file__).resolve().parents[2] / "docs" / "wire-protocol.md"


def test_crc_is_the_documented_crc32():
    assert zlib.crc32(b"123456789") == 0xCBF43926  # CRC-32/ISO-HDLC check value


def test_document_examples_decode_as_stated():
    text = DOC.read_text(encoding="utf-8")
    examples = re.findall(r"^example: ([0-9a-f ]+)\n= (.+), seq (\d+)$", text, re.M)
    assert len(examples) >= 15
    types = set()
    for hexstr, expected, seq in examples:
        (frame,) = FrameDecoder().feed(bytes.fromhex(hexstr))
        msg = M.decode(frame)
        # every field the example states, as it states it (a field appended since the
        # example was written is not in it: the growth rule, §1b)
        name, _, stated = expected.partition("(")
        assert type(msg).__name__ == name
        for part in re.findall(r"(\w+)=((?:\([^)]*\))|b'[^']*'|[^,)]+)", stated):
            assert repr(getattr(msg, part[0])) == part[1], (name, part)
        assert frame.seq == int(seq)
        types.add(type(msg))
    assert {M.Hello, M.HelloAck, M.SceneBegin, M.Contact, M.WindowDone, M.TraceBlock} <= types


def test_document_states_the_layouts_the_code_uses():
    text = DOC.read_text(encoding="utf-8")
    assert f"**SCENE_BEGIN** body ({struct.calcsize('<' + M.SceneBegin.FMT)} bytes)" in text
    for cls in M.MESSAGES.values():
        assert f"0x{cls.TYPE:02x}" in text, cls.__name__


def test_the_documented_sizes_are_the_encoders():
    """The document once said 1,034 bytes on the wire where the encoder's worst case is
    1,030: the largest payload of bytes that are never zero (COBS's worst), delimited."""
    text = " ".join(DOC.read_text(encoding="utf-8").split())
    worst = len(cobs_encode(b"\x01" * MAX_PAYLOAD)) + 1
    assert f"at most {worst:,} bytes on the wire" in text
    longest = max(4 + s.fixed_size + 4 + (s.max_items or 0) * (s.items.size if s.items else 0)
                  for s in C.SPECS if s.fixed_items is None)
    assert longest <= MAX_PAYLOAD
    assert f"The longest message is {longest:,} bytes of payload" in text


@given(st.binary(max_size=2000))
def test_cobs_round_trip(data):
    enc = cobs_encode(data)
    assert 0 not in enc
    assert cobs_decode(enc) == data
    assert len(enc) <= len(data) + len(data) // 254 + 1


@given(mtype=st.integers(0, 255), seq=st.integers(0, 65535),
       body=st.binary(max_size=MAX_PAYLOAD - 8))
def test_frame_round_trip(mtype, seq, body):
    f = encode_frame(mtype, seq, body)
    assert f.endswith(b"\x00") and f.count(0) == 1
    out = decode_payload(f[:-1])
    assert (out.type, out.seq, out.body) == (mtype, seq, body)


@given(chunks=st.lists(st.integers(1, 64), min_size=1, max_size=30), n=st.integers(1, 10))
def test_decoder_handles_any_chunking(chunks, n):
    frames = [M.encode(M.Contact(1, i, -i), i) for i in range(n)]
    stream = b"".join(frames)
    dec, got, pos, k = FrameDecoder(), [], 0, 0
    while pos < len(stream):
        step = chunks[k % len(chunks)]
        got += dec.feed(stream[pos: pos + step])
        pos += step
        k += 1
    assert [f.seq for f in got] == list(range(n))


_TYPE_RANGE = {"u8": (0, 255), "u16": (0, 65535), "u32": (0, 2**32 - 1), "u64": (0, 2**64 - 1),
               "i16": (-32768, 32767), "i32": (-2**31, 2**31 - 1)}


def _field(f: C.Field):
    """Any value the contract allows in field ``f`` (bounds that name a device limit: the
    type's range)."""
    if f.type.startswith("bytes"):  # fixed-width text: no trailing zeros (they are padding)
        return st.binary(max_size=int(f.type[5:])).map(lambda b: b.rstrip(b"\x00"))
    lo = f.lo if isinstance(f.lo, (int, float)) else None
    hi = f.hi if isinstance(f.hi, (int, float)) else None
    if f.type == "f32":
        return st.floats(min_value=C.f32(lo), max_value=C.f32(hi), width=32, allow_nan=False,
                         allow_infinity=False)
    tlo, thi = _TYPE_RANGE[f.type]
    lo = tlo if lo is None else int(lo)
    return st.integers(max(lo, 1) if f.subset else lo, thi if hi is None else int(hi))


def _strategy(cls):
    spec = C.BY_NAME[cls.NAME]
    head = [_field(f) for f in spec.fields]
    if spec.items is None:
        return st.tuples(*head).map(lambda v: cls(*v))
    names = [f.name for f in dataclasses.fields(cls)]
    items = st.lists(_field(spec.items), max_size=min(60, cls.MAX_ITEMS)).map(tuple)

    def build(v):
        *h, it = v
        if cls is M.TraceChunk:  # n records of one item per channel in the mask
            h[names.index("channels")] = 0b101
            it = it[: len(it) // 2 * 2]
            h[names.index("n")] = len(it) // 2
        elif cls.ITEMS is not None:  # an array of fixed length
            it = (tuple(it) + (0,) * cls.ITEMS)[: cls.ITEMS]
        elif "n" in names:  # the count field must match the items
            h[names.index("n")] = len(it)
        return cls(*h, it)

    return st.tuples(*head, items).map(build)


@pytest.mark.parametrize("cls", list(M.MESSAGES.values()), ids=lambda c: c.__name__)
def test_every_message_round_trips(cls):
    newest = C.BY_NAME[cls.NAME].versions[-1]

    @given(msg=_strategy(cls), seq=st.integers(0, 65535))
    def check(msg, seq):
        (frame,) = FrameDecoder().feed(M.encode(msg, seq, newest))
        assert frame.seq == seq
        assert M.decode(frame) == msg

    check()


def test_misfit_bodies_are_message_errors():
    with pytest.raises(M.MessageError, match="n = 5 but 3 items"):
        M.SceneChunk.from_body(struct.pack("<HIH", 1, 0, 5) + struct.pack("<3h", 1, 2, 3))
    with pytest.raises(M.MessageError, match="expected at least 4"):
        M.Home.from_body(b"\x01\x02")
    with pytest.raises(M.MessageError, match="unknown message type 0x7f"):
        (frame,) = FrameDecoder().feed(encode_frame(0x7F, 1, b""))
        M.decode(frame)


def test_bad_frames_are_counted_not_accepted():
    good = M.encode(M.Ping(5), 3)
    dec = FrameDecoder()
    bad_crc = bytearray(good)
    bad_crc[3] ^= 0x10
    wrong_version = cobs_encode(bytes([2]) + decode_payload(good[:-1]).body) + b"\x00"
    assert dec.feed(bytes(bad_crc) + b"\x01\x02\x03\x00" + wrong_version + good) != []
    assert dec.frames_ok == 1
    assert dec.errors["crc"] >= 1 and sum(dec.errors.values()) >= 3
    with pytest.raises(FramingError, match="exceeds"):
        encode_frame(1, 1, bytes(MAX_PAYLOAD))


def test_mutation_fuzzer_accepts_no_corrupt_frame():
    """10⁴ frames, half mutated (bit flips, truncation, insertion, overwrite), a fifth with
    garbage in front: 0 corrupt frames accepted, every clean frame after any corruption
    decoded (resynchronisation within one frame). 10⁶ in `hapticlab bench link --fuzz`."""
    r = fuzz(10_000, seed=11)
    assert r.mutated > 4000
    assert r.accepted_corrupt == 0
    assert r.intact_lost == 0
    assert r.decoded > 3000


def test_fixed_point_encodings_keep_their_resolution():
    v = 0.114523  # m/s → nm/s
    (frame,) = FrameDecoder().feed(M.encode(M.Contact(1, 10, int(round(v * 1e9))), 1))
    assert M.decode(frame).velocity_nm_s * 1e-9 == pytest.approx(v, abs=5e-10)
    f = np.array([0.0005, -1.2344, 3.0])  # N → mN LSB
    q = np.round(f * 1000).astype("<i2")
    assert np.max(np.abs(q / 1000 - f)) <= 0.0005 + 1e-12


@given(st.floats(-1e3, 1e3, allow_nan=False))
def test_contact_speeds_beyond_the_wire_range_saturate_instead_of_failing(v):
    """A hard block's ringing makes the encoder read rebounds faster than the i32 nm/s field
    holds (aluminum: 3.7 m/s); the emulator used to crash encoding them."""
    (frame,) = FrameDecoder().feed(M.encode(M.Contact(1, 5, M.contact_velocity_nm_s(v)), 3))
    got = M.decode(frame).velocity_nm_s * 1e-9
    assert got == pytest.approx(max(-2.147483647, min(2.147483647, v)), abs=1e-9)
