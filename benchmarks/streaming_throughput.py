"""Throughput of the streaming corrector on ONE CPU core, in IMU samples per second.

    python benchmarks/streaming_throughput.py [--models euroc tumvi-denoiser tumvi] [--seconds 3]

Pins the process to one core and one thread (torch, BLAS), feeds a real EuRoC IMU stream when the
shared data is there (else synthetic samples: the cost does not depend on the values), and times:
sample-by-sample push (numpy and torch backends), chunked push, and the batch model for reference.
Writes benchmarks/results/streaming_throughput.json and .md.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy loads BLAS
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gyrodenoise.atomic import write_text  # noqa: E402
from gyrodenoise.models.build import build_model  # noqa: E402
from gyrodenoise.models.denoiser import count_parameters, predict_gyro  # noqa: E402
from gyrodenoise.paths import portable_command  # noqa: E402
from gyrodenoise.pretrained import load_model  # noqa: E402
from gyrodenoise.streaming import StreamingCorrector  # noqa: E402

HERE = Path(__file__).resolve().parent
DATA = Path(os.environ.get("GYRODENOISE_DATA", HERE.parents[1] / "shared" / "data"))


def load_stream(n: int) -> tuple[np.ndarray, str]:
    f = DATA / "euroc" / "V1_01_easy" / "mav0" / "imu0" / "data.csv"
    if f.is_file():
        from gyrodenoise.data.readers import read_imu

        d = read_imu(f)
        imu = np.concatenate([d.gyro, d.acc], axis=1)
        return np.resize(imu, (n, 6)), str(f.relative_to(DATA))
    rng = np.random.default_rng(0)
    return rng.normal(size=(n, 6)) + [0, 0, 0, 0, 0, 9.81], "synthetic"


def rate(fn, n_samples: int, min_seconds: float) -> float:
    """Samples per second, best of repeated runs lasting at least min_seconds in total."""
    best, spent = 0.0, 0.0
    while spent < min_seconds or best == 0.0:
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        spent += dt
        best = max(best, n_samples / dt)
    return best


def latency_us(sc: StreamingCorrector, stream: np.ndarray) -> dict[str, float]:
    """Per-sample `push` latency (microseconds): median, 99th percentile and max over the stream."""
    times = np.empty(len(stream))
    for k, sample in enumerate(stream):
        t0 = time.perf_counter()
        sc.push(sample)
        times[k] = time.perf_counter() - t0
    q50, q99 = np.percentile(times, [50, 99]) * 1e6
    return {"median": round(float(q50), 1), "p99": round(float(q99), 1), "max": round(float(times.max()) * 1e6, 1)}


def onnx_stateful_rates(model, imu: np.ndarray, n: int, seconds: float) -> dict[str, float]:
    """The stateful ONNX export (`export --stateful`) in onnxruntime, one thread: one sample per call and chunks,
    the state passed back each call. Empty without the [export] extra or for a model that keeps no state."""
    try:
        import onnxruntime as ort

        from gyrodenoise.export import export_onnx
        from gyrodenoise.stateful_graph import StatefulCorrection
    except ImportError:
        return {}
    size = StatefulCorrection(model).state_size
    if size == 0:
        return {}
    with tempfile.TemporaryDirectory() as tmp:
        path = export_onnx(model, Path(tmp) / "step.onnx", stateful=True)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = opts.inter_op_num_threads = 1
        sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    x = imu.astype(np.float32)[None]
    out: dict[str, float] = {}
    for chunk, total in ((1, n), (10, 20000), (200, 20000)):

        def stream(chunk=chunk, total=total):
            state, first = np.zeros((1, size), np.float32), True
            for start in range(0, total, chunk):
                feed = {"imu": x[:, start : start + chunk], "state": state, "reset": np.array([first])}
                state = sess.run(None, feed)[-1]
                first = False

        out["onnx_stateful" + (f"_chunk{chunk}" if chunk > 1 else "")] = rate(stream, total, seconds)
    return out


def measure(model, imu: np.ndarray, seconds: float) -> dict:
    """Samples per second of each path, per-sample latency, and the streaming-batch parity, for one model."""
    n = 4000
    results: dict[str, float] = {}
    for backend in ("numpy", "torch"):
        sc = StreamingCorrector(model, backend=backend)
        sc.push_chunk(imu[:1])
        stream = imu[1 : n + 1]

        def per_sample(sc=sc, stream=stream):
            for s in stream:
                sc.push(s)

        results[f"push_{backend}"] = rate(per_sample, n, seconds)
        for chunk in (10, 200):
            blocks = np.array_split(imu[:20000], 20000 // chunk)

            def chunked(sc=sc, blocks=blocks):
                for b in blocks:
                    sc.push_chunk(b)

            results[f"push_chunk{chunk}_{backend}"] = rate(chunked, 20000, seconds)
    results.update(onnx_stateful_rates(model, imu, n, seconds))
    results["batch_predict_gyro_20000"] = rate(lambda: predict_gyro(model, imu[:20000]), 20000, seconds)
    sc = StreamingCorrector(model)
    sc.push_chunk(imu[:600])  # past the start-up
    lat = latency_us(sc, imu[600 : 600 + n])
    sc = StreamingCorrector(model)  # parity once more on what was timed
    ref = predict_gyro(model, imu[:3000]).numpy()
    err = float(np.abs(np.stack([sc.push(s) for s in imu[:3000]]) - ref).max())
    best = max((k for k in results if k.startswith("push_") and "chunk" not in k), key=results.get)
    return {
        "parameters": count_parameters(model),
        "members": len(model.members) if hasattr(model, "members") else 1,
        "receptive_field": int(getattr(model, "receptive_field", 1)),
        "samples_per_second": {k: round(v) for k, v in results.items()},
        "push_numpy_latency_us": lat,
        "best_per_sample": {"path": best, "samples_per_second": round(results[best])},
        "realtime_factor_at_200Hz": round(results[best] / 200.0, 1),
        "parity_max_abs_err_rad_s": err,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--models", nargs="+", default=["euroc", "tumvi-denoiser", "tumvi"],
        help="shipped names or paths (default: the 8-network euroc ensemble, one network, the calibrated model); "
        "'random' = the default denoiser architecture with random weights",
    )  # fmt: skip
    ap.add_argument("--seconds", type=float, default=3.0, help="minimum timing per case")
    ap.add_argument("--out", default=str(HERE / "results" / "streaming_throughput"))
    args = ap.parse_args()

    load_at_start = round(os.getloadavg()[0], 2)  # other processes share the machine: note how busy
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    torch.set_num_threads(1)
    imu, source = load_stream(20000)
    per_model = {}
    for name in args.models:
        if name == "random":  # same architecture as a shipped network, so the same cost
            model = build_model("denoiser").eval()
            torch.nn.init.normal_(model.net[-1].weight, std=0.1)  # a non-zero correction for the parity check
            name = "random (default denoiser architecture, random weights)"
        else:
            model = load_model(name)[0]
        per_model[name] = measure(model, imu, args.seconds)
        print(name, json.dumps(per_model[name]), flush=True)
    report = {
        "command": "python " + portable_command(sys.argv),
        "machine": f"{platform.node()} ({platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPU threads visible, pinned to 1 core, 1 thread)",
        "load_average_1min_at_start": load_at_start,
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "input": source,
        "models": per_model,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text(out.with_suffix(".json"), json.dumps(report, indent=2) + "\n")
    write_text(out.with_suffix(".md"), markdown(report))


def markdown(r: dict) -> str:
    models = r["models"]
    head = "| path | " + " | ".join(f"`{m}`" for m in models) + " |\n|---|" + "---:|" * len(models)
    paths = list(dict.fromkeys(k for m in models.values() for k in m["samples_per_second"]))
    rows = "\n".join(
        f"| `{k}` | " + " | ".join(f"{m['samples_per_second'][k]:,}" if k in m["samples_per_second"] else "-"
                                   for m in models.values()) + " |"
        for k in paths
    )  # fmt: skip
    facts = "\n".join(
        f"- `{name}`: {m['members']} network(s), {m['parameters']:,} parameters, receptive field "
        f"{m['receptive_field']} samples; `push` (numpy) per sample: median {m['push_numpy_latency_us']['median']} us, "
        f"p99 {m['push_numpy_latency_us']['p99']} us, max {m['push_numpy_latency_us']['max']} us; best per-sample path "
        f"{m['best_per_sample']['samples_per_second']:,} samples/s = {m['realtime_factor_at_200Hz']}x real time at "
        f"200 Hz; max |streaming - batch| on 3,000 samples {m['parity_max_abs_err_rad_s']:.2e} rad/s"
        for name, m in models.items()
    )
    return f"""# Streaming corrector throughput (one CPU core)

Command: `{r["command"]}`
Machine: {r["machine"]}; 1-min load average at start {r["load_average_1min_at_start"]}.
Python {r["python"]}, torch {r["torch"]}, numpy {r["numpy"]}; {r["date"]}.
Input: {r["input"]}.

Samples per second:

{head}
{rows}

{facts}

`push_*`: one sample per call (what an onboard loop does); `push_chunkN_*`: N samples per call;
`onnx_stateful*`: the stateful ONNX export (`python -m gyrodenoise.export MODEL --onnx F --stateful`) in onnxruntime
with one thread, the state passed back at each call (`-`: a model without state, or no onnxruntime);
`batch_predict_gyro_20000`: the batch model on 20,000 samples at once, for reference. An ensemble of K networks
costs about K times one network.
"""


if __name__ == "__main__":
    main()
