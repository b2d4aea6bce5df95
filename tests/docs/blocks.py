"""The code blocks of the documentation's pages, read as docs/reference/documentation-conventions.md
says: commands to run, files to write, Python to execute, and blocks skipped by name.

A page is read with markdown-it (the parser MyST is built on), so a fence inside a longer
fence (an example of the convention itself) stays an example.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from markdown_it import MarkdownIt

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"

#: the captions that mark a block the test machine cannot run, and why
SKIP_MARKS = ("needs hardware", "needs a person", "in the checkout")
#: languages whose blocks are commands: `console` with `$ ` prompts, the others line by line
SHELL_LANGUAGES = ("console", "sh", "bash", "shell")
#: a caption that is a file name: the block is that file's content, written before later
#: blocks run
FILE_CAPTION = re.compile(r"^[\w.-]+\.[A-Za-z0-9]+$")


@dataclass(frozen=True)
class Block:
    """One fenced block of a page.

    Attributes
    ----------
    page : Path
        The Markdown file.
    line : int
        1-based line of the opening fence.
    language : str
        The block's language (``console``, ``python``, ``pycon``, ``toml`` …).
    caption : str
        The ``:caption:`` of a ``{code-block}`` directive, ``""`` for a plain fence.
    text : str
        The block's content, without directive options.
    """

    page: Path
    line: int
    language: str
    caption: str
    text: str

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"

    @property
    def skip_mark(self) -> str | None:
        """The skip mark this block's caption starts with, if any."""
        low = self.caption.lower()
        for mark in SKIP_MARKS:
            if low.startswith(mark):
                return mark
        return None

    @property
    def file_name(self) -> str | None:
        """The file this block is the content of, when its caption is a file name."""
        return self.caption if FILE_CAPTION.match(self.caption) else None

    def commands(self) -> list[str]:
        """The shell commands of a command block, a continued line (``\\``) joined to its
        next; ``[]`` for other blocks."""
        return [cmd for cmd, _ in self.steps()]

    def steps(self) -> list[tuple[str, list[str]]]:
        """Each command of a command block with the output lines the page shows after it
        (a ``console`` block's lines up to the next ``$ ``; none for the other shells)."""
        if self.language not in SHELL_LANGUAGES:
            return []
        prompted = self.language == "console"
        out: list[tuple[str, list[str]]] = []
        pending = ""
        for raw in self.text.splitlines():
            if pending:
                line = raw
            elif prompted:
                if not raw.startswith("$ "):
                    if out and raw.strip():
                        out[-1][1].append(raw)  # what the command printed
                    continue
                line = raw[2:]
            else:
                line = raw
                if not line.strip() or line.lstrip().startswith("#"):
                    continue
            if line.rstrip().endswith("\\"):
                pending += line.rstrip()[:-1] + " "
                continue
            out.append((pending + line, []))
            pending = ""
        if pending:
            out.append((pending, []))
        return out


def shown_output_matches(shown: list[str], printed: str) -> str | None:
    """None when every line ``shown`` appears among the ``printed`` lines, in order, where
    ``…`` stands for any text and runs of spaces count as one; else the first line that does
    not."""
    lines = [" ".join(p.split()) for p in printed.splitlines()]
    i = 0
    for want in shown:
        norm = " ".join(want.split())
        if norm == "…":
            continue
        pattern = re.compile(".*".join(re.escape(part) for part in norm.split("…")) + r"\Z")
        while i < len(lines) and not pattern.match(lines[i]):
            i += 1
        if i == len(lines):
            return want
        i += 1
    return None


_MD = MarkdownIt("commonmark")


def _directive(info: str, content: str) -> tuple[str, str, str]:
    """(language, caption, text) of a fence's info string and content."""
    info = info.strip()
    m = re.match(r"^\{(code-block|code|sourcecode)\}\s*(\S*)", info)
    if not m:
        return info.split()[0] if info else "", "", content
    language = m.group(2)
    caption = ""
    lines = content.splitlines(keepends=True)
    i = 0
    if lines and lines[0].strip() == "---":  # options as YAML between --- lines
        end = next((j for j in range(1, len(lines)) if lines[j].strip() == "---"), 0)
        for opt in lines[1:end]:
            if opt.strip().startswith("caption:"):
                caption = opt.split(":", 1)[1].strip()
        i = end + 1
    else:
        while i < len(lines) and re.match(r"^:[\w-]+:", lines[i]):
            key, _, value = lines[i][1:].partition(":")
            if key == "caption":
                caption = value.strip()
            i += 1
    while i < len(lines) and not lines[i].strip():
        i += 1
    return language, caption, "".join(lines[i:])


def read_blocks(page: Path) -> list[Block]:
    """Every fenced block of ``page``, in order."""
    tokens = _MD.parse(page.read_text(encoding="utf-8"))
    out = []
    for tok in tokens:
        if tok.type != "fence":
            continue
        language, caption, text = _directive(tok.info, tok.content)
        out.append(Block(page, tok.map[0] + 1 if tok.map else 0, language, caption, text))
    return out


def pages(*sections: str) -> list[Path]:
    """The Markdown pages of the given docs/ sections (all of docs/ when none given)."""
    if not sections:
        return sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)
    return sorted(p for s in sections for p in (DOCS / s).glob("*.md"))
