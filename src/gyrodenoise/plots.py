"""Figures shared by TensorBoard logging and the evaluation report (matplotlib).

Figures are built as `matplotlib.figure.Figure` objects, outside pyplot: importing the package chooses no backend
(a notebook or an `MPLBACKEND` keeps its own) and no figure is left open in pyplot's registry."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure

from gyrodenoise.atomic import atomic_path
from gyrodenoise.so3 import rpy_of
from gyrodenoise.uncertainty import CalibrationResult

AXES = ("roll", "pitch", "yaw")
# one colour per method in every figure (matplotlib's cycle by position gave calibrated orange in one, green in another)
METHOD_COLORS = {"raw IMU": "C0", "calibrated IMU": "C1", "proposed": "C2", "zero motion": "C7"}


def method_colors(names: list[str]) -> dict[str, str]:
    """The colour of each method: fixed for the built-in ones, the rest of matplotlib's cycle for others."""
    spare = iter(("C3", "C4", "C5", "C6", "C8", "C9"))  # the cycle without the built-in methods' colours
    return {n: METHOD_COLORS.get(n) or next(spare, "0.3") for n in names}


def broken_at_wraps(y_deg: np.ndarray) -> np.ndarray:
    """An angle curve (deg, one per sample) to draw: a copy with NaN at each sample that steps by more than 180 deg
    from the one before (the angle wrapped to the other side of its 360-degree window), so that the line has a gap
    there instead of a vertical line across the panel. The other samples, and NaN already there, are kept."""
    y = np.array(y_deg, dtype=float)
    with np.errstate(invalid="ignore"):
        y[1:][np.abs(np.diff(y_deg)) > 180.0] = np.nan
    return y


def subplots(nrows: int = 1, ncols: int = 1, figsize: tuple[float, float] = (6.4, 4.8), **kwargs) -> tuple[Figure, Any]:
    """`pyplot.subplots` without pyplot: a Figure and its axes (`Figure.subplots` keywords: sharex, squeeze, ...)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def _shade_gaps(axs, t: np.ndarray, gt_mask: np.ndarray | None) -> None:
    """Grey spans where the ground truth is missing (mocap occlusions): its curve there is interpolated."""
    if gt_mask is None or gt_mask.all():
        return
    edges = np.flatnonzero(np.diff(np.r_[0, (~gt_mask).astype(int), 0]))
    for k, (a, b) in enumerate(zip(edges[::2], edges[1::2], strict=True)):
        for ax in axs:
            ax.axvspan(t[a], t[min(b, len(t) - 1)], color="0.85", zorder=0, label="no ground truth" if k == 0 else None)


def orientation_figure(
    t: np.ndarray,
    R_gt: np.ndarray,
    estimates: dict[str, np.ndarray],
    title: str = "",
    gt_mask: np.ndarray | None = None,
) -> Figure:
    """Roll, pitch, yaw (deg) of ground truth and each estimate over time (Fig. 6); `gt_mask` False: no ground
    truth there (shaded).

    Every curve is broken where it wraps (`broken_at_wraps`). The ground truth is drawn in a 360-degree window per
    angle, centred on its circular mean (EuRoC's roll near +-180 deg sits mid-panel); each estimate on the ground
    truth's side of it, sample by sample, so that the distance between the curves is the angle's error (at most
    180 deg)."""
    fig, axs = subplots(3, 1, figsize=(9, 7), sharex=True)
    _shade_gaps(axs, t, gt_mask)
    rpy_gt = rpy_of(R_gt)
    # unwrapped instead (np.unwrap), the ground truth drifted by whole turns at each near-180 deg step of roll and
    # yaw near pitch +-90 deg (V1_03_difficult: yaw to 2170 deg), which squashed the curves
    centre = np.arctan2(np.sin(rpy_gt).mean(0), np.cos(rpy_gt).mean(0))
    gt = centre + _wrap(rpy_gt - centre)
    # estimates unwrapped on their own can end up whole turns away from the ground truth, which hides the error
    on_branch = {name: gt + _wrap(rpy_of(R) - rpy_gt) for name, R in estimates.items()}
    colors = method_colors(list(on_branch))
    for k, ax in enumerate(axs):
        ax.plot(t, broken_at_wraps(np.degrees(gt[:, k])), "k", lw=1.5, label="ground truth")
        for name, rpy in on_branch.items():
            ax.plot(t, broken_at_wraps(np.degrees(rpy[:, k])), lw=1, label=name, color=colors[name])
        ax.set_ylabel(f"{AXES[k]} (deg)")
        ax.grid(alpha=0.3)
    axs[0].legend(loc="best", fontsize=8)
    axs[-1].set_xlabel("t (s)")
    axs[0].set_title(title)
    fig.tight_layout()
    return fig


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles (rad) wrapped to [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def error_figure(
    t: np.ndarray, errors: dict[str, tuple[np.ndarray, np.ndarray]], title: str = "", gt_mask: np.ndarray | None = None
) -> Figure:
    """3D and yaw orientation error (deg) over time for each method (Fig. 7); `gt_mask` as orientation_figure:
    no error is drawn where it is False (against interpolated ground truth it would not be an error)."""
    fig, axs = subplots(2, 1, figsize=(9, 5.5), sharex=True)
    _shade_gaps(axs, t, gt_mask)
    colors = method_colors(list(errors))
    for name, (e3d, eyaw) in errors.items():
        if gt_mask is not None:
            e3d, eyaw = np.where(gt_mask, e3d, np.nan), np.where(gt_mask, eyaw, np.nan)
        axs[0].plot(t, np.degrees(e3d), lw=1, label=name, color=colors[name])
        axs[1].plot(t, np.degrees(np.abs(eyaw)), lw=1, label=name, color=colors[name])
    axs[0].set_ylabel("3D error (deg)")
    axs[1].set_ylabel("|yaw error| (deg)")
    axs[1].set_xlabel("t (s)")
    for ax in axs:
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
    axs[0].legend(loc="best", fontsize=8)
    axs[0].set_title(title)
    fig.tight_layout()
    return fig


def correction_figure(t: np.ndarray, w_tilde: np.ndarray, title: str = "", spread: np.ndarray | None = None) -> Figure:
    """Gyro correction w_hat - w_imu per axis (deg/s) over time (Fig. 8); with `spread` (N, 3) rad/s,
    an ensemble's per-sample std, a +-2 sigma band around each axis."""
    fig, ax = subplots(figsize=(9, 3.5))
    for k, lab in enumerate("xyz"):
        (line,) = ax.plot(t, np.degrees(w_tilde[:, k]), lw=0.8, label=f"$\\tilde\\omega_{lab}$")
        if spread is not None:
            c, s2 = np.degrees(w_tilde[:, k]), 2 * np.degrees(spread[:, k])
            ax.fill_between(t, c - s2, c + s2, color=line.get_color(), alpha=0.25, lw=0)
    if spread is not None:
        ax.fill_between([], [], [], color="0.5", alpha=0.25, label="$\\pm 2\\sigma$ (ensemble)")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("correction (deg/s)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    return fig


def calibration_figure(result: CalibrationResult, title: str = "") -> Figure:
    """Predicted vs actual increment error per window (log-log scatter) with the reliability bins
    (RMS actual vs RMS predicted) and the line of a calibrated spread."""
    fig, ax = subplots(figsize=(5.5, 5))
    pred, act = np.degrees(result.predicted), np.degrees(result.actual)
    if not len(pred):  # no window with ground truth throughout: nothing to draw on log axes (matplotlib refuses)
        ax.text(0.5, 0.5, f"no {result.window_s:g}-s window with ground truth throughout", ha="center", va="center")
        ax.set_axis_off()
        ax.set_title(title)
        return fig
    ax.scatter(pred, act, s=4, alpha=0.3, color="0.4", label=f"{len(pred)} windows of {result.window_s:g} s")
    rows = result.table
    ax.plot(
        [r["rms_predicted_deg"] for r in rows],
        [r["rms_actual_deg"] for r in rows],
        "o-",
        color="C3",
        label="bins (RMS)",
    )
    pos = np.concatenate([pred[pred > 0], act[act > 0]])
    if len(pos):
        lim = [pos.min() * 0.8, pos.max() * 1.25]
        ax.plot(lim, lim, "k--", lw=1, label="spread = error (a calibrated uncertainty)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    for axis in (ax.xaxis, ax.yaxis):  # 1-2-5 labels: default minor labels overlap on narrow log ranges
        axis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("predicted increment error (deg)")
    ax.set_ylabel("actual increment error (deg)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"{title}\nSpearman {result.spearman:.2f} ({result.mode})".strip())
    fig.tight_layout()
    return fig


def roe_boxplot(roe: dict[float, dict[str, tuple[np.ndarray, np.ndarray]]], title: str = "") -> Figure:
    """Box plots of ROE (3D and yaw) per travelled distance and method (Fig. 5); boxes: quartiles, whiskers:
    1.5 x the interquartile range, outliers not drawn (the figure says so)."""
    dists = sorted(roe)
    methods = list(next(iter(roe.values())).keys()) if roe else []
    fig, axs = subplots(1, 2, figsize=(11, 4))
    width = 0.8 / max(len(methods), 1)
    colors = method_colors(methods)
    for a, ax in enumerate(axs):
        for m, name in enumerate(methods):
            data = [np.degrees(roe[d][name][a]) for d in dists]
            pos = np.arange(len(dists)) + (m - (len(methods) - 1) / 2) * width
            # black medians: matplotlib's default (orange) vanishes inside an orange box
            bp = ax.boxplot(
                data,
                positions=pos,
                widths=width * 0.9,
                patch_artist=True,
                showfliers=False,
                medianprops={"color": "black", "lw": 1.5},
            )
            for box in bp["boxes"]:
                box.set_facecolor(colors[name])
            ax.plot([], [], color=colors[name], lw=6, label=name)
        ax.set_xticks(np.arange(len(dists)), [f"{d:g} m" for d in dists])
        ax.set_xlabel("travelled distance")
        ax.set_yscale("log")
        ax.set_ylabel(("3D" if a == 0 else "yaw") + " ROE (deg)")
        ax.grid(alpha=0.3, which="both")
    axs[0].legend(fontsize=8)
    # the box legend once, under the title: as each panel's x label it was wider than the panel and clipped
    fig.suptitle(f"{title}\nboxes: quartiles; whiskers: 1.5 x interquartile range; outliers not drawn".strip())
    fig.tight_layout()
    return fig


def save(fig: Figure, path: str | Path, dpi: int = 110) -> None:
    """Write the figure atomically (format from the file suffix)."""
    with atomic_path(path, Path(path).suffix) as tmp:
        fig.savefig(tmp, dpi=dpi)
