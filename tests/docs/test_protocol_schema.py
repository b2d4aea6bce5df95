"""The protocol-file reference (docs/reference/protocol-files.md) lists exactly the keys the
loader accepts, table by table, and the transient kinds' keys the scene parser accepts.

The loader keeps its keys in its code, not in a schema; asked to read a key it does not
know, it names the keys it allows. So each documented table is read with one unknown key
in it, and the keys the error allows are compared with the page's (unit tier: parsing only).
"""

from __future__ import annotations

import re

import pytest
from markdown_it import MarkdownIt

from device.scene import Scene, SceneError, transient_kinds
from protocols.loader import ProtocolError, parse_protocol

from .blocks import DOCS

PAGE = DOCS / "reference" / "protocol-files.md"

#: a protocol the loader reads up to the table under test (TOML text before and after it)
_VALID = """
[protocol]
name = "schema"
[rating]
min = 1
max = 7
question = "How real?"
[[samples]]
id = "a"
scene.spring = 100.0
[[samples]]
id = "b"
scene.spring = 200.0
[[phases]]
name = "testing"
samples = "all"
"""


def _documented() -> dict[str, set[str]]:
    """The page's tables: heading (a TOML table in a code span) → keys of its first column."""
    tokens = MarkdownIt("commonmark").enable("table").parse(PAGE.read_text(encoding="utf-8"))
    out: dict[str, set[str]] = {}
    heading = None
    in_first_cell = False
    for i, tok in enumerate(tokens):
        if tok.type == "heading_open":
            inline = tokens[i + 1]
            codes = [c.content for c in inline.children or [] if c.type == "code_inline"]
            heading = codes[0] if codes else None
        elif tok.type == "tbody_open" and heading and heading not in out:
            out[heading] = set()
        elif tok.type == "tr_open":
            in_first_cell = True
        elif tok.type == "inline" and in_first_cell and heading in out and \
                tokens[i - 1].type == "td_open":
            in_first_cell = False
            for c in tok.children or []:
                if c.type == "code_inline":
                    out[heading].update(k.strip() for k in c.content.split(","))
        elif tok.type == "tbody_close":
            heading = None
    return out


def _allowed(message: str) -> set[str]:
    m = re.search(r"allowed: (.*)$", message)
    assert m, f"the error names no allowed keys: {message}"
    return {k.strip() for k in m.group(1).split(",")}


def _loader_keys(table: str) -> set[str]:
    """Keys the loader allows in ``table`` (as the page heads it), read from its error."""
    if table == "analysis":  # a phase's analysis table
        text = _VALID + "[phases.analysis]\nzzz_unknown = 1\n"
    elif table == "[[phases]]":  # the last phase of a valid protocol
        text = _VALID + "zzz_unknown = 1\n"
    elif table.startswith("[["):
        name = table.strip("[]")
        text = ('[protocol]\nname = "schema"\n' + f"[[{name}]]\nzzz_unknown = 1\n"
                '[[phases]]\nname = "t"\nsamples = "all"\n')
    else:
        name = table.strip("[]")
        text = ('[protocol]\nname = "schema"\n' if name != "protocol" else "") + \
            f"[{name}]\nzzz_unknown = 1\n" + ('name = "schema"\n' if name == "protocol" else "") \
            + '[[phases]]\nname = "t"\nsamples = "all"\n'
    with pytest.raises(ProtocolError) as err:
        parse_protocol(text, "schema.toml")
    assert "zzz_unknown" in str(err.value), str(err.value)
    return _allowed(str(err.value))


_TABLES = sorted(_documented())


def test_the_page_documents_the_tables() -> None:
    assert {"[protocol]", "[window]", "[rating]", "[[samples]]", "[[phases]]",
            "analysis"} <= set(_TABLES)


@pytest.mark.parametrize("table", [t for t in _TABLES if t.startswith("[") or t == "analysis"])
def test_documented_keys_are_the_loaders(table: str) -> None:
    documented = _documented()[table]
    loader = _loader_keys(table)
    assert documented == loader, (
        f"{PAGE.name} {table}: documented but not accepted {sorted(documented - loader)}, "
        f"accepted but not documented {sorted(loader - documented)}")


def _documented_transients() -> dict[str, set[str]]:
    text = PAGE.read_text(encoding="utf-8")
    out = {}
    for m in re.finditer(r'`transient = \{ kind = "(\w+)", ([^}]*) \}`', text):
        out[m.group(1)] = {k.strip() for k in m.group(2).split(",")}
    return out


def test_every_transient_kind_is_documented_with_its_keys() -> None:
    documented = _documented_transients()
    assert set(documented) == set(transient_kinds())
    for kind, keys in documented.items():
        with pytest.raises(SceneError) as err:
            Scene.from_dict({"name": "x", "spring": 100.0,
                             "transient": {"kind": kind, "zzz_unknown": 1}})
        assert keys == _allowed(str(err.value)), f"transient {kind}"
