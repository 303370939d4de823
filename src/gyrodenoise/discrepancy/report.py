"""Write the discrepancy report: report.json, report.md and the plots, each atomically."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gyrodenoise.discrepancy.workflow import NO_EFFECT  # noqa: E402

AXES = "xyz"


def _atomic_write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _save_fig(fig, path: Path) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.png")
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=90, format="png")
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.remove(tmp)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.floating | float):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    return x


def write_json(path: Path, data: dict) -> None:
    _atomic_write(path, json.dumps(_jsonable(data), indent=2) + "\n")


def _fmt(v) -> str:
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        return f"{float(a):.4g}"
    return "[" + ", ".join(_fmt(x) for x in a) + "]"


def markdown(report: dict) -> str:
    lines = ["# Discrepancy report: simulation vs measurement", ""]
    lines += [
        f"Fit sequences: {', '.join(report['fit_sequences'])}  ",
        f"Held-out sequences: {', '.join(report['holdout_sequences'])}  ",
        f"Base model: {', '.join(report['base_model'])}",
        "",
        f"**Verdict: {report['verdict']}.**",
        "",
    ]
    if report["named_effects"]:
        lines += ["## Named effects (datasheet units, +- one standard error)", ""]
        lines += ["| effect | parameter | value | unit | delta BIC | explained |", "|---|---|---|---|---|---|"]
        for e in report["named_effects"]:
            first = True
            for k, d in e["datasheet"].items():
                if k.endswith("per_sequence"):
                    continue
                val = _fmt(d["value"])
                if "standard_error" in d:
                    val += " +- " + _fmt(d["standard_error"])
                dbic = f"{e['delta_bic']:.1f}" if first and e.get("delta_bic") is not None else ""
                gain = f"{100 * e['explained_fraction']:.2f}%" if first and e.get("explained_fraction") else ""
                lines.append(f"| {e['name'] if first else ''} | {k} | {val} | {d['unit']} | {dbic} | {gain} |")
                first = False
        lines.append("")
    else:
        lines += [f"{NO_EFFECT[0].upper() + NO_EFFECT[1:]}: no candidate clears the threshold.", ""]
    if report["not_identifiable"]:
        lines += [
            f"Not identifiable from this motion: {', '.join(report['not_identifiable'])} "
            "(the data cannot separate these effects from the others; they were not tested).",
            "",
        ]
    gb, ga = report["gap_before"], report["gap_after"]
    lines += [
        "## Gap on held-out sequences",
        "",
        "| | base model | with named effects |",
        "|---|---|---|",
        f"| residual RMS (rad/s) | {gb['residual_rms_rad_s']:.5g} | {ga['residual_rms_rad_s']:.5g} |",
        f"| median 10-s drift, measured vs model gyro (deg) | {gb['drift_10s_median_deg']:.4g} | "
        f"{ga['drift_10s_median_deg']:.4g} |",
        f"| Allan-deviation gap, mean abs log10 ratio | {gb['allan_gap_log10']:.3f} | {ga['allan_gap_log10']:.3f} |",
        "",
        "Sensor constants come from the fit sequences; per-sequence nuisances (bias, random-walk knots, "
        "vibration phase) are refitted on each held-out sequence.",
        "",
        "## Selection steps (greedy forward selection, BIC)",
        "",
    ]
    for s in report["selection_steps"]:
        top = ", ".join(f"{c['effect']} {c['delta_bic']:+.0f}" for c in s["candidates"][:5])
        lines.append(f"- model [{', '.join(s['model'])}] -> {s.get('added', 'stop')}; best delta BIC: {top}")
    lines += [
        "",
        "## Plots",
        "",
        "![Allan deviation](allan.png) ![spectrum](spectrum.png)",
        "![residual](residual.png) ![drift](drift.png) ![gap](gap.png)",
        "",
    ]
    return "\n".join(lines)


def plots(out: Path, arrays: dict, report: dict) -> list[str]:
    files = []
    al = arrays["allan"]
    fig, axs = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for i, ax in enumerate(axs):
        ax.loglog(al["tau_s"], al["measured"][:, i], "k-", label="measured")
        ax.loglog(al["tau_s"], al["sim_before"][:, i], "C0--", label="simulated, base model")
        ax.loglog(al["tau_s"], al["sim_after"][:, i], "C3:", label="simulated, with named effects")
        ax.set_title(f"gyro {AXES[i]}: Allan deviation of (gyro - true rate)")
        ax.set_xlabel("tau (s)")
        ax.grid(True, which="both", alpha=0.3)
    axs[0].set_ylabel("rad/s")
    axs[0].legend(fontsize=8)
    _save_fig(fig, out / "allan.png")
    files.append("allan.png")

    sp = arrays["spectrum"]
    fig, axs = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for i, ax in enumerate(axs):
        ax.semilogy(sp["f_hz"], sp["measured"][:, i], "k-", lw=0.8, label="measured - base prediction")
        ax.semilogy(sp["f_hz"], sp["sim_before"][:, i], "C0--", lw=0.8, label="simulated, base model")
        ax.semilogy(sp["f_hz"], sp["measured_after"][:, i], "C2-", lw=0.8, label="measured - final prediction")
        ax.semilogy(sp["f_hz"], sp["sim_after"][:, i], "C3:", lw=0.8, label="simulated, final model")
        ax.set_title(f"gyro {AXES[i]}: residual PSD")
        ax.set_xlabel("Hz")
    axs[0].set_ylabel("(rad/s)^2/Hz")
    axs[0].legend(fontsize=7)
    _save_fig(fig, out / "spectrum.png")
    files.append("spectrum.png")

    rs = arrays["residual_series"]
    fig, axs = plt.subplots(3, 1, figsize=(12, 6), sharex=True)
    step = max(len(rs["t"]) // 4000, 1)
    for i, ax in enumerate(axs):
        ax.plot(rs["t"][::step], rs["before"][::step, i], "C0", lw=0.5, label="base model")
        ax.plot(rs["t"][::step], rs["after"][::step, i], "C3", lw=0.5, label="with named effects")
        ax.set_ylabel(f"{AXES[i]} (rad/s)")
    axs[0].set_title(f"{rs['name']}: measured - model gyro")
    axs[0].legend(fontsize=8)
    axs[-1].set_xlabel("t (s)")
    _save_fig(fig, out / "residual.png")
    files.append("residual.png")

    dr = arrays["drift"]
    if dr:
        fig, axs = plt.subplots(1, len(dr), figsize=(4.3 * len(dr), 3.6))
        axs = np.atleast_1d(axs)
        for ax, (w, d) in zip(axs, dr.items(), strict=True):
            ax.boxplot(
                [d["measured"], d["sim_before"], d["sim_after"]],
                tick_labels=["measured", "sim base", "sim final"],
            )
            ax.set_title(f"attitude drift vs truth over {w} s")
            ax.set_ylabel("deg")
        _save_fig(fig, out / "drift.png")
        files.append("drift.png")

    gb, ga = report["gap_before"], report["gap_after"]
    fig, axs = plt.subplots(1, 3, figsize=(11, 3.2))
    for ax, (k, lab) in zip(
        axs,
        [
            ("residual_rms_rad_s", "residual RMS (rad/s)"),
            ("drift_10s_median_deg", "median 10-s drift (deg)"),
            ("allan_gap_log10", "Allan gap (log10)"),
        ],
        strict=True,
    ):
        ax.bar(["base", "final"], [gb[k], ga[k]], color=["C0", "C3"])
        ax.set_title(lab, fontsize=9)
    fig.suptitle("held-out gap before / after adding the named effects", fontsize=10)
    fig.tight_layout()
    _save_fig(fig, out / "gap.png")
    files.append("gap.png")
    return files


def write_report(out_dir: str | Path, report: dict, arrays: dict, make_plots: bool = True) -> Path:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if make_plots:
        report["plots"] = plots(out, arrays, report)
    write_json(out / "report.json", report)
    _atomic_write(out / "report.md", markdown(report))
    return out
