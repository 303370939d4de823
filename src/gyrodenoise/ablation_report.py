"""Paired ablation tables, plots and the whole of reports/ablation_euroc.md from collected runs.

The runs (gyrodenoise.ablation: Hydra run folders or committed summary JSON files) are grouped into arms
by their values of the ablated keys; one arm is the reference (the paper's setting). Every other arm is
paired with it seed by seed (gyrodenoise.ablation_stats) on the test AOE, the validation AOE (`val`)
and, when the runs have it, the end-of-flight validation AOE (`val_tail`).

Repeated runs of one arm and seed are all kept and listed, with a warning; their *mean* is the seed's
value in the pairs, because the seed (and with it the validation fold) is the unit of pairing and a
repeat is not an independent sample. Seeds that have no partner are listed, never silently dropped.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import os
import shlex
import statistics
import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from gyrodenoise.ablation_runs import (
    IGNORED_KEYS,
    MISSING,
    SEED_KEY,
    Run,
    ablated_keys,
    find_runs,
    group,
    matching,
    mean_sd_n,
    mean_wall_s,
    parse_where,
    plus_minus,
    same_value,
    with_ext,
)
from gyrodenoise.ablation_stats import CLAIMS, Claim, PairedDiff, check, claim_verdict, holm, paired_diff
from gyrodenoise.atomic import write_bytes, write_text
from gyrodenoise.tables import markdown_table

SPLITS = ("test", "val", "val_tail")
REFERENCE_DIR = "reference"  # reports/ablation_runs/reference: the paper's setting, shared by every claim
APPENDIX_HEADING = "# Appendix: earlier verdicts and runs"


@dataclass
class Arm:
    values: tuple[str, ...]
    label: str
    runs: list[Run]
    is_reference: bool = False
    per_seed: dict[str, dict[str, float]] = field(default_factory=dict)  # split -> seed -> mean of its runs
    duplicates: dict[str, int] = field(default_factory=dict)  # seed -> runs (> 1)
    diffs: dict[str, PairedDiff] = field(default_factory=dict)  # split -> paired difference vs reference
    no_reference: list[str] = field(default_factory=list)  # test seeds of this arm without a reference run
    missing: list[str] = field(default_factory=list)  # reference test seeds this arm lacks
    expected: str | None = None

    def stats(self, split: str) -> tuple[float, float, int]:
        return mean_sd_n(self.per_seed.get(split, {}).values())  # over seeds (a seed's runs are averaged first)

    def wall_s(self) -> float:
        return mean_wall_s(self.runs)

    def check(self, split: str) -> str:
        return check(self.expected, self.diffs.get(split)) if self.expected else ""


@dataclass
class Analysis:
    title: str
    keys: list[str]
    reference_spec: dict[str, str]
    arms: list[Arm]  # the reference first
    splits: list[str]  # the splits the runs have
    runs: list[Run]
    claim_name: str | None = None
    warnings: list[str] = field(default_factory=list)
    verdicts: dict[str, tuple[str, list[str]]] = field(default_factory=dict)  # split -> claim verdict

    @property
    def reference(self) -> Arm:
        return self.arms[0]

    @property
    def claim(self) -> Claim | None:
        return CLAIMS.get(self.claim_name) if self.claim_name else None


def parse_assignments(items: Sequence[str], what: str = "--reference") -> dict[str, str]:
    """["a=1", "b=2 c=3"] -> {a: 1, b: 2, c: 3} (config-group keys without their +)."""
    out = {}
    for item in items:
        for part in item.split():
            if "=" not in part:
                raise ValueError(f"{what} {part!r}: expected KEY=VALUE")
            k, v = part.split("=", 1)
            out[k.lstrip("+")] = v
    return out


def _seed(run: Run) -> str:
    return str(run.seed)


def _label(keys: Sequence[str], values: Sequence[str]) -> str:
    return " ".join(f"{k}={v}" for k, v in zip(keys, values, strict=True))


def _matches(arm: Arm, keys: Sequence[str], spec: dict[str, str]) -> bool:
    return all(k in keys and same_value(arm.values[keys.index(k)], v) for k, v in spec.items())


def analyse(
    runs: Sequence[Run],
    reference: dict[str, str],
    keys: Sequence[str] | None = None,
    claim_name: str | None = None,
    title: str | None = None,
) -> Analysis:
    """Arms of `runs`, the reference arm picked by `reference` (key -> value), and every arm's paired
    differences against it; with a claim, its expected outcomes and verdicts."""
    claim = CLAIMS.get(claim_name) if claim_name else None
    if claim_name and claim is None:
        raise ValueError(f"unknown claim {claim_name!r}: choose one of {', '.join(CLAIMS)}")
    if not runs:
        raise ValueError("no runs to analyse")
    keys = list(keys or (claim.keys if claim else ablated_keys(runs)))
    keys += [k for k in reference if k not in keys]  # the reference's keys are part of an arm's identity
    if not keys:
        raise ValueError("the runs do not differ in any overridden key: name the ablated keys with --keys")
    settings = group(runs, keys, defaults=reference)
    arms = [Arm(s.values, _label(keys, s.values), s.runs) for s in settings]
    refs = [a for a in arms if _matches(a, keys, reference)]
    found = "; ".join(a.label for a in arms)
    if not refs:
        raise ValueError(
            f"no run matches the reference {_label(list(reference), list(reference.values()))} (arms found: {found})"
        )
    if len(refs) > 1:
        raise ValueError(f"the reference {reference} matches {len(refs)} arms ({found}): give every key")
    ref = refs[0]
    ref.is_reference = True
    arms = [ref, *(a for a in arms if a is not ref)]
    splits = [s for s in SPLITS if any(math.isfinite(r.metric(s)) for r in runs)]
    out = Analysis(title or "", keys, dict(reference), arms, splits, list(runs), claim_name)
    out.title = title or (f"{claim.title} (paper, Section {claim.section})" if claim else f"Paired ablation: {found}")

    for arm in arms:
        by_seed: dict[str, list[Run]] = {}
        for r in arm.runs:
            by_seed.setdefault(_seed(r), []).append(r)
        arm.duplicates = {s: len(rs) for s, rs in by_seed.items() if len(rs) > 1}
        for split in splits:
            arm.per_seed[split] = {}
            for s, rs in by_seed.items():
                xs = [r.metric(split) for r in rs if math.isfinite(r.metric(split))]
                arm.per_seed[split][s] = statistics.fmean(xs) if xs else math.nan
        for s, n in arm.duplicates.items():
            paths = ", ".join(str(r.path) for r in by_seed[s])
            out.warnings.append(f"{arm.label}, seed {s}: {n} runs ({paths}); their mean is paired")
    for arm in arms[1:]:
        for split in splits:
            d, no_ref, missing = paired_diff(arm.per_seed[split], ref.per_seed[split])
            arm.diffs[split] = d
            if split == "test":
                arm.no_reference, arm.missing = no_ref, missing
        if arm.no_reference:
            out.warnings.append(f"{arm.label}: seeds {', '.join(arm.no_reference)} have no reference run (unpaired)")
        if arm.missing:
            out.warnings.append(f"{arm.label}: lacks the reference seeds {', '.join(arm.missing)} (unpaired)")
    _check_folds(arms, out.warnings)
    protocols = Counter(math.isfinite(r.metric("val_tail")) for r in runs)
    if len(protocols) > 1:
        out.warnings.append(
            f"{protocols[False]} of {len(runs)} runs have no val_tail/aoe_deg: their val/aoe_deg is the end of "
            "the training flights, not a held-out flight, and their val pairs mix two protocols"
        )

    if claim:
        checks: dict[str, list] = {s: [] for s in splits}
        named: list[Arm] = []
        for arm_spec, expected in claim.expect:
            hits = [a for a in arms[1:] if _matches(a, keys, parse_assignments([arm_spec], "claim arm"))]
            for a in hits:
                a.expected = expected
            named += hits
            for s in splits:
                checks[s].append((arm_spec, expected, hits[0].diffs.get(s) if hits else None))
        out.verdicts = {s: claim_verdict(checks[s]) for s in splits}
        out.arms = [ref, *named, *(a for a in arms[1:] if a not in named)]  # the claim's order first
    return out


def _check_folds(arms: Sequence[Arm], warnings: list[str]) -> None:
    """A pair is only a pair if both runs held out the same validation flight (dataset.cv_fold): warn
    about seeds whose runs differ there (e.g. a reference made before cv_fold existed)."""
    folds: dict[str, set[str]] = {}
    for arm in arms:
        for r in arm.runs:
            folds.setdefault(_seed(r), set()).add(r.value("dataset.cv_fold"))
    mixed = {s: sorted(f) for s, f in folds.items() if len(f) > 1}
    for s, f in sorted(mixed.items()):
        warnings.append(f"seed {s}: runs with different dataset.cv_fold ({', '.join(f)}): its val pairs compare folds")


# --- tables -------------------------------------------------------------------------------------------------


def _signed(x: float) -> str:
    return f"{x:+.2f}" if math.isfinite(x) else "-"


def diff_cell(d: PairedDiff | None) -> str:
    """'+0.50 [+0.41, +0.59] (boot. +0.45, +0.55)': mean difference, t-interval, bootstrap interval."""
    if d is None or d.n == 0:
        return "-"
    cell = _signed(d.mean)
    if math.isfinite(d.t_ci[0]):
        cell += f" [{_signed(d.t_ci[0])}, {_signed(d.t_ci[1])}]"
    if d.boot_ci is not None:
        cell += f" (boot. {_signed(d.boot_ci[0])}, {_signed(d.boot_ci[1])})"
    return cell


def _n_cell(arm: Arm, split: str = "test") -> str:
    if arm.is_reference:
        return f"{arm.stats(split)[2]} ({len(arm.runs)} runs)"
    d = arm.diffs.get(split)
    return f"{d.n if d else 0} paired ({len(arm.runs)} runs)"


def arm_table(a: Analysis) -> str:
    """Arm, seeds, mean +- sd of test and val AOE, paired differences with intervals and verdicts."""
    has_claim = a.claim is not None
    head = [
        "arm",
        "n",
        "test AOE (deg)",
        "val AOE (deg)",
        "Δ test vs reference [95% t-CI] (bootstrap)",
        "verdict (test)",
        "Δ val vs reference [95% t-CI] (bootstrap)",
        "verdict (val)",
    ]
    head += ["expected (paper) → test / val"] if has_claim else []
    head += ["train s/run"]
    rows = []
    for arm in a.arms:
        cells = [f"**{arm.label}** (reference)" if arm.is_reference else arm.label, _n_cell(arm)]
        cells += [plus_minus(*arm.stats(s)[:2]) for s in ("test", "val")]
        for s in ("test", "val"):
            d = arm.diffs.get(s)
            cells += ["reference", ""] if arm.is_reference else [diff_cell(d), d.describe() if d else "-"]
        if has_claim:
            cells.append(f"{arm.expected} → {arm.check('test')} / {arm.check('val')}" if arm.expected else "")
        cells.append(f"{arm.wall_s():.0f}" if math.isfinite(arm.wall_s()) else "-")
        rows.append(cells)
    return markdown_table(head, rows)


def tail_table(a: Analysis) -> str:
    head = ["arm", "n", "val_tail AOE (deg)", "Δ val_tail vs reference [95% t-CI] (bootstrap)", "verdict"]
    rows = []
    for arm in a.arms:
        d = arm.diffs.get("val_tail")
        tail = ["reference", ""] if arm.is_reference else [diff_cell(d), d.describe() if d else "-"]
        rows.append([arm.label, _n_cell(arm, "val_tail"), plus_minus(*arm.stats("val_tail")[:2]), *tail])
    return markdown_table(head, rows)


def seeds_of(a: Analysis) -> list[str]:
    return sorted({s for arm in a.arms for s in arm.per_seed.get("test", {})}, key=lambda s: (len(s), s))


def seed_table(a: Analysis) -> str:
    """Test / val AOE of every arm and seed (the numbers behind the pairs)."""
    seeds = seeds_of(a)
    head = ["arm", *(f"seed {s}" for s in seeds)]
    rows = []
    for arm in a.arms:
        cells = []
        for s in seeds:
            t, v = (arm.per_seed.get(x, {}).get(s, math.nan) for x in ("test", "val"))
            cells.append("-" if not math.isfinite(t) else f"{t:.2f} / {v:.2f}" + ("*" if s in arm.duplicates else ""))
        rows.append([arm.label, *cells])
    return markdown_table(head, rows)


def csv_text(a: Analysis) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    stat = [f"{s}_{x}" for s in a.splits for x in ("mean", "sd")]
    diff = [
        f"d_{s}_{x}"
        for s in a.splits
        for x in ("n", "mean", "sd", "t_lo", "t_hi", "boot_lo", "boot_hi", "verdict", "n_star")
    ]
    w.writerow(
        [
            "arm",
            *a.keys,
            "reference",
            "n_runs",
            "seeds",
            *stat,
            *[f"{s}_per_seed" for s in a.splits],
            *diff,
            "unpaired_no_reference",
            "unpaired_missing",
            "duplicate_seeds",
            "expected",
            "check_test",
            "check_val",
            "train_wall_time_s_mean",
        ]
    )
    seeds = seeds_of(a)
    for arm in a.arms:
        row = [
            arm.label,
            *arm.values,
            arm.is_reference,
            len(arm.runs),
            " ".join(s for s in seeds if s in arm.per_seed["test"]),
        ]
        row += [f"{v:.4f}" for s in a.splits for v in arm.stats(s)[:2]]
        row += [" ".join(f"{s}:{v:.4f}" for s, v in arm.per_seed[x].items()) for x in a.splits]
        for s in a.splits:
            d = arm.diffs.get(s)
            if d is None:
                row += [""] * 9
                continue
            boot = d.boot_ci or (math.nan, math.nan)
            row += [d.n, *(f"{v:.4f}" for v in (d.mean, d.sd, *d.t_ci, *boot)), d.verdict, f"{d.n_star:g}"]
        row += [
            " ".join(arm.no_reference),
            " ".join(arm.missing),
            " ".join(arm.duplicates),
            arm.expected or "",
            arm.check("test"),
            arm.check("val"),
            f"{arm.wall_s():.1f}",
        ]
        w.writerow(row)
    return buf.getvalue()


# --- the paired-difference plot ----------------------------------------------------------------------------


def plot_png(a: Analysis) -> bytes:
    """One panel per non-reference arm: each seed a line from the reference's AOE to the arm's, test on
    the left and validation on the right of the panel; the mean of the pairs in black."""
    from gyrodenoise.plots import subplots

    arms = a.arms[1:] or a.arms  # a reference alone still gets its points drawn
    ncol = min(4, len(arms))
    nrow = math.ceil(len(arms) / ncol)
    fig, axes = subplots(nrow, ncol, figsize=(3.4 * ncol, 3.3 * nrow + 0.6), sharey=True, squeeze=False)
    seeds = seeds_of(a)
    colors = {s: f"C{i % 10}" for i, s in enumerate(seeds)}
    ref = a.reference
    for ax, arm in zip(axes.flat, arms, strict=False):
        for x0, split in ((0.0, "test"), (2.2, "val")):
            pairs = [(ref.per_seed[split].get(s, math.nan), arm.per_seed[split].get(s, math.nan), s) for s in seeds]
            pairs = [(r, v, s) for r, v, s in pairs if math.isfinite(r) or math.isfinite(v)]
            for r, v, s in pairs:
                ax.plot(
                    [x0, x0 + 1],
                    [r, v],
                    "-o",
                    color=colors[s],
                    ms=4,
                    lw=1.2,
                    alpha=0.8,
                    label=f"seed {s}" if split == "test" else None,
                )
            both = [(r, v) for r, v, _ in pairs if math.isfinite(r) and math.isfinite(v)]
            if both:
                mr, mv = statistics.fmean(r for r, _ in both), statistics.fmean(v for _, v in both)
                ax.plot([x0, x0 + 1], [mr, mv], "-", color="k", lw=2.5, zorder=5)
        ax.set_xticks([0, 1, 2.2, 3.2])
        ax.set_xticklabels(["ref.", "arm", "ref.", "arm"], fontsize=8)
        ax.text(0.5, -0.16, "test", transform=ax.get_xaxis_transform(), ha="center", fontsize=8)
        ax.text(2.7, -0.16, "val", transform=ax.get_xaxis_transform(), ha="center", fontsize=8)
        d_t, d_v = arm.diffs.get("test"), arm.diffs.get("val")
        sub = f"Δtest {diff_cell(d_t).split(' (')[0]}\nΔval {diff_cell(d_v).split(' (')[0]}" if d_t else "reference"
        ax.set_title(f"{arm.label}\n{sub}", fontsize=7.5)
        ax.set_xlim(-0.4, 3.6)
        ax.grid(axis="y", alpha=0.3)
    for ax in axes.flat[len(arms) :]:
        ax.axis("off")
    axes[0, 0].set_ylabel("AOE (deg)")
    if seeds:
        axes[0, 0].legend(fontsize=6, loc="best")
    fig.suptitle(f"{a.title}: per-seed pairs vs {ref.label} (black: mean)", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return buf.getvalue()


# --- text ---------------------------------------------------------------------------------------------------


def reproduce_command(a: Analysis) -> str:
    """One multirun command for all arms and seeds, generalised from the runs' overrides: the ablated
    keys as comma lists (reference first), the seeds as a list, and the overrides every run shares."""
    arm_runs = [r for arm in a.arms[1:] for r in arm.runs] or a.runs
    experiments = Counter(r.overrides["experiment"] for r in arm_runs if "experiment" in r.overrides)
    tokens = [f"experiment={experiments.most_common(1)[0][0]}"] if experiments else []
    spelled = {k: v for r in a.runs for k, v in r.spelled.items()}
    n_settings = 1
    for i, key in enumerate(a.keys):
        values: list[str] = []
        for arm in a.arms:
            v = arm.values[i]
            if v != MISSING and not any(same_value(v, u) for u in values):
                values.append(v)
        n_settings *= max(len(values), 1)
        tokens.append(f"{spelled.get(key, key)}={','.join(values)}")
    shared = set.intersection(*(set(r.overrides.items()) for r in a.runs))
    for key, value in sorted(shared):
        if key not in a.keys and key not in IGNORED_KEYS and key != SEED_KEY:
            tokens.append(f"{spelled.get(key, key)}={value}")
    seeds = sorted({_seed(r) for r in a.runs}, key=lambda s: (len(s), s))
    offsets = {_fold_offset(r) for r in a.runs} - {None}
    k = next(iter(offsets)) if len(offsets) == 1 else 0
    if k:  # a confirmation on fresh seeds: the fold is the seed minus a constant, not the experiments' cv_fold = seed
        args = " ".join(shlex.quote(t) for t in tokens) + f" seed=$s dataset.cv_fold=$((s - {k}))"
        cmd = f"for s in {' '.join(seeds)}; do python -m gyrodenoise.train -m {args}; done"
    else:
        tokens.append(f"seed={','.join(seeds)}")
        cmd = "python -m gyrodenoise.train -m " + " ".join(shlex.quote(t) for t in tokens)
        if len(offsets) > 1:
            cmd += "  # with each run's own dataset.cv_fold (its summary)"
    if n_settings != len(a.arms):  # Hydra sweeps the product of the lists
        cmd += f"  # the sweep's product has {n_settings} settings; the runs are {len(a.arms)} of them"
    return cmd


def _fold_offset(run: Run) -> int | None:
    """seed - dataset.cv_fold of a run (0 where the fold is the seed), None without a held-out fold."""
    fold = run.summary.get("config", {}).get("dataset", {}).get("cv_fold")
    try:
        return None if fold is None else int(str(run.seed)) - int(fold)
    except ValueError:  # a seed that is no number: no offset to speak of
        return None


def _fmt_verdict(a: Analysis, split: str) -> str:
    return a.verdicts[split][0] if split in a.verdicts else "-"


def _facts(a: Analysis) -> list[str]:
    epochs = sorted({str(r.summary.get("epochs", "?")) for r in a.runs})
    selection = sorted({str(r.summary.get("selection", "best_val (older runs)")) for r in a.runs})
    machines = Counter(str(r.summary.get("machine", "?")) for r in a.runs)
    steps = Counter(str(r.summary.get("training_step", "eager (run before the graph step existed)")) for r in a.runs)
    walls = [float(r.summary.get("train_wall_time_s") or 0) for r in a.runs]
    val_note = (
        "`val` is a training flight held out (dataset.cv_fold, tied to the seed), `val_tail` the end of the training "
        "flights"
        if "val_tail" in a.splits
        else "`val` is the end of the training flights (no held-out flight in these runs)"
    )
    return [
        f"- Seeds: {', '.join(seeds_of(a))}; {len(a.runs)} runs in {len(a.arms)} arms.",
        f"- Schedule: {', '.join(epochs)} epochs (from the summaries); model selection: {', '.join(selection)}.",
        f"- Validation: {val_note}.",
        f"- Training wall time: {sum(walls) / 3600:.2f} h over the {len(a.runs)} runs (per arm: last column).",
        "- Machine: " + "; ".join(f"{m} ({n} runs)" for m, n in machines.most_common()) + ".",
        "- Training step: " + "; ".join(f"{m} ({n} runs)" for m, n in steps.most_common()) + ".",
        f"- Reproduce: `{reproduce_command(a)}`",
    ]


def claim_section(a: Analysis, plot_link: str | None = None, level: int = 2) -> list[str]:
    """The Markdown of one analysis: verdicts, arm table, plot, per-seed values, facts, warnings."""
    h = "#" * level
    md = [f"{h} {a.title}", ""]
    claim = a.claim
    if claim:
        md += [f"> {claim.sentence} (paper, Section {claim.section})", ""]
        md += [
            f"**Test AOE: {_fmt_verdict(a, 'test')}.** Validation AOE: {_fmt_verdict(a, 'val')}."
            + (f" Old validation (val_tail): {_fmt_verdict(a, 'val_tail')}." if "val_tail" in a.verdicts else ""),
            "",
        ]
        md += [f"- {r}" for r in a.verdicts.get("test", ("", []))[1]]
        md += [f"- Note: {claim.note}."] if claim.note else []
        md += [""]
    md += [arm_table(a)]
    if "val_tail" in a.splits:
        md += ["Old validation figure (end of the training flights):", "", tail_table(a)]
    if plot_link:
        md += [f"![paired differences]({plot_link})", ""]
    md += [
        f"Per seed, test / val AOE (deg){'; * = mean of repeated runs' if any(x.duplicates for x in a.arms) else ''}:",
        "",
        seed_table(a),
    ]
    md += _facts(a) + [""]
    if a.warnings:
        md += ["Warnings:", "", *(f"- {w}" for w in a.warnings), ""]
    return md


METHOD = """\
Each arm is compared with the reference arm (the paper's setting) **seed by seed**: with the held-out
flight tied to the seed (`dataset.cv_fold` = the seed, or the seed minus 6 in a confirmation on fresh
seeds) a seed fixes the initialisation, the crops, the augmentation and the held-out validation flight,
so d = AOE(arm) − AOE(reference) of one seed cancels what the two runs share.
Positive d: the arm is worse. Per arm: the mean of d, its 95 % t-interval (n − 1 degrees of freedom)
and a 95 % percentile-bootstrap interval (9999 resamples, fixed seed; from 3 pairs on; with a handful
of seeds it is narrower than the t-interval, so the verdict uses the t-interval). Verdict: *worse* /
*better* when the t-interval excludes 0, else *not resolved at n = K*, with n* = ⌈(t₀.₉₇₅,ₙ₋₁ · sd /
|mean d|)²⌉, the seeds that would resolve it if the observed mean and sd held (an estimate). A claim is
*supported* when every arm it names is resolved the expected way (for claims that only say a change
"does not (systematically/necessarily) help": nothing contradicts and at least one such arm is resolved
worse), *contradicted* when an arm is resolved against it, else *not resolved at this sample size*
(rules and the expected outcome of each arm: `CLAIMS` in `src/gyrodenoise/ablation_stats.py`). The
headline is the test AOE; the validation AOE is judged the same way."""


def write_outputs(a: Analysis, out: Path, sources: Sequence[Path] = ()) -> None:
    png = with_ext(out, ".png")
    md = [*claim_section(a, png.name, level=1)]
    if sources:
        md.insert(2, f"Runs: {', '.join(f'`{s}`' for s in sources)}\n")
    write_text(with_ext(out, ".md"), "\n".join(md))
    write_text(with_ext(out, ".csv"), csv_text(a))
    write_bytes(png, plot_png(a))
    for w in a.warnings:
        print(f"warning: {w}", file=sys.stderr)


def write_report(
    root: Path = Path("reports/ablation_runs"),
    out: Path = Path("reports/ablation_euroc.md"),
    tables: Path | None = None,
    appendix: Path | None = None,
    title: str | None = None,
) -> dict[str, Analysis]:
    """The whole of `out` from every claim folder under `root` (plus root/reference, the shared paper
    setting), each claim's tables in `tables` (default: <out without .md>/paired/), and the text of
    `appendix` (default: <out stem>_appendix.md) kept verbatim below its heading; <out stem>_intro.md, if there is
    one, is kept verbatim under the title."""
    root, out = Path(root), Path(out)
    tables = Path(tables) if tables else out.parent / out.stem / "paired"
    appendix = Path(appendix) if appendix else out.parent / f"{out.stem}_appendix.md"
    intro = out.parent / f"{out.stem}_intro.md"  # hand-written text kept verbatim under the title, if there is one
    ref_runs = find_runs([root / REFERENCE_DIR])[0] if (root / REFERENCE_DIR).is_dir() else []
    results: dict[str, Analysis] = {}
    sections: list[str] = []
    summary = [
        "| claim | paper | verdict (test AOE) | verdict (val AOE) | arms × seeds | epochs |",
        "|---|---|---|---|---|---|",
    ]
    for i, (name, claim) in enumerate(CLAIMS.items(), 1):
        folder = root / name
        runs = find_runs([folder])[0] if folder.is_dir() else []
        heading = f"## {i}. {claim.title} (Section {claim.section})"
        if not runs:
            sections += [
                heading,
                "",
                f"> {claim.sentence}",
                "",
                f"No summaries under `{folder}` yet. Runs: `python -m gyrodenoise.train -m experiment=ablation_{name}`"
                f" (then commit each run's summary.json as `{folder}/<arm>_s<seed>.json`).",
                "",
            ]
            summary.append(f"| {claim.title} | {claim.section} | no runs yet | | | |")
            continue
        a = analyse(
            [*ref_runs, *runs], dict(claim.reference), claim.keys, name, f"{i}. {claim.title} (Section {claim.section})"
        )
        results[name] = a
        write_outputs(a, tables / name, sources=[root / REFERENCE_DIR, folder])
        link = os.path.relpath(tables / f"{name}.png", out.parent)
        sections += claim_section(a, link, level=2)
        sections.append(f"Table files: [{name}.md]({link[:-4]}.md), [{name}.csv]({link[:-4]}.csv)\n")
        epochs = ", ".join(sorted({str(r.summary.get("epochs", "?")) for r in a.runs}))
        summary.append(
            f"| [{claim.title}](#{_anchor(a.title)}) | {claim.section} | {_fmt_verdict(a, 'test')} | "
            f"{_fmt_verdict(a, 'val')} | {len(a.arms)} × {len(seeds_of(a))} | {epochs} |"
        )
    others = (
        sorted(p.name for p in root.iterdir() if p.is_dir() and p.name not in CLAIMS and p.name != REFERENCE_DIR)
        if root.is_dir()
        else []
    )
    md = [
        f"# {title or 'EuRoC ablations of Section V: paired seeds'}",
        "",
        *([intro.read_text().rstrip("\n"), ""] if intro.is_file() else []),
        f"Generated by `python -m gyrodenoise.ablation --report` from the run summaries committed under `{root}/`"
        f" (the shared reference arm in `{root / REFERENCE_DIR}/`); do not edit by hand."
        + (
            " The earlier four-seed verdicts and 120-epoch tables are kept verbatim in the appendix."
            if appendix.is_file()
            else ""
        ),
        "",
        *summary,
        "",
        *many_arms_section(results),
        "## Method",
        "",
        METHOD,
        "",
        *sections,
    ]
    if others:
        md += [f"Folders under `{root}` that are no claim (not analysed): {', '.join(others)}.", ""]
    if appendix.is_file():
        md += [APPENDIX_HEADING, "", appendix.read_text()]
    write_text(out, "\n".join(md).rstrip("\n") + "\n")
    return results


FIGURE_NAMES = {"test": "test AOE", "val": "val AOE (the held-out training flight)"}


def many_arms_section(results: dict[str, Analysis], splits: Sequence[str] = ("test", "val")) -> list[str]:
    """Each verdict is one arm's own 95 % interval; over a report's many arms some come out resolved by chance.
    Per figure: every arm's paired-t p and its Holm-adjusted p over all arms of all claims; the table lists the
    arms resolved alone or after the correction."""
    md = ["## Many arms at once", ""]
    for split in splits:
        family = [
            (name, arm, arm.diffs[split])
            for name, a in results.items()
            for arm in a.arms[1:]
            if split in arm.diffs and arm.diffs[split].n >= 2
        ]
        if not family:
            continue
        adjusted = holm([d.p_value for _, _, d in family])
        rows = [
            [name, arm.label, _signed(d.mean), f"{d.p_value:.3g}", f"{q:.3g}", "yes" if q < 0.05 else "no"]
            for (name, arm, d), q in zip(family, adjusted, strict=True)
            if d.direction  # Holm's p is never below the arm's own, so what holds is resolved alone too
        ]
        held = sum(r[-1] == "yes" for r in rows)
        md += [
            f"**{FIGURE_NAMES.get(split, split)}**: {len(family)} arm{'s' * (len(family) != 1)} compared with the "
            "reference; "
            f"{len(rows)} resolved by their own 95 % interval (about {0.05 * len(family):.1f} expected by chance if "
            f"no arm made a difference); {held} of them {'holds' if held == 1 else 'hold'} after Holm's correction "
            "over all of them (family-wise 5 %, valid although the arms share one reference)."
            + (" Resolved arms:" if rows else ""),
            "",
        ]
        if rows:
            head = ["claim", "arm", "Δ mean (deg)", "p (paired t)", "p (Holm)", "holds"]
            md += [markdown_table(head, rows).rstrip("\n"), ""]
    return md


def _anchor(title: str) -> str:
    """GitHub's heading anchor: lower case, punctuation dropped, spaces to hyphens."""
    keep = "".join(c for c in title.lower() if c.isalnum() or c in " -")
    return keep.replace(" ", "-")


# --- command line (python -m gyrodenoise.ablation) ----------------------------------------------------------


def claim_of(dirs: Sequence[Path]) -> str | None:
    """The claim a lone folder is named after (reports/ablation_runs/activation -> activation)."""
    names = {Path(d).name for d in dirs} & set(CLAIMS)
    return names.pop() if len(names) == 1 else None


def paired_cli(a: argparse.Namespace, keys: list[str] | None) -> int:
    """Paired mode: the claim (--claim, or the folder's name) gives keys, reference and expectations;
    --reference overrides its reference. When no run matches the reference, a sibling reference/
    folder (reports/ablation_runs/reference, the arm shared by all claims) is read too."""
    claim = a.claim or claim_of(a.dirs)
    reference = dict(CLAIMS[claim].reference) if claim in CLAIMS else {}
    reference.update(parse_assignments(a.reference))
    if not reference:
        raise ValueError("name the reference arm with --reference KEY=VALUE (or --claim NAME)")
    where = parse_where(a.where)
    dirs = list(a.dirs)
    runs = matching(find_runs(dirs)[0], where)
    try:
        analysis = analyse(runs, reference, keys, claim, a.title)
    except ValueError as e:
        siblings = [Path(d).parent / REFERENCE_DIR for d in dirs]
        extra = next((s for s in siblings if s.is_dir() and s not in dirs), None)
        if extra is None or "no run matches the reference" not in str(e):
            raise
        print(f"reference arm not among the runs given: reading {extra} too", file=sys.stderr)
        dirs.append(extra)
        runs += [r for r in find_runs([extra])[0] if all(same_value(r.value(k), v) for k, v in where)]
        analysis = analyse(runs, reference, keys, claim, a.title)
    write_outputs(analysis, a.out, sources=dirs)
    print(with_ext(a.out, ".md").read_text())
    print(f"wrote {a.out}.md, .csv, .png ({len(analysis.arms)} arms, reference {analysis.reference.label})")
    return 0


def report_cli(a: argparse.Namespace) -> int:
    root = a.dirs[0] if a.dirs else Path("reports/ablation_runs")
    out = a.out or Path("reports/ablation_euroc.md")
    if out.suffix != ".md":  # --out is a prefix elsewhere: PREFIX.md
        out = out.with_name(out.name + ".md")
    results = write_report(root, out, a.tables, a.appendix, a.title)
    for name, an in results.items():
        print(f"{name}: test {an.verdicts.get('test', ('-',))[0]}, val {an.verdicts.get('val', ('-',))[0]}")
    print(f"wrote {out} ({len(results)} claims with runs)")
    if not results:
        print(
            f"--report reads {root}/<claim>/<arm>_s<seed>.json (the layout of benchmarks/queues/ablations.txt);"
            " for your own sweep's multirun folder use: python -m gyrodenoise.ablation DIR --claim NAME --out PREFIX",
            file=sys.stderr,
        )
    return 0
