"""Workspace slices like thesis Figs. 9.3, 9.5, 9.7 and 9.11-9.12, as PNG files."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_py.mechanics.geometry import Geometry
from firmware_py.mechanics.rotation import rpy_to_quat
from firmware_py.mechanics.workspace import check_poses
from hil.plotting import plt, save
from hil.tools.workspace_figures import dexterous_mask


def _grid(a_range, b_range, n):
    a = np.linspace(*a_range, n)
    b = np.linspace(*b_range, n)
    aa, bb = np.meshgrid(a, b)
    return a, b, aa.ravel(), bb.ravel()


def _mask_plot(ax, a, b, mask, xlabel, ylabel, title):
    ax.imshow(mask.reshape(len(b), len(a)), origin="lower", extent=(a[0], a[-1], b[0], b[-1]),
              cmap="Blues", vmin=0, vmax=1.4, aspect="auto")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)


def plot_workspace(geometry: Geometry, out_dir: Path, resolution: int = 81) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    n = resolution
    written = []
    # Fig. 9.3: dexterous (+/-25 deg) workspace, slices z = 675 mm and y = 0
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.5))
    a, b, xx, yy = _grid((-0.6, 0.6), (-0.6, 0.6), n)
    mask = dexterous_mask(geometry, np.column_stack([xx, yy, np.full_like(xx, 0.675)]))
    _mask_plot(axes[0], a * 1e3, b * 1e3, mask, "x [mm]", "y [mm]", "dexterous (+/-25 deg), z = 675 mm (Fig. 9.3a)")
    a, b, xx, zz = _grid((-0.6, 0.6), (0.45, 0.9), n)
    mask = dexterous_mask(geometry, np.column_stack([xx, np.zeros_like(xx), zz]))
    _mask_plot(axes[1], a * 1e3, b * 1e3, mask, "x [mm]", "z [mm]", "dexterous (+/-25 deg), y = 0 (Fig. 9.3b)")
    written.append(_saved(fig, out_dir / "fig9_3_dexterous.png"))
    # Fig. 9.5: parallel platforms, slices z = 600 mm and y = 0
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.5))
    a, b, xx, yy = _grid((-0.7, 0.7), (-0.7, 0.7), n)
    mask = check_poses(geometry, np.column_stack([xx, yy, np.full_like(xx, 0.6)]), [1, 0, 0, 0]).reachable
    _mask_plot(axes[0], a * 1e3, b * 1e3, mask, "x [mm]", "y [mm]", "parallel platforms, z = 600 mm (Fig. 9.5a)")
    a, b, xx, zz = _grid((-0.7, 0.7), (0.45, 0.9), n)
    mask = check_poses(geometry, np.column_stack([xx, np.zeros_like(xx), zz]), [1, 0, 0, 0]).reachable
    _mask_plot(axes[1], a * 1e3, b * 1e3, mask, "x [mm]", "z [mm]", "parallel platforms, y = 0 (Fig. 9.5b)")
    written.append(_saved(fig, out_dir / "fig9_5_translation.png"))
    # Fig. 9.7 and 9.11-9.12: orientation workspace at r = [0, 0, 700] mm, singular surface
    centre = np.array([0.0, 0.0, 0.7])
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    a, b, rr, pp = _grid((-80, 80), (-80, 80), n)
    report = check_poses(geometry, np.tile(centre, (len(rr), 1)), rpy_to_quat(np.radians(rr), np.radians(pp), 0.0))
    _mask_plot(axes[0], a, b, report.reachable, "roll [deg]", "pitch [deg]", "yaw = 0, r = [0, 0, 700] (Fig. 9.7a)")
    for ax, roll, fig_no in ((axes[1], 0.0, "9.7b / 9.12b"), (axes[2], 30.0, "9.12c")):
        a, b, pp, yy = _grid((-80, 80), (-150, 150), n)
        report = check_poses(geometry, np.tile(centre, (len(pp), 1)),
                             rpy_to_quat(np.radians(roll), np.radians(pp), np.radians(yy)))
        _mask_plot(ax, a, b, report.reachable, "pitch [deg]", "yaw [deg]",
                   f"roll = {roll:g} deg, det Jx = 0 in red (Fig. {fig_no})")
        ax.contour(a, b, np.sign(report.det_jx).reshape(len(b), len(a)), levels=[0.0], colors="red")
    written.append(_saved(fig, out_dir / "fig9_7_fig9_12_orientation.png"))
    return written


def _saved(fig, path: Path) -> Path:
    save(fig, path)
    return path
