"""The discrepancy report's figures: Allan deviation, residual spectrum and series, held-out drift and gaps, and
what the named effects leave unexplained (`lack_of_fit`), each saved atomically beside report.md."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gyrodenoise.plots import save as save_figure
from gyrodenoise.plots import subplots

AXES = "xyz"
PLOT_NAMES = ("allan", "spectrum", "residual", "drift", "gap", "unexplained")  # <name>.png beside report.md


def gap_band_hz(report: dict, rate_hz: float) -> float | None:
    """The band the held-out Allan and spectral gaps compare (`workflow.gap`'s `band_hz`: the narrowest held-out
    sequence's; None: the whole spectrum). Above it the true rate is not trusted (section "Where the reconstructed
    true rate is trusted"): the residual there is the reconstruction's error, not the sensor's."""
    band = (report.get("gap_before") or {}).get("band_hz")
    if band is None:  # a report without it: the held-out sequences' narrowest compared band
        rows = (report.get("reconstruction") or {}).get("holdout", [])
        band = min((b["f_max_hz"] for b in rows if not b.get("whole_spectrum")), default=None)
    return None if band is None or band >= rate_hz / 2 else float(band)


def plots(out: Path, arrays: dict, report: dict) -> list[str]:
    """Draw every figure of the report into `out`; returns their file names (for report.md)."""
    files = []
    f_max = gap_band_hz(report, arrays["rate_hz"])
    al = arrays["allan"]
    held_out = ", ".join(report.get("holdout_sequences", []))
    fig, axs = subplots(1, 3, figsize=(13, 4.2), sharey=True)
    for i, ax in enumerate(axs):
        ax.loglog(al["tau_s"], al["measured"][:, i], "k-", label="measured")
        ax.loglog(al["tau_s"], al["sim_before"][:, i], "C0--", label="simulated, base model")
        ax.loglog(al["tau_s"], al["sim_after"][:, i], "C3:", label="simulated, with named effects")
        if f_max is not None and 1.0 / f_max > al["tau_s"][0]:
            # the Allan gap is computed band-limited, at tau >= 1 / f_max; the curves drawn are full band
            ax.axvspan(al["tau_s"][0], 1.0 / f_max, color="0.85", zorder=0, label="not compared (tau < 1/f_max)")
        ax.set_title(f"gyro {AXES[i]}: Allan deviation of (gyro - true rate)", fontsize=9)
        ax.set_xlabel("tau (s)")
        ax.grid(True, which="both", alpha=0.3)
    axs[0].set_ylabel("rad/s")
    axs[0].legend(fontsize=8)
    fig.suptitle(f"held out: {held_out}", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "allan.png", dpi=90)
    files.append("allan.png")

    sp = arrays["spectrum"]
    fig, axs = subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for i, ax in enumerate(axs):
        ax.semilogy(sp["f_hz"], sp["measured"][:, i], "k-", lw=0.8, label="measured - base prediction")
        ax.semilogy(sp["f_hz"], sp["sim_before"][:, i], "C0--", lw=0.8, label="simulated, base model")
        ax.semilogy(sp["f_hz"], sp["measured_after"][:, i], "C2-", lw=0.8, label="measured - final prediction")
        ax.semilogy(sp["f_hz"], sp["sim_after"][:, i], "C3:", lw=0.8, label="simulated, final model")
        ax.set_title(f"gyro {AXES[i]}: residual PSD")
        ax.set_xlabel("Hz")
        if f_max is not None and f_max < sp["f_hz"][-1]:
            ax.axvspan(f_max, sp["f_hz"][-1], color="0.85", zorder=0, label="not compared (reconstruction error)")
    axs[0].set_ylabel("(rad/s)^2/Hz")
    axs[0].legend(fontsize=7)
    save_figure(fig, out / "spectrum.png", dpi=90)
    files.append("spectrum.png")

    rs = arrays["residual_series"]
    fig, axs = subplots(3, 1, figsize=(12, 6), sharex=True)
    step = max(len(rs["t"]) // 4000, 1)
    for i, ax in enumerate(axs):
        ax.plot(rs["t"][::step], rs["before"][::step, i], "C0", lw=0.5, label="base model")
        ax.plot(rs["t"][::step], rs["after"][::step, i], "C3", lw=0.5, label="with named effects")
        ax.set_ylabel(f"{AXES[i]} (rad/s)")
    axs[0].set_title(f"{rs['name']}: measured - model gyro")
    axs[0].legend(fontsize=8)
    axs[-1].set_xlabel("t (s)")
    save_figure(fig, out / "residual.png", dpi=90)
    files.append("residual.png")

    dr = arrays["drift"]
    if dr:
        fig, axs = subplots(1, len(dr), figsize=(4.3 * len(dr), 3.6))
        axs = np.atleast_1d(axs)
        for ax, (w, d) in zip(axs, dr.items(), strict=True):
            ax.boxplot(
                [d["measured"], d["sim_before"], d["sim_after"]],
                tick_labels=["measured", "sim base", "sim final"],
            )
            ax.set_title(f"attitude drift vs truth over {w} s")
            ax.set_ylabel("deg")
        fig.suptitle(f"held out: {held_out}", fontsize=9)
        fig.tight_layout()
        save_figure(fig, out / "drift.png", dpi=90)
        files.append("drift.png")

    gb, ga = report["gap_before"], report["gap_after"]
    metrics = [
        ("residual_rms_rad_s", "residual RMS (rad/s)"),
        ("drift_10s_median_deg", "median 10-s drift (deg)"),
        ("allan_gap_log10", "Allan gap (log10)"),
        ("psd_gap_log10", "spectral gap (log10)"),
    ]
    metrics = [(k, lab) for k, lab in metrics if k in gb and k in ga]
    if metrics:  # squeeze=False: one metric's one axis in an array too; at least the title's width
        fig, axs = subplots(1, len(metrics), figsize=(max(3.7 * len(metrics), 5.0), 3.2), squeeze=False)
        for ax, (k, lab) in zip(axs[0], metrics, strict=True):
            values = [np.nan if v is None else float(v) for v in (gb[k], ga[k])]
            ax.bar(["base", "final"], values, color=["C0", "C3"])  # a NaN bar is not drawn: said in words below
            ax.set_xlim(-0.5, 1.5)  # both places, also where a NaN bar set none
            at_foot = ax.get_xaxis_transform()  # x: the bar's place; y: a share of the axis' height
            for x, v in enumerate(values):
                if not np.isfinite(v):  # e.g. no 10-s window to take a drift over: an empty place reads as 0
                    ax.text(x, 0.02, "not measured", ha="center", va="bottom", fontsize=8, transform=at_foot)
            if not np.isfinite(values).any():
                ax.set_yticks([])  # no value: the scale would be matplotlib's default around 0
            ax.set_title(lab, fontsize=9)
        fig.suptitle("held-out gap before / after adding the named effects", fontsize=10)
        fig.tight_layout()
        save_figure(fig, out / "gap.png", dpi=90)
        files.append("gap.png")
    if report.get("lack_of_fit"):
        files.append(_lack_of_fit_plot(out, report["lack_of_fit"], held_out))
    return files


def _lack_of_fit_plot(out: Path, lof: dict, held_out: str) -> str:
    """Bin means of the held-out residual against each reading, with the re-simulations' 95% band."""
    signals = list(dict.fromkeys(row["signal"] for row in lof["rows"]))
    fig, axs = subplots(len(signals), 3, figsize=(12, 3.0 * len(signals)), squeeze=False)
    for row in lof["rows"]:
        ax = axs[signals.index(row["signal"]), AXES.index(row["axis"])]
        x = np.asarray(row["bin_centres"])
        lo, hi = (1e3 * np.asarray(b) for b in row["null_band_rad_s"])
        ax.fill_between(x, lo, hi, color="0.8", label="re-simulated final model, 95%")
        ax.plot(
            x, 1e3 * np.asarray(row["bin_means_rad_s"]), "C3o-" if row["flagged"] else "ko-", ms=3, label="measured"
        )
        ax.axhline(0.0, color="0.5", lw=0.5)
        ax.set_title(
            f"{row['signal']} {row['axis']}: p {row['p_corrected']:.2g}" + (" (flagged)" if row["flagged"] else ""),
            fontsize=9,
        )
        ax.set_xlabel(row["unit"])
    for ax in axs[:, 0]:
        ax.set_ylabel("mean residual (mrad/s)")
    axs[0, 0].legend(fontsize=7)
    fig.suptitle(f"held-out residual after the final model, by sensor reading ({held_out})", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "unexplained.png", dpi=90)
    return "unexplained.png"
