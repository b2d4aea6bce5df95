"""Messages of the hapticlab wire protocol, versions 1 to 3 (docs/wire-protocol.md).

Each message is a frozen dataclass named after its entry in the wire contract
(:mod:`device.serial.contract`), which gives its type byte, little-endian layout in each
version, item counts and field ranges. Units and fixed-point encodings are stated per
field. A message decoded from a version whose layout lacks a field (a version-2 device's
LIMITS has no ``capabilities``), or from a body that ends before it (docs §1b), has None
there: not stated, never a made-up zero.
"""

from __future__ import annotations

import struct
from dataclasses import astuple, dataclass, fields
from typing import ClassVar

from . import contract as C
from .framing import Frame, FramingError, encode_frame

__all__ = ["MESSAGES", "encode", "decode", "Status", "Channel", "FaultCode", "State",
           "MessageError", "contact_velocity_nm_s", "limit_values"]


class MessageError(FramingError):
    """A frame decoded but its body does not fit its message type."""


class Status:
    """ACK status codes."""

    OK = 0
    BAD_MESSAGE = 1  #: body does not fit the type, or a field is out of range
    BAD_STATE = 2  #: not allowed now (e.g. a window before HOME, a chunk without BEGIN)
    FAULT_LATCHED = 3  #: output is latched off (e-stop, watchdog); CLEAR_FAULT first
    UNKNOWN_SCENE = 4  #: scene id not begun or not committed
    TABLE_CRC = 5  #: SCENE_COMMIT's CRC-32 differs from the table received
    BUSY = 6  #: a window or playback is running

    NAMES: ClassVar[dict[int, str]] = {0: "ok", 1: "bad message", 2: "bad state",
                                       3: "fault latched", 4: "unknown scene",
                                       5: "table CRC mismatch", 6: "busy"}


class FaultCode:
    """Why output latched off (FAULT.code, STATUS.fault, WINDOW_DONE.fault)."""

    WATCHDOG = 1
    ESTOP = 2
    NONFINITE = 3  #: the servo computed a current that is not finite
    DEVICE = 4  #: the device's own I/O failed (a bridge's SDK call, a servo held up)
    FORCE_BUTTON = 5  #: a commercial device's force button or dead-man switch cut its forces
    VELOCITY_LIMIT = 6  #: the device's own velocity limit cut its forces
    FORCE_LIMIT = 7  #: the device's own force or force-impulse limit cut its forces
    MOTOR_HEAT = 8  #: the device's motors are too warm: it cut its forces
    CALIBRATION = 9  #: the device is not calibrated (or lost it): its heights are not absolute
    NAMES: ClassVar[dict[int, str]] = dict(C.FAULTS)


class State:
    IDLE, HOMED, WINDOW, PLAYING, FAULT = range(5)


class Channel:
    """Trace channels (TRACE_REQUEST / TRACE_BLOCK), all IEEE-754 binary32, SI units."""

    NAMES: ClassVar[tuple[str, ...]] = ("position", "velocity", "force_cmd", "force_out",
                                        "current", "accel", "flags", "true_position",
                                        "true_velocity", "true_accel")


@dataclass(frozen=True)
class Message:
    """A message of the wire contract (:mod:`device.serial.contract`), named by ``NAME``;
    its type byte, struct layout (``FMT``), trailing array (``ARRAY``, the struct code of
    its items) and item counts come from the contract's entry."""

    NAME: ClassVar[str] = ""
    TYPE: ClassVar[int] = -1
    FMT: ClassVar[str] = ""
    ARRAY: ClassVar[str | None] = None  # struct code of a trailing array field "items"
    ITEMS: ClassVar[int | None] = None  # the array's fixed length, when it has one
    MAX_ITEMS: ClassVar[int | None] = None  # the most items one frame carries

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        spec = C.BY_NAME[cls.NAME]
        # a field appended to the contract and not declared here joins the class at its end
        # (before @dataclass reads the class): the growth rule appends fields only
        ann = cls.__dict__.get("__annotations__", {})
        for f in spec.fields:
            if f.name not in ann:
                kind = {"f32": float}.get(f.type, bytes if f.type.startswith("bytes") else int)
                ann[f.name] = kind.__name__
                setattr(cls, f.name, kind())
        cls.__annotations__ = ann
        cls.TYPE, cls.FMT = spec.type, spec.fmt
        cls.ARRAY = spec.items.code if spec.items is not None else None
        cls.ITEMS = spec.fixed_items
        cls.MAX_ITEMS = spec.fixed_items or spec.max_items

    def body(self, version: int = C.PROTOCOL) -> bytes:
        """The body as protocol ``version`` lays it out (its fields only)."""
        layout = C.BY_NAME[self.NAME].layout(version)
        fmt = "".join(f.code for f in layout)
        head = struct.pack("<" + fmt, *(getattr(self, f.name) for f in layout))
        if self.ARRAY is None:
            return head
        items = self.items  # type: ignore[attr-defined]
        return head + struct.pack(f"<{len(items)}{self.ARRAY}", *items)

    @classmethod
    def from_body(cls, body: bytes, version: int = C.PROTOCOL) -> Message:
        """The message in ``body``, laid out as protocol ``version`` lays it out (docs §1b).

        Before the growth rule the body is exactly its length; from it on, at least the
        length the version was published with: fields past the body's end are None (or 0
        in a command, whose appended fields mean by 0 what it meant before), and bytes
        past the fields this code knows are ignored in a report, and must be zero in a
        command (a device cannot do what it does not know)."""
        spec = C.BY_NAME[cls.NAME]
        if version not in spec.versions:
            raise MessageError(f"{cls.__name__}: not in protocol version {version}")
        layout = spec.layout(version)
        size = spec.size(version)
        # a field the version does not have: absent (0 in a command: what it meant before)
        values = dict.fromkeys((f.name for f in spec.fields),
                               0 if spec.sender == "host" else None)
        if cls.ARRAY is None:
            grows = version >= C.EXTENSIBLE_FROM and cls.NAME not in C.FOREVER
            least = C.min_size(spec, version) if grows else size
            if len(body) < least or (not grows and len(body) != size):
                raise MessageError(f"{cls.__name__}: body of {len(body)} bytes, expected "
                                   + (f"at least {least}" if grows else f"{size}"))
            if spec.sender == "host" and any(body[size:]):
                raise MessageError(f"{cls.__name__}: bytes {size}–{len(body) - 1} ask for "
                                   "fields this device does not know")
            at = 0
            for f in layout:
                if at + f.size > len(body):
                    values[f.name] = 0 if spec.sender == "host" else None
                else:
                    values[f.name] = struct.unpack_from("<" + f.code, body, at)[0]
                at += f.size
            return cls(**values)
        item = struct.calcsize("<" + cls.ARRAY)
        if len(body) < size or (len(body) - size) % item:
            raise MessageError(f"{cls.__name__}: body of {len(body)} bytes does not fit "
                               f"{size} + n×{item}")
        n = (len(body) - size) // item
        if cls.MAX_ITEMS is not None and n > cls.MAX_ITEMS:
            raise MessageError(f"{cls.__name__}: {n} items, at most {cls.MAX_ITEMS}")
        fmt = "".join(f.code for f in layout)
        values.update(zip((f.name for f in layout), struct.unpack("<" + fmt, body[:size]),
                          strict=True))
        obj = cls(**values, items=struct.unpack(f"<{n}{cls.ARRAY}", body[size:]))
        obj.check_count()
        return obj

    def check_count(self) -> None:
        n = getattr(self, "n", None)
        if n is not None and n != len(self.items):  # type: ignore[attr-defined]
            raise MessageError(f"{type(self).__name__}: n = {n} but "
                               f"{len(self.items)} items follow")  # type: ignore[attr-defined]
        if self.ITEMS is not None and len(self.items) != self.ITEMS:  # type: ignore
            raise MessageError(f"{type(self).__name__}: {len(self.items)} items, "  # type: ignore
                               f"expected {self.ITEMS}")

    def check(self, limits: dict[str, int] | None = None) -> None:
        """Raise :class:`~device.serial.contract.RangeError` naming the first field outside
        the range the contract gives it; ``limits``: the device's (:func:`limit_values`),
        None to skip the bounds that name them."""
        C.check(self.NAME, {f.name: getattr(self, f.name) for f in fields(self)}, limits)


def limit_values(limits: Limits | None, current_limit_ma: int | None) -> dict[str, int]:
    """The device's resources by the names the contract's bounds use."""
    out = {} if limits is None else {k: getattr(limits, k) for k in
                                     ("table_items", "play_items", "channels",
                                      "max_decimation")}
    if current_limit_ma is not None:
        out["current_limit_ma"] = current_limit_ma
    return out


def _str(b: bytes) -> str:
    return b.rstrip(b"\x00").decode("utf-8", "replace")


# ---------------------------------------------------------------- host → device
@dataclass(frozen=True)
class Hello(Message):
    """Open a session. host_protocol: the protocol version the host speaks."""

    NAME = "HELLO"
    host_protocol: int = 1


@dataclass(frozen=True)
class Heartbeat(Message):
    """Host is alive; resets the device watchdog. No reply."""

    NAME = "HEARTBEAT"


@dataclass(frozen=True)
class Ping(Message):
    """Round-trip probe; the device answers PONG with the same stamp. stamp: host µs (u32)."""

    NAME = "PING"
    stamp: int = 0


@dataclass(frozen=True)
class SceneBegin(Message):
    """Start a scene upload.

    kind: 0 real sample (no rendering), 1 spring, 2 spring + transient table.
    surface_um: surface height [µm, i32]. spring: [N/m, f32].
    stiffness, damping, ring_slope, ring_decay, ring_freq, block_mass: the real sample
    (:class:`~device.scene.Material`: [N/m], [N·s/m], [1/s], [1/s], [Hz], [kg; 0 for a
    sample that does not move], f32) — firmware ignores them; an emulator simulates the
    physical sample with them (a block's given support follows in SCENE_SUPPORT).
    rows, row_len: transient table size; blend: 0 scale, 1 nearest, 2 linear;
    attenuation: [1, f32].
    """

    NAME = "SCENE_BEGIN"
    scene_id: int = 0
    kind: int = 0
    surface_um: int = 0
    spring: float = 0.0
    stiffness: float = 0.0
    damping: float = 0.0
    ring_slope: float = 0.0
    ring_decay: float = 0.0
    ring_freq: float = 0.0
    block_mass: float = 0.0
    rows: int = 0
    row_len: int = 0
    blend: int = 0
    attenuation: float = 1.0


@dataclass(frozen=True)
class SceneVelocities(Message):
    """Reference speed of each table row [m/s, f32], ascending."""

    NAME = "SCENE_VELOCITIES"
    scene_id: int = 0
    items: tuple = ()


@dataclass(frozen=True)
class SceneChunk(Message):
    """Part of the force table, row-major: offset [samples, u32], n, items [i16, 1 mN LSB]."""

    NAME = "SCENE_CHUNK"
    scene_id: int = 0
    offset: int = 0
    n: int = 0
    items: tuple = ()


@dataclass(frozen=True)
class SceneSupport(Message):
    """What a real block rests on: stiffness [N/m, f32], damping [N·s/m, f32] (emulators)."""

    NAME = "SCENE_SUPPORT"
    scene_id: int = 0
    stiffness: float = 0.0
    damping: float = 0.0


@dataclass(frozen=True)
class SceneCommit(Message):
    """Finish the upload; crc32 over the table's i16 LE bytes (0 when there is no table)."""

    NAME = "SCENE_COMMIT"
    scene_id: int = 0
    crc32: int = 0


@dataclass(frozen=True)
class Home(Message):
    """Move to rest clearance_um [µm, u32] above the surface; enable output with a ramp."""

    NAME = "HOME"
    clearance_um: int = 20_000


@dataclass(frozen=True)
class StartWindow(Message):
    """Run a tapping window: duration_ms from the first contact (or from now when
    from_contact = 0); timeout_ms to wait for a first contact."""

    NAME = "START_WINDOW"
    window_id: int = 0
    duration_ms: int = 5000
    timeout_ms: int = 30000
    from_contact: int = 1


@dataclass(frozen=True)
class StopWindow(Message):
    NAME = "STOP_WINDOW"


@dataclass(frozen=True)
class PlayChunk(Message):
    """Open-loop force buffer: offset [samples, u32], n, items [i16, 1 mN LSB]."""

    NAME = "PLAY_CHUNK"
    offset: int = 0
    n: int = 0
    items: tuple = ()


@dataclass(frozen=True)
class PlayStart(Message):
    """Play the buffer's first n_samples in free air with the hand holding the stylus."""

    NAME = "PLAY_START"
    window_id: int = 0
    n_samples: int = 0


@dataclass(frozen=True)
class SetLimit(Message):
    """Clamp the amplifier current at current_ma [mA, u16, 1 … rating] from now on; a HELLO
    restores the rating."""

    NAME = "SET_LIMIT"
    current_ma: int = 0


@dataclass(frozen=True)
class EStop(Message):
    NAME = "ESTOP"


@dataclass(frozen=True)
class ClearFault(Message):
    NAME = "CLEAR_FAULT"


@dataclass(frozen=True)
class Zero(Message):
    NAME = "ZERO"


@dataclass(frozen=True)
class TraceRequest(Message):
    """Ask for count samples of a channel of a finished window, from sample start."""

    NAME = "TRACE_REQUEST"
    window_id: int = 0
    channel: int = 0
    start: int = 0
    count: int = 0


@dataclass(frozen=True)
class TraceConfig(Message):
    """Version 2: the channels (bit mask, bit i = channel i) and decimation (1 record per
    ``decimation`` servo ticks) streamed during the following windows and playbacks."""

    NAME = "TRACE_CONFIG"
    channels: int = 0x7F
    decimation: int = 1


@dataclass(frozen=True)
class LinkQuery(Message):
    """Version 2: ask for LINK_REPORT, the device's view of the host's frames since HELLO
    or the last reset; ``reset`` 1 starts counting afresh after the report."""

    NAME = "LINK_QUERY"
    reset: int = 0


# ---------------------------------------------------------------- device → host
@dataclass(frozen=True)
class Ack(Message):
    """Reply to every command: the command's seq and a Status code."""

    NAME = "ACK"
    ack_seq: int = 0
    status: int = 0


@dataclass(frozen=True)
class HelloAck(Message):
    """Device identity and ratings.

    servo_rate_hz [u32]; current_limit_ma [mA, u16]; force_constant [mN/A, u16];
    effective_mass [mg, u32]; watchdog_ms [u16]; encoder_nm [nm, u32];
    accel_range [mm/s², u32]; model (32 bytes), serial (16), firmware (16): UTF-8,
    zero-padded.
    """

    NAME = "HELLO_ACK"
    protocol: int = 1
    servo_rate_hz: int = 10_000
    current_limit_ma: int = 1400
    force_constant: int = 2150
    effective_mass: int = 55_000
    watchdog_ms: int = 100
    encoder_nm: int = 10_000
    accel_range: int = 490_333
    model: bytes = b""
    serial: bytes = b""
    firmware: bytes = b""

    @property
    def strings(self) -> tuple[str, str, str]:
        return _str(self.model), _str(self.serial), _str(self.firmware)

    @classmethod
    def from_body(cls, body: bytes, version: int = C.PROTOCOL) -> Message:
        m = super().from_body(body, version)
        return cls(*astuple(m)[:8], *(b.rstrip(b"\x00") for b in astuple(m)[8:]))


@dataclass(frozen=True)
class Limits(Message):
    """Version 2, sent right after HELLO_ACK: the device's resources. table_items and
    play_items [i16 items]; ring_records: the trace ring buffer [records]; channels: the
    channels it records (bit mask); max_decimation; link_bytes_s: the bytes per second its
    link carries towards the host [B/s] (e.g. 100,000 for a 1-Mbaud UART), 0 when the link
    is no limit (USB, a pty); tick_p99_us and tick_max_us: the 99th percentile and the
    longest of its servo's tick periods since it started [µs of wall time], where a servo
    loop runs on a computer's clock (the host builds, the bridges), 0 where not measured
    (a board's timer interrupt, the Python emulator); capabilities: what the device is and
    can do, a bit mask (:data:`~device.serial.contract.CAPABILITIES`; :meth:`can`)."""

    NAME = "LIMITS"
    table_items: int = 0
    play_items: int = 0
    ring_records: int = 0
    channels: int = 0
    max_decimation: int = 1
    link_bytes_s: int = 0
    tick_p99_us: int = 0
    tick_max_us: int = 0
    capabilities: int = 0

    def can(self, name: str) -> bool | None:
        """Whether the device states capability ``name`` (a value of
        :data:`~device.serial.contract.CAPABILITIES`, e.g. ``"simulated_contact"``); None
        where it states none (a version-2 device, whose LIMITS has no capabilities)."""
        bit = {v: k for k, v in C.CAPABILITIES.items()}[name]
        return None if self.capabilities is None else bool(self.capabilities >> bit & 1)


@dataclass(frozen=True)
class Pong(Message):
    NAME = "PONG"
    stamp: int = 0


@dataclass(frozen=True)
class Contact(Message):
    """A contact: window tick [u32] and incoming speed [nm/s, i32; ±2.1 m/s, a device
    saturates faster readings (:func:`contact_velocity_nm_s`)]."""

    NAME = "CONTACT"
    window_id: int = 0
    tick: int = 0
    velocity_nm_s: int = 0


def contact_velocity_nm_s(velocity: float) -> int:
    """A contact's speed [m/s] as the wire's i32 nm/s, saturated at ±2.147 m/s. Such speeds
    are not taps: the encoder's estimate during a hard block's ringing (aluminum's rebounds
    read up to 3.7 m/s) would otherwise not be encodable."""
    return int(max(-(2**31 - 1), min(2**31 - 1, round(velocity * 1e9))))


@dataclass(frozen=True)
class Saturation(Message):
    """A run of clamped ticks: start tick, duration [ticks], peak commanded current [mA, i32]."""

    NAME = "SATURATION"
    window_id: int = 0
    tick: int = 0
    duration: int = 0
    peak_ma: int = 0


@dataclass(frozen=True)
class Fault(Message):
    """Output latched off: FaultCode, device time [µs, u64] when output was zeroed."""

    NAME = "FAULT"
    code: int = 0
    time_us: int = 0


@dataclass(frozen=True)
class StatusReport(Message):
    """Sent at ≥ 20 Hz: device time [µs, u64], State, output force [mN, i32], latched
    FaultCode (0: none)."""

    NAME = "STATUS"
    time_us: int = 0
    state: int = 0
    output_mn: int = 0
    fault: int = 0


@dataclass(frozen=True)
class WindowDone(Message):
    """End of a window or playback: t0 [µs, u64] of tick 0, ticks recorded, first contact
    tick (−1: none), event counts, timed_out and fault flags."""

    NAME = "WINDOW_DONE"
    window_id: int = 0
    t0_us: int = 0
    n_ticks: int = 0
    first_contact: int = -1
    n_contacts: int = 0
    n_saturations: int = 0
    timed_out: int = 0
    fault: int = 0


@dataclass(frozen=True)
class TraceBlock(Message):
    """Samples start..start+n−1 of a channel [binary32, SI units]."""

    NAME = "TRACE_BLOCK"
    window_id: int = 0
    channel: int = 0
    start: int = 0
    n: int = 0
    items: tuple = ()


@dataclass(frozen=True)
class Position(Message):
    """During a window, at 20–50 Hz: the stylus's height above the surface [µm, i32] at a
    window tick (for the participant's cursor)."""

    NAME = "POSITION"
    window_id: int = 0
    tick: int = 0
    height_um: int = 0


@dataclass(frozen=True)
class TraceChunk(Message):
    """Version 2, streamed during a window: records start..start+n−1, each one binary32 per
    channel of the mask in channel order (``items`` record-major)."""

    NAME = "TRACE_CHUNK"
    window_id: int = 0
    channels: int = 1
    start: int = 0
    n: int = 0
    items: tuple = ()

    @property
    def width(self) -> int:
        return bin(self.channels).count("1")

    def check_count(self) -> None:
        if self.width == 0 or self.n * self.width != len(self.items):
            raise MessageError(f"TraceChunk: {self.n} records of {self.width} channels but "
                               f"{len(self.items)} items follow")


@dataclass(frozen=True)
class TraceLost(Message):
    """Version 2: records start..start+n−1 of a window were dropped on the device (its ring
    buffer overflowed); the trace has a gap there, said, never silent."""

    NAME = "TRACE_LOST"
    window_id: int = 0
    start: int = 0
    n: int = 0


#: LINK_REPORT's gap histogram: bins of this many µs of device time, the last one open
LINK_GAP_BIN_US = 2000
LINK_GAP_BINS = C.GAP_BINS  # LinkReport.ITEMS


@dataclass(frozen=True)
class LinkReport(Message):
    """Version 2, answering LINK_QUERY: what the device saw of the host since ``since_us``
    [µs, device clock] — intact frames, frames that failed a check, the longest gap between
    two intact frames [µs of device time], the longest an ESTOP took from its arrival to
    the tick that zeroed output (from when the device last found its input empty before
    it) [µs of device time; 0xFFFFFFFF: no ESTOP] and the gaps'
    histogram (``items``: 64 u16 counts, bin k for gaps in [2k, 2k + 2) ms, the last bin
    ≥ 126 ms; a count saturates at 65,535). The gaps are what the device's watchdog
    judges."""

    NAME = "LINK_REPORT"
    since_us: int = 0
    frames: int = 0
    bad_frames: int = 0
    max_gap_us: int = 0
    estop_max_us: int = 0xFFFFFFFF
    items: tuple = (0,) * LINK_GAP_BINS

    def check_count(self) -> None:
        if len(self.items) != LINK_GAP_BINS:
            raise MessageError(f"LinkReport: {len(self.items)} gap bins, expected "
                               f"{LINK_GAP_BINS}")


MESSAGES: dict[int, type[Message]] = {
    m.TYPE: m for m in (Hello, Heartbeat, Ping, SceneBegin, SceneVelocities, SceneChunk,
                        SceneSupport,
                        SceneCommit, Home, StartWindow, StopWindow, PlayChunk, PlayStart, SetLimit,
                        EStop,
                        ClearFault, Zero, TraceRequest, Ack, HelloAck, Pong, Contact, Saturation,
                        Fault, StatusReport, WindowDone, TraceBlock, Position, TraceConfig,
                        Limits, TraceChunk, TraceLost, LinkQuery, LinkReport)}

CHUNK_ITEMS = C.CHUNK_ITEMS  # i16 items per SceneChunk / PlayChunk (960 bytes of data)
TRACE_ITEMS = C.TRACE_ITEMS  # f32 items per TraceBlock, and at most per TraceChunk (n × k)


def encode(msg: Message, seq: int, version: int = 1) -> bytes:
    """The delimited frame carrying ``msg`` in protocol ``version`` (laid out as that version
    lays it out; HELLO travels in version 1, whose layout it keeps in every version)."""
    layout = version if version in C.BY_NAME[msg.NAME].versions else C.PROTOCOL
    return encode_frame(msg.TYPE, seq, msg.body(layout), version)


def decode(frame: Frame) -> Message:
    """The message in a decoded frame; MessageError for unknown types or misfit bodies.
    Ranges are not judged here: a command's are the device's to judge against its own
    limits (:meth:`Message.check`), and a device's report is taken as sent (a FAULT with a
    code this host does not know is still a fault, named by its number)."""
    cls = MESSAGES.get(frame.type)
    if cls is None:
        raise MessageError(f"unknown message type 0x{frame.type:02x}")
    try:
        return cls.from_body(frame.body, frame.version)
    except struct.error as exc:
        raise MessageError(f"{cls.__name__}: {exc}") from None

