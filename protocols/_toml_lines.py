"""Where a key stands in a TOML file, so errors can name the line.

``tomllib`` returns values without positions. This scanner walks the text once and
maps key paths such as ``("phases", 2, "repetitions")`` or
``("samples", 0, "scene", "transient", "gain")`` to 1-based line numbers. It follows
table headers, arrays of tables, dotted keys and (approximately) inline tables; a
path it cannot place resolves to its longest known prefix.
"""

from __future__ import annotations

import re

__all__ = ["key_lines", "line_of"]

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_NAME = r'(?:[A-Za-z0-9_-]+|"[^"]*")'
_KEY = re.compile(rf"^\s*({_NAME}(?:\s*\.\s*{_NAME})*)\s*=")

Path = tuple


def _parts(dotted: str) -> list[str]:
    return [p.strip().strip('"') for p in re.split(r"\.(?=(?:[^\"]*\"[^\"]*\")*[^\"]*$)", dotted)]


def key_lines(text: str) -> dict[Path, int]:
    """Map every key path found in ``text`` to its line number (1-based)."""
    lines: dict[Path, int] = {}
    counts: dict[Path, int] = {}
    table: Path = ()
    for no, raw in enumerate(text.splitlines(), start=1):
        h = _HEADER.match(raw)
        if h and not _KEY.match(raw):
            names = _parts(h.group(2))
            # resolve parent arrays of tables to their current element
            prefix: list = []
            for name in names[:-1]:
                prefix.append(name)
                idx = counts.get(tuple(prefix))
                if idx is not None:
                    prefix.append(idx)
            if h.group(1) == "[[":
                key = (*prefix, names[-1])
                lines.setdefault(key, no)  # the array itself: its first element
                counts[key] = counts.get(key, -1) + 1
                table = (*key, counts[key])
            else:
                table = (*prefix, names[-1])
            lines.setdefault(table, no)
            continue
        k = _KEY.match(raw)
        if not k:
            continue
        path = (*table, *_parts(k.group(1)))
        lines.setdefault(path, no)
        rest = raw[k.end():]
        if "{" in rest:  # inline table: nested keys on the same line (depth tracked roughly)
            stack = list(path)
            depth = 0
            for m in re.finditer(r"[{}]|(?:[{,]\s*([A-Za-z0-9_-]+|\"[^\"]*\")\s*=)", rest):
                tok = m.group(0)
                if tok == "{":
                    depth += 1
                elif tok == "}":
                    depth -= 1
                    del stack[len(path) + depth:]
                else:
                    if tok.startswith("{"):
                        depth += 1
                    del stack[len(path) + depth - 1:]
                    stack.append(m.group(1).strip('"'))
                    lines.setdefault(tuple(stack), no)
    return lines


def line_of(index: dict[Path, int], path: Path) -> int | None:
    """Line of ``path``, or of its longest known prefix; None when nothing matches."""
    p = tuple(path)
    while p:
        if p in index:
            return index[p]
        p = p[:-1]
    return None
