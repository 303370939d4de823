"""The C export on microcontroller-class toolchains (`gyrodenoise.c_targets`): cross-compiled for Cortex-M4F, Cortex-M7
and 32-bit ARM Linux with -Werror -Wdouble-promotion -Wconversion, free of double arithmetic, and run under QEMU
(bare metal on the MPS2 boards for Cortex-M; qemu-arm for armhf) against the Python streaming corrector, stamps and a
gap included.

Each target skips, naming the packages to install, when its cross compiler or QEMU is missing (CI has neither: a C
cross toolchain is a system package). With the tools present, every check can fail.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import torch
from _models import random_imu, random_model

from gyrodenoise import c_export, c_targets
from gyrodenoise.models.ensemble import EnsembleCorrection
from gyrodenoise.streaming import StreamingCorrector

ATOL = 1e-5  # rad/s, as the host checks (tests/test_c_export.py)
SMALL = {"channels": (8, 16, 12), "kernel_size": 3, "dilations": (1, 4, 9)}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A 2-member ensemble at 200 Hz (gelu and elu: erff, expm1f from the target's libm), exported once."""
    members = [random_model(seed=1, act="gelu", **SMALL), random_model(seed=2, act="elu", **SMALL)]
    for m in members:
        m.net[-1].weight.data *= 10  # corrections of ~1 rad/s
    model = EnsembleCorrection(members, spread_scale=1.3)
    out = tmp_path_factory.mktemp("c")
    c_export.export_c(model, out, {"name": "test", "rate_hz": 200.0})
    return model, out


def stream() -> tuple[np.ndarray, np.ndarray]:
    """300 samples at 200 Hz with jitter and a 1 s gap before sample 150."""
    jitter = np.random.default_rng(0).integers(-400_000, 400_000, 300)
    t = 1_403_636_579_000_000_000 + 5_000_000 * np.arange(300) + jitter
    t[150:] += 1_000_000_000
    return random_imu(300, seed=3), t


@pytest.mark.parametrize("name", list(c_targets.TARGETS))
def test_cross_compiled_and_run_under_qemu(name, exported, tmp_path):
    target = c_targets.TARGETS[name]
    if lacking := c_targets.missing(target):
        pytest.skip(f"{name}: not installed: {', '.join(lacking)}")
    model, c_dir = exported
    obj = c_targets.compile_object(c_dir / c_export.SOURCE, target, tmp_path / "model.o")  # STRICT: -Werror
    assert c_targets.double_symbols(obj, target) == []
    sizes = c_targets.section_sizes(obj, target)
    assert sizes["rodata"] > sizes["text"] > 0 and sizes["bss"] == 0  # weights in flash; no RAM but the caller's state
    ring = int(re.search(r"#define GD_RING_FLOATS +(\d+)", (c_dir / c_export.HEADER).read_text()).group(1))
    assert 4 * ring < c_targets.state_size(c_dir, target, tmp_path) < 4 * ring + 1024

    exe = c_targets.build_example(c_dir, target, tmp_path / "gyrodenoise", tmp_path)
    imu, t = stream()
    gyro, std = c_targets.run_example_on(target, exe, imu, t, timeout=120)
    sc = StreamingCorrector(model, rate_hz=200.0)
    ref = [sc.push_with_spread(x, t_ns=int(s)) for x, s in zip(imu[:150].astype(np.float32), t[:150], strict=True)]
    sc.reset()  # the gap: gd_step_t restarts the stream, Python's caller resets
    ref += [sc.push_with_spread(x, t_ns=int(s)) for x, s in zip(imu[150:].astype(np.float32), t[150:], strict=True)]
    assert np.abs(gyro - np.stack([r[0] for r in ref])).max() < ATOL
    assert std is not None and np.abs(std - np.stack([r[1] for r in ref])).max() < ATOL


def test_double_arithmetic_is_found(tmp_path):
    """The double check finds a double that sneaks in: -Wdouble-promotion refuses it at compile time, and without that
    warning the Cortex-M4F object calls the soft-float double routines, which `double_symbols` names."""
    target = c_targets.TARGETS["cortex-m4f"]
    if lacking := c_targets.missing(target):
        pytest.skip(f"cortex-m4f: not installed: {', '.join(lacking)}")
    src = tmp_path / "d.c"
    src.write_text("float f(float x);\nfloat f(float x) { return (float)(x * 0.5 + 1.0f); }\n")
    with pytest.raises(RuntimeError, match="double-promotion"):
        c_targets.compile_object(src, target, tmp_path / "d.o")
    obj = c_targets.compile_object(src, target, tmp_path / "d.o", extra=("-Wno-double-promotion",))
    assert any(s.startswith("__aeabi_d") for s in c_targets.double_symbols(obj, target))


def test_instructions_per_step_are_counted(exported, tmp_path):
    """QEMU -icount counts a Cortex-M4F step's instructions: at least one per multiply-add of the convolutions, and
    the same for every step (no data-dependent work but the activations' libm calls)."""
    target = c_targets.TARGETS["cortex-m4f"]
    if lacking := c_targets.missing(target):
        pytest.skip(f"cortex-m4f: not installed: {', '.join(lacking)}")
    model, c_dir = exported
    imu, t = stream()
    n = c_targets.instructions_per_step(c_dir, target, tmp_path, imu[:40], t[:40])
    macs = sum(m.weight.numel() for m in model.modules() if isinstance(m, torch.nn.Conv1d))
    assert len(n) == 39 and macs < n.min() and n.max() < 1.5 * n.min()
    with pytest.raises(ValueError, match="bare-metal"):
        c_targets.instructions_per_step(c_dir, c_targets.TARGETS["armhf"], tmp_path, imu[:5], t[:5])
