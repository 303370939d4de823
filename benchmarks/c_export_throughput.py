"""Time per sample of the plain C export's step (`python -m gyrodenoise.export MODEL --c DIR`), on ONE CPU core.

    python benchmarks/c_export_throughput.py [--passes 5]

Exports one network (the first member of the shipped `euroc`) and the whole 8-network `euroc` ensemble, compiles each
with `cc -O2 -std=c99` (no -march, no -ffast-math: what the export's header says to run) and a timing driver, and
times every `gd_step` call with clock_gettime over 4,000 EuRoC samples (MH_02_easy; synthetic when the shared data is
absent: the cost does not depend on the values), repeated `--passes` times after one warm-up pass. For comparison, the
Python `StreamingCorrector.push` (numpy) on the same samples, and the agreement of both over the first 2,000.
Writes benchmarks/results/c_export_throughput.json and .md.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy loads BLAS
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gyrodenoise import c_export  # noqa: E402
from gyrodenoise.atomic import write_text  # noqa: E402
from gyrodenoise.paths import portable_command  # noqa: E402
from gyrodenoise.pretrained import load_model  # noqa: E402
from gyrodenoise.streaming import StreamingCorrector  # noqa: E402

HERE = Path(__file__).resolve().parent
DATA = Path(os.environ.get("GYRODENOISE_DATA", HERE.parents[1] / "shared" / "data"))
N_SAMPLES = 4000

# reads `passes` then N lines of 6 floats; steps through them `passes + 1` times (the first: warm-up, not timed),
# resetting before each pass, and prints every timed step's duration in ns
DRIVER = r"""
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "gyrodenoise_model.h"
static gd_state st;
int main(void)
{
    int passes, n = 0, cap = 1 << 16;
    float (*x)[6] = malloc(sizeof *x * cap), w[3], sd[3];
    if (!x || scanf("%d", &passes) != 1) return 1;
    while (n < cap && scanf("%g,%g,%g,%g,%g,%g", &x[n][0], &x[n][1], &x[n][2], &x[n][3], &x[n][4], &x[n][5]) == 6) n++;
    for (int p = 0; p <= passes; p++) {
        gd_reset(&st);
        for (int i = 0; i < n; i++) {
            struct timespec a, b;
            clock_gettime(CLOCK_MONOTONIC, &a);
            if (gd_step(&st, x[i], w, sd) != 0) return 2;
            clock_gettime(CLOCK_MONOTONIC, &b);
            if (p > 0) printf("%ld\n", (long)((b.tv_sec - a.tv_sec) * 1000000000L + (b.tv_nsec - a.tv_nsec)));
        }
    }
    free(x);
    return 0;
}
"""


def load_stream(n: int) -> tuple[np.ndarray, str]:
    f = DATA / "euroc" / "MH_02_easy" / "mav0" / "imu0" / "data.csv"
    if f.is_file():
        from gyrodenoise.data.readers import read_imu

        d = read_imu(f)
        return np.concatenate([d.gyro, d.acc], axis=1)[:n], str(f.relative_to(DATA))
    rng = np.random.default_rng(0)
    return rng.normal(size=(n, 6)) * 0.3 + [0, 0, 0, 9.81, 0, 0], "synthetic"


FLAGS = {"-O2": ["-O2"], "-O3 -march=native": ["-O3", "-march=native"]}  # the first: the export's documented build


def compile_driver(src_dir: Path, exe: Path, flags: list[str]) -> None:
    (src_dir / "bench_main.c").write_text(DRIVER)
    cmd = ["cc", *flags, "-std=c99", "-D_POSIX_C_SOURCE=199309L", "-o", str(exe)]
    subprocess.run([*cmd, str(src_dir / "bench_main.c"), str(src_dir / c_export.SOURCE), "-lm"], check=True)


def step_times_us(exe: Path, imu: np.ndarray, passes: int) -> np.ndarray:
    text = f"{passes}\n" + "".join(",".join(f"{v:.9g}" for v in row) + "\n" for row in imu.astype(np.float32).tolist())
    done = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
    return np.array(done.stdout.split(), dtype=np.float64) / 1e3


def python_push_us(model, imu: np.ndarray) -> np.ndarray:
    sc = StreamingCorrector(model)
    times = np.empty(len(imu))
    for k, sample in enumerate(imu):
        t0 = time.perf_counter()
        sc.push(sample)
        times[k] = time.perf_counter() - t0
    return times * 1e6


def summary(us: np.ndarray) -> dict[str, float]:
    q50, q99 = np.percentile(us, [50, 99])
    return {"median": round(float(q50), 2), "mean": round(float(us.mean()), 2), "p99": round(float(q99), 2),
            "max": round(float(us.max()), 1)}  # fmt: skip


def measure(model, meta: dict, imu: np.ndarray, passes: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp)
        c_export.export_c(model, src, meta)
        c_us = {}
        for label, flags in FLAGS.items():
            compile_driver(src, src / "bench", flags)
            c_us[label] = step_times_us(src / "bench", imu, passes)
        gyro, std = c_export.run_example(c_export.compile_example(src, src / "example"), imu[:2000])
    ref, ref_std = c_export.stream_reference(model, imu[:2000])
    err = float(np.abs(gyro - ref).max())
    if std is not None:
        err = max(err, float(np.abs(std - ref_std).max()))
    sc = StreamingCorrector(model)
    macs = sum(sum(ly.weight.size for ly in m.layers) for m in (sc.members or [sc]))
    return {
        "members": len(getattr(model, "members", [model])),
        "conv_multiply_adds_per_sample": int(macs),
        "c_step_us": {label: summary(us) for label, us in c_us.items()},
        "python_push_numpy_us": summary(python_push_us(model, imu)),
        "c_vs_streaming_max_abs_rad_s_2000_samples": err,
        "timed_steps": int(len(c_us["-O2"])),
    }


def machine() -> dict[str, str]:
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.processor())  # fmt: skip
    cc = subprocess.run(["cc", "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    return {"cpu": cpu, "cpu_threads": str(os.cpu_count()), "compiler": cc, "host": platform.node()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passes", type=int, default=5, help="timed passes over the samples (after one warm-up)")
    ap.add_argument("--out", default=str(HERE / "results" / "c_export_throughput"))
    args = ap.parse_args()

    load_at_start = round(os.getloadavg()[0], 2)  # other processes share the machine: note how busy
    if hasattr(os, "sched_setaffinity"):  # one core, inherited by the compiled drivers
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    torch.set_num_threads(1)
    imu, source = load_stream(N_SAMPLES)
    ens, meta = load_model("euroc")
    cases = {
        "one network (euroc member 0)": (ens.members[0], {**meta, "name": "euroc member 0"}),
        "euroc (8 networks)": (ens, meta),
    }
    results = {}
    for name, (model, m_meta) in cases.items():
        results[name] = measure(model, m_meta, imu, args.passes)
        print(name, json.dumps(results[name]), flush=True)
    report = {
        "command": "python " + portable_command(sys.argv),
        "machine": machine(),
        "pinned": "1 core (sched_setaffinity), 1 thread",
        "compile": "cc -std=c99 with " + " or ".join(FLAGS) + " (driver: -D_POSIX_C_SOURCE=199309L for clock_gettime)",
        "load_average_1min_at_start": load_at_start,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "input": f"{source}, first {len(imu)} samples",
        "models": results,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    out = Path(args.out)
    write_text(out.with_suffix(".json"), json.dumps(report, indent=2) + "\n")
    write_text(out.with_suffix(".md"), markdown(report))


def markdown(r: dict) -> str:
    m, models = r["machine"], r["models"]
    rows = []
    for name, x in models.items():
        py = x["python_push_numpy_us"]["median"]
        for label, c in x["c_step_us"].items():
            gflops = 2 * x["conv_multiply_adds_per_sample"] / (c["median"] * 1e3)
            rows.append(
                f"| {name} | {x['conv_multiply_adds_per_sample']:,} | `{label}` | {c['median']} | {c['mean']} | "
                f"{c['p99']} | {gflops:.1f} | {py} | {py / c['median']:.1f}x |"
            )
    agree = "; ".join(
        f"{name}: {x['c_vs_streaming_max_abs_rad_s_2000_samples']:.1e} rad/s" for name, x in models.items()
    )
    return f"""# C export: time per sample of `gd_step` (one CPU core)

Command: `{r["command"]}`
Machine: {m["cpu_threads"]}-core VM ({m["host"]}), CPU "{m["cpu"]}" (/proc/cpuinfo); pinned to {r["pinned"]};
1-min load average at start {r["load_average_1min_at_start"]} (the VM is shared). Compiler: {m["compiler"]};
{r["compile"]}. Python {r["python"]}, numpy {r["numpy"]}; {r["date"]}. Input: {r["input"]}.

| model | conv multiply-adds / sample | flags | C step median [us] | mean [us] | p99 [us] | GFLOP/s | Python `push` median [us] | C speed-up |
|---|---:|---|---:|---:|---:|---:|---:|---:|
{chr(10).join(rows)}

C step: one `gd_step` call (normalisation, every layer's ring buffer and dot products, head, C_hat; for the ensemble
also the members' mean and std), timed with clock_gettime around each call over {models[next(iter(models))]["timed_steps"]:,}
steps (the passes after a warm-up one). `-O2` is the build the export documents (portable, no -ffast-math: results
equal the Python ones to float32 rounding); `-O3 -march=native` lets gcc use this CPU's SIMD units. Python `push`: the
numpy StreamingCorrector, one sample per call, same samples (the speed-up is against it). At 200 Hz a sample arrives
every 5,000 us.

Agreement, the exported `example_main.c` (`cc -O2 -std=c99`) against StreamingCorrector on the first 2,000 samples,
max |diff| over the gyro (and the ensemble's std): {agree}.
"""  # noqa: E501


if __name__ == "__main__":
    main()
