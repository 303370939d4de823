"""Paired statistics of an ablation arm against the reference arm, and the paper's Section V claims as data.

A pair is one seed run in both arms. With `dataset.cv_fold = seed` the seed fixes the initialisation, the
crops, the augmentation draws and the held-out validation flight, so the per-seed difference
d = AOE(arm) - AOE(reference) cancels what the two runs share; the spread of d, not the spread of each
arm, decides whether an effect is resolved.

- mean of d and its 95 % t-interval (scipy.stats.t, n - 1 degrees of freedom);
- a 95 % bootstrap interval of the mean of d (scipy.stats.bootstrap, percentile method, fixed seed),
  only from 3 pairs on: with a handful of seeds it is narrower than the t-interval (it ignores the
  uncertainty of the spread), so the verdict uses the t-interval;
- verdict: "worse" (arm AOE higher) or "better" when the t-interval excludes 0, else "not resolved at
  n=K", with n* = ceil((t_{0.975,n-1} sd / |mean d|)^2), the number of seeds that would resolve it *if*
  the observed mean and sd held (an estimate, not a promise).
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

CONFIDENCE = 0.95
BOOTSTRAP_MIN_N = 3
BOOTSTRAP_RESAMPLES = 9999
BOOTSTRAP_SEED = 0


def t_interval(mean: float, sd: float, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Two-sided t-interval of a mean of n values with sample sd; (nan, nan) below 2 values."""
    if n < 2 or not math.isfinite(sd):
        return math.nan, math.nan
    if sd == 0.0:  # identical differences: scipy's scale must be > 0
        return mean, mean
    lo, hi = stats.t.interval(confidence, n - 1, loc=mean, scale=sd / math.sqrt(n))
    return float(lo), float(hi)


def bootstrap_interval(diffs: Sequence[float], confidence: float = CONFIDENCE) -> tuple[float, float] | None:
    """Percentile bootstrap interval of the mean of `diffs` (fixed seed); None below BOOTSTRAP_MIN_N."""
    d = np.asarray(diffs, dtype=float)
    if len(d) < BOOTSTRAP_MIN_N:
        return None
    if np.all(d == d[0]):  # every resample has the same mean
        return float(d[0]), float(d[0])
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    # scipy >= 1.15 names the generator `rng`, older versions `random_state`
    seed_kw = "rng" if "rng" in inspect.signature(stats.bootstrap).parameters else "random_state"
    res = stats.bootstrap(
        (d,),
        np.mean,
        confidence_level=confidence,
        n_resamples=BOOTSTRAP_RESAMPLES,
        method="percentile",
        **{seed_kw: rng},
    )
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def seeds_to_resolve(mean: float, sd: float, n: int, confidence: float = CONFIDENCE) -> float:
    """n* = ceil((t_{(1+c)/2, n-1} sd / |mean|)^2), at least n + 1: the seeds a t-interval would need to
    exclude 0 if the observed mean and sd held. inf for a zero mean, nan when unknown (n < 2)."""
    if n < 2 or not (math.isfinite(sd) and math.isfinite(mean)):
        return math.nan
    if mean == 0.0:
        return math.inf
    t = stats.t.ppf(0.5 + confidence / 2, n - 1)
    return float(max(math.ceil((t * sd / abs(mean)) ** 2), n + 1))


def detectable_difference(sd: float, n: int, power: float = 0.8, confidence: float = CONFIDENCE) -> float:
    """The smallest true mean difference that a two-sided paired t-test on n values of this sd finds with `power`,
    from the noncentral t distribution (exact for normal differences; the usual approximation
    (t_{(1+c)/2, n-1} + t_{power, n-1}) sd / sqrt(n) is ~0.7 % smaller at n = 6). nan below 2 values."""
    if not 0.0 < confidence < 1.0 or not 1.0 - confidence < power < 1.0:
        raise ValueError(f"power {power} must lie between 1 - confidence ({1 - confidence:g}) and 1")
    if n < 2 or not math.isfinite(sd):
        return math.nan
    if sd < 0:
        raise ValueError(f"sd {sd} is negative")
    return float(_detectable_per_sd(int(n), float(power), float(confidence)) * sd)


@functools.lru_cache(maxsize=256)
def _detectable_per_sd(n: int, power: float, confidence: float) -> float:
    """The true mean difference, in units of the sd, that the two-sided t-test on n values finds with `power`."""
    crit = stats.t.ppf(0.5 + confidence / 2, n - 1)

    def shortfall(effect: float) -> float:
        nc = effect * math.sqrt(n)
        # the lower tail as the upper tail at -nc (scipy's cdf gives nan there for some large nc at 1 df)
        return float(stats.nct.sf(crit, n - 1, nc) + stats.nct.sf(crit, n - 1, -nc)) - power

    guess = (crit + stats.t.ppf(power, n - 1)) / math.sqrt(n)  # the approximation: just below the answer
    hi = 2 * guess
    while shortfall(hi) < 0:
        hi *= 2
    return float(optimize.brentq(shortfall, 0.0, hi, xtol=1e-12))


@dataclass(frozen=True)
class FoldSeedSpread:
    """A paired difference measured at several seeds on each of several folds, split into what more seeds average
    away and what they do not: d[k, s] = mean + a_k + e[k, s], with the fold's own effect a_k (sd `between_sd`:
    how the two recipes' difference changes from one held-out flight to the next) and the seed's e (sd
    `within_sd`). Method of moments of the one-way random-effects model; `interaction_p` is the F-test of
    between_sd = 0."""

    n_folds: int
    n_seeds: int
    mean: float
    between_sd: float
    within_sd: float
    interaction_f: float
    interaction_p: float

    def between_sd_upper(self, confidence: float = CONFIDENCE) -> float:
        """The upper limit of the two-sided `confidence` interval of between_sd, from the F distribution of the
        ratio between / within variance (Searle's interval): the point estimate is cut at 0 and can be far below
        what the data allow."""
        if not math.isfinite(self.interaction_f):
            return math.nan
        df1, df2 = self.n_folds - 1, self.n_folds * (self.n_seeds - 1)
        ratio = (self.interaction_f / stats.f.ppf((1 - confidence) / 2, df1, df2) - 1) / self.n_seeds
        return math.sqrt(max(ratio, 0.0)) * self.within_sd

    def fold_mean_sd(self, seeds: float) -> float:
        """The sd of one fold's mean difference over `seeds` seeds (inf: the fold's effect alone)."""
        if not seeds >= 1:
            raise ValueError(f"seeds per fold {seeds!r}: at least 1 (inf: the fold's effect alone)")
        return math.sqrt(self.between_sd**2 + (0.0 if math.isinf(seeds) else self.within_sd**2 / seeds))

    def detectable(self, seeds: float, folds: int | None = None, power: float = 0.8) -> float:
        """The smallest difference a t-test over the fold means finds with `power`, at `seeds` seeds per fold."""
        return detectable_difference(self.fold_mean_sd(seeds), folds or self.n_folds, power)

    def seeds_for(self, difference: float, folds: int | None = None, power: float = 0.8) -> float:
        """Seeds per fold at which `difference` becomes `detectable` (inf: not even with every seed, the fold
        effect alone is too large)."""
        per_unit_sd = detectable_difference(1.0, folds or self.n_folds, power)
        room = (abs(difference) / per_unit_sd) ** 2 - self.between_sd**2  # what the seeds' share may be
        if self.within_sd == 0.0:
            return 1.0 if room >= 0 else math.inf
        return self.within_sd**2 / room if room > 0 else math.inf


def fold_seed_spread(d: np.ndarray) -> FoldSeedSpread:
    """`d`: (folds, seeds) paired differences, every fold at the same seeds (at least 2 of each)."""
    d = np.asarray(d, dtype=float)
    if d.ndim != 2 or min(d.shape) < 2 or not np.isfinite(d).all():
        raise ValueError(f"fold_seed_spread needs finite differences at >= 2 folds x >= 2 seeds, got {d.shape}")
    k, s = d.shape
    ms_within = float(d.var(axis=1, ddof=1).mean())  # k (s - 1) degrees of freedom
    ms_between = float(s * d.mean(axis=1).var(ddof=1))  # k - 1 degrees of freedom
    # differences equal up to rounding have no spread to compare: no F (it read inf, or 0 from rounding residue)
    tiny = (64 * np.finfo(float).eps * max(1.0, float(np.abs(d).max()))) ** 2
    if ms_within <= tiny and ms_between <= tiny:
        f, p = math.nan, math.nan
    else:
        f = ms_between / ms_within if ms_within > tiny else math.inf
        p = float(stats.f.sf(f, k - 1, k * (s - 1))) if math.isfinite(f) else 0.0
    between = math.sqrt(max(0.0, (ms_between - ms_within) / s))
    return FoldSeedSpread(k, s, float(d.mean()), between, math.sqrt(ms_within), f, p)


@dataclass(frozen=True)
class PairedDiff:
    """d = AOE(arm) - AOE(reference) per paired seed (deg): positive means the arm is worse."""

    seeds: tuple[str, ...]
    diffs: tuple[float, ...]
    mean: float = field(init=False)
    sd: float = field(init=False)
    t_ci: tuple[float, float] = field(init=False)
    boot_ci: tuple[float, float] | None = field(init=False)

    def __post_init__(self) -> None:
        d = np.asarray(self.diffs, dtype=float)
        n = len(d)
        if len(self.seeds) != n:
            raise ValueError(f"PairedDiff: {len(self.seeds)} seeds for {n} differences")
        if not np.isfinite(d).all():  # `paired_diff` leaves them out and names them
            raise ValueError(f"PairedDiff: differences must be finite, got {list(self.diffs)}")
        set_ = object.__setattr__  # frozen: derived fields are set once here
        set_(self, "mean", float(d.mean()) if n else math.nan)
        set_(self, "sd", float(d.std(ddof=1)) if n > 1 else math.nan)
        set_(self, "t_ci", t_interval(self.mean, self.sd, n))
        set_(self, "boot_ci", bootstrap_interval(d))

    @property
    def n(self) -> int:
        return len(self.diffs)

    @property
    def direction(self) -> int:
        """+1: the arm is resolved worse (t-interval above 0), -1: resolved better, 0: not resolved."""
        lo, hi = self.t_ci
        return 1 if lo > 0 else -1 if hi < 0 else 0  # nan compares False: not resolved

    @property
    def verdict(self) -> str:
        if self.n == 0:
            return "no pairs"
        return {1: "worse", -1: "better"}.get(self.direction, f"not resolved at n={self.n}")

    @property
    def p_value(self) -> float:
        """Two-sided p of the paired t-test of mean d = 0 (the test behind the t-interval); nan below 2 pairs."""
        if self.n < 2 or not math.isfinite(self.sd):
            return math.nan
        if self.sd == 0.0:  # identical differences: certain unless they are all 0
            return 1.0 if self.mean == 0.0 else 0.0
        return float(stats.ttest_1samp(self.diffs, 0.0).pvalue)

    @property
    def n_star(self) -> float:
        """Seeds estimated to resolve an unresolved difference (see seeds_to_resolve); nan if resolved."""
        return math.nan if self.direction else seeds_to_resolve(self.mean, self.sd, self.n)

    def describe(self) -> str:
        """The verdict with, when not resolved, the estimated seeds n*."""
        if self.direction or self.n == 0:
            return self.verdict
        ns = self.n_star
        if math.isnan(ns):
            return f"{self.verdict} (n* unknown: no spread from one pair)"
        if math.isinf(ns):
            return f"{self.verdict} (mean difference 0: no n* would resolve it)"
        return f"{self.verdict} (n* ≈ {ns:.0f} if the observed mean and sd held)"


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm-Bonferroni adjusted p-values: family-wise error control whatever the dependence between the tests
    (arms that share one reference do depend). A nan (no test) stays nan and does not count in the family."""
    if bad := [p for p in p_values if math.isfinite(p) and not 0.0 <= p <= 1.0]:
        raise ValueError(f"holm: p-values lie in [0, 1], got {bad}")
    ok = sorted((p, i) for i, p in enumerate(p_values) if math.isfinite(p))
    adjusted = [math.nan] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(ok):
        running = max(running, min(1.0, (len(ok) - rank) * p))  # adjusted values never decrease with p
        adjusted[i] = running
    return adjusted


def paired_diff(arm: dict[str, float], reference: dict[str, float]) -> tuple[PairedDiff, list[str], list[str]]:
    """Pair seed -> AOE maps: (the paired difference, arm seeds without a reference run, reference seeds
    without an arm run). Non-finite values do not pair (and count as missing)."""
    ok_arm = {s for s, v in arm.items() if math.isfinite(v)}
    ok_ref = {s for s, v in reference.items() if math.isfinite(v)}
    seeds = sorted(ok_arm & ok_ref, key=_seed_order)
    d = PairedDiff(tuple(seeds), tuple(arm[s] - reference[s] for s in seeds))
    return d, sorted(ok_arm - ok_ref, key=_seed_order), sorted(ok_ref - ok_arm, key=_seed_order)


def _seed_order(seed: str) -> tuple[int, float, str]:
    try:
        return 0, float(seed), seed
    except ValueError:
        return 1, 0.0, seed


# --- the paper's claims -----------------------------------------------------------------------------------
# Expected outcome of an arm, against the reference (the paper's setting), on the paired test AOE:
#   "worse" / "better": the arm's AOE is higher / lower (supported when resolved so, contradicted when
#     resolved the other way);
#   "not better" / "not worse": a claim that the arm does not beat / is not beaten by the reference;
#     contradicted when resolved the forbidden way, supported when resolved the other way, else consistent;
#   "no systematic gain": the arms so marked, taken together, do not systematically improve; contradicted
#     only when every one of them is resolved better, supported when at least one is resolved worse.
EXPECTED = ("worse", "better", "not better", "not worse", "no systematic gain")


@dataclass(frozen=True)
class Claim:
    title: str
    section: str
    sentence: str  # the paper's words
    keys: tuple[str, ...]  # the ablated keys (config-group choices without the +)
    reference: dict[str, str]  # the paper's value of each key: picks the reference arm
    expect: tuple[tuple[str, str], ...]  # (arm as "key=value[ key=value]", expected outcome)
    note: str = ""


# claim name (= its folder under reports/ablation_runs/, and experiment=ablation_<name>) -> claim
CLAIMS: dict[str, Claim] = {
    "activation": Claim(
        "Activation function",
        "V-B1",
        # "the GELU and other smooth activation functions, such as ELU, perform well, whereas ReLU based
        # network is more prone to overfit."
        "the GELU and other smooth activation functions, such as ELU, perform well, whereas ReLU based "
        "network is more prone to overfit",
        ("model.act",),
        {"model.act": "gelu"},
        (("model.act=relu", "worse"), ("model.act=elu", "not worse"), ("model.act=silu", "not worse")),
    ),
    "shape": Claim(
        "Network size",
        "V-B2",
        # "increasing the depth, channel and/or kernel sizes of the network ... does not systematically
        # lead to better results."
        "increasing the depth, channel and/or kernel sizes of the network does not systematically lead to "
        "better results",
        ("model/shape",),
        {"model/shape": "paper"},
        (
            ("model/shape=wide", "no systematic gain"),  # channels x2
            ("model/shape=deep", "no systematic gain"),  # 6 layers
            ("model/shape=kernel11", "no systematic gain"),  # kernel 11
        ),
        "only the variants that increase depth, channels or kernel carry the claim; the others are shown",
    ),
    "batchnorm": Claim(
        "Batch norm",
        "V-B3",
        # "batchnorm layer improves both training speed and accuracy, and is highly recommended."
        "batchnorm layer improves both training speed and accuracy",
        ("model.batch_norm",),
        {"model.batch_norm": "true"},
        (("model.batch_norm=false", "worse"),),
        "accuracy only: the speed part needs the validation curves (TensorBoard)",
    ),
    "scheduler": Claim(
        "Learning-rate schedule",
        "V-C2",
        # "adopting a learning rate policy with cosine warning restart leads to substantial improvement"
        "adopting a learning rate policy with cosine warm restart leads to substantial improvement",
        ("optim.scheduler.name",),
        {"optim.scheduler.name": "cosine_warm_restarts"},
        (("optim.scheduler.name=constant", "worse"),),
    ),
    "regularization": Claim(
        "Dropout × weight decay",
        "V-C3",
        # "dropout and weight decay hyperparameters are crucial to avoid overfitting."
        "dropout and weight decay hyperparameters are crucial to avoid overfitting",
        ("model.dropout", "optim.weight_decay"),
        {"model.dropout": "0.1", "optim.weight_decay": "0.1"},
        (
            ("model.dropout=0.0 optim.weight_decay=0.0", "worse"),
            ("model.dropout=0.0 optim.weight_decay=0.1", "worse"),
            ("model.dropout=0.1 optim.weight_decay=0.0", "worse"),
        ),
    ),
    "increments": Claim(
        "Loss increments j",
        "III-C",
        # "the choice of (10) corresponds to error increments at 200/16 ≈ 12 Hz and 200/32 ≈ 6 Hz ...
        # Setting too high a j ... would make the algorithm prone to overfitting"
        "increments j = 16, 32 (about the ground-truth rate); setting too high a j would make the algorithm "
        "prone to overfitting",
        ("loss.increments",),
        {"loss.increments": "[16,32]"},
        (
            ("loss.increments=[64,128]", "worse"),
            ("loss.increments=[32,64]", "not better"),
            ("loss.increments=[8,16]", "not better"),
        ),
    ),
    "train_duration": Claim(
        "Amount of training data",
        "V-A2, IV-A",
        # "training with only this part of data (the first 50 s of the training sequences) is sufficient
        # (and best) to succeed."
        "training with only the first 50 s of the training sequences is sufficient (and best)",
        ("dataset.train_duration_s",),
        {"dataset.train_duration_s": "50"},
        (
            ("dataset.train_duration_s=25", "not better"),
            ("dataset.train_duration_s=100", "not better"),
            ("dataset.train_duration_s=null", "not better"),  # the whole of each training flight
        ),
        "with cv_fold the validation flight is held out whatever the duration, so val compares too",
    ),
    "augmentation": Claim(
        "Data augmentation",
        "III-E",
        # "Although each point may increase the diversity of data, we found they do not necessarily improve
        # the results. We opted for addition of a Gaussian noise (only)"
        "adding static bias, un-calibrating the IMU and rotating the accelerometer frame do not necessarily "
        "improve the results; Gaussian noise (only) is used",
        ("dataset/augment",),
        {"dataset/augment": "noise"},
        (
            ("dataset/augment=none", "worse"),  # the noise is the augmentation kept: it should help
            ("dataset/augment=bias", "no systematic gain"),
            ("dataset/augment=uncalibrate", "no systematic gain"),
            ("dataset/augment=rotate_acc", "no systematic gain"),
        ),
    ),
}


def check(expected: str, diff: PairedDiff | None) -> str:
    """One arm against its expected outcome: supported / contradicted / not resolved / consistent /
    no runs. For "no systematic gain" a resolved gain reads "gain" (the claim is about the group)."""
    if expected not in EXPECTED:
        raise ValueError(f"expected outcome {expected!r}: choose one of {EXPECTED}")
    if diff is None or diff.n == 0:
        return "no runs"
    sign = diff.direction
    if expected in ("worse", "better"):
        want = 1 if expected == "worse" else -1
        return "supported" if sign == want else "contradicted" if sign == -want else "not resolved"
    if expected == "no systematic gain":
        return "supported" if sign == 1 else "gain" if sign == -1 else "consistent"
    forbidden = -1 if expected == "not better" else 1
    return "contradicted" if sign == forbidden else "supported" if sign == -forbidden else "consistent"


SUPPORTED, CONTRADICTED, NOT_RESOLVED = "supported", "contradicted", "not resolved at this sample size"


def claim_verdict(checks: Sequence[tuple[str, str, PairedDiff | None]]) -> tuple[str, list[str]]:
    """(verdict, reasons) of a claim from its (arm, expected, paired difference) list.

    contradicted: an arm resolved against its expectation, or every "no systematic gain" arm resolved
    better. supported: nothing contradicts, every "worse"/"better" arm is resolved as expected, no
    expected arm lacks runs, and, for a claim made only of "not ..."/"no systematic gain" expectations,
    at least one arm is resolved the allowed way. Otherwise: not resolved at this sample size.
    """
    results = [(arm, exp, check(exp, d)) for arm, exp, d in checks]
    reasons = [f"{arm}: expected {exp}, {res}" for arm, exp, res in results]
    group = [res for _, exp, res in results if exp == "no systematic gain"]
    contradicted = any(res == "contradicted" for *_, res in results) or (
        bool(group) and all(r == "gain" for r in group)
    )
    if contradicted:
        return CONTRADICTED, reasons
    directional = [res for _, exp, res in results if exp in ("worse", "better")]
    if any(res == "no runs" for *_, res in results) or not results:
        return NOT_RESOLVED, reasons
    if directional:
        ok = all(res == "supported" for res in directional)
    else:
        ok = any(res == "supported" for *_, res in results)
    return (SUPPORTED if ok else NOT_RESOLVED), reasons
