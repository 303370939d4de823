"""The Markdown of benchmarks/c_export_mcu.py's result (benchmarks/results/c_export_mcu.md) from its JSON report."""

from __future__ import annotations

TOL = 1e-5  # rad/s: the C export's parity tolerance (gyrodenoise.c_export.PARITY_TOL_RAD_S)
CORES = {"cortex-m4f": "M4F", "cortex-m7": "M7"}


def _kib(n: int) -> str:
    return f"{n / 1024:,.1f}"


def _flash(fw: dict) -> int:
    return fw["text"] + fw["rodata"] + fw["data"]


def _ram(fw: dict) -> int:
    return fw["data"] + fw["bss"]


def size_rows(models: dict) -> list[str]:
    rows = []
    for name, m in models.items():
        for target, s in m["sizes"].items():
            os_, o2 = s["model_object"]["-Os"], s["model_object"]["-O2"]
            fw = s["firmware_Os"]
            st = s["stack_bytes"]
            rows.append(
                f"| {name} | {target} | {os_['text']:,} / {o2['text']:,} | {_kib(os_['rodata'])} | "
                f"{_kib(s['sizeof_gd_state'])} ({s['sizeof_gd_state']:,} B) | "
                f"{st['gd_step_t']} ({st['all_functions_sum']}) | "
                f"{_kib(_flash(fw))} | {_kib(_ram(fw))} | {', '.join(s['double_symbols']) or 'none'} |"
            )
    return rows


def instruction_rows(models: dict) -> list[str]:
    rows = []
    for name, m in models.items():
        for label, n in m["instructions_per_step"].items():
            rows.append(
                f"| {name} | {label} | {n['mean']:,.0f} | {n['min']:,.0f} - {n['max']:,.0f} | "
                f"{n['mean'] / m['multiply_adds_per_sample']:.2f} |"
            )
    return rows


def _step_ms(m: dict, mcu: dict) -> float:
    """Milliseconds of a step at one instruction per cycle (-O2, without fused multiply-adds)."""
    return m["instructions_per_step"][f"{mcu['core']} -O2"]["mean"] / (mcu["mhz"] * 1e3)


def fit_rows(models: dict, mcus: list[dict], rate: float) -> list[str]:
    rows = []
    for mcu in mcus:
        cells = []
        for m in models.values():
            s = m["sizes"][mcu["core"]]
            flash, state = _flash(s["firmware_Os"]), s["sizeof_gd_state"]
            region = mcu["largest_sram_kib"] * 1024
            problems = []
            if flash > mcu["flash_kib"] * 1024:
                problems.append(f"flash {_kib(flash)} > {mcu['flash_kib']}")
            if state > region:
                problems.append(f"state {_kib(state)} > {mcu['largest_sram_kib']}")
            ms = _step_ms(m, mcu)
            used = 100 * flash / (mcu["flash_kib"] * 1024)
            fit = (
                "**no**: " + ", ".join(problems)
                if problems
                else f"yes: {_kib(region - state)} KiB of the region left, flash {used:.0f} % used"
            )
            cells.append(f"{fit}; step {ms:.3g} ms ({100 * ms * rate / 1e3:.0f} % of the period)")
        rows.append(
            f"| {mcu['mcu']} | {CORES[mcu['core']]} {mcu['mhz']} MHz | {mcu['flash_kib']:,} | "
            f"{mcu['largest_sram_kib']} ({mcu['sram_kib']}) | " + " | ".join(cells) + " |"
        )
    return rows


def number_rows(models: dict) -> list[str]:
    rows = []
    for name, m in models.items():
        for label, d in m["max_abs_diff_rad_s"].items():
            std = "-" if d["std_vs_streaming"] is None else f"{d['std_vs_streaming']:.1e}"
            worst = max(v for k, v in d.items() if k.endswith(("_streaming", "_batch")) and v is not None)
            if "gyro_vs_plain_build" in d:
                label += f" (differs from the plain build by up to {d['gyro_vs_plain_build']:.1e})"
            rows.append(
                f"| {name} | {label} | {d['gyro_vs_streaming']:.1e} | {d['gyro_vs_batch']:.1e} | {std} | "
                f"{'yes' if worst <= TOL else '**NO**'} |"
            )
    return rows


def markdown(r: dict) -> str:
    m, models = r["machine"], r["models"]
    tools = "; ".join(f"`{k}`: {v}" for k, v in m["tools"].items())
    pkgs = ", ".join(f"{k} {v}" for k, v in m["packages"].items())
    targets = "\n".join(
        f"- `{n}`: {t['about']}; `{t['flags']}`; run by `{t['qemu']} PROGRAM`" for n, t in r["targets"].items()
    )
    heads = " | ".join(models)
    n_counted = next(iter(next(iter(models.values()))["instructions_per_step"].values()))["steps"] + 1
    return f"""# C export on microcontrollers: flash, RAM, stack, and its numbers on 32-bit ARM (QEMU)

Command: `{r["command"]}` ({r["wall_s"]} s; {r["date"]})
Machine: {m["cpu_threads"]}-thread VM ({m["host"]}), CPU "{m["cpu"]}", {m["os"]}.
Tools: {tools}. Debian packages: {pkgs}.

Targets (`gyrodenoise.c_targets`); every exported file compiled with `{r["strict_flags"]}`:
{targets}

## Flash, RAM and stack

| model | target | code .text, -Os / -O2 [B] | weights .rodata [KiB] | sizeof(gd_state) [KiB] | stack of gd_step_t (all the file's functions) [B] | firmware flash [KiB] | firmware RAM [KiB] | double routines called |
|---|---|---:|---:|---:|---:|---:|---:|---|
{chr(10).join(size_rows(models))}

- code and weights: `arm-none-eabi-size -A gyrodenoise_model.o` (the weights are the same at -Os and -O2); the model's
  object has no .data nor .bss: its only RAM is the caller's `gd_state` (one struct: it needs one contiguous region).
- sizeof(gd_state): on the target (the symbol size of a `gd_state` object, `arm-none-eabi-nm -S`).
- stack: `-fstack-usage` at -Os, gd_step_t's own frame (the static functions it calls are inlined into it or listed
  apart; the sum over all the file's functions bounds any chain of them); the libm calls (expf, erff, ...) come on top.
- firmware: a minimal program linked at -Os with `--gc-sections`, newlib-nano and libm (start-up code, vector table,
  one `gd_step_t` call, no stdio): flash = .text + .rodata + .data, RAM = .data + .bss (the state included; no stack,
  no heap).
- double routines: the soft-float double functions (`__aeabi_d*`, `__aeabi_f2d`, ...) and double libm functions the
  model's object calls (`arm-none-eabi-nm -u`); with `-Wdouble-promotion -Werror` too, no double arithmetic.

## Instructions per step

Counted, not timed: each `gd_step_t` call's instructions on the Cortex-M build, by QEMU with `-icount shift=0` (one
instruction per ns of virtual time, read from SysTick and calibrated with a loop of known length), over the first
{n_counted} samples of the input below (the first step, which fills the rings, left out). A Cortex-M4 issues at most one
instruction per cycle (FP loads, branches and flash wait states add cycles): its cycles per step are at least these
counts. A Cortex-M7 can issue two per cycle and stalls on memory: these counts bound nothing there.

| model | build | instructions per step (mean) | min - max | per multiply-add |
|---|---|---:|---:|---:|
{chr(10).join(instruction_rows(models))}

Where they go: the convolutions' inner loop (`conv_step`: one dot product per output over eight partial sums kept in
registers) loads a weight and an input per multiply-add, beside the multiply-add and the loop's own instructions; the
first layer's six inputs go through the loop's remainder, one sum. (The earlier kernel, every output updated per input,
loaded and stored each partial sum at every multiply-add: 7.27 instructions per multiply-add for one network, -O2,
Cortex-M4F, at commit 5bfc2d3.)

## Which MCUs it fits

Datasheet figures (not measured): flash, the largest contiguous SRAM region (and all SRAM) in KiB. A model fits when
the linked firmware above fits the flash and `gd_state` one region. "step": the instructions per step (-O2, no fused
multiply-adds) at one per cycle at the MCU's clock, and its share of the sample period at the model's rate
({r["rate_hz"]:.3f} Hz): on a Cortex-M4 a lower bound of the step's time; on a Cortex-M7 a rough figure (dual issue
shortens it, memory stalls lengthen it). Not measured on hardware.

| MCU | core | flash [KiB] | largest SRAM region (all) [KiB] | {heads} |
|---|---|---:|---:|{"---|" * len(models)}
{chr(10).join(fit_rows(models, r["mcus_datasheet"], r["rate_hz"]))}

SRAM regions: {"; ".join(f"{x['mcu']}: {x['note']}" for x in r["mcus_datasheet"])}. What a region has left is all the
rest of the firmware (the flight stack, its buffers, the stack) can have of it.

## The numbers on 32-bit ARM

`example_main.c` built for each target (-O2), run under QEMU on {r["input"]}, stamped (`gd_step_t`), against
`StreamingCorrector.push(x, t_ns)` (numpy, float32) and the batch model (torch, float32); max |diff| over all samples,
rad/s (tolerance {TOL:g}, as the x86 check). Cortex-M: bare metal, Thumb-2, the FPU, newlib's libm; QEMU computes
each float32 operation as IEEE 754 prescribes, so the differences are the C code's, not the emulator's.

| model | build | gyro vs streaming | gyro vs batch | std vs streaming | within {TOL:g} |
|---|---|---:|---:|---:|---|
{chr(10).join(number_rows(models))}

`-ffp-contract=fast`: fused multiply-adds (`vfma`), which gcc uses in its GNU C modes (`-std=gnu11`, as PX4 and
ArduPilot build) but not with `-std=c99`.
"""  # noqa: E501
