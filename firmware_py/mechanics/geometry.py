"""The 6-UPS mechanism as data: anchors, leg limits, joint cones, links, inertias.

The numbers live in the rig's `geometry.toml` (physics/data, thesis units: mm, deg, kg mm^2);
this module is the controller's reading of it, converted once to SI and to the arrays the
kinematics and dynamics kernels use (the plant emulator reads the same file with its own code).
Frames: the base frame O has its origin at the centre of the circle through the universal
joint centres, z up; the platform frame P has its origin at the centre of the circle
through the spherical joint centres, w (its z) normal to the platform.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from physics.constants import GRAVITY_M_S2, KG_MM2, MM
from program.errors import UserInputError

N_LEGS = 6


class GeometryError(UserInputError):
    """A geometry file that is missing keys or holds impossible values."""


@dataclass(frozen=True)
class LinkInertia:
    """A rigid link: mass, centre of mass and inertia about the centre of mass (SI).

    `com_m` is given in the link's frame (its z along the leg axis, see dynamics.py).
    """
    mass_kg: float
    com_m: np.ndarray
    inertia_kg_m2: np.ndarray


@dataclass(frozen=True)
class Geometry:
    base_anchor_m: np.ndarray            # (6, 3) universal-joint centres a_i in O
    platform_anchor_m: np.ndarray        # (6, 3) spherical-joint centres b_i in P
    universal_axis: np.ndarray           # (6, 3) first U-joint axis u1_i (fixed to the base) in O
    leg_min_m: float                     # leg length (U centre to S centre) fully retracted
    stroke_m: float
    home_position_m: np.ndarray          # (3,) platform origin at home, orientation identity
    universal_cone_rad: float            # half-aperture about the base normal
    spherical_cone_rad: float            # half-aperture about the platform normal
    cylinder_length_m: float             # lower link, from the U centre along the leg
    cylinder_radius_m: float
    rod_length_m: float                  # upper link, from the S centre back along the leg
    rod_radius_m: float
    platform: LinkInertia
    cylinder: LinkInertia
    rod: LinkInertia
    gravity_m_s2: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -GRAVITY_M_S2]))
    source: str = ""

    @property
    def leg_max_m(self) -> float:
        return self.leg_min_m + self.stroke_m

    def with_payload(self, payload_kg: float) -> Geometry:
        """The platform carrying a payload at its centre of mass (a point mass there adds no
        inertia about it), as the rig's operator declares it."""
        return replace(self, platform=replace(self.platform, mass_kg=self.platform.mass_kg + payload_kg))

    @property
    def home_quaternion(self) -> np.ndarray:
        return np.array([1.0, 0.0, 0.0, 0.0])

    @property
    def characteristic_length_m(self) -> float:
        """Platform radius: scales rotations against translations in the condition index."""
        return float(np.linalg.norm(self.platform_anchor_m[0, :2]))


def ring_points(radius_m: float, angles_deg: list[float]) -> np.ndarray:
    angles = np.radians(np.asarray(angles_deg, dtype=float))
    return np.stack([radius_m * np.cos(angles), radius_m * np.sin(angles), np.zeros_like(angles)], axis=1)


def _need(table: dict, key: str, where: str):
    if key not in table:
        raise GeometryError(f"geometry: missing key {where + '.' if where else ''}{key}")
    return table[key]


def _positive(value, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise GeometryError(f"geometry: {name} = {value!r} is not a number") from None
    if not np.isfinite(number) or number <= 0.0:
        raise GeometryError(f"geometry: {name} = {value!r} must be a positive finite number")
    return number


def _vector(value, length: int, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (length,) or not np.all(np.isfinite(array)):
        raise GeometryError(f"geometry: {name} must be {length} finite numbers, got {value!r}")
    return array


def _link(table: dict, where: str) -> LinkInertia:
    mass = _positive(_need(table, "mass_kg", where), f"{where}.mass_kg")
    com = _vector(_need(table, "com_mm", where), 3, f"{where}.com_mm") * MM
    inertia = np.asarray(_need(table, "inertia_kg_mm2", where), dtype=float)
    if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)):
        raise GeometryError(f"geometry: {where}.inertia_kg_mm2 must be a 3x3 matrix")
    inertia = 0.5 * (inertia + inertia.T) * KG_MM2     # CAD tables round the symmetric terms
    if np.linalg.eigvalsh(inertia).min() <= 0.0:
        raise GeometryError(f"geometry: {where}.inertia_kg_mm2 is not positive definite")
    return LinkInertia(mass, com, inertia)


def universal_axes(base_anchor_m: np.ndarray, rule: str) -> np.ndarray:
    """First U-joint axis per leg, horizontal: tangent or radial to the base ring."""
    radial = base_anchor_m / np.linalg.norm(base_anchor_m, axis=1, keepdims=True)
    if rule == "radial":
        return radial
    if rule == "tangential":
        return np.stack([-radial[:, 1], radial[:, 0], np.zeros(len(radial))], axis=1)
    raise GeometryError(f"geometry: joints.universal_first_axis = {rule!r}: use 'tangential' or 'radial'")


_LINK_KEYS = {"mass_kg": None, "com_mm": None, "inertia_kg_mm2": None}
# every key a geometry file may hold: a misspelt one is an error, not silently the default
GEOMETRY_KEYS = {
    "rings": dict.fromkeys(("base_radius_mm", "platform_radius_mm", "base_anchor_angles_deg",
                            "platform_anchor_angles_deg")),
    "legs": dict.fromkeys(("min_length_mm", "stroke_mm", "home_height_mm")),
    "joints": dict.fromkeys(("universal_cone_deg", "spherical_cone_deg", "universal_first_axis")),
    "links": dict.fromkeys(("cylinder_length_mm", "cylinder_diameter_mm", "rod_length_mm", "rod_diameter_mm")),
    "inertia": {"platform": _LINK_KEYS, "cylinder": _LINK_KEYS, "rod": _LINK_KEYS},
}


def _reject_unknown(table: dict, known: dict, where: str = "") -> None:
    for key, value in table.items():
        name = f"{where}.{key}" if where else key
        if key not in known:
            kind = "section" if isinstance(value, dict) else "key"
            raise GeometryError(f"geometry: unknown {kind} {name} (known: {', '.join(known)})")
        if isinstance(known[key], dict):
            if not isinstance(value, dict):
                raise GeometryError(f"geometry: {name} = {value!r} must be a section ([{name}])")
            _reject_unknown(value, known[key], name)


def parse_geometry(data: dict, source: str = "") -> Geometry:
    _reject_unknown(data, GEOMETRY_KEYS)
    rings = _need(data, "rings", "")
    legs = _need(data, "legs", "")
    joints = _need(data, "joints", "")
    links = _need(data, "links", "")
    inertia = _need(data, "inertia", "")
    base_r = _positive(_need(rings, "base_radius_mm", "rings"), "rings.base_radius_mm") * MM
    plat_r = _positive(_need(rings, "platform_radius_mm", "rings"), "rings.platform_radius_mm") * MM
    base_angles = _vector(_need(rings, "base_anchor_angles_deg", "rings"), N_LEGS, "rings.base_anchor_angles_deg")
    plat_angles = _vector(_need(rings, "platform_anchor_angles_deg", "rings"), N_LEGS,
                          "rings.platform_anchor_angles_deg")
    base = ring_points(base_r, list(base_angles))
    platform = ring_points(plat_r, list(plat_angles))
    leg_min = _positive(_need(legs, "min_length_mm", "legs"), "legs.min_length_mm") * MM
    stroke = _positive(_need(legs, "stroke_mm", "legs"), "legs.stroke_mm") * MM
    home = _positive(_need(legs, "home_height_mm", "legs"), "legs.home_height_mm") * MM
    u_cone = np.radians(_positive(_need(joints, "universal_cone_deg", "joints"), "joints.universal_cone_deg"))
    s_cone = np.radians(_positive(_need(joints, "spherical_cone_deg", "joints"), "joints.spherical_cone_deg"))
    if u_cone > np.pi / 2 + 1e-12 or s_cone > np.pi / 2 + 1e-12:
        raise GeometryError("geometry: joint cone half-apertures must be at most 90 deg")
    geometry = Geometry(
        base_anchor_m=base, platform_anchor_m=platform,
        universal_axis=universal_axes(base, str(_need(joints, "universal_first_axis", "joints"))),
        leg_min_m=leg_min, stroke_m=stroke, home_position_m=np.array([0.0, 0.0, home]),
        universal_cone_rad=float(u_cone), spherical_cone_rad=float(s_cone),
        cylinder_length_m=_positive(_need(links, "cylinder_length_mm", "links"), "links.cylinder_length_mm") * MM,
        cylinder_radius_m=0.5 * _positive(_need(links, "cylinder_diameter_mm", "links"),
                                          "links.cylinder_diameter_mm") * MM,
        rod_length_m=_positive(_need(links, "rod_length_mm", "links"), "links.rod_length_mm") * MM,
        rod_radius_m=0.5 * _positive(_need(links, "rod_diameter_mm", "links"), "links.rod_diameter_mm") * MM,
        platform=_link(_need(inertia, "platform", "inertia"), "inertia.platform"),
        cylinder=_link(_need(inertia, "cylinder", "inertia"), "inertia.cylinder"),
        rod=_link(_need(inertia, "rod", "inertia"), "inertia.rod"),
        source=source,
    )
    home_legs = np.linalg.norm(geometry.home_position_m + platform - base, axis=1)
    if np.any(home_legs < leg_min) or np.any(home_legs > leg_min + stroke):
        raise GeometryError(f"geometry: the home pose needs leg lengths {np.round(home_legs / MM, 1)} mm, "
                            f"outside [{leg_min / MM:g}, {(leg_min + stroke) / MM:g}] mm")
    return geometry


def load_geometry_file(path: str | Path) -> Geometry:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as error:
        raise GeometryError(f"geometry: cannot read {path}: {error.strerror}") from None
    except tomllib.TOMLDecodeError as error:
        raise GeometryError(f"geometry: {path} is not valid TOML: {error}") from None
    return parse_geometry(data, str(path))


@lru_cache(maxsize=1)
def default_geometry() -> Geometry:
    """The rig's geometry shipped with the project (physics/data/geometry.toml)."""
    text = resources.files("physics").joinpath("data/geometry.toml").read_text()
    return parse_geometry(tomllib.loads(text), "physics/data/geometry.toml")
