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

Two flavours: `check_poses`, vectorised NumPy for sweeps of many poses, and
`PoseChecker`, a numba kernel per pose for the few poses of a waypoint commit (its cost
must fit in the slack of a 2 ms cycle; `check_poses` is its oracle in the tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from firmware_py.mechanics.geometry import Geometry
from firmware_py.mechanics.kinematics import condition_index_batch, ik_batch, ik_into, jacobian_batch, jacobian_into
from firmware_py.mechanics.rotation import quat_to_matrix

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


# -- one pose at a time, compiled ---------------------------------------------------------

# layout of PoseChecker's limits array and of its result array
(LIM_LEG_MIN, LIM_LEG_MAX, LIM_COS_UNIVERSAL, LIM_COS_SPHERICAL, LIM_CYLINDER_LENGTH, LIM_ROD_LENGTH,
 LIM_CYLINDER_RADIUS, LIM_ROD_RADIUS, LIM_CHARACTERISTIC_LENGTH) = range(9)
OUT_REACHABLE, OUT_CLEARANCE, OUT_DET, OUT_CONDITION = range(4)


@njit(cache=True)
def _segment_distance(p1, q1, p2, q2) -> float:
    """`segment_distance` for one pair of segments (3-vectors)."""
    a = e = f = c = b = 0.0
    for k in range(3):
        d1, d2, r = q1[k] - p1[k], q2[k] - p2[k], p1[k] - p2[k]
        a += d1 * d1
        e += d2 * d2
        f += d2 * r
        c += d1 * r
        b += d1 * d2
    denom = a * e - b * b
    s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > 1e-18 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        s = min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        s = min(max((b - c) / a, 0.0), 1.0)
    t = min(max(t, 0.0), 1.0)
    total = 0.0
    for k in range(3):
        gap = (p1[k] + (q1[k] - p1[k]) * s) - (p2[k] + (q2[k] - p2[k]) * t)
        total += gap * gap
    return math.sqrt(total)


@njit(cache=True)
def pose_check_into(base, platform, limits, r, p, rot, platform_world, lengths, units, ends, jac, out):
    """The workspace test of one pose (the rules of `check_poses`) into out[OUT_*]; `ends`
    (4, 6, 3) holds each leg's cylinder (U centre, its end) and rod (S centre, its end)."""
    ik_into(base, platform, r, p, rot, platform_world, lengths, units)
    n = base.shape[0]
    reachable = True
    for i in range(n):
        reachable &= limits[LIM_LEG_MIN] <= lengths[i] <= limits[LIM_LEG_MAX]
        reachable &= units[i, 2] >= limits[LIM_COS_UNIVERSAL]
        normal_dot = units[i, 0] * rot[0, 2] + units[i, 1] * rot[1, 2] + units[i, 2] * rot[2, 2]
        reachable &= normal_dot >= limits[LIM_COS_SPHERICAL]
        cylinder = min(limits[LIM_CYLINDER_LENGTH], lengths[i])
        rod = min(limits[LIM_ROD_LENGTH], lengths[i])
        for k in range(3):
            top = base[i, k] + units[i, k] * lengths[i]
            ends[0, i, k] = base[i, k]
            ends[1, i, k] = base[i, k] + units[i, k] * cylinder
            ends[2, i, k] = top
            ends[3, i, k] = top - units[i, k] * rod
    radius = (limits[LIM_CYLINDER_RADIUS], limits[LIM_ROD_RADIUS])
    clearance = np.inf
    for i in range(n):
        for j in range(i + 1, n):
            for first in range(2):
                for second in range(2):
                    gap = _segment_distance(ends[2 * first, i], ends[2 * first + 1, i],
                                            ends[2 * second, j], ends[2 * second + 1, j])
                    clearance = min(clearance, gap - (radius[first] + radius[second]))
    jacobian_into(units, platform_world, jac)
    out[OUT_DET] = np.linalg.det(jac)
    for i in range(n):
        for k in range(3, 6):
            jac[i, k] /= limits[LIM_CHARACTERISTIC_LENGTH]
    singular_values = np.linalg.svd(jac)[1]
    out[OUT_CONDITION] = singular_values[-1] / singular_values[0]
    out[OUT_CLEARANCE] = clearance
    out[OUT_REACHABLE] = 1.0 if reachable and clearance >= 0.0 else 0.0


class PoseChecker:
    """`pose_check_into` with its work arrays allocated once, for one geometry."""

    def __init__(self, geometry: Geometry):
        g = geometry
        self.base, self.platform = g.base_anchor_m, g.platform_anchor_m
        self.limits = np.array([g.leg_min_m, g.leg_max_m, np.cos(g.universal_cone_rad), np.cos(g.spherical_cone_rad),
                                g.cylinder_length_m, g.rod_length_m, g.cylinder_radius_m, g.rod_radius_m,
                                g.characteristic_length_m])
        n = len(g.base_anchor_m)
        self.rot, self.platform_world = np.empty((3, 3)), np.empty((n, 3))
        self.lengths, self.units = np.empty(n), np.empty((n, 3))
        self.ends, self.jac = np.empty((4, n, 3)), np.empty((n, 6))
        self.out = np.empty(4)

    def check(self, position_m, quat) -> np.ndarray:
        """out[OUT_*] of the pose; `lengths` holds its leg lengths."""
        pose_check_into(self.base, self.platform, self.limits, position_m, quat, self.rot, self.platform_world,
                        self.lengths, self.units, self.ends, self.jac, self.out)
        return self.out
