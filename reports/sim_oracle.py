"""reports/sim.md: oracle diagnostic: what AOE floor is left by the unobservable (stochastic) errors, and how much a
12-parameter calibration leaves on top of it, for the sim.yaml error model."""

import sys
import time

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from gyrodenoise.metrics import aoe
from gyrodenoise.sim.dataset import KINDS, _sequence_seed
from gyrodenoise.sim.effects import Bias, effect_from_config
from gyrodenoise.sim.imu import simulate_imu
from gyrodenoise.so3 import integrate_gyro

cfg = yaml.safe_load(open(sys.argv[1]))
gen = cfg["generation"]
STOCH = {"white_noise", "bias_random_walk", "quantization"}


def sim(name, keep):
    kind = name.split("_")[0]
    rng = np.random.default_rng(_sequence_seed(int(gen["seed"]), name))
    traj = KINDS[kind](gen["duration_s"] + 2.0, int(rng.integers(1 << 30)))
    eff = [effect_from_config(dict(c)) for c in gen["error_model"]]
    eff = [e for e in eff if keep(e)]
    j = float(gen.get("bias_jitter_rad_s", 0))
    jb = rng.normal(0, j, 3) if j > 0 else np.zeros(3)
    if keep(Bias()) or True:
        eff.append(Bias(bias=jb))
    return simulate_imu(traj, eff, rate_hz=200.0, seed=int(rng.integers(1 << 30)))


def A(s, g):
    R = Rotation.from_quat(s.gt_quat_xyzw).as_matrix()
    dt = np.r_[0, np.diff(s.t_ns) * 1e-9]
    return aoe(R, integrate_gyro(R[0], g, dt))[0]


train, test = list(cfg["train_seqs"]), list(cfg["test_seqs"])  # the training split of the yaml, its test set
t0 = time.time()
full = {n: sim(n, lambda e: True) for n in train + test}
stoch = {n: sim(n, lambda e: e.name in STOCH) for n in test}
print("sim s", time.time() - t0)
# calibration LS on training: y - w = (C-I) w + b  -> w = (y - b) solved as w ~ A y + c
X = np.concatenate([np.c_[full[n].gyro, np.ones(len(full[n].gyro))] for n in train])
Y = np.concatenate([full[n].true_gyro for n in train])
P = np.linalg.lstsq(X, Y, rcond=None)[0]
# + g-sensitivity-aware linear model (w ~ A y + G f + c): what a linear network input gets
X2 = np.concatenate([np.c_[full[n].gyro, full[n].acc, np.ones(len(full[n].gyro))] for n in train])
P2 = np.linalg.lstsq(X2, Y, rcond=None)[0]


def X3f(s):
    return np.c_[s.gyro, s.acc, s.gyro * np.abs(s.gyro), np.ones(len(s.gyro))]


X3 = np.concatenate([X3f(full[n]) for n in train])
P3 = np.linalg.lstsq(X3, Y, rcond=None)[0]
rows = []
for n in test:
    s = full[n]
    r = [
        A(s, s.gyro),
        A(s, np.c_[s.gyro, np.ones(len(s.gyro))] @ P),
        A(s, np.c_[s.gyro, s.acc, np.ones(len(s.gyro))] @ P2),
        A(s, X3f(s) @ P3),
        A(stoch[n], stoch[n].gyro),
    ]
    rows.append(r)
    print(n, " ".join(f"{np.degrees(v):7.2f}" for v in r))
print("mean", " ".join(f"{np.degrees(v):7.2f}" for v in np.mean(rows, 0)))
print("cols: raw, calib(12p LS), +acc linear, +acc+nonlin, oracle(stochastic only)")
