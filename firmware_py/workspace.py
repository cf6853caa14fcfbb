"""Workspace and singularity tests (thesis chapters 9.3 and 9.6), vectorised over poses.

A pose is in the workspace when (chapter 9.3):
1. every leg length is within [L_min, L_min + stroke];
2. every leg stays inside the universal joint's cone (axis: base normal) and the spherical
   joint's cone (axis: platform normal), half-apertures from the geometry;
3. no two legs interfere: each leg is two cylinders (the cylinder body from the U centre,
   the rod from the S centre) and the distance between the axis segments of any two
   cylinders of different legs must exceed the sum of their radii.
Singularity: det Jx (eq. 9.27) changes sign across the singular surface; the condition
index 1/cond(Jx) (rotation columns scaled by the platform radius) measures proximity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Geometry
from .kinematics import condition_index_batch, ik_batch, jacobian_batch
from .rotation import quat_to_matrix

# Singularity proximity limit of the rig: poses with 1/cond(Jx) below this are refused
# (waypoint validation, supervisor) and left out of the usable workspace. At the limit, a
# 1 N leg-force error gives up to ~200x larger platform wrench errors, and the direct
# kinematics has a second assembly mode within about a millimetre (measured in dk-eval).
MIN_CONDITION_INDEX = 0.005

LEG_PAIRS = np.array([(i, j) for i in range(6) for j in range(i + 1, 6)])


def segment_distance(p1, q1, p2, q2) -> np.ndarray:
    """Shortest distance between segments [p1, q1] and [p2, q2], vectorised over leading axes.

    Closest points of two segments (Ericson, Real-Time Collision Detection, 5.1.9).
    """
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = np.einsum("...k,...k", d1, d1)
    e = np.einsum("...k,...k", d2, d2)
    f = np.einsum("...k,...k", d2, r)
    c = np.einsum("...k,...k", d1, r)
    b = np.einsum("...k,...k", d1, d2)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-18 * a * e, np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        t = (b * s + f) / e
        s = np.where(t < 0.0, np.clip(-c / a, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    closest = (p1 + d1 * s[..., None]) - (p2 + d2 * t[..., None])
    return np.linalg.norm(closest, axis=-1)


@dataclass
class WorkspaceReport:
    """Per-pose results of the workspace test (arrays of length N)."""
    lengths_m: np.ndarray
    stroke_ok: np.ndarray
    universal_ok: np.ndarray
    spherical_ok: np.ndarray
    interference_ok: np.ndarray
    min_clearance_m: np.ndarray
    det_jx: np.ndarray
    condition_index: np.ndarray

    @property
    def reachable(self) -> np.ndarray:
        return self.stroke_ok & self.universal_ok & self.spherical_ok & self.interference_ok


def check_poses(geometry: Geometry, positions_m, quats, chunk: int = 20000) -> WorkspaceReport:
    """The workspace test and singularity measures for N poses."""
    positions_m = np.atleast_2d(np.asarray(positions_m, dtype=float))
    quats = np.broadcast_to(np.atleast_2d(np.asarray(quats, dtype=float)), (len(positions_m), 4))
    parts = [_check_chunk(geometry, positions_m[k:k + chunk], quats[k:k + chunk])
             for k in range(0, len(positions_m), chunk)]
    return WorkspaceReport(*(np.concatenate([getattr(p, name) for p in parts])
                             for name in WorkspaceReport.__dataclass_fields__))


def _check_chunk(geometry: Geometry, positions_m, quats) -> WorkspaceReport:
    lengths, units = ik_batch(geometry, positions_m, quats)
    stroke_ok = np.all((lengths >= geometry.leg_min_m) & (lengths <= geometry.leg_max_m), axis=1)
    universal_ok = np.all(units[..., 2] >= np.cos(geometry.universal_cone_rad), axis=1)
    platform_normal = quat_to_matrix(quats)[..., :, 2]
    spherical_ok = np.all(np.einsum("nkj,nj->nk", units, platform_normal) >= np.cos(geometry.spherical_cone_rad),
                          axis=1)
    clearance = _interference_clearance(geometry, lengths, units)
    jac = jacobian_batch(geometry, positions_m, quats)
    return WorkspaceReport(lengths, stroke_ok, universal_ok, spherical_ok, clearance >= 0.0, clearance,
                           np.linalg.det(jac), condition_index_batch(geometry, jac))


def _interference_clearance(geometry: Geometry, lengths, units) -> np.ndarray:
    """Smallest (segment distance - radii sum) over all cylinder pairs of different legs."""
    base = geometry.base_anchor_m[None]
    top = base + units * lengths[..., None]
    cyl_len = np.minimum(geometry.cylinder_length_m, lengths)[..., None]
    rod_len = np.minimum(geometry.rod_length_m, lengths)[..., None]
    cylinder = (np.broadcast_to(base, top.shape), base + units * cyl_len, geometry.cylinder_radius_m)
    rod = (top, top - units * rod_len, geometry.rod_radius_m)
    i, j = LEG_PAIRS[:, 0], LEG_PAIRS[:, 1]
    clearance = np.full(len(lengths), np.inf)
    for first in (cylinder, rod):
        for second in (cylinder, rod):
            gap = segment_distance(first[0][:, i], first[1][:, i], second[0][:, j], second[1][:, j])
            clearance = np.minimum(clearance, np.min(gap, axis=1) - (first[2] + second[2]))
    return clearance
