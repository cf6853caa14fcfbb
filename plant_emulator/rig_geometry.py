"""The plant's own reading of the rig's geometry file (physics/data/geometry.toml): what
the MuJoCo model is built from. The controller reads the same file with its own code, so a
mistake in either reading shows up as a disagreement in HIL rather than being shared.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from physics.constants import GRAVITY_M_S2, KG_MM2, MM
from program.errors import UserInputError


class RigGeometryError(UserInputError):
    """The geometry file lacks a value the plant needs, or holds an unusable one."""


@dataclass(frozen=True)
class Body:
    mass_kg: float
    com_m: np.ndarray            # in the body's own frame
    inertia_kg_m2: np.ndarray    # about the centre of mass, symmetric


@dataclass(frozen=True)
class RigGeometry:
    base_anchor_m: np.ndarray            # (6, 3) universal-joint centres, base frame
    platform_anchor_m: np.ndarray        # (6, 3) spherical-joint centres, platform frame
    universal_axis: np.ndarray           # (6, 3) first hinge of each universal joint, horizontal
    leg_min_m: float
    stroke_m: float
    home_position_m: np.ndarray
    cylinder_length_m: float
    cylinder_radius_m: float
    rod_length_m: float
    rod_radius_m: float
    platform: Body
    cylinder: Body
    rod: Body
    universal_cone_rad: float = math.pi / 2   # each universal joint's half-aperture about the base normal
    gravity_m_s2: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -GRAVITY_M_S2]))

    @property
    def leg_max_m(self) -> float:
        return self.leg_min_m + self.stroke_m

    @property
    def home_quaternion(self) -> np.ndarray:
        return np.array([1.0, 0.0, 0.0, 0.0])


def _value(data: dict, source: str, section: str, key: str):
    try:
        return data[section][key]
    except (KeyError, TypeError):
        raise RigGeometryError(f"geometry {source}: missing [{section}].{key}") from None


def _ring(radius_mm: float, angles_deg) -> np.ndarray:
    """Points on a circle in the z = 0 plane of its frame."""
    phi = np.deg2rad(np.asarray(angles_deg, dtype=float))
    return np.outer(np.cos(phi), [radius_mm * MM, 0.0, 0.0]) + np.outer(np.sin(phi), [0.0, radius_mm * MM, 0.0])


def _first_hinges(base_anchor_m: np.ndarray, rule: str, source: str) -> np.ndarray:
    outward = base_anchor_m / np.linalg.norm(base_anchor_m, axis=1)[:, None]
    if rule == "radial":
        return outward
    if rule == "tangential":
        return np.cross([0.0, 0.0, 1.0], outward)
    raise RigGeometryError(f"geometry {source}: [joints].universal_first_axis = {rule!r} (tangential or radial)")


def _body(data: dict, source: str, name: str) -> Body:
    section = f"inertia.{name}"
    table = data.get("inertia", {}).get(name)
    if not isinstance(table, dict):
        raise RigGeometryError(f"geometry {source}: missing [{section}]")
    try:
        inertia = np.asarray(table["inertia_kg_mm2"], dtype=float) * KG_MM2
        body = Body(float(table["mass_kg"]), np.asarray(table["com_mm"], dtype=float) * MM,
                    0.5 * (inertia + inertia.T))
    except KeyError as missing:
        raise RigGeometryError(f"geometry {source}: missing [{section}].{missing.args[0]}") from None
    if body.inertia_kg_m2.shape != (3, 3) or body.com_m.shape != (3,) or not body.mass_kg > 0:
        raise RigGeometryError(f"geometry {source}: [{section}] needs a positive mass, a 3-vector and a 3x3 matrix")
    return body


def read_rig_geometry(path: str | Path | None = None) -> RigGeometry:
    """The rig's geometry from `path`, or the file the project ships."""
    if path is None:
        source = "physics/data/geometry.toml"
        text = resources.files("physics").joinpath("data/geometry.toml").read_text()
    else:
        source = str(path)
        try:
            text = Path(path).read_text()
        except OSError as error:
            raise RigGeometryError(f"geometry {source}: cannot read ({error.strerror})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise RigGeometryError(f"geometry {source}: not valid TOML ({error})") from None
    base = _ring(_value(data, source, "rings", "base_radius_mm"),
                 _value(data, source, "rings", "base_anchor_angles_deg"))
    return RigGeometry(
        base_anchor_m=base,
        platform_anchor_m=_ring(_value(data, source, "rings", "platform_radius_mm"),
                                _value(data, source, "rings", "platform_anchor_angles_deg")),
        universal_axis=_first_hinges(base, _value(data, source, "joints", "universal_first_axis"), source),
        leg_min_m=_value(data, source, "legs", "min_length_mm") * MM,
        stroke_m=_value(data, source, "legs", "stroke_mm") * MM,
        home_position_m=np.array([0.0, 0.0, _value(data, source, "legs", "home_height_mm") * MM]),
        cylinder_length_m=_value(data, source, "links", "cylinder_length_mm") * MM,
        cylinder_radius_m=_value(data, source, "links", "cylinder_diameter_mm") * MM / 2.0,
        rod_length_m=_value(data, source, "links", "rod_length_mm") * MM,
        rod_radius_m=_value(data, source, "links", "rod_diameter_mm") * MM / 2.0,
        platform=_body(data, source, "platform"), cylinder=_body(data, source, "cylinder"),
        rod=_body(data, source, "rod"),
        universal_cone_rad=math.radians(_value(data, source, "joints", "universal_cone_deg")),
    )
