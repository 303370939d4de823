"""The C export on microcontroller-class toolchains: cross-compiled for Cortex-M and 32-bit ARM Linux, measured
(flash, RAM, stack) and run under QEMU.

    targets:  cortex-m4f  arm-none-eabi-gcc -mcpu=cortex-m4 -mfpu=fpv4-sp-d16 (single-precision FPU), QEMU mps2-an386
              cortex-m7   arm-none-eabi-gcc -mcpu=cortex-m7 -mfpu=fpv5-d16, QEMU mps2-an500
              armhf       arm-linux-gnueabihf-gcc (ARMv7-A, hard-float VFP, glibc), qemu-arm (user mode)

The exported files are compiled with STRICT (-std=c99 -Wall -Wextra -pedantic -Werror, -Wdouble-promotion: no float
is silently promoted to double, which an FPU without double precision would run in software; -Wconversion), and the
model's object is checked for calls into the soft-float double routines (`double_symbols`). On Cortex-M the example
runs bare metal under qemu-system-arm, its stdin/stdout through semihosting (newlib's rdimon) and its own start-up
code (`STARTUP`, `LINKER_SCRIPT`: vector table, .data/.bss, the FPU enabled). QEMU checks the numbers (IEEE float32,
newlib's libm), not the time: QEMU's speed says nothing about a microcontroller's; `instructions_per_step` counts a
step's instructions instead (QEMU -icount), which a Cortex-M4 takes at least as many cycles to run.

Tools: apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm gcc-arm-linux-gnueabihf
libc6-dev-armhf-cross qemu-user (Debian/Ubuntu). `missing` names what a target lacks.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyrodenoise.c_export import EXAMPLE, HEADER, SOURCE, example_input, example_output

STRICT = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-Wdouble-promotion", "-Wconversion")
APT = {
    "arm-none-eabi-gcc": "gcc-arm-none-eabi libnewlib-arm-none-eabi",
    "qemu-system-arm": "qemu-system-arm",
    "arm-linux-gnueabihf-gcc": "gcc-arm-linux-gnueabihf libc6-dev-armhf-cross",
    "qemu-arm": "qemu-user",
}
# soft-float double routines (ARM run-time ABI) and libm's double functions the model must not call
_DOUBLE = re.compile(r"^(__aeabi_d\w+|__aeabi_[fil]2d|__aeabi_[ui]l?2d|(erf|exp|expm1|log1p|tanh|sqrt|fabs|pow))$")


@dataclass(frozen=True)
class Target:
    name: str
    cc: str
    flags: tuple[str, ...]
    qemu: tuple[str, ...]  # the command that runs a program (the program's path follows)
    bare_metal: bool
    about: str
    tools: tuple[str, ...] = field(default=())

    @property
    def size_tool(self) -> str:
        return self.cc.removesuffix("gcc") + "size"

    @property
    def nm_tool(self) -> str:
        return self.cc.removesuffix("gcc") + "nm"


_QEMU_MPS2 = ("-nographic", "-monitor", "none", "-serial", "none", "-semihosting-config", "enable=on,target=native")
TARGETS = {
    t.name: t
    for t in (
        Target(
            "cortex-m4f",
            "arm-none-eabi-gcc",
            ("-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"),
            ("qemu-system-arm", "-M", "mps2-an386", *_QEMU_MPS2, "-kernel"),
            True,
            "Cortex-M4F (FPv4-SP: single-precision FPU), e.g. STM32F4, STM32G4",
            ("arm-none-eabi-gcc", "qemu-system-arm"),
        ),
        Target(
            "cortex-m7",
            "arm-none-eabi-gcc",
            ("-mcpu=cortex-m7", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv5-d16"),
            ("qemu-system-arm", "-M", "mps2-an500", *_QEMU_MPS2, "-kernel"),
            True,
            "Cortex-M7 (FPv5, double-precision FPU), e.g. STM32F7, STM32H7",
            ("arm-none-eabi-gcc", "qemu-system-arm"),
        ),
        Target(
            "armhf",
            "arm-linux-gnueabihf-gcc",
            ("-static",),
            ("qemu-arm",),
            False,
            "32-bit ARM Linux, hard-float VFP (Debian armhf: ARMv7-A, Thumb-2, VFPv3-D16), glibc",
            ("arm-linux-gnueabihf-gcc", "qemu-arm"),
        ),
    )
}

# bare metal: vector table, .data copied and .bss zeroed, the FPU enabled, semihosting opened (-DSEMIHOSTING: stdio
# through the debugger, here QEMU), main(1, argv)
STARTUP = r"""
#include <stdint.h>
#include <stdlib.h>
extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
extern int main(int argc, char **argv);
extern void initialise_monitor_handles(void);
void Reset_Handler(void);
void Fault_Handler(void);
void _init(void);
void _fini(void);
__attribute__((section(".vectors"), used)) const void *const vectors[16] = {
    &_estack, (const void *)Reset_Handler, (const void *)Fault_Handler, (const void *)Fault_Handler,
    (const void *)Fault_Handler, (const void *)Fault_Handler, (const void *)Fault_Handler,
};
void Fault_Handler(void) { exit(99); }
void _init(void) {}
void _fini(void) {}
void Reset_Handler(void)
{
    static char *argv[] = {"gyrodenoise", 0};
    *(volatile uint32_t *)0xE000ED88 |= 0xFu << 20; /* CPACR: CP10 and CP11 (the FPU) full access */
    __asm volatile("dsb\n isb");
    for (uint32_t *s = &_sidata, *d = &_sdata; d < &_edata;) *d++ = *s++;
    for (uint32_t *d = &_sbss; d < &_ebss;) *d++ = 0;
#ifdef SEMIHOSTING
    initialise_monitor_handles();
#endif
    exit(main(1, argv));
}
"""
# the MPS2 boards' memory: 4 MiB of SSRAM at 0 (code, like flash) and 4 MiB at 0x20000000 (data)
LINKER_SCRIPT = """
MEMORY { FLASH (rx) : ORIGIN = 0x00000000, LENGTH = 4M
         RAM (rwx) : ORIGIN = 0x20000000, LENGTH = 4M }
ENTRY(Reset_Handler)
SECTIONS {
  .text : { KEEP(*(.vectors)) *(.text*) *(.rodata*) KEEP(*(.init)) KEEP(*(.fini)) . = ALIGN(4); } > FLASH
  .ARM.exidx : { *(.ARM.exidx*) } > FLASH
  _sidata = LOADADDR(.data);
  .data : { _sdata = .; *(.data*) . = ALIGN(4); _edata = .; } > RAM AT > FLASH
  .bss (NOLOAD) : { _sbss = .; *(.bss*) *(COMMON) . = ALIGN(4); _ebss = .; } > RAM
  end = .; _end = .;
  _estack = ORIGIN(RAM) + LENGTH(RAM);
}
"""
# a minimal firmware for the sizes: one stream stepped from a volatile input (no stdio)
FIRMWARE = r"""
#include "gyrodenoise_model.h"
static gd_state st;
volatile float input[6];
volatile int64_t stamp;
volatile float output[6];
int main(int argc, char **argv)
{
    float imu[6], w[3], sd[3];
    (void)argc, (void)argv;
    for (int c = 0; c < 6; c++) imu[c] = input[c];
    int code = gd_step_t(&st, stamp, imu, w, sd);
    for (int a = 0; a < 3; a++) output[a] = w[a], output[3 + a] = sd[a];
    return code;
}
"""

# instructions per step on a Cortex-M under QEMU -icount shift=0 (one instruction, one ns of virtual time): SysTick,
# clocked at the MPS2's 25 MHz, counts virtual time; a loop of known length calibrates it (instructions per tick).
# stdin: lines t,gx,gy,gz,ax,ay,az; stdout: calibration ticks, then the ticks of every step but the first
COUNTER = r"""
#include <stdint.h>
#include <stdio.h>
#include "gyrodenoise_model.h"
#define SYST_CSR (*(volatile uint32_t *)0xE000E010)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018)
static gd_state st;
static uint32_t since(uint32_t a) { return (a - SYST_CVR) & 0xFFFFFFu; }
int main(int argc, char **argv)
{
    long long t;
    float imu[6], w[3], sd[3];
    (void)argc, (void)argv;
    SYST_RVR = 0xFFFFFFu, SYST_CVR = 0, SYST_CSR = 5u; /* on, the processor clock, no interrupt */
    uint32_t a = SYST_CVR;
    __asm volatile("mov r0, %0\n1: subs r0, r0, #1\n nop\n bne 1b\n" : : "r"(CALIBRATION) : "r0", "cc");
    printf("%lu\n", (unsigned long)since(a));
    for (long n = 0; scanf("%lld,%g,%g,%g,%g,%g,%g", &t, imu, imu + 1, imu + 2, imu + 3, imu + 4, imu + 5) == 7; n++) {
        a = SYST_CVR;
        if (gd_step_t(&st, (int64_t)t, imu, w, sd) < 0) return 3;
        const uint32_t d = since(a);
        if (n > 0) printf("%lu\n", (unsigned long)d); /* the first step fills the rings */
    }
    return 0;
}
"""
CALIBRATION = 1_000_000  # iterations of 3 instructions (subs, nop, bne)


def missing(target: Target) -> list[str]:
    """The tools `target` needs that are not on the PATH (or its C library, beside its compiler), with the Debian
    packages that bring them."""
    out = [f"{t} (apt-get install {APT[t]})" for t in target.tools if shutil.which(t) is None]
    if shutil.which(target.cc):
        libc = ["librdimon.a", "libc.a"] if target.bare_metal else ["libc.a"]
        for lib in libc:
            ask = [target.cc, *target.flags, f"-print-file-name={lib}"]
            # gcc echoes the bare name of a library it cannot find
            if not Path(subprocess.run(ask, capture_output=True, text=True).stdout.strip()).is_absolute():
                out.append(f"{target.cc}'s C library, {lib} (apt-get install {APT[target.cc]})")
                break
    return out


def _run(cmd: list[str], what: str, **kw) -> subprocess.CompletedProcess:
    done = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if done.returncode != 0:
        raise RuntimeError(f"{what}: {' '.join(map(str, cmd))} failed:\n{(done.stderr or done.stdout)[-3000:]}")
    return done


def compile_object(src: Path, target: Target, out: Path, opt: str = "-Os", extra: tuple[str, ...] = ()) -> Path:
    """One C file to an object for `target` with the STRICT warnings as errors."""
    _run([target.cc, *target.flags, opt, *STRICT, *extra, "-c", "-o", str(out), str(src)], f"{target.name} compile")
    return out


def section_sizes(obj: Path, target: Target) -> dict[str, int]:
    """Bytes by kind, from `size -A`: text (code), rodata (the weights), data, bss."""
    out = {"text": 0, "rodata": 0, "data": 0, "bss": 0}
    for line in _run([target.size_tool, "-A", str(obj)], "size").stdout.splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[1].isdigit():
            kind = next((k for k in out if parts[0].startswith(f".{k}")), None)
            if kind:
                out[kind] += int(parts[1])
    return out


def double_symbols(obj: Path, target: Target) -> list[str]:
    """The soft-float double routines and double libm functions an object calls (none expected)."""
    undefined = _run([target.nm_tool, "-u", str(obj)], "nm").stdout.split()
    return sorted(s for s in undefined if _DOUBLE.match(s))


def state_size(c_dir: Path, target: Target, work: Path) -> int:
    """sizeof(gd_state) on the target: the size of a gd_state object in a probe's symbol table."""
    probe = work / "state_probe.c"
    probe.write_text(f'#include "{HEADER}"\ngd_state gd_state_probe;\n')
    obj = compile_object(probe, target, work / "state_probe.o", extra=("-I", str(c_dir)))
    for line in _run([target.nm_tool, "-S", str(obj)], "nm").stdout.splitlines():
        if line.endswith(" gd_state_probe"):
            return int(line.split()[1], 16)
    raise RuntimeError(f"{obj}: no gd_state_probe symbol")


def stack_usage(c_dir: Path, target: Target, work: Path, opt: str = "-Os") -> dict[str, int]:
    """Bytes of stack of each function of the model's file (gcc -fstack-usage; their calls to libm not included)."""
    compile_object(c_dir / SOURCE, target, work / "su_model.o", opt, ("-fstack-usage",))
    out = {}
    for line in (work / "su_model.su").read_text().splitlines():
        where, size, _ = line.split("\t")
        out[where.rsplit(":", 1)[-1]] = int(size)
    return out


def _link(target: Target, objs: list[Path], exe: Path, work: Path, specs: tuple[str, ...]) -> Path:
    """Link for `target`: bare metal with STARTUP and LINKER_SCRIPT (semihosting with rdimon's specs), else a static
    Linux program."""
    cmd = [target.cc, *target.flags]
    if target.bare_metal:
        (work / "startup.c").write_text(STARTUP)
        (work / "mps2.ld").write_text(LINKER_SCRIPT)
        startup = work / "startup.o"
        semihosting = ["-DSEMIHOSTING"] if "--specs=rdimon.specs" in specs else []
        cmd_startup = [target.cc, *target.flags, "-O2", *semihosting, "-c", "-o", str(startup), str(work / "startup.c")]
        _run(cmd_startup, "startup")
        cmd += [*specs, "-nostartfiles", "-T", str(work / "mps2.ld"), str(startup)]
    _run([*cmd, "-Wl,--gc-sections", "-o", str(exe), *map(str, objs), "-lm"], f"{target.name} link")
    return exe


def firmware_sizes(c_dir: Path, target: Target, work: Path, opt: str = "-Os") -> dict[str, int]:
    """Sections of a minimal linked firmware (start-up, the model, libm; newlib-nano, no stdio) stepping one stream:
    flash = text + rodata + data (its initial values), RAM = data + bss (the state included)."""
    (work / "firmware.c").write_text(FIRMWARE)
    sections = ("-ffunction-sections", "-fdata-sections")
    objs = [
        compile_object(work / "firmware.c", target, work / "fw_main.o", opt, ("-I", str(c_dir), *sections)),
        compile_object(c_dir / SOURCE, target, work / "fw_model.o", opt, sections),
    ]
    specs = ("--specs=nano.specs", "--specs=nosys.specs")
    return section_sizes(_link(target, objs, work / "firmware.elf", work, specs), target)


def build_example(
    c_dir: Path, target: Target, exe: Path, work: Path, opt: str = "-O2", extra: tuple[str, ...] = ()
) -> Path:
    """example_main.c and the model, STRICT (and `extra`), linked for `target` (bare metal: semihosting stdio through
    rdimon)."""
    objs = [
        compile_object(c_dir / EXAMPLE, target, work / "example.o", opt, extra),
        compile_object(c_dir / SOURCE, target, work / "model.o", opt, extra),
    ]
    return _link(target, objs, exe, work, ("--specs=rdimon.specs",))


def run_example_on(
    target: Target, exe: Path, imu: np.ndarray, t_ns: np.ndarray, timeout: float = 600
) -> tuple[np.ndarray, np.ndarray | None]:
    """The example under QEMU on stamped samples (every one must be taken): (gyro (N, 3), std (N, 3) or None)."""
    cmd = [*target.qemu, str(exe)]
    done = _run(cmd, f"{target.name} example under QEMU", input=example_input(imu, t_ns), timeout=timeout)
    return example_output(done.stdout, len(imu), f"{exe.name} under {target.qemu[0]}")


def tool_versions(target: Target) -> dict[str, str]:
    """The first line of `--version` of each tool of `target`."""
    out = {}
    for tool in target.tools:
        done = subprocess.run([tool, "--version"], capture_output=True, text=True)
        out[tool] = (done.stdout or done.stderr).splitlines()[0].strip()
    return out


def instructions_per_step(
    c_dir: Path, target: Target, work: Path, imu: np.ndarray, t_ns: np.ndarray, opt: str = "-O2", extra=()
) -> np.ndarray:
    """Instructions of each gd_step_t call (but the first) on a bare-metal target, counted by QEMU -icount (not
    cycles: a Cortex-M4 takes at least one cycle per instruction, more for FP loads, branches and flash wait
    states; a Cortex-M7 may issue two per cycle)."""
    if not target.bare_metal:
        raise ValueError(f"{target.name}: instructions are counted on the bare-metal (Cortex-M) targets only")
    (work / "counter.c").write_text(COUNTER)
    flags = ("-I", str(c_dir), f"-DCALIBRATION={CALIBRATION}", *extra)
    objs = [
        compile_object(work / "counter.c", target, work / "counter.o", opt, flags),
        compile_object(c_dir / SOURCE, target, work / "count_model.o", opt, extra),
    ]
    exe = _link(target, objs, work / "counter.elf", work, ("--specs=rdimon.specs",))
    qemu = [*target.qemu[:-1], "-icount", "shift=0", target.qemu[-1], str(exe)]
    text = example_input(imu, t_ns).split("\n", 1)[1]
    ticks = np.array(_run(qemu, f"{target.name} instruction count", input=text).stdout.split(), dtype=np.int64)
    if ticks[0] <= 0:
        raise RuntimeError(f"{target.name}: SysTick did not count under {' '.join(qemu[:3])} -icount")
    return ticks[1:] * (3 * CALIBRATION / ticks[0])
