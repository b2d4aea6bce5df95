"""Texts that name the built-in protocols name all of them (``protocols.BUILTIN``).

Docstrings, help texts and documentation pages listed three built-in protocols after three
more had been added. A list of them in parentheses after "built-in", a count of them ("the
three built-in protocols") and the protocol-file reference's table of them must each agree
with ``BUILTIN``; a text that means only some of them says which without claiming to be
the list (unit tier: text read with regular expressions).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from protocols import BUILTIN

ROOT = Path(__file__).resolve().parents[2]
#: every text a user or a reader of the code sees: the packages' sources and the docs
TEXTS = sorted([p for pkg in ("app", "protocols", "analysis", "device", "benchmarks", "plugins")
                for p in (ROOT / pkg).rglob("*.py")]
               + [p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts]
               + [ROOT / "README.md"])
#: "built-in … (realism, factorial, identification)": a list of them in parentheses
_LISTED = re.compile(r"built-in[^.;()]{0,40}\(([^()]{0,300})\)", re.IGNORECASE)
_JOINERS = {"or", "and", "e", "g"}
_NUMBERS = {w: n for n, w in enumerate("one two three four five six seven eight nine ten"
                                       .split(), start=1)}
#: "the three built-in protocols", "its three protocols": a count of all of them
_COUNTED = re.compile(r"\b(?:the|its|hapticlab's)\s+(" + "|".join(_NUMBERS) +
                      r")\s+(?:built-in\s+)?protocols\b", re.IGNORECASE)


def _where(path: Path, root: Path, text: str, pos: int) -> str:
    return f"{path.relative_to(root)}:{text.count(chr(10), 0, pos) + 1}"


def listed(paths=TEXTS, root: Path = ROOT) -> list[str]:
    """Lists of built-in protocols that leave some out."""
    bad = []
    for path in paths:
        text = path.read_text(encoding="utf-8")
        for m in _LISTED.finditer(text):
            words = re.findall(r"[A-Za-z_]+", m.group(1))
            named = [w for w in words if w in BUILTIN]
            if len(named) >= 2 and all(w in BUILTIN or w in _JOINERS for w in words):
                if set(named) != set(BUILTIN):
                    bad.append(f"{_where(path, root, text, m.start())}: {', '.join(named)}")
    return bad


def counted(paths=TEXTS, root: Path = ROOT) -> list[str]:
    """Counts of the built-in protocols that are not ``len(BUILTIN)``."""
    bad = []
    for path in paths:
        text = path.read_text(encoding="utf-8")
        for m in _COUNTED.finditer(text):
            if _NUMBERS[m.group(1).lower()] != len(BUILTIN):
                bad.append(f"{_where(path, root, text, m.start())}: {' '.join(m.group(0).split())}")
    return bad


def test_a_list_of_the_built_in_protocols_names_every_one():
    assert not listed(), f"lists missing some of {BUILTIN}:\n" + "\n".join(listed())


def test_a_count_of_the_built_in_protocols_is_theirs():
    assert not counted(), f"{len(BUILTIN)} built-in protocols, not:\n" + "\n".join(counted())


def test_the_scans_see_a_short_list_and_a_wrong_count(tmp_path):
    page = tmp_path / "p.md"
    page.write_text('A built-in protocol name (``realism``, ``factorial``) or a file.\n'
                    f'Every built-in name ({", ".join(BUILTIN)}) or a path.\n'
                    'Rows: every sample of the three\nbuilt-in protocols.\n'
                    'Two built-in protocols measure thresholds.\n')
    assert listed([page], tmp_path) == ["p.md:1: realism, factorial"]
    assert counted([page], tmp_path) == ["p.md:3: the three built-in protocols"]


@pytest.mark.parametrize("name", BUILTIN)
def test_the_protocol_file_reference_has_a_row_for_each(name):
    page = (ROOT / "docs" / "reference" / "protocol-files.md").read_text(encoding="utf-8")
    assert f"\n| `{name}` |" in page
