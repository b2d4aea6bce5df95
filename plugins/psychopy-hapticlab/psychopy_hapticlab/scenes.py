"""A scene for a Builder experiment: a built-in sample, a scene file, or fields of a
conditions row, each made into hapticlab's :class:`device.Scene` (which checks it).

Nothing here renders anything or imports PsychoPy: what the device plays is the device
layer's, and every check is :meth:`device.Scene.from_dict`'s, so a field a Builder user got
wrong is named the way hapticlab names it everywhere.
"""

from __future__ import annotations

import json
import numbers
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from device import Scene, SceneError

__all__ = ["SOURCES", "TRANSIENTS", "TRANSIENT_FIELDS", "builtin_samples", "sample_scene",
           "file_scene", "fields_scene"]

#: where a Haptic contact's scene comes from
SOURCES = ("parameters", "built-in sample", "scene file")

#: the transients a scene made of fields may play (``none``: the spring alone); a grasp
#: model scene comes from a scene file
TRANSIENTS = ("none", "q_sinusoid", "sinusoid", "pulse", "library")

#: per transient kind: the Builder parameter behind each of its fields
TRANSIENT_FIELDS: dict[str, dict[str, str]] = {
    "q_sinusoid": {"slope": "slope", "decay": "decay", "frequency": "frequency"},
    "sinusoid": {"gain": "gain", "decay_time": "decayTime", "frequency": "frequency"},
    "pulse": {"gain": "gain", "duration": "pulseDuration"},
    "library": {"source": "librarySource", "attenuation": "attenuation"},
    "none": {},
}


def _number(v: Any) -> Any:
    """A number from a conditions file as a float (numpy's and pandas' integers are not
    Python ints), a numeric text as its number; anything else as it is, for the scene's
    own check to name."""
    if isinstance(v, bool):
        return v
    if isinstance(v, numbers.Real):
        return float(v)
    if isinstance(v, str):
        try:
            return float(v.strip())
        except ValueError:
            return v
    return v


def builtin_samples() -> list[str]:
    """Every sample of the built-in protocols, as ``protocol/sample`` (the values the
    Builder parameter offers), in the protocols' order."""
    from protocols import BUILTIN, load_protocol

    return [f"{p}/{s}" for p in BUILTIN for s in load_protocol(p).samples]


def sample_scene(ref: str) -> Scene:
    """The scene of a built-in sample: ``protocol/sample`` (``realism/sinusoid_firm``), or a
    sample id alone when one built-in protocol has it.

    Raises
    ------
    SceneError
        No such sample (the message lists where to look), or a bare id several protocols use.
    """
    from protocols import BUILTIN, load_protocol

    ref = str(ref).strip()
    if "/" in ref:
        proto, _, sample = ref.partition("/")
        if proto not in BUILTIN:
            raise SceneError(f"no built-in protocol {proto!r}; built-in: {', '.join(BUILTIN)}",
                             "sample", where="Haptic contact")
        samples = load_protocol(proto).samples
        if sample not in samples:
            raise SceneError(f"protocol {proto!r} has no sample {sample!r}; it has "
                             f"{', '.join(samples)}", "sample", where="Haptic contact")
        return samples[sample].scene
    found = [(p, load_protocol(p).samples.get(ref)) for p in BUILTIN]
    found = [(p, s) for p, s in found if s is not None]
    if not found:
        raise SceneError(f"no built-in sample {ref!r}; name one as protocol/sample (e.g. "
                         "realism/sinusoid_firm)", "sample", where="Haptic contact")
    scenes = {repr(s.scene.to_dict()) for _, s in found}
    if len(scenes) > 1:
        raise SceneError(f"sample {ref!r} differs between protocols "
                         f"{', '.join(p for p, _ in found)}: name one as protocol/{ref}",
                         "sample", where="Haptic contact")
    return found[0][1].scene


def file_scene(path: str | Path) -> Scene:
    """The scene in a TOML or JSON file: one table with ``name``, ``spring`` and
    ``transient`` (or ``material``), as :meth:`device.Scene.from_dict` reads it.

    Raises
    ------
    SceneError
        The file is missing or not TOML/JSON (named), or the scene in it is not valid.
    """
    if path in (None, "") or not str(path).strip():
        raise SceneError("name a scene file (TOML or JSON)", "sceneFile", where="Haptic contact")
    p = Path(path)
    where = f"scene file {p}"
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError("no such file", where=where) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot be read ({exc})", where=where) from None
    try:
        data = json.loads(text) if p.suffix.lower() == ".json" else tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"not valid {'JSON' if p.suffix.lower() == '.json' else 'TOML'} "
                         f"({exc})", where=where) from None
    if isinstance(data, Mapping) and "scene" in data and isinstance(data["scene"], Mapping):
        data = {"name": p.stem, **data["scene"]}
    elif isinstance(data, Mapping) and "name" not in data:
        data = {"name": p.stem, **data}
    return Scene.from_dict(data, where=where)


def fields_scene(name: str, spring: Any, transient: str, surface_height: Any = 0.0,
                 **fields: Any) -> Scene:
    """A virtual sample from Builder fields (constants or a conditions row's values).

    Parameters
    ----------
    name : str
        The scene's name (what the data file records).
    spring : float [N/m]
        Penetration spring.
    transient : str
        One of :data:`TRANSIENTS`.
    surface_height : float [m]
    **fields
        The transient's fields by their Builder names (:data:`TRANSIENT_FIELDS`): ``slope``
        [1/s], ``decay`` [1/s], ``frequency`` [Hz], ``gain`` [N·s/m], ``decayTime`` [s],
        ``pulseDuration`` [s], ``librarySource``, ``attenuation``; those the kind does not
        use are ignored.

    Raises
    ------
    SceneError
        Naming the field and the value, and what is allowed.
    """
    kind = str(transient).strip()
    if kind not in TRANSIENT_FIELDS:
        raise SceneError(f"must be one of {', '.join(TRANSIENTS)}, got {transient!r}",
                         "transient", where=f"scene '{name}'")
    data: dict[str, Any] = {"name": str(name) or "scene", "spring": _number(spring),
                            "surface_height": _number(surface_height)}
    if kind != "none":
        table: dict[str, Any] = {"kind": kind}
        for field, param in TRANSIENT_FIELDS[kind].items():
            if param not in fields:
                raise SceneError(f"a {kind} transient needs {param}", field,
                                 where=f"scene '{name}'.transient")
            v = fields[param]
            table[field] = str(v).strip() if field == "source" else _number(v)
        data["transient"] = table
    return Scene.from_dict(data)
