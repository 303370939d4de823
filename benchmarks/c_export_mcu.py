"""The plain C export on microcontroller toolchains: flash, RAM and stack on Cortex-M4F and Cortex-M7, and the numbers
it computes on 32-bit ARM (under QEMU) against the Python streaming corrector, on real EuRoC samples.

    python benchmarks/c_export_mcu.py [--samples N]

Exports one network (the first member of the shipped `euroc`), the 8-network `euroc` ensemble and the calibrated
`euroc-calibrated`, and for each:

- sizes: cross-compiles gyrodenoise_model.c with arm-none-eabi-gcc for each Cortex-M target (`gyrodenoise.c_targets`:
  -std=c99 -Wall -Wextra -pedantic -Werror -Wdouble-promotion -Wconversion) at -Os and -O2, and reads with
  arm-none-eabi-size its code (.text) and weights (.rodata); sizeof(gd_state) on the target; the stack of each of its
  functions (-fstack-usage); the soft-float double routines it calls (none expected); and the sections of a minimal
  linked firmware (start-up code, the model, newlib-nano's libm; one gd_step_t call; -Os, --gc-sections).
- numbers: builds example_main.c for each target (Cortex-M: bare metal, run by qemu-system-arm on the MPS2 boards
  AN386 (M4) and AN500 (M7) with semihosting stdio; armhf: static, run by qemu-arm) and feeds it EuRoC MH_02_easy's
  IMU samples with their stamps (the stamped step gd_step_t); compares with StreamingCorrector.push(x, t_ns) and with
  the batch model. One build with -ffp-contract=fast on the Cortex-M4F (fused multiply-adds, as GNU C modes give).
- instructions: each gd_step_t call's instructions on each Cortex-M build, counted by QEMU -icount (`c_targets.
  instructions_per_step`); a Cortex-M4's cycles are at least as many.

QEMU's speed is not the microcontroller's: no time is measured under it. The MCUs are a datasheet table (flash, the
largest contiguous SRAM region): which of them each model fits, and the instructions of a step at one per cycle at
their clock. Writes benchmarks/results/c_export_mcu.json and .md (--markdown-only: the .md again from the .json).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from c_export_mcu_report import markdown  # beside this script

from gyrodenoise import c_export, c_targets
from gyrodenoise.atomic import write_text
from gyrodenoise.models.ensemble import predict_with_spread
from gyrodenoise.paths import portable_command
from gyrodenoise.pretrained import load_model, model_rate
from gyrodenoise.streaming import StreamingCorrector

HERE = Path(__file__).resolve().parent
DATA = Path(os.environ.get("GYRODENOISE_DATA", HERE.parents[1] / "shared" / "data"))
SEQUENCE = ("euroc", "MH_02_easy", "mav0", "imu0", "data.csv")
SIZE_TARGETS = ("cortex-m4f", "cortex-m7")
OPTS = ("-Os", "-O2")
FMA = ("-ffp-contract=fast",)  # fused multiply-adds, as gcc's GNU C modes give
N_COUNTED = 500  # steps whose instructions are counted (a step's count hardly depends on the sample)
PACKAGES = ("gcc-arm-none-eabi", "libnewlib-arm-none-eabi", "qemu-system-arm", "gcc-arm-linux-gnueabihf", "qemu-user")

# Datasheet figures (KiB, MHz), not measured: flash, the largest contiguous SRAM region (gd_state is one struct: it
# must fit one region) and the SRAM in all.
MCUS = (
    ("STM32F411xE", "cortex-m4f", 100, 512, 128, 128, "one SRAM"),
    ("STM32F405/407xG", "cortex-m4f", 168, 1024, 128, 192, "SRAM1+SRAM2 128; CCM 64 apart (CPU only)"),
    ("STM32F722xE", "cortex-m7", 216, 512, 256, 256, "DTCM 64 + SRAM1 176 + SRAM2 16, contiguous"),
    ("STM32F745xG", "cortex-m7", 216, 1024, 320, 320, "DTCM 64 + SRAM1 240 + SRAM2 16, contiguous"),
    ("STM32F765xI", "cortex-m7", 216, 2048, 512, 512, "DTCM 128 + SRAM1 368 + SRAM2 16, contiguous"),
    ("STM32H743xI", "cortex-m7", 480, 2048, 512, 1024, "AXI SRAM 512; SRAM1-3 288, DTCM 128, SRAM4 64 apart"),
    ("STM32H750xB", "cortex-m7", 480, 128, 512, 1024, "as H743; 128 KiB of internal flash"),
)


def load_stream(n: int | None) -> tuple[np.ndarray, np.ndarray, str]:
    from gyrodenoise.data.readers import read_imu

    path = DATA.joinpath(*SEQUENCE)
    if not path.is_file():
        sys.exit(f"error: {path} not found: set GYRODENOISE_DATA to the folder holding euroc/ (ASL format)")
    d = read_imu(path)
    imu = np.concatenate([d.gyro, d.acc], axis=1)[:n]
    return imu, d.t_ns[:n], str(path.relative_to(DATA))


def sizes(c_dir: Path, work: Path) -> dict:
    """Per Cortex-M target: the model object's sections at each -O, the state, the stack, the linked firmware."""
    out = {}
    for name in SIZE_TARGETS:
        target = c_targets.TARGETS[name]
        objs = {
            opt: c_targets.compile_object(c_dir / c_export.SOURCE, target, work / f"{name}{opt}.o", opt) for opt in OPTS
        }
        stack = c_targets.stack_usage(c_dir, target, work)
        out[name] = {
            "model_object": {opt: c_targets.section_sizes(obj, target) for opt, obj in objs.items()},
            "double_symbols": sorted({s for obj in objs.values() for s in c_targets.double_symbols(obj, target)}),
            "sizeof_gd_state": c_targets.state_size(c_dir, target, work),
            "stack_bytes": {"gd_step_t": stack.get("gd_step_t"), "all_functions_sum": sum(stack.values())},
            "stack_by_function": stack,
            "firmware_Os": c_targets.firmware_sizes(c_dir, target, work),
        }
    return out


def instructions(c_dir: Path, work: Path, imu: np.ndarray, t: np.ndarray) -> dict:
    """Instructions per gd_step_t on each Cortex-M target under QEMU -icount, -O2 with and without fused multiply-adds:
    mean, min, max over the samples."""
    out = {}
    for name in SIZE_TARGETS:
        for extra in ((), FMA):
            n = c_targets.instructions_per_step(c_dir, c_targets.TARGETS[name], work, imu, t, "-O2", extra)
            label = " ".join([name, "-O2", *extra])
            out[label] = {"mean": float(n.mean()), "min": float(n.min()), "max": float(n.max()), "steps": len(n)}
    return out


def numbers(model, c_dir: Path, work: Path, imu: np.ndarray, t: np.ndarray, rate: float, fma: bool) -> dict:
    """Max |C on each ARM target - Python| over the gyro (and the std), stamped samples."""
    sc = StreamingCorrector(model, rate_hz=rate)
    ref = [sc.push_with_spread(x, t_ns=int(s)) for x, s in zip(imu.astype(np.float32), t, strict=True)]
    gyro_ref = np.stack([r[0] for r in ref])
    std_ref = None if ref[0][1] is None else np.stack([r[1] for r in ref])
    batch, _ = predict_with_spread(model, imu.astype(np.float32))
    builds = [(name, ()) for name in c_targets.TARGETS] + ([("cortex-m4f", FMA)] if fma else [])
    out, plain = {}, {}
    for name, extra in builds:
        target = c_targets.TARGETS[name]
        exe = c_targets.build_example(c_dir, target, work / f"ex-{name}", work, "-O2", extra)
        gyro, std = c_targets.run_example_on(target, exe, imu, t, timeout=3600)
        label = name + ("".join(f" {e}" for e in extra))
        if extra:  # the same target without them: the build did change the numbers (fused rounding)
            out[label] = {"gyro_vs_plain_build": float(np.abs(gyro - plain[name]).max())}
        plain.setdefault(name, gyro)
        out[label] = out.get(label, {}) | {
            "gyro_vs_streaming": float(np.abs(gyro - gyro_ref).max()),
            "gyro_vs_batch": float(np.abs(gyro - batch).max()),
            "std_vs_streaming": None
            if std_ref is None
            else float(np.abs((0.0 if std is None else std) - std_ref).max()),
            "build": " ".join([target.cc, *target.flags, "-O2", *c_targets.STRICT, *extra]),
        }
        print(f"  {label}: {json.dumps(out[label])}", flush=True)
    return out


def environment() -> dict:
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.processor())  # fmt: skip
    tools = {}
    for target in c_targets.TARGETS.values():
        tools |= c_targets.tool_versions(target)
    pkgs = {}
    if shutil.which("dpkg-query"):
        for p in PACKAGES:
            done = subprocess.run(["dpkg-query", "-W", "-f=${Version}", p], capture_output=True, text=True)
            pkgs[p] = done.stdout.strip() or "not installed"
    return {"cpu": cpu, "cpu_threads": str(os.cpu_count()), "host": platform.node(), "os": platform.platform(),
            "tools": tools, "packages": pkgs}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=None, help="the first N samples of MH_02_easy (default: all)")
    ap.add_argument("--out", default=str(HERE / "results" / "c_export_mcu"))
    ap.add_argument("--markdown-only", action="store_true", help="rewrite OUT.md from OUT.json")
    args = ap.parse_args()
    out = Path(args.out)
    if args.markdown_only:
        write_text(out.with_suffix(".md"), markdown(json.loads(out.with_suffix(".json").read_text())))
        return
    if lacking := sorted({m for t in c_targets.TARGETS.values() for m in c_targets.missing(t)}):
        sys.exit("error: not installed: " + "; ".join(lacking))

    start = time.time()
    imu, t, source = load_stream(args.samples)
    ens, meta = load_model("euroc")
    cal, cal_meta = load_model("euroc-calibrated")
    cases = {
        "one network (euroc member 0)": (ens.members[0], {**meta, "name": "euroc member 0"}, True),
        "euroc (8 networks)": (ens, meta, False),
        "euroc-calibrated": (cal, cal_meta, False),
    }
    results = {}
    for name, (model, m_meta, fma) in cases.items():
        print(name, flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            c_dir = work / "c"
            c_export.export_c(model, c_dir, m_meta)
            sc = StreamingCorrector(model)
            results[name] = {
                "members": len(getattr(model, "members", [model])),
                "multiply_adds_per_sample": int(
                    sum(sum(ly.weight.size for ly in m.layers) + m.head_w.size + 9 for m in (sc.members or [sc]))
                ),
                "sizes": sizes(c_dir, work),
                "instructions_per_step": instructions(c_dir, work, imu[:N_COUNTED], t[:N_COUNTED]),
                "max_abs_diff_rad_s": numbers(model, c_dir, work, imu, t, model_rate(m_meta), fma),
            }
    report = {
        "command": "python " + portable_command(sys.argv),
        "machine": environment(),
        "input": f"{source}: {len(imu)} samples with their stamps ({(t[-1] - t[0]) * 1e-9:.0f} s)",
        "rate_hz": model_rate(meta),
        "strict_flags": " ".join(c_targets.STRICT),
        "targets": {
            n: {"flags": " ".join(tg.flags), "qemu": " ".join(tg.qemu), "about": tg.about}
            for n, tg in c_targets.TARGETS.items()
        },  # fmt: skip
        "models": results,
        "mcus_datasheet": [
            dict(zip(("mcu", "core", "mhz", "flash_kib", "largest_sram_kib", "sram_kib", "note"), m, strict=True))
            for m in MCUS
        ],  # fmt: skip
        "wall_s": round(time.time() - start),
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    write_text(out.with_suffix(".json"), json.dumps(report, indent=2) + "\n")
    write_text(out.with_suffix(".md"), markdown(report))
    print(f"wrote {out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
