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


#: the PsychoPy plugin's own package (a separate distribution in plugins/): with app/, the
#: one place PsychoPy is imported
PLUGIN = ROOT / "plugins" / "psychopy-hapticlab" / "psychopy_hapticlab"


def _source_files():
    """Every .py of the repository but the tests' (which drive PsychoPy to test what imports
    it) and what is not ours (the environment, build output)."""
    skip = {".venv", "out", "build", "dist", "tests", ".git"}
    for f in sorted(ROOT.rglob("*.py")):
        if not skip & set(f.relative_to(ROOT).parts):
            yield f


@pytest.mark.slow  # reads every module's imports, the plugin's too
def test_psychopy_is_imported_in_app_and_the_plugin_alone():
    """PsychoPy is imported by app/ and by the plugin's package, nowhere else; and none of
    our packages imports the plugin (it depends on hapticlab, never the other way)."""
    allowed = (ROOT / "app", PLUGIN)
    users = [f for f in _source_files() if "psychopy" in imported_roots(f)]
    assert users and any(PLUGIN in f.parents for f in users)
    bad = [str(f.relative_to(ROOT)) for f in users if not any(d in f.parents for d in allowed)]
    assert not bad, f"PsychoPy imported outside app/ and the plugin: {bad}"
    back = [str(f.relative_to(ROOT)) for f in _source_files()
            if PLUGIN not in f.parents and "psychopy_hapticlab" in imported_roots(f)]
    assert not back, f"our packages import the plugin: {back}"


def test_the_plugin_uses_hapticlab_through_public_names():
    """The plugin reaches hapticlab through public modules and names (no private module,
    name or attribute of device/, no backend insides): it adds hapticlab to PsychoPy and
    copies none of its device code."""
    files = sorted(PLUGIN.rglob("*.py"))
    assert files
    for f in files:
        bad = _private_device_uses(f)
        assert not bad, f"{f.relative_to(ROOT)}: {bad}"
        insides = sorted(m for m in imported_modules(f) if m.startswith(BACKEND_INSIDES))
        assert not insides, f"{f.relative_to(ROOT)} imports {insides}"


def test_liblsl_is_loaded_in_one_module_only():
    """pylsl (and with it liblsl, which talks on the network) is imported by app/markers.py
    alone, which checks for a private network first where one is required; among the
    tests, by the receiver that runs inside one."""
    users = {f.relative_to(ROOT).as_posix() for d in (*sorted(OURS), "tests", "tools")
             for f in (ROOT / d).rglob("*.py") if "pylsl" in imported_roots(f)}
    assert users == {"app/markers.py", "tests/app/lsl_receive.py"}


def test_the_checker_sees_imports(tmp_path):
    bad = tmp_path / "m.py"
    bad.write_text("import os\nfrom app.cli import main\ndef f():\n    import psychopy.visual\n")
    assert imported_roots(bad) == {"os", "app", "psychopy"}


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imported_modules(path: Path) -> set[str]:
    """Every module of ours ``path`` imports, relative imports resolved, lazy (function-level)
    imports included: a cycle through a lazy import is still a cycle of the design."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    here = _module_name(path)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            # "from pkg import sub" may name a submodule
            names = [mod] + [f"{mod}.{a.name}" for a in node.names]
        else:
            continue
        out.update(n for n in names if n.split(".")[0] in OURS)
    return out


def _our_modules() -> dict[str, Path]:
    mods = {}
    for pkg in OURS:
        for f in (ROOT / pkg).rglob("*.py"):
            mods[_module_name(f)] = f
    return mods


def _graph() -> dict[str, set[str]]:
    mods = _our_modules()
    graph = {}
    for name, f in mods.items():
        deps = set()
        for m in imported_modules(f):
            while m and m not in mods:  # "from device.scene import Scene" → device.scene
                m = m.rpartition(".")[0]
            if m and m != name:
                deps.add(m)
        graph[name] = deps
    return graph


def test_simulated_device_does_not_import_matching():
    """Loading a scene on the simulated device never runs an experiment: device.sim renders
    tables and never reaches into acceleration matching (building a library is explicit)."""
    graph = _graph()
    for mod, deps in graph.items():
        if mod.startswith("device.sim"):
            bad = sorted(d for d in deps if d.startswith("device.matching"))
            assert not bad, f"{mod} imports {bad}"


def test_backends_do_not_build_tables():
    """One function outside the backends turns a transient into a table (device.tables)."""
    for mod, deps in _graph().items():
        if mod.startswith(("device.sim", "device.serial")):
            assert "device.tables" not in deps, mod
            assert not any(d.startswith("device.matching") for d in deps), mod


def test_no_import_cycles():
    graph = _graph()
    index, low, stack, on, cycles = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def _private_device_uses(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 \
                and node.module.split(".")[0] == "device":
            if any(p.startswith("_") for p in node.module.split(".")):
                bad.append(f"line {node.lineno}: from {node.module}")
            bad += [f"line {node.lineno}: import {a.name} from {node.module}"
                    for a in node.names if a.name.startswith("_")]
        elif isinstance(node, ast.Import):
            bad += [f"line {node.lineno}: import {a.name}" for a in node.names
                    if a.name.split(".")[0] == "device"
                    and any(p.startswith("_") for p in a.name.split("."))]
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_") \
                and not node.attr.startswith("__") \
                and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
            bad.append(f"line {node.lineno}: .{node.attr}")
    return bad


#: the simulator's and the serial driver's insides: app/ talks to a backend's class, never
#: to its parameters, plant, kernel, tapper, framing or messages
BACKEND_INSIDES = ("device.sim.params", "device.sim.plant", "device.sim.kernel",
                   "device.sim.tapper", "device.serial.framing", "device.serial.messages",
                   "device.serial.link")


def test_app_uses_only_public_device_api():
    """app/ reaches devices through public names only: no private modules or names of
    device, no private attributes of objects it does not own, and no backend insides (a
    simulated participant's hand goes through ``set_simulated_hand``, a device's ratings
    through ``DeviceInfo``)."""
    for f in sorted((ROOT / "app").rglob("*.py")):
        bad = _private_device_uses(f)
        assert not bad, f"{f.relative_to(ROOT)}: {bad}"
        insides = sorted(m for m in imported_modules(f) if m.startswith(BACKEND_INSIDES))
        assert not insides, f"{f.relative_to(ROOT)} imports {insides}"


def test_the_private_use_checker_sees_them(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("from device.sim._jit import lazy_njit\nfrom device.scene import _finite\n"
                 "def g(dev):\n    return dev._scene, self._ok\n")
    assert len(_private_device_uses(f)) == 3


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


@pytest.mark.integration
def test_core_imports_without_psychopy_or_writes(tmp_path):
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}  # Python's own caches are not ours
    out = subprocess.run([sys.executable, "-c", IMPORT_PROBE], capture_output=True, text=True,
                         cwd=tmp_path, check=True, env=env)
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["psychopy"] == []
    assert report["written"] == []
    assert list(tmp_path.iterdir()) == []


def _exported_errors() -> dict[str, str]:
    """Exception classes named in an ``__all__`` of our packages: name → module."""
    import importlib

    out = {}
    for name in _our_modules():
        if name.startswith("benchmarks") or name.endswith("__main__"):
            continue
        mod = importlib.import_module(name)
        for attr in getattr(mod, "__all__", ()):
            obj = getattr(mod, attr, None)
            if isinstance(obj, type) and issubclass(obj, BaseException) \
                    and obj.__module__.split(".")[0] in OURS:
                out[attr] = obj.__module__
    return out


def test_every_exported_error_is_raised_somewhere():
    """An error a package exports is one its code raises (directly, through a subclass, or
    handed to the code that raises it), never a name kept for show."""
    import importlib

    raised: set[str] = set()
    for path in _our_modules().values():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Raise) and node.exc is not None:
                target = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                if isinstance(target, ast.Name):
                    raised.add(target.id)
                elif isinstance(target, ast.Attribute):
                    raised.add(target.attr)
            elif isinstance(node, ast.Call):  # an error class passed on to be raised
                raised.update(a.id for a in node.args if isinstance(a, ast.Name)
                              and a.id.endswith(("Error", "Interrupted")))
            elif isinstance(node, (ast.Dict, ast.Tuple)):  # a table of errors to raise
                elts = node.values if isinstance(node, ast.Dict) else node.elts
                raised.update(e.id for e in elts if isinstance(e, ast.Name)
                              and e.id.endswith("Error"))
                raised.update(x.id for e in elts if isinstance(e, ast.Tuple) for x in e.elts
                              if isinstance(x, ast.Name) and x.id.endswith("Error"))
    errors = _exported_errors()
    classes = {n: getattr(importlib.import_module(m), n) for n, m in errors.items()}
    unused = []
    for n, cls in classes.items():
        subs = [s for s, c in classes.items() if c is not cls and issubclass(c, cls)]
        if n not in raised and not any(s in raised for s in subs):
            unused.append(f"{errors[n]}.{n}")
    assert not unused, f"exported but never raised: {unused}"
    assert {"CRCStormError", "HapticlabError", "SceneError"} <= set(errors)


def _kind_comparisons(path: Path, names: set[str]) -> list[str]:
    """Each comparison in ``path`` of something called ``kind`` with a phase kind's name
    (``trial.kind == "free"``, ``kind in ("rated", …)``), as ``file:line``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))

    def is_kind(node) -> bool:
        return (isinstance(node, ast.Attribute) and node.attr == "kind"
                or isinstance(node, ast.Name) and node.id == "kind")

    def named(node) -> bool:
        if isinstance(node, ast.Constant):
            return node.value in names
        if isinstance(node, ast.Tuple | ast.List | ast.Set):
            return any(named(e) for e in node.elts)
        return False

    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            if any(is_kind(s) for s in sides) and any(named(s) for s in sides):
                out.append(f"{os.path.relpath(path, ROOT)}:{node.lineno}")
    return out


def test_phase_kinds_are_looked_up_not_compared():
    """What differs between phase kinds is declared once, in protocols/kinds.py: elsewhere
    a kind is looked up (``phase_kind(name).surfaces``), never compared by name, so a new
    kind needs no branch anywhere else (issue 33)."""
    from protocols.kinds import REFERENCE, phase_kinds

    names = {*phase_kinds(), REFERENCE}
    found = [hit for d in sorted(OURS) for f in sorted((ROOT / d).rglob("*.py"))
             if f != ROOT / "protocols" / "kinds.py" for hit in _kind_comparisons(f, names)]
    assert not found, f"phase kinds compared by name: {found}"


def test_the_kind_checker_sees_comparisons(tmp_path):
    bad = tmp_path / "m.py"
    bad.write_text("if trial.kind == 'free':\n    pass\nok = kind in ('rated', 'x')\n"
                   "fine = phase.kind == other\nalso = status == 'free'\n")
    assert [h.rsplit(":", 1)[1] for h in _kind_comparisons(bad, {"free", "rated"})] \
        == ["1", "3"]


def _raw_meta_uses(path: Path) -> list[str]:
    """``meta["key"]`` and ``meta.get("key")`` on a name ending in ``meta`` (session.json
    read as a dict), as ``path:line``."""
    hits = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        target = None
        if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant) \
                and isinstance(node.slice.value, str):
            target = node.value
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and node.func.attr in ("get", "setdefault", "pop"):
            target = node.func.value
        name = (target.id if isinstance(target, ast.Name) else target.attr
                if isinstance(target, ast.Attribute) else "")
        if name.endswith("meta"):
            hits.append(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}:"
                        f"{node.lineno}")
    return hits


def test_session_json_is_read_and_written_through_its_record():
    """session.json has one owner, ``SessionRecord`` in analysis/session_format.py: the
    recorder, the runner, the API, the loader and the BIDS export use its fields, never
    its keys, so a key renamed or retyped changes one file (issue 33). A transient
    library's own record of how it was made is another file's, named ``provenance``."""
    own = ROOT / "analysis" / "session_format.py"
    found = [hit for d in sorted(OURS) for f in sorted((ROOT / d).rglob("*.py"))
             if f != own for hit in _raw_meta_uses(f)]
    assert not found, f"session.json read or written by key: {found}"


def test_the_record_checker_sees_keys(tmp_path):
    bad = tmp_path / "m.py"
    bad.write_text("a = meta['seed']\nb = self.meta.get('kind')\nc = meta.seed\n"
                   "d = row['seed']\ne = files.meta\nmeta.setdefault('notes', [])\n")
    assert [h.rsplit(":", 1)[1] for h in _raw_meta_uses(bad)] == ["1", "2", "6"]


#: what names a device rather than saying what it can do: DeviceInfo's ``backend`` and
#: ``firmware`` texts (and the variables that hold them)
_NAME_FIELDS = ("backend", "firmware", "device_backend")


def _names_a_device(node) -> bool:
    return (isinstance(node, ast.Attribute) and node.attr in _NAME_FIELDS) \
        or (isinstance(node, ast.Name) and node.id in _NAME_FIELDS) \
        or (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
            and node.func.attr == "get" and bool(node.args)
            and isinstance(node.args[0], ast.Constant) and node.args[0].value in _NAME_FIELDS)


def _texts(node):
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        yield node.value
    elif isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        for e in node.elts:
            yield from _texts(e)


def _name_comparisons(path: Path, names: set[str], exempt: tuple[str, ...] = ()) -> list[str]:
    """Where ``path`` decides by a device's name: a comparison or a prefix or pattern test
    of a backend's or a build's name (``info.backend == "sim"``, ``spec.startswith("sim:")``,
    ``firmware in ("qemu", ...)``), outside the functions named in ``exempt``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    skip = {id(n) for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and f.name in exempt
            for n in ast.walk(f)}
    prefixes = names | {f"{n}:" for n in names}
    hits = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Compare):
            ops = [node.left, *node.comparators]
            bad = any(_names_a_device(o) for o in ops) \
                or any(t in prefixes for o in ops for t in _texts(o))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and node.func.attr in ("startswith", "endswith", "match", "search",
                                       "fullmatch"):
            bad = _names_a_device(node.func.value) or any(_names_a_device(a) for a in node.args) \
                or any(t in prefixes for a in node.args for t in _texts(a))
        else:
            continue
        if bad:
            hits.append(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}:"
                        f"{node.lineno}: {ast.unparse(node)}")
    return hits


def _device_names() -> set[str]:
    from device import backends
    from device.serial.firmware import BUILDS

    return set(backends()) | set(BUILDS)


def test_no_code_outside_a_backend_decides_by_a_device_name():
    """Capabilities, not names (issue 54): the application, the protocols and the analysis
    ask a device what it is and can do (DeviceInfo), never compare a backend's or a
    firmware build's name. The one exception reads files older than format 4, which
    recorded names and no capabilities (session_format.device_capabilities)."""
    names = _device_names()
    found = [hit for d in ("app", "protocols", "analysis")
             for f in sorted((ROOT / d).rglob("*.py"))
             for hit in _name_comparisons(f, names, ("device_capabilities",))]
    assert not found, f"decided by a device's name: {found}"


def test_the_name_checker_sees_them(tmp_path):
    bad = tmp_path / "m.py"
    bad.write_text("a = info.backend == 'x'\nb = spec.startswith('sim:')\n"
                   "c = build in ('qemu', 'host')\nd = PATTERN.match(firmware)\n"
                   "e = d.get('backend') != ''\nf = what == 'link'\n"
                   "def device_capabilities(d):\n    return d.backend == 'sim'\n")
    hits = _name_comparisons(bad, _device_names(), ("device_capabilities",))
    assert [h.split(":")[1] for h in hits] == ["1", "2", "3", "4", "5"], hits


#: the most lines a module holds before it must say why at its top (issue 54)
MODULE_LINES = 700


def test_a_module_over_700_lines_says_why_at_its_top():
    """Modules with one job: one over 700 lines in app/, device/, analysis/ or protocols/
    states the reason in its docstring, in a paragraph that starts with ``Size:``."""
    unexplained = []
    for d in ("app", "device", "analysis", "protocols"):
        for f in sorted((ROOT / d).rglob("*.py")):
            text = f.read_text(encoding="utf-8")
            if text.count("\n") > MODULE_LINES and \
                    "\nSize: " not in (ast.get_docstring(ast.parse(text)) or ""):
                unexplained.append(f"{f.relative_to(ROOT)} ({text.count(chr(10))} lines)")
    assert not unexplained, f"over {MODULE_LINES} lines without a reason at the top: " \
        f"{unexplained}"
