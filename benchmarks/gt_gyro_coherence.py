"""Does a dataset's ground truth follow its own gyro? (`gyrodenoise.discrepancy.truth_check`, every sequence)

The discrepancy workflow compares the gyro with the rate of the ground truth; that comparison only
shows the gyro's errors where the ground truth is independent of the gyro. A motion tracker (Vicon,
OptiTrack) is; a batch estimate that fuses the same IMU (EuRoC's `state_groundtruth_estimate0`)
is not, at the frequencies where the IMU dominates the estimate. Per sequence and band this script
reports the coherence of the truth's rate with the gyro and the residual's PSD over the sensor's
datasheet white noise (the dataset config's `sensor.gyro_noise_density`): an independent truth leaves
at least the gyro's noise in the residual; a ratio below 0.5 says the truth follows the gyro (the
module's docstring has the method). The discrepancy CLI runs the same check with
`--gyro-noise-density`. Writes <out>/gt_gyro_coherence.{json,md}.

    python benchmarks/gt_gyro_coherence.py [--euroc ../shared/data/euroc] [--tumvi ../shared/data/tumvi]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

from gyrodenoise import atomic
from gyrodenoise.config import compose_config
from gyrodenoise.discrepancy.truth_check import BANDS_HZ, FOLLOWS_RATIO, check_sequence
from gyrodenoise.paths import portable_command

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"


def noise_density(dataset: str) -> float:
    """The gyro's datasheet white-noise density (rad/s/sqrt(Hz)) of the dataset's config."""
    return float(compose_config("train", [f"dataset={dataset}"]).dataset.sensor.gyro_noise_density)


def _sequences(root: Path | None) -> list[Path]:
    if root is None or not root.is_dir():
        return []
    return sorted(p.parent for p in root.glob("*/mav0/imu0"))


def _cell(b: dict | None) -> str:
    if b is None:
        return "-"
    coh = "/".join(f"{x:.2f}" for x in b["coherence"])
    ratio = "/".join(f"{x:.2g}" for x in b["residual_over_noise"])
    return f"{coh}; {ratio}{' *' if b['follows_gyro'] else ''}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--euroc", type=Path, default=ROOT / ".." / "shared" / "data" / "euroc")
    p.add_argument("--tumvi", type=Path, default=ROOT / ".." / "shared" / "data" / "tumvi")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args()
    t0 = time.time()
    rows = {}
    for name, root in (("euroc", args.euroc), ("tumvi", args.tumvi)):
        sigma = noise_density(name)
        for mav0 in _sequences(root):
            c = check_sequence(mav0, noise_density=sigma)
            rows[f"{name}/{mav0.parent.name}"] = {**c, "ground_truth": os.path.relpath(c["ground_truth"], ROOT)}
            print(mav0.parent.name, flush=True)
    if not rows:
        sys.exit(f"no sequences under {args.euroc} or {args.tumvi}: give --euroc / --tumvi")
    result = {
        "command": "python " + portable_command(sys.argv),
        "machine": f"{platform.node()} ({platform.machine()}, {os.cpu_count()} CPU threads)",
        "wall_time_s": time.time() - t0,
        "sequences": rows,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(args.out / "gt_gyro_coherence.json", json.dumps(result, indent=2) + "\n")
    heads = [f"{lo:g}-{hi:g} Hz" for lo, hi in BANDS_HZ]
    lines = [
        "# Does the ground truth follow the gyro?",
        "",
        f"`{result['command']}` ({result['machine']}, {result['wall_time_s']:.0f} s). Method: "
        "`gyrodenoise.discrepancy.truth_check`.",
        "",
        "Per band: coherence of the ground truth's rate with the gyro (power-weighted over the band, x/y/z); the "
        "median PSD of the residual gyro - truth over the datasheet white noise 2 sigma^2 (x/y/z; sigma from the "
        f"dataset config: {noise_density('euroc'):g} rad/s/sqrt(Hz) for EuRoC's ADIS16448, "
        f"{noise_density('tumvi'):g} for TUM-VI's BMI160). An independent truth leaves at least the gyro's noise "
        f"in the residual (ratio >= ~1); * marks a band where an axis is below {FOLLOWS_RATIO:g}: the truth "
        "follows the gyro there. Bands above 90% of the truth's Nyquist frequency are left out.",
        "",
        "| sequence | truth rate | " + " | ".join(heads) + " |",
        "|---|---|" + "---|" * len(heads),
    ]
    for seq, r in rows.items():
        cells = {b["band_hz"][0]: b for b in r["bands"]}
        lines.append(
            f"| {seq} | {r['truth_rate_hz']:.0f} Hz | " + " | ".join(_cell(cells.get(lo)) for lo, _ in BANDS_HZ) + " |"
        )
    lines += [
        "",
        "Reading: EuRoC's ground truth is a batch estimate that fuses this IMU (../shared/data/README.md). In the "
        "Machine Hall, where the tracker measures position only, the residual keeps at most a few tenths of the "
        "gyro's own noise on some axis in every band (x: 0.2-25%): the gyro's noise is in the truth. In the Vicon "
        "rooms it depends on the flight: V1_02 and V2_03 keep the datasheet noise or more on every axis and band, "
        "V2_01 loses it on x below 5 Hz, V1_01 and V1_03 on x below 40 Hz, V2_02 on some axis in every band. "
        "TUM-VI's mocap leaves its own noise, orders of magnitude above the gyro's. The discrepancy workflow's "
        "noise levels are meaningful only on sequences and bands without a * (`python -m gyrodenoise.discrepancy "
        "... --gyro-noise-density SIGMA` marks them in its report).",
    ]
    atomic.write_text(args.out / "gt_gyro_coherence.md", "\n".join(lines) + "\n")
    print((args.out / "gt_gyro_coherence.md").read_text())


if __name__ == "__main__":
    main()
