"""Plain C export (`python -m gyrodenoise.export MODEL --c DIR`): the compiled C step equals the streaming corrector
and the batch model, sample by sample, for every activation, an ensemble and the calibrated model.

The C files are compiled with the machine's C compiler (-std=c99 -Wall -Wextra -pedantic -Werror); without one the
tests skip and say why (a compiler is a system package, not something `pip install` brings: CI does not require one).
"""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch
from _models import random_imu, random_model
from conftest import require_data

from gyrodenoise import c_export
from gyrodenoise.export import main
from gyrodenoise.models.build import build_model
from gyrodenoise.models.denoiser import ACTIVATIONS, DilatedCNNDenoiser
from gyrodenoise.models.ensemble import EnsembleCorrection, predict_with_spread
from gyrodenoise.pretrained import save_model
from gyrodenoise.streaming import StreamingCorrector

# rad/s. Python and C both run in float32 but sum the ~1000-term dot products in other orders, so they differ by
# float32 rounding: ~1e-7 rad/s measured (outputs ~1 rad/s, eps 1.2e-7). A wrong weight, tap, fold or start-up
# differs by >= 1e-3.
ATOL = 1e-5
SMALL = {"channels": (8, 16, 12), "kernel_size": 3, "dilations": (1, 4, 9)}

# a test driver beside example_main.c: argv[1] = the sample index before which it calls gd_reset; a refused
# sample prints "refused" (and the state must be unchanged)
DRIVER = r"""
#include <stdio.h>
#include <stdlib.h>
#include "gyrodenoise_model.h"
static gd_state st;
int main(int argc, char **argv)
{
    long reset_at = argc > 1 ? atol(argv[1]) : -1, n = 0;
    float imu[6], w[3], sd[3];
    while (scanf("%g,%g,%g,%g,%g,%g", &imu[0], &imu[1], &imu[2], &imu[3], &imu[4], &imu[5]) == 6) {
        if (n++ == reset_at) gd_reset(&st);
        if (gd_step(&st, imu, w, sd) != 0) { printf("refused\n"); continue; }
        printf("%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", w[0], w[1], w[2], sd[0], sd[1], sd[2]);
    }
    return 0;
}
"""


def compiled(model, tmp_path, compiler, meta: dict | None = None):
    out = tmp_path / "c"
    c_export.export_c(model, out, meta or {"name": "test"})
    return c_export.compile_example(out, tmp_path / "gd", compiler, werror=True)


def assert_matches_python(model, imu: np.ndarray, gyro: np.ndarray, std: np.ndarray | None) -> None:
    """C == StreamingCorrector (one push per sample) and == the batch model on the whole stream, within ATOL."""
    ref, ref_std = c_export.stream_reference(model, imu)
    batch, batch_std = predict_with_spread(model, imu.astype(np.float32))
    assert np.abs(gyro - ref).max() < ATOL
    assert np.abs(gyro - batch).max() < ATOL
    assert (std is None) == (ref_std is None) == (batch_std is None)
    if std is not None:
        assert np.abs(std - ref_std).max() < ATOL
        assert np.abs(std - batch_std).max() < ATOL


@pytest.mark.parametrize("act", sorted(ACTIVATIONS))
def test_denoiser_with_batch_norm_each_activation(act, tmp_path, compiler):
    imu = random_imu(1500, seed=5)
    model = random_model(seed=3, act=act, **SMALL)  # random BN running statistics: folding is exercised
    model.set_normalization(imu.mean(0), imu.std(0))
    model.net[-1].weight.data *= 10  # corrections of ~1 rad/s: an error in a hidden unit shows in the output
    gyro, std = c_export.run_example(compiled(model, tmp_path, compiler), imu)
    assert np.abs(gyro - imu[:, :3]).max() > 0.1
    assert_matches_python(model, imu, gyro, std)


def test_two_member_ensemble_mean_and_spread(tmp_path, compiler):
    members = [
        random_model(seed=1, act="gelu", **SMALL),
        random_model(seed=2, channels=(10, 6), kernel_size=5, dilations=(2, 7), act="elu", batch_norm=False),
    ]
    members[1].set_normalization([0.1, 0, 0, 0, 0, 9.7], [0.4, 0.5, 0.3, 1.2, 1.1, 0.9])
    ens = EnsembleCorrection(members, spread_scale=1.7)
    imu = random_imu(1500, seed=6)
    gyro, std = c_export.run_example(compiled(ens, tmp_path, compiler), imu)
    assert std is not None and std.min() > 0
    assert_matches_python(ens, imu, gyro, std)


@pytest.mark.parametrize("g_sensitivity", [False, True])
def test_calibrated_model(g_sensitivity, tmp_path, compiler):
    model = build_model("calibrated", g_sensitivity=g_sensitivity)
    model.bias.data[:] = torch.tensor([0.01, 0.02, -0.03])
    model.C_delta.data.normal_(std=0.01)
    if g_sensitivity:
        model.G.data.normal_(std=1e-3)
    imu = random_imu(1500, seed=7)
    exe = compiled(model, tmp_path, compiler)
    gyro, std = c_export.run_example(exe, imu)
    assert std is None
    assert_matches_python(model, imu, gyro, std)
    assert "GD_N_RINGS          0 " in (tmp_path / "c" / c_export.HEADER).read_text()
    # the example stops at a refused sample or a malformed line, naming it
    for text, said in (("0,0,0,0,0,0,9.8\n1,nan,0,0,0,0,9.8\n", "line 2 (sample 2, t=1)"), ("t\n0,1,2\n", "line 2:")):
        done = subprocess.run([str(exe)], input=text, capture_output=True, text=True)
        assert done.returncode == 1 and said in done.stderr


def test_reset_and_refused_samples(tmp_path, compiler):
    """gd_reset starts a new stream like StreamingCorrector.reset(); a NaN or impossible sample is refused and leaves
    the state unchanged, as StreamingCorrector refuses it."""
    model = random_model(seed=4, **SMALL)
    compiled(model, tmp_path, compiler)
    exe = c_export.compile_example(tmp_path / "c", tmp_path / "driver", compiler, werror=True)
    driver = tmp_path / "c" / "driver.c"
    driver.write_text(DRIVER)
    cmd = [*compiler.split(), "-O2", "-std=c99", "-Wall", "-Werror", "-o", str(exe), str(driver)]
    subprocess.run([*cmd, str(tmp_path / "c" / c_export.SOURCE), "-lm"], check=True)
    imu = random_imu(300, seed=8).astype(np.float32)
    bad = {50: np.nan, 120: 1e3}  # gyro NaN, gyro 1000 rad/s
    lines = []
    for n, row in enumerate(imu):
        sample = row.copy()
        if n in bad:
            sample[0] = bad[n]
        lines.append(",".join(f"{v:.9g}" for v in sample))
        if n in bad:
            lines.append(",".join(f"{v:.9g}" for v in row))  # then the good sample
    done = subprocess.run([str(exe), "202"], input="\n".join(lines) + "\n", capture_output=True, text=True, check=True)
    out = done.stdout.splitlines()
    assert [i for i, ln in enumerate(out) if ln == "refused"] == [50, 121]
    gyro = np.array([[float(v) for v in ln.split(",")[:3]] for ln in out if ln != "refused"])
    sc = StreamingCorrector(model)
    ref = [sc.push(s) for s in imu[:200]]
    sc.reset()  # the driver resets before its input line 202 = sample 200 (two refused lines before it)
    ref += [sc.push(s) for s in imu[200:]]
    assert np.abs(gyro - np.array(ref)).max() < ATOL


GARBAGE_DRIVER = r"""
#include <stdio.h>
#include <string.h>
#include "gyrodenoise_model.h"
int main(void)
{
    gd_state st;
    float imu[6], w[3];
    memset(&st, 0x7f, sizeof st); /* a state never zeroed, as on the stack */
    gd_reset(&st);                /* the header: "Call it before the first sample (or zero the state)" */
    while (scanf("%g,%g,%g,%g,%g,%g", &imu[0], &imu[1], &imu[2], &imu[3], &imu[4], &imu[5]) == 6) {
        if (gd_step(&st, imu, w, NULL) != 0) return 2;
        printf("%.9g,%.9g,%.9g\n", w[0], w[1], w[2]);
    }
    return 0;
}
"""


def test_gd_reset_of_a_never_zeroed_state(tmp_path, compiler):
    """gd_reset alone makes a state of any bytes a fresh one (it left the ring indices as they were: an index beyond
    the ring wrote out of bounds)."""
    model = random_model(seed=4, **SMALL)
    compiled(model, tmp_path, compiler)
    (tmp_path / "c" / "garbage.c").write_text(GARBAGE_DRIVER)
    exe = tmp_path / "garbage"
    cmd = [*compiler.split(), "-O2", "-std=c99", "-Wall", "-Werror", "-o", str(exe), str(tmp_path / "c" / "garbage.c")]
    subprocess.run([*cmd, str(tmp_path / "c" / c_export.SOURCE), "-lm"], check=True)
    imu = random_imu(100, seed=8).astype(np.float32)
    text = "".join(",".join(f"{v:.9g}" for v in row) + "\n" for row in imu)
    done = subprocess.run([str(exe)], input=text, capture_output=True, text=True)
    assert done.returncode == 0
    gyro = np.array([[float(v) for v in ln.split(",")] for ln in done.stdout.splitlines()])
    ref, _ = c_export.stream_reference(model, imu)
    assert gyro.shape == ref.shape and np.abs(gyro - ref).max() < ATOL


CPP_DRIVER = r"""
#include "gyrodenoise_model.h"
static gd_state st;
int main() { float imu[6] = {0, 0, 0, 0, 0, 9.8f}, w[3]; gd_reset(&st); return gd_step(&st, imu, w, nullptr); }
"""


def test_header_from_cpp_and_metadata_in_its_comment(tmp_path, compiler):
    """A C++ program (PX4, ArduPilot) includes the header and links the C-compiled model (extern "C"); comment
    markers in the metadata neither end nor open a comment (gcc -Wall -Werror: "/*" within comment)."""
    model = random_model(seed=4, **SMALL)
    exe = compiled(model, tmp_path, compiler, {"name": "a */ int x; /* b", "dataset": "c/*d"})
    assert "int x;" in (tmp_path / "c" / c_export.HEADER).read_text()
    assert c_export.run_example(exe, random_imu(5))[0].shape == (5, 3)
    cxx = shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")
    if cxx is None:
        pytest.skip("no C++ compiler found (c++, g++, clang++)")
    obj, main_cpp = tmp_path / "model.o", tmp_path / "c" / "main.cpp"
    main_cpp.write_text(CPP_DRIVER)
    subprocess.run(
        [*compiler.split(), "-std=c99", "-c", "-o", str(obj), str(tmp_path / "c" / c_export.SOURCE)], check=True
    )
    done = subprocess.run(
        [cxx, "-Wall", "-Wextra", "-pedantic", "-Werror", "-o", str(tmp_path / "cpp"), str(main_cpp), str(obj), "-lm"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert subprocess.run([str(tmp_path / "cpp")]).returncode == 0


def test_shipped_euroc_ensemble_on_real_data(tmp_path, compiler):
    """The shipped 8-network `euroc` through the C code on 2000 samples of EuRoC MH_02_easy."""
    from gyrodenoise.data.readers import read_imu
    from gyrodenoise.pretrained import available_models, load_model

    if "euroc" not in available_models():
        pytest.skip("the shipped euroc model is not installed")
    data = read_imu(require_data("euroc", "MH_02_easy", "mav0", "imu0", "data.csv"))
    imu = np.concatenate([data.gyro, data.acc], axis=1)[3000:5000]
    model, meta = load_model("euroc")
    gyro, std = c_export.run_example(compiled(model, tmp_path, compiler, meta), imu)
    assert len(model.members) == 8 and std is not None
    assert_matches_python(model, imu, gyro, std)
    header = (tmp_path / "c" / c_export.HEADER).read_text()
    assert all(s in header for s in ("Model: euroc", "ADIS16448", "Receptive field: 511", "Exported by gyrodenoise"))


class OtherDenoiser(DilatedCNNDenoiser):
    """A subclass: its correction could be another function; the C export must not assume it is not."""


def test_models_without_a_c_form_are_refused(tmp_path):
    with pytest.raises(ValueError, match="has no C form"):
        c_export.export_c(OtherDenoiser(**SMALL), tmp_path)
    model = random_model(**SMALL)
    model.net[2] = torch.nn.Hardtanh()  # an activation the model classes do not offer
    with pytest.raises(ValueError, match="has no C form.*Hardtanh"):
        c_export.export_c(model, tmp_path)
    ens = EnsembleCorrection([random_model(**SMALL), OtherDenoiser(**SMALL)])
    with pytest.raises(ValueError, match="member 1 .* has no C form"):
        c_export.export_c(ens, tmp_path)
    assert not any(tmp_path.iterdir())


def test_cli_writes_compiles_and_checks(tmp_path, capsys, compiler):
    path = save_model(random_model(**SMALL), {"name": "denoiser", **SMALL}, tmp_path / "m.pt", {"rate_hz": 200.0})
    assert main([str(path), "--c", str(tmp_path / "out")]) == 0
    said = capsys.readouterr().out
    assert "gyrodenoise_model.c" in said and "max |diff|" in said
    assert {p.name for p in (tmp_path / "out").iterdir()} == {c_export.HEADER, c_export.SOURCE, c_export.EXAMPLE}
    assert "#define GD_RATE_HZ          200.0 " in (tmp_path / "out" / c_export.HEADER).read_text()
    (tmp_path / "file").write_text("x")
    assert main([str(path), "--c", str(tmp_path / "file")]) == 2  # a file where the folder of C files goes


def test_cli_checks_a_one_member_ensemble(tmp_path, capsys, compiler):
    """A one-member ensemble streams a zero std and its C example writes no std columns: the check compares the gyro
    (it failed with a TypeError)."""
    cfg = {"name": "ensemble", "members": [{"name": "denoiser", **SMALL}]}
    path = save_model(EnsembleCorrection([random_model(**SMALL)]), cfg, tmp_path / "m.pt")
    assert main([str(path), "--c", str(tmp_path / "out")]) == 0
    assert "max |diff|" in capsys.readouterr().out


def test_cli_refusal_is_one_line(tmp_path, capsys):
    cfg = {"name": "custom", "_target_": f"{__name__}.OtherDenoiser", **SMALL}
    path = save_model(OtherDenoiser(**SMALL), cfg, tmp_path / "m.pt")
    assert main([str(path), "--c", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "has no C form" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_cli_unwritable_folder_is_one_line(tmp_path, capsys):
    """OUT_DIR under a file (NotADirectoryError; a read-only or unwritable folder alike) is a one-line error, not a
    traceback."""
    path = save_model(random_model(**SMALL), {"name": "denoiser", **SMALL}, tmp_path / "m.pt")
    (tmp_path / "file").write_text("x")
    assert main([str(path), "--c", str(tmp_path / "file" / "out"), "--no-check"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --c ") and "cannot write" in err and err.count("\n") == 1


def test_cli_with_a_cross_compiler_in_cc_is_one_line(tmp_path, capsys, monkeypatch):
    """$CC that builds for another machine (arm-none-eabi-gcc): the check cannot run the example; one line (it was an
    OSError traceback: Exec format error)."""
    fake = tmp_path / "cross-cc"
    fake.write_text(
        f"#!{sys.executable}\nimport sys\nexe = sys.argv[sys.argv.index('-o') + 1]\n"
        "open(exe, 'wb').write(bytes([127, 69, 76, 70, 2, 1, 1, 0]) + b'not for this machine')\n"
    )
    fake.chmod(0o755)
    monkeypatch.setenv("CC", str(fake))
    path = save_model(random_model(**SMALL), {"name": "denoiser", **SMALL}, tmp_path / "m.pt")
    assert main([str(path), "--c", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "cannot run here" in err and err.count("\n") == 1
    assert (tmp_path / "out" / c_export.HEADER).is_file()  # right, maybe, for the machine it is built for: kept


def test_cli_removes_files_that_do_not_compile_and_names_a_missing_cc(tmp_path, capsys, monkeypatch, compiler):
    """Files the compiler refuses are not written, like files that compute something else (none left to look whole,
    and an earlier export in the folder stays as it was);
    a $CC that is not on the PATH is named, and the host compiler checks instead."""
    path = save_model(random_model(**SMALL), {"name": "denoiser", **SMALL}, tmp_path / "m.pt")
    assert main([str(path), "--c", str(tmp_path / "bad"), "--no-check"]) == 0  # an earlier export, kept
    earlier = (tmp_path / "bad" / c_export.SOURCE).read_text()
    monkeypatch.setenv("CC", f"{compiler} -include {tmp_path / 'no_such_header.h'}")
    assert main([str(path), "--c", str(tmp_path / "bad"), "--c-prefix", "other"]) == 2
    err = capsys.readouterr().err
    assert "do not compile or run" in err and "so they were not written" in err
    assert (tmp_path / "bad" / c_export.SOURCE).read_text() == earlier  # the failed export replaced nothing
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad", "m.pt"]  # and left no staging folder
    assert main([str(path), "--c", str(tmp_path / "new")]) == 2
    assert not (tmp_path / "new").exists()
    monkeypatch.setenv("CC", "no-such-cross-gcc")
    assert main([str(path), "--c", str(tmp_path / "good")]) == 0
    assert "$CC=no-such-cross-gcc is not on the PATH: checked with" in capsys.readouterr().out


def test_cli_without_a_compiler_writes_and_says_it_did_not_check(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(c_export, "find_c_compiler", lambda: None)
    path = save_model(random_model(**SMALL), {"name": "denoiser", **SMALL}, tmp_path / "m.pt")
    assert main([str(path), "--c", str(tmp_path / "out")]) == 0
    assert "not compiled nor checked: no C compiler found" in capsys.readouterr().out
    assert (tmp_path / "out" / c_export.SOURCE).is_file()


TWO_MODELS_DRIVER = r"""
#include <stdio.h>
#include "a/gyrodenoise_model.h"
#include "b/gyrodenoise_model.h"
int main(void) {
    static net_state s1;
    static cal_state s2;
    float imu[6] = {0.1f, -0.2f, 0.3f, 0.0f, 0.0f, 9.81f}, w1[3], w2[3];
    int i;
    for (i = 0; i < 3; ++i) {
        if (net_step(&s1, imu, w1, NULL) != 0 || cal_step(&s2, imu, w2, NULL) != 0) return 1;
    }
    printf("%.9g %.9g %.9g %.9g %.9g %.9g\n", w1[0], w1[1], w1[2], w2[0], w2[1], w2[2]);
    return NET_N_MEMBERS == 1 && CAL_N_RINGS == 0 ? 0 : 2;
}
"""


def test_two_models_with_their_own_prefixes_link_into_one_program(tmp_path, compiler):
    """--c-prefix: a network and a calibrated model (a fallback) in one binary; each answers as its own export."""
    net = random_model(seed=7, **SMALL)
    cal = build_model("calibrated")
    cal.bias.data[:] = torch.tensor([0.01, 0.02, -0.03])
    c_export.export_c(net, tmp_path / "a", {"name": "net"}, prefix="net")
    c_export.export_c(cal, tmp_path / "b", {"name": "cal"}, prefix="cal")
    assert "gd_" not in (tmp_path / "a" / c_export.HEADER).read_text()
    (tmp_path / "main.c").write_text(TWO_MODELS_DRIVER)
    objs = []
    for part in ("a", "b"):  # each model's .c compiled on its own (same file name, another folder)
        obj = tmp_path / f"{part}.o"
        src = tmp_path / part / c_export.SOURCE
        subprocess.run([*compiler.split(), "-std=c99", "-Wall", "-Werror", "-c", "-o", str(obj), str(src)], check=True)
        objs.append(str(obj))
    exe = tmp_path / "two"
    cmd = [*compiler.split(), "-std=c99", "-Wall", "-Werror", "-I", str(tmp_path), "-o", str(exe)]
    done = subprocess.run([*cmd, str(tmp_path / "main.c"), *objs, "-lm"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split()
    imu = np.tile(np.array([0.1, -0.2, 0.3, 0.0, 0.0, 9.81], dtype=np.float32), (3, 1))
    for model, got in ((net, out[:3]), (cal, out[3:])):
        ref, _ = c_export.stream_reference(model, imu)
        np.testing.assert_allclose(np.array(got, dtype=float), ref[-1], atol=ATOL)
    with pytest.raises(ValueError, match="a C identifier"):
        c_export.export_c(net, tmp_path / "x", prefix="9lives")


NAN_DRIVER = r"""
#include <stdio.h>
#include "gyrodenoise_model.h"
static gd_state st;
int main(void)
{
    float imu[6] = {0.1f, -0.2f, 0.05f, 0.0f, 0.0f, 9.81f}, w[3], sd[3] = {0.0f, 0.0f, 0.0f};
    if (gd_step(&st, imu, w, sd) != 0) return 2;
    printf("%d %d %d\n", sd[0] != sd[0], sd[1] != sd[1], sd[2] != sd[2]);
    return 0;
}
"""


def test_one_network_writes_a_nan_spread_not_zeros(tmp_path, compiler):
    """A single network measures no spread: its std_out read 0, a certainty (a review of the one-member change)."""
    compiled(random_model(seed=4, **SMALL), tmp_path, compiler)
    driver, exe = tmp_path / "c" / "nan_driver.c", tmp_path / "nan_driver"
    driver.write_text(NAN_DRIVER)
    cmd = [*compiler.split(), "-O2", "-std=c99", "-Wall", "-Werror", "-o", str(exe), str(driver)]
    subprocess.run([*cmd, str(tmp_path / "c" / c_export.SOURCE), "-lm"], check=True)
    assert subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split() == ["1", "1", "1"]
