"""The fit rows of columns that depend on the sample times alone (the bias, the random walk's hats) are shared
between designs over the same samples (`discrepancy.time_only_rows`): a design served shared rows has the normal
equations of one that built its own, to the bit, and a change of what those rows depend on gets rows of its own."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from gyrodenoise.discrepancy import time_only_rows
from gyrodenoise.discrepancy.compare import load_fit_context
from gyrodenoise.discrepancy.design import Design, sensor_view, set_reconstruction_model
from gyrodenoise.sim.effects import EFFECTS

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks" / "blind_discrepancy"))
import generate  # noqa: E402  (the standalone generator)


def _normal_equations(fcs, effects, sigma, fresh: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    if fresh:
        time_only_rows._rows.clear()
    d = Design(fcs, effects, sigma)
    return d.G, d.b, d.rr


def _same_bits(got, want) -> bool:
    return all(np.array_equal(g, w) for g, w in zip(got, want, strict=True))


def test_shared_rows_are_the_rows_a_design_would_build(tmp_path, monkeypatch):
    generate.make_trial(tmp_path, "time_offset", 2, 20.0, 3)  # a noisy mocap: weighted Fourier rows, edge impulses
    fcs = [load_fit_context(tmp_path, f"seq{i:02d}") for i in range(2)]
    set_reconstruction_model(fcs, [fc.residual - fc.residual.mean(0) for fc in fcs])
    assert all(fc.extra.get("row_weights") is not None for fc in fcs)  # the path the sharing is for
    effects = {n: EFFECTS[n]() for n in ("bias", "bias_random_walk", "time_offset", "scale_factor")}
    effects["bias_random_walk"].knot_spacing_s = 5.0
    sigma = np.array([1e-3, 2e-3, 1.5e-3])
    views = [sensor_view(fc, 30.0) for fc in fcs]  # another corner of a search: the same samples, another motion

    time_only_rows._rows.clear()
    shared = [_normal_equations(v, effects, sigma) for v in (fcs, views)]
    assert len(time_only_rows._rows) == 4  # the bias and the hats of two sequences, built once for both designs
    assert _same_bits(shared[1], _normal_equations(views, effects, sigma, fresh=True))
    # against one transform of all the columns at once (the code before the sharing): the same to rounding
    with monkeypatch.context() as m:
        for name in ("bias", "bias_random_walk"):
            m.setattr(type(effects[name]), "time_only_key", lambda self: None)
        plain = _normal_equations(views, effects, sigma)
    for got, want in zip(shared[1], plain, strict=True):
        assert np.allclose(got, want, rtol=1e-12, atol=1e-14 * np.abs(want).max())

    # what the rows depend on changes: the knot spacing, the row weights, the noise levels
    _normal_equations(fcs, effects, sigma)
    effects["bias_random_walk"].knot_spacing_s = 10.0
    assert _same_bits(_normal_equations(fcs, effects, sigma), _normal_equations(fcs, effects, sigma, fresh=True))
    _normal_equations(fcs, effects, sigma)
    fcs[0].extra["row_weights"] = fcs[0].extra["row_weights"] * 0.5
    assert _same_bits(_normal_equations(fcs, effects, sigma), _normal_equations(fcs, effects, sigma, fresh=True))
    _normal_equations(fcs, effects, sigma)
    assert _same_bits(_normal_equations(fcs, effects, 2 * sigma), _normal_equations(fcs, effects, 2 * sigma, True))
    assert len(time_only_rows._rows) <= time_only_rows.MAX_ENTRIES
