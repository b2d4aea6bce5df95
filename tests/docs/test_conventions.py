"""The documentation's conventions hold on every page (unit tier: reads files only): one
`#` title per page, skip marks the command test knows, commands where a console block
shows them."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from markdown_it import MarkdownIt

from .blocks import DOCS, ROOT, SKIP_MARKS, Block, pages, read_blocks, shown_output_matches


def _section_pages() -> list:
    return [pytest.param(p, id=str(p.relative_to(DOCS))) for p in pages()]


@pytest.mark.parametrize("page", _section_pages())
def test_page_has_one_title(page: Path) -> None:
    tokens = MarkdownIt("commonmark").parse(page.read_text(encoding="utf-8"))
    titles = [t for t in tokens if t.type == "heading_open" and t.tag == "h1"]
    assert len(titles) == 1, f"{page.relative_to(ROOT)} has {len(titles)} '#' titles, not 1"


@pytest.mark.parametrize("page", _section_pages())
def test_skip_marks_are_known_and_say_what(page: Path) -> None:
    for block in read_blocks(page):
        if block.caption.lower().startswith("needs"):
            assert block.skip_mark, (
                f"{block.where}: caption {block.caption!r} starts like a skip mark but is "
                f"none of {SKIP_MARKS} (the command test would run the block)")
            rest = block.caption[len(block.skip_mark):].strip(" —-:")
            assert rest, f"{block.where}: {block.skip_mark!r} does not say what it needs"


@pytest.mark.parametrize("page", [p for p in _section_pages()
                                  if p.values[0].parent.name in ("tutorials", "howto")])
def test_console_blocks_show_commands(page: Path) -> None:
    for block in read_blocks(page):
        if block.language == "console":
            assert block.commands(), (f"{block.where}: a console block with no '$ ' command "
                                      "(show output alone as a `text` block)")


def test_continued_commands_join() -> None:

    block = Block(ROOT / "x.md", 1, "console", "",
                  "$ hapticlab simulate realism \\\n    --participants 2\nprinted\n$ ls\n")
    assert block.commands() == ["hapticlab simulate realism      --participants 2", "ls"]
    assert block.steps()[0][1] == ["printed"]
    sh = Block(ROOT / "x.md", 1, "sh", "", "# a comment\nhapticlab demo\n\nls -l\n")
    assert sh.commands() == ["hapticlab demo", "ls -l"]


def test_shown_output_must_have_been_printed() -> None:
    printed = "realism: participant 1/3 done (15 s)\n3 simulated sessions in sim-data/ (22 s)\n"
    assert shown_output_matches(["…", "3 simulated sessions in sim-data/ (… s)"], printed) is None
    assert shown_output_matches(["3 sessions  in sim-data/ (… s)"], printed) == \
        "3 sessions  in sim-data/ (… s)"
    # in order: a line shown after another must come after it
    assert shown_output_matches(["3 simulated …", "realism: …"], printed) == "realism: …"


def _links(md: Path) -> list[str]:
    tokens = MarkdownIt("commonmark").parse(md.read_text(encoding="utf-8"))
    return [c.attrs["href"] for t in tokens if t.type == "inline"
            for c in t.children or [] if c.type == "link_open"]


def test_readme_links_reach_files() -> None:
    """The README is read outside Sphinx (on a forge, in an editor): its links to the
    repository's files must reach them (Sphinx checks the site's own links)."""
    readme = ROOT / "README.md"
    for href in _links(readme):
        if "://" in href or href.startswith("#"):
            continue
        target = (readme.parent / href.split("#")[0]).resolve()
        assert target.exists(), f"README.md links to {href}, which does not exist"


def test_the_architecture_links_each_way_to_extend_it() -> None:
    """How hapticlab is built names where it grows (a backend, a phase kind, a field of the
    wire protocol, an analysis type): each mention links the how-to guide that adds one,
    so a reader goes from the map to the recipe."""
    text = (DOCS / "explanation" / "architecture.md").read_text(encoding="utf-8")
    guides = sorted(p.stem for p in (DOCS / "howto").glob("add-*.md"))
    missing = [g for g in guides if not re.search(r"\{doc\}`[^`]*howto/" + g + "`", text)]
    assert len(guides) >= 4 and not missing, f"architecture.md does not link {missing}"
