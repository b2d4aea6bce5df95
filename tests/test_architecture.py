"""The dependency direction of DESIGN.md, and imports free of PsychoPy and of I/O."""

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = {"app", "protocols", "analysis", "device", "benchmarks"}

# package -> our packages it may import
ALLOWED = {
    "device": set(),
    "protocols": {"device"},
    "analysis": set(),
    "app": {"device", "protocols", "analysis", "benchmarks"},
    "benchmarks": {"device", "protocols", "analysis", "app"},  # they measure every package
}


def imported_roots(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    roots = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
    return roots


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_dependency_direction(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"package {package} has no modules"
    for f in files:
        roots = imported_roots(f)
        ours = (roots & OURS) - {package}
        assert ours <= ALLOWED[package], f"{f.relative_to(ROOT)} imports {sorted(ours)}"
        if package != "app":
            assert "psychopy" not in roots, f"{f.relative_to(ROOT)} imports PsychoPy"


def test_the_checker_sees_imports(tmp_path):
    bad = tmp_path / "m.py"
    bad.write_text("import os\nfrom app.cli import main\ndef f():\n    import psychopy.visual\n")
    assert imported_roots(bad) == {"os", "app", "psychopy"}


IMPORT_PROBE = r"""
import json, sys
opened = []
def hook(event, args):
    if event == "open" and args and isinstance(args[0], str):
        mode = args[1] if len(args) > 1 and isinstance(args[1], str) else "r"
        if any(c in mode for c in "wax+"):
            opened.append(args[0])
sys.addaudithook(hook)
import device, device.sim.backend, device.suite, protocols, analysis
print(json.dumps({"psychopy": sorted(m for m in sys.modules if m.split(".")[0] == "psychopy"),
                  "written": opened}))
"""


def test_core_imports_without_psychopy_or_writes(tmp_path):
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}  # Python's own caches are not ours
    out = subprocess.run([sys.executable, "-c", IMPORT_PROBE], capture_output=True, text=True,
                         cwd=tmp_path, check=True, env=env)
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["psychopy"] == []
    assert report["written"] == []
    assert list(tmp_path.iterdir()) == []
