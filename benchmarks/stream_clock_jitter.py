"""How many samples the stream clock refuses on imperfect stamps: a stream a few % off the model's rate, with uniform
jitter, single missing samples, a stream much slower than the model's (restarts expected), or a driver whose every
other stamp is late. Python's `StreamClock` (the C export's
`gd_step_t` decides alike: tests/test_c_export_stamps.py). No model is run: the clock alone decides.

    python benchmarks/stream_clock_jitter.py [--out benchmarks/results/stream_clock_jitter.md]

A refused-as-early sample is dropped by the deployment loop of docs/deployment.md; a gap restarts the stream.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import warnings
from pathlib import Path

import numpy as np

from gyrodenoise.atomic import write_text
from gyrodenoise.stream_clock import StreamClock, StreamTimeError

PERIOD_NS = 5_000_000  # 200 Hz, the model's rate
N = 20_000


def decisions(stamps: np.ndarray) -> np.ndarray:
    """docs/deployment.md's loop on one stamp at a time: each stamp's kind ('ok', 'early', 'gap', ...)."""
    clock, kinds = StreamClock(1e9 / PERIOD_NS), []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the rate warning of the faster streams: not what is counted here
        for t in stamps.tolist():
            try:
                clock.commit(clock.check(t, 1))
                kinds.append("ok")
            except StreamTimeError as e:
                kinds.append(e.kind)
                if e.kind in ("gap", "clock"):
                    clock.reset()
                    clock.commit(clock.check(t, 1))
    return np.array(kinds)


def jittered(fast: float, jitter_ns: float, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (np.arange(N) * PERIOD_NS / (1 + fast) + rng.uniform(-jitter_ns, jitter_ns, N)).astype(np.int64)


def with_single_drops(stamps: np.ndarray, fraction: float, seed: int = 2) -> np.ndarray:
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(np.arange(1, len(stamps) - 1), int(fraction * len(stamps)), replace=False))
    idx = idx[np.concatenate([[True], np.diff(idx) > 1])]  # single samples: two in a row are a gap by design
    return np.delete(stamps, idx)


def rows() -> list[tuple[str, np.ndarray]]:
    out = []
    for fast in (0.0, 0.01, 0.03, 0.04, 0.05):
        for jitter in (0.5e6, 1.0e6, 1.5e6):
            out.append((f"{fast:.0%} fast, jitter ±{jitter / 1e6:g} ms", jittered(fast, jitter)))
    out.append(("3% fast, jitter ±1 ms, 5% single samples missing", with_single_drops(jittered(0.03, 1.0e6, 2), 0.05)))
    for slow in (0.05, 0.1, 0.2, 0.3, 0.5):  # slower streams: restarted as gaps from ~15 % slow (50 %: 100 Hz)
        out.append((f"{slow:.0%} slow, no jitter", (np.arange(N) * PERIOD_NS / (1 - slow)).astype(np.int64)))
    for late in (2.4e6, 2.6e6, 3.0e6, 4.0e6):
        t = np.arange(2000) * PERIOD_NS + np.where(np.arange(2000) % 2, int(late), 0)
        out.append((f"every other stamp {late / 1e6:g} ms late", t.astype(np.int64)))
    t = np.delete(np.arange(100) * PERIOD_NS, [50, 53])
    out.append(("two single samples missing, 3 apart", t.astype(np.int64)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/stream_clock_jitter.md"))
    args = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    lines = [
        "# Stream clock: samples refused on imperfect stamps",
        "",
        f"`python benchmarks/stream_clock_jitter.py` at commit {commit or '?'} ({platform.machine()}, "
        f"{platform.python_version()}); 200 Hz model, {N} stamps per jittered row.",
        "",
        "| stamps | refused as early [%] | restarts (gaps) |",
        "|---|---|---|",
    ]
    for name, stamps in rows():
        k = decisions(stamps)
        lines.append(f"| {name} | {100 * np.mean(k == 'early'):.2f} | {int(np.sum(k == 'gap'))} |")
        print(lines[-1], flush=True)
    write_text(args.out, "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
