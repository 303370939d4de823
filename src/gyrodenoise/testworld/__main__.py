"""Generate test-world sequences in the ASL layout, with truth.json beside each.

    python -m gyrodenoise.testworld --out /tmp/world --trajectory euroc:V1_02_medium --seed 0 \\
        --effects scale_factor=2000ppm,time_offset=1.5ms
    python -m gyrodenoise.testworld --out /tmp/world --trajectory procedural --duration 60 --preset null
    python -m gyrodenoise.testworld --out /tmp/world --trajectory procedural:1 --seed 3 --effects scale_factor=3000ppm
    python -m gyrodenoise.testworld --out /tmp/world --trajectory procedural:2 --seed 3 --effects scale_factor=3000ppm
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from gyrodenoise.testworld.mocap import MOCAP_PRESETS, MocapConfig
from gyrodenoise.testworld.spec import PRESETS, EffectSpecError, describe
from gyrodenoise.testworld.units import UnitError, to_si
from gyrodenoise.testworld.world import make_sequence


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m gyrodenoise.testworld",
        description=__doc__.split("\n\n")[0]
        + " An IMU and a motion-capture truth made independently of gyrodenoise.sim, to test the discrepancy"
        " workflow on data it did not generate; see src/gyrodenoise/testworld/README.md.",
        epilog="examples:\n"
        + __doc__.split("\n\n")[1].rstrip()
        + "\n\neffects: NAME=VALUE with its unit written on, e.g. bias=0.8deg/s (below: each one's datasheet unit;\n"
        + "other units of the same quantity convert, e.g. rad/s, deg/h; 'a:b:c' gives per-axis values):\n"
        + describe(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", type=Path, required=True, help="folder that receives <name>/mav0/... and <name>/truth.json")
    p.add_argument(
        "--trajectory",
        default="procedural",
        help="'procedural' (its motion drawn from --seed), 'procedural:<K>' (motion drawn from K: a fit and a "
        "held-out sequence of one sensor with different motion) or 'euroc:<SEQ>' (default procedural)",
    )
    p.add_argument(
        "--duration", type=float, default=None, help="seconds of IMU data (default: 60 procedural, all euroc)"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="one seed, one sensor: effect values depend on it only (a single number for a 3-axis effect, e.g. "
        "scale_factor=3000ppm, is a magnitude: each axis gets it with a sign drawn from the seed; give "
        "3000:-3000:3000ppm for chosen signs)",
    )
    p.add_argument(
        "--preset",
        default="null",
        choices=sorted(PRESETS),
        help="base effects before --effects: null = a constant 1 deg/s bias and ADIS16448-like white noise "
        "(what the discrepancy workflow's base model holds), none = a perfect gyro (default null)",
    )
    p.add_argument("--effects", default="", help="comma-separated NAME=VALUE or NAME.PARAM=VALUE items")
    p.add_argument("--name", default=None, help="sequence folder name (default: the EuRoC name or procedural_s<seed>)")
    p.add_argument("--bandwidth", default="integrate", help="integrate|integrate-trailing|butterN:FHz|besselN:FHz")
    p.add_argument("--imu-rate", type=float, default=200.0, help="Hz")
    p.add_argument("--oversample", type=int, default=20, help="internal rate = oversample x IMU rate")
    p.add_argument("--imu-jitter", default="0us", help="std of the IMU stamp jitter (e.g. 20us)")
    p.add_argument(
        "--mocap",
        default="vicon",
        choices=list(MOCAP_PRESETS),
        help="ground-truth preset (default vicon: 100 Hz, 0.2 deg, 1 mm, 100 us); the flags below override it",
    )
    p.add_argument("--mocap-rate", type=float, default=None, help="Hz (EuRoC Vicon 100, TUM-VI 120)")
    p.add_argument("--mocap-orientation-noise", default=None, help="per-axis std, e.g. 0.2deg")
    p.add_argument("--mocap-position-noise", default=None, help="per-axis std, e.g. 1mm")
    p.add_argument("--mocap-jitter", default=None, help="std of the capture time about the stamp, e.g. 100us")
    p.add_argument("--euroc-root", type=Path, default=None, help="folder holding the EuRoC ASL sequences")
    p.add_argument("--smoothing", type=float, default=15.0, help="euroc: low-pass corner of the replay, Hz")
    p.add_argument("--overwrite", action="store_true", help="replace an existing sequence folder of the same name")
    return p.parse_args(argv)


def _mocap(args: argparse.Namespace) -> MocapConfig:
    cfg = MOCAP_PRESETS[args.mocap]
    changes = {}
    if args.mocap_rate is not None:
        changes["rate_hz"] = args.mocap_rate
    for flag, field, quantity in (
        ("mocap_orientation_noise", "orientation_noise_rad", "angle"),
        ("mocap_position_noise", "position_noise_m", "length"),
        ("mocap_jitter", "jitter_s", "time"),
    ):
        text = getattr(args, flag)
        if text is not None:
            changes[field] = float(to_si(text, quantity, "--" + flag.replace("_", "-"))[0])
    return replace(cfg, **changes)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        mocap = _mocap(args)
        duration = args.duration
        if duration is None and args.trajectory == "procedural":
            duration = 60.0
        seq = make_sequence(
            args.out,
            args.trajectory,
            args.effects,
            args.preset,
            duration,
            args.seed,
            args.name,
            args.imu_rate,
            args.bandwidth,
            args.oversample,
            args.imu_jitter,
            mocap,
            args.euroc_root,
            args.smoothing,
            args.overwrite,
        )
    except (EffectSpecError, UnitError, ValueError, FileNotFoundError, FileExistsError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    t = seq.truth
    span = np.diff(t["imu_span_ns"])[0] * 1e-9
    print(f"{seq.path}: {span:.1f} s, hidden effects: {', '.join(t['hidden_effects']) or 'none (null case)'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
