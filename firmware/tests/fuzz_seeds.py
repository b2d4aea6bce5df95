"""Seed inputs for the device fuzzer (tests/fuzz_device.c) into tests/fuzz-corpus/.

Run from the repository root: ``.venv/bin/python firmware/tests/fuzz_seeds.py``. Raw-byte
seeds are the wire vectors' frames; command seeds are whole sessions a host would run
(a spring, a transient table, a playback, faults and their clearing), in the fuzzer's
script form: mode byte 1, then [type, length, body] and a tick count per command.
"""

from __future__ import annotations

import hashlib
import sys
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from device.serial import messages as M  # noqa: E402
from device.serial.vectors import vectors  # noqa: E402

OUT = ROOT / "firmware" / "tests" / "fuzz-corpus"


def script(*steps: tuple[M.Message, int]) -> bytes:
    out = bytearray([1])
    for msg, wait in steps:
        body = msg.body()
        assert len(body) < 250, type(msg).__name__
        out += bytes([msg.TYPE, len(body)]) + body + bytes([wait])
    return bytes(out)


def seeds() -> dict[str, bytes]:
    out = {}
    out["raw-vectors"] = b"\0" + b"".join(enc + b"\0" for _, enc in vectors())
    for name, enc in vectors():
        out[f"raw-{name}"] = b"\0" + enc + b"\0"
    spring = M.SceneBegin(1, 1, 0, 680.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1.0)
    out["cmd-spring-window"] = script(
        (spring, 1), (M.SceneCommit(1, 0), 1), (M.Home(20_000), 255),
        (M.StartWindow(1, 100, 100, 0), 255), (M.Heartbeat(), 255), (M.Heartbeat(), 255),
        (M.StopWindow(), 8), (M.LinkQuery(1), 4))
    items = tuple(range(-40, 40, 2))
    crc = zlib.crc32(M.SceneChunk(2, 0, len(items), items).body()[8:]) & 0xFFFFFFFF
    out["cmd-table-contact"] = script(
        (M.SceneBegin(2, 2, -1000, 680.0, 0, 0, 0, 0, 0, 0, 2, 20, 2, 0.8), 1),
        (M.SceneVelocities(2, (0.05, 0.2)), 1), (M.SceneChunk(2, 0, len(items), items), 1),
        (M.SceneCommit(2, crc), 1), (M.Home(500), 50), (M.StartWindow(2, 50, 600, 1), 255),
        (M.Heartbeat(), 255), (M.Heartbeat(), 255), (M.EStop(), 4), (M.ClearFault(), 4))
    out["cmd-playback"] = script(
        (M.SetLimit(700), 1), (M.TraceConfig(0x21, 4), 1),
        (M.PlayChunk(0, 60, tuple(range(0, 30000, 500))), 1), (M.PlayStart(3, 60), 100),
        (M.PlayStart(4, 60), 20), (M.Zero(), 4), (M.Ping(7), 2))
    out["cmd-real-sample"] = script(
        (M.SceneBegin(5, 0, 2000, 0.0, 70000.0, 20.0, -3.0, 90.0, 400.0, 0.026, 0, 0, 0, 1.0),
         1), (M.SceneSupport(5, 350.0, 3.0), 1), (M.SceneCommit(5, 0), 1), (M.Home(1), 255),
        (M.StartWindow(6, 1, 1, 1), 255))
    return out


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    for old in OUT.glob("seed-*"):
        old.unlink()
    for name, data in seeds().items():
        digest = hashlib.sha1(data).hexdigest()[:12]
        (OUT / f"seed-{name}-{digest}").write_bytes(data)
    print(f"wrote {len(seeds())} seeds to {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
