"""What a device renders for one sample: the :class:`Scene` and its parts.

A scene is plain validated data with SI units. It lists exactly what the sample
needs, and the device models nothing more: a real sample has a physical
:class:`Material` and no rendering; a virtual sample has a penetration spring and
optionally a :class:`Transient` played open-loop at contact.

The parts live beside it and are imported from here as well: a real sample's physics in
:mod:`device.materials`, what a virtual one plays at contact in :mod:`device.transients`,
the checks they share in ``device._checks``.

Sign conventions (used throughout :mod:`device`): heights point up, the surface
is at ``surface_height``; penetration is ``surface_height - z``; an *incoming
velocity* is reported as a positive speed into the surface; forces are positive
out of the surface (upwards).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from ._checks import (
    _STIFFNESS,
    MAX_DAMPING,
    MAX_DECAY,
    MAX_GAIN,
    MAX_RINGING_HZ,
    MAX_SLOPE,
    MAX_STIFFNESS,
    _check_keys,
    _finite,
    unknown_key,
)
from .errors import SceneError
from .materials import (  # noqa: F401 - BLOCK_HINT re-exported: a scene's parts, from here
    BLOCK_HINT,
    MAX_BLOCK_KG,
    Material,
    Ringing,
    Support,
)
from .transients import (  # noqa: F401 - re-exported: a scene's parts, imported from here
    BLENDS,
    MAX_TRANSIENT_S,
    MIN_RENDERED,
    OVERSAMPLE,
    PUBLISHED_GRASP,
    WARN_RENDERED,
    AccelSinusoid,
    ForceSinusoid,
    GraspModel,
    GraspTransient,
    LibraryTransient,
    Pulse,
    TableTransient,
    Transient,
    TransientTable,
    parse_transient,
    register_transient,
    transient_kinds,
)

__all__ = [
    "TransientTable",
    "LibraryTransient",
    "TableTransient",
    "GraspModel",
    "GraspTransient",
    "PUBLISHED_GRASP",
    "Scene",
    "Material",
    "Support",
    "MAX_BLOCK_KG",
    "MAX_STIFFNESS",
    "MAX_DAMPING",
    "MAX_RINGING_HZ",
    "MAX_SLOPE",
    "MAX_DECAY",
    "MAX_GAIN",
    "Ringing",
    "Transient",
    "Pulse",
    "ForceSinusoid",
    "AccelSinusoid",
    "register_transient",
    "transient_kinds",
    "unknown_key",
]

#: farthest a surface may be from the device's origin [m]: a desktop stylus reaches a few
#: centimetres, and a surface beyond reach would make every window time out
MAX_REACH_M = 0.5


@dataclass(frozen=True)
class Scene:
    """One sample as the device sees it.

    Exactly one of ``material`` (a real sample, physically touched) and ``spring``
    (a virtual sample) is set. Build scenes from data with :meth:`from_dict`.

    Parameters
    ----------
    name : str
        Identifier, used in records and messages.
    surface_height : float [m]
        Height of the (real or virtual) surface in device coordinates, within
        ±:data:`MAX_REACH_M`.
    spring : float or None [N/m]
        Penetration-spring stiffness of a virtual sample (0 allowed: transient only);
        None for a real sample.
    transient : Transient or None
        Open-loop force transient played at each contact (virtual samples only).
    material : Material or None
        Physical contact of a real sample.
    """

    name: str
    surface_height: float = 0.0
    spring: float | None = None
    transient: Transient | None = None
    material: Material | None = None
    meta: Mapping[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise SceneError(f"must be a non-empty string, got {self.name!r}", "name",
                             where="scene")
        where = f"scene '{self.name}'"
        object.__setattr__(self, "surface_height",
                           _finite(where, "surface_height", self.surface_height,
                                   minimum=-MAX_REACH_M, maximum=MAX_REACH_M))
        if self.material is None and self.spring is None:
            raise SceneError("a scene needs either 'material' (real sample) or 'spring' "
                             "(virtual sample)", "spring", where=where)
        if self.material is not None and (self.spring is not None or self.transient is not None):
            raise SceneError("a real sample ('material') cannot also have 'spring' or "
                             "'transient'; real samples are touched, not rendered",
                             "spring" if self.spring is not None else "transient", where=where)
        if self.spring is not None:
            object.__setattr__(self, "spring", _finite(where, "spring", self.spring,
                                                       **{**_STIFFNESS, "strict": False}))

    @property
    def is_real(self) -> bool:
        """True for a physical sample (no rendering)."""
        return self.material is not None

    @property
    def kind(self) -> str:
        """``real``, ``spring`` or the transient kind."""
        if self.material is not None:
            return "real"
        return self.transient.kind if self.transient is not None else "spring"

    # ------------------------------------------------------------------ data
    _KEYS: ClassVar[set[str]] = {"name", "surface_height", "spring", "transient", "material"}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str | None = None) -> Scene:
        """Build and validate a scene from plain data (e.g. a TOML table).

        Parameters
        ----------
        data : mapping
            Keys ``name``, ``surface_height`` [m], and either ``spring`` [N/m] with an
            optional ``transient`` table (``kind`` plus its fields), or a ``material``
            table (``stiffness`` [N/m], ``damping`` [N·s/m], optional ``ringing`` table
            with ``slope`` [1/s], ``decay`` [1/s], ``frequency`` [Hz]).
        where : str, optional
            Prefix for error messages (e.g. a file and table name).

        Raises
        ------
        SceneError
            Naming the field, the offending value and what is allowed.
        """
        if not isinstance(data, Mapping):
            raise SceneError(f"expected a table, got {type(data).__name__}",
                             where=where or "scene")
        name = data.get("name", "?")
        where = where or f"scene '{name}'"
        _check_keys(where, data, cls._KEYS, {"name"})
        kwargs: dict[str, Any] = {"name": data["name"]}
        if "surface_height" in data:
            kwargs["surface_height"] = data["surface_height"]
        if "spring" in data:
            kwargs["spring"] = data["spring"]
        if "transient" in data:
            kwargs["transient"] = _in_part(("transient",), parse_transient,
                                           f"{where}.transient", data["transient"])
        if "material" in data:
            kwargs["material"] = _in_part(("material",), _parse_material,
                                          f"{where}.material", data["material"])
        try:
            return cls(**kwargs)
        except SceneError as exc:
            raise exc.within(where=where) from None

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form accepted by :meth:`from_dict`."""
        out: dict[str, Any] = {"name": self.name, "surface_height": self.surface_height}
        if self.spring is not None:
            out["spring"] = self.spring
        if self.transient is not None:
            out["transient"] = self.transient.to_dict()
        if self.material is not None:
            m: dict[str, Any] = {"stiffness": self.material.stiffness,
                                 "damping": self.material.damping}
            if self.material.ringing is not None:
                r = self.material.ringing
                m["ringing"] = {"slope": r.slope, "decay": r.decay, "frequency": r.frequency}
            if self.material.mass is not None:
                m["mass"] = self.material.mass
            if self.material.support is not None:
                sp = self.material.support
                m["support"] = {"stiffness": sp.stiffness, "damping": sp.damping}
            out["material"] = m
        return out


def _in_part(part: tuple[str, ...], parse: Callable[[str, Any], Any], where: str, data: Any):
    """Run a sub-parser, recording in any SceneError which part of the scene failed."""
    try:
        return parse(where, data)
    except SceneError as exc:
        raise exc.within(part) from None


def _parse_material(where: str, data: Any) -> Material:
    if not isinstance(data, Mapping):
        raise SceneError(f"expected a table, got {data!r}", where=where)
    _check_keys(where, data, {"stiffness", "damping", "ringing", "mass", "support"},
                {"stiffness"})
    if "damping" in data and "mass" in data and "ringing" in data:
        raise SceneError("a ringing block's contact damping is derived from its ringing's "
                         "decay; remove 'damping'", "damping", where=where)
    ringing = _sub_table(where, data, "ringing", Ringing, {"slope", "decay", "frequency"},
                         {"slope", "decay", "frequency"})
    support = _sub_table(where, data, "support", Support, {"stiffness", "damping"},
                         {"stiffness"})
    try:
        return Material(stiffness=data["stiffness"], damping=data.get("damping", 0.0),
                        ringing=ringing, mass=data.get("mass"), support=support)
    except SceneError as exc:
        raise exc.within(where=where) from None


def _sub_table(where: str, data: Mapping[str, Any], key: str, cls, allowed: set[str],
               required: set[str]):
    """The optional sub-table ``key`` of a material, built as ``cls`` (None when absent)."""
    if key not in data:
        return None
    r = data[key]
    w = f"{where}.{key}"
    if not isinstance(r, Mapping):
        raise SceneError(f"expected a table, got {r!r}", part=(key,), where=w)

    def build(w: str, d: Mapping[str, Any]):
        _check_keys(w, d, allowed, required)
        try:
            return cls(**d)
        except SceneError as exc:
            raise exc.within(where=w) from None

    return _in_part((key,), build, w, r)
