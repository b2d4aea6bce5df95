"""The shared test vectors (docs/wire-vectors.txt) decoded by both implementations: the
Python host code and the firmware's C code (firmware/, built here with the host's cc)."""

import subprocess
from pathlib import Path

import pytest

from device.serial.framing import FrameDecoder
from device.serial.vectors import expectation, render, vectors

ROOT = Path(__file__).resolve().parents[2]
FILE = ROOT / "docs" / "wire-vectors.txt"


def _lines():
    return [ln for ln in FILE.read_text().splitlines() if ln and not ln.startswith("#")]


def test_the_vectors_file_is_current():
    """Regenerate with: python -m device.serial.vectors > docs/wire-vectors.txt"""
    assert FILE.read_text() == render()


def test_python_decodes_every_vector_as_the_file_says():
    types = set()
    for line in _lines():
        name, hexa, expect = line.split(" ", 2)
        assert expectation(bytes.fromhex(hexa)) == expect, name
        if expect.endswith(" fit"):
            types.add(int(expect.split()[2]))
    # every message type of both versions has a valid vector (0x7F is the COBS-block
    # vector's made-up type, which fits nothing), and so do COBS frames past 254 bytes
    from device.serial.messages import MESSAGES

    assert types == set(MESSAGES)
    assert len(MESSAGES) == 34
    long = [bytes.fromhex(ln.split()[1]) for ln in _lines() if ln.startswith("cobs_")]
    assert max(map(len, long)) > 1000 and all(0 not in b for b in long)
    # and the streaming decoder finds exactly the valid frames among them all
    dec = FrameDecoder()
    frames = dec.feed(b"".join(enc + b"\x00" for _, enc in vectors()))
    assert len(frames) == sum(" frame " in ln for ln in _lines())


@pytest.fixture(scope="module")
def c_decoder(tmp_path_factory):
    out = subprocess.run(["make", "-s", "-C", str(ROOT / "firmware"), "build/hl_test"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return ROOT / "firmware" / "build" / "hl_test"


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.slow
def test_c_decodes_every_vector_as_python_does(c_decoder):
    out = subprocess.run([str(c_decoder), "vectors", str(FILE)], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    c_lines = out.stdout.splitlines()
    py = [f"{ln.split(' ', 2)[0]} {ln.split(' ', 2)[2]}" for ln in _lines()]
    assert c_lines == py


@pytest.mark.integration
@pytest.mark.firmware
def test_c_fuzz_accepts_no_corrupt_frame(c_decoder):
    """10⁵ seeded mutations here (make -C firmware test runs 10⁶)."""
    out = subprocess.run([str(c_decoder), "fuzz", str(FILE), "100000", "7"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 corrupt accepted" in out.stdout
