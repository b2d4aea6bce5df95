"""Docs that cannot lie: every command shown in the tutorials, the how-to guides and the
README runs, and every Python example in any page runs and prints what it shows.

One page is one test: its blocks become one bash script, run in a fresh folder with this
environment's programs first on PATH, in page order (a file block is written where it
stands, a `pycon` block goes through doctest, a `python` block runs as a script). What a
`console` block shows after a command must be what it printed: every shown line, in order,
with `…` standing for any text. A block
captioned "needs hardware — …" or "needs a person — …" is skipped, and the skip names it.
The convention is docs/reference/documentation-conventions.md.
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from .blocks import DOCS, ROOT, Block, pages, read_blocks, shown_output_matches

pytestmark = [pytest.mark.integration]

#: a page's bound: a hung command fails its page instead of the suite's timeout
PAGE_TIMEOUT = 900  # s
EOF = "HAPTICLAB_DOC_BLOCK_END"
#: README lines that are the project's own set-up: the suite is `make test`, and `make demo`
#: builds the environment this test already runs in
README_NOT_RUN = ("make demo", "make test")


def _script(blocks: list[Block], shell: bool, not_run: tuple[str, ...] = ()
            ) -> tuple[str, list, list]:
    """A bash script running ``blocks`` in order, the blocks it skipped (with why), and per
    command run in the foreground: (its output file, the output the page shows, where)."""
    py = shlex.quote(sys.executable)
    lines = [
        "set -euo pipefail",
        # background commands a page starts (an emulator) end with the page
        "trap 'kill $(jobs -p) 2>/dev/null || true' EXIT",
        "mkdir -p .doc-out; DOC_OUT=\"$PWD/.doc-out\"",  # absolute: a page may `cd`
    ]
    skipped = []
    checks = []
    for n, block in enumerate(blocks):
        if block.skip_mark:
            skipped.append((block.where, block.caption))
            continue
        if block.file_name:
            lines += [f"cat > {shlex.quote(block.file_name)} <<'{EOF}'", block.text.rstrip("\n"),
                      EOF]
        elif block.language == "pycon":
            doc = f".doc-block-{n}.txt"
            lines += [f"cat > {doc} <<'{EOF}'", block.text.rstrip("\n"), EOF,
                      f"echo '>>> ({block.where})'",
                      f"{py} -m doctest -o ELLIPSIS -o NORMALIZE_WHITESPACE {doc}"]
        elif block.language == "python":
            src = f".doc-block-{n}.py"
            lines += [f"cat > {src} <<'{EOF}'", block.text.rstrip("\n"), EOF,
                      f"echo '# python ({block.where})'", f"{py} {src}"]
        elif shell:
            for cmd, shown in block.steps():
                if cmd.strip() in not_run:
                    skipped.append((block.where, cmd))
                    continue
                lines.append(f"printf '%s\\n' {shlex.quote(f'$ {cmd}   ({block.where})')}")
                if cmd.rstrip().endswith("&"):  # runs on in the background: not captured
                    lines.append(cmd)
                    continue
                # in this shell (a `cd` or a variable holds for the next command), its
                # output kept for the check and shown in the log
                out = f".doc-out/{len(checks)}"
                path = f'"$DOC_OUT/{len(checks)}"'
                lines.append(f"{{ {cmd}\n}} > {path} 2>&1 || {{ rc=$?; cat {path}; exit $rc; }}; "
                             f"cat {path}")
                checks.append((out, shown, block.where, cmd))
    return "\n".join(lines) + "\n", skipped, checks


def _run_page(page: Path, tmp_path: Path, shell: bool, not_run: tuple[str, ...] = ()) -> None:
    script, skipped, checks = _script(read_blocks(page), shell, not_run)
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.setdefault("MPLBACKEND", "Agg")
    proc = subprocess.Popen(["bash", "-c", script], cwd=tmp_path, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=PAGE_TIMEOUT)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        pytest.fail(f"{page.relative_to(ROOT)} still ran after {PAGE_TIMEOUT} s; its last "
                    f"output:\n{out[-4000:]}")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # anything the page left behind
        except ProcessLookupError:
            pass
    tail = "\n".join(out.splitlines()[-60:])
    assert proc.returncode == 0, (
        f"{page.relative_to(ROOT)}: a block failed (exit {proc.returncode}); the line after "
        f"the last '$ ' is its output:\n{tail}")
    for out, shown, where, cmd in checks:
        printed = (tmp_path / out).read_text(encoding="utf-8", errors="replace")
        missing = shown_output_matches(shown, printed)
        assert missing is None, (
            f"{where}: `{cmd}` did not print the line the page shows:\n  {missing}\n"
            f"it printed:\n{printed[-3000:]}")
    for where, what in skipped:
        print(f"not run: {where}: {what}")


#: commands that start a device on this computer (an emulator, a firmware build on a
#: pseudo-terminal): its watchdog judges how soon this host's frames come, a deadline
_DEVICE_STARTS = ("device emulate", "build/hlfw-")


def _page_params(sections: tuple[str, ...]) -> list:
    """A page per test; a page whose commands start a device is real-time (its test runs
    in the real-time group, not on a worker that yields its core: beside load, the
    first-session tutorial's self-test met its emulator's watchdog there)."""
    return [pytest.param(p, id=str(p.relative_to(DOCS)), marks=[pytest.mark.realtime] if any(
                not b.skip_mark and any(s in b.text for s in _DEVICE_STARTS)
                for b in read_blocks(p)) else [])
            for p in pages(*sections) if p.name != "index.md"]


@pytest.mark.slow
@pytest.mark.parametrize("page", _page_params(("tutorials", "howto")))
def test_commands_in_tutorials_and_guides_run(page: Path, tmp_path: Path) -> None:
    _run_page(page, tmp_path, shell=True)


@pytest.mark.slow
def test_readme_commands_run(tmp_path: Path) -> None:
    _run_page(ROOT / "README.md", tmp_path, shell=True, not_run=README_NOT_RUN)


@pytest.mark.parametrize("page", [
    pytest.param(p, id=str(p.relative_to(DOCS))) for p in pages()
    if p.parent.name not in ("tutorials", "howto")
    and any(b.language in ("pycon", "python") for b in read_blocks(p))])
def test_python_examples_in_other_pages_run(page: Path, tmp_path: Path) -> None:
    _run_page(page, tmp_path, shell=False)
