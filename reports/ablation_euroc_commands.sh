#!/usr/bin/env bash
# The runs behind reports/ablation_euroc.md: EuRoC, 3 seeds per setting, one run at a time on a 2-core
# machine shared with other work (one torch thread per run: OMP_NUM_THREADS=1).
# Shortened schedule, the same for every setting (the paper: 1800 epochs, T_0=600, T_mult=2, i.e.
# cycles of 600 + 1200 epochs):
#   120 epochs, cosine warm restarts T_0=40, T_mult=2 (the paper's cycles scaled by 1/15: they end at
#   epochs 40 and 120), validation every 10 epochs; the best validation checkpoint is tested.
# The paper's setting (GELU, batch norm, dropout 0.1, weight decay 0.1) is run once (in the activation
# sweep) and shared by the three tables. Order: what the report needs most first.
set -euo pipefail
cd "$(dirname "$0")/.."
export OMP_NUM_THREADS=1
SCHED="trainer.max_epochs=120 optim.scheduler.T_0=40 trainer.check_val_every_n_epoch=10"
OUT=${OUT:-multirun/ablation_euroc}

# activation: gelu (= the paper's setting), relu x seeds 0,1,2 (6 runs)
python -m gyrodenoise.train -m experiment=ablation_activation model.act=gelu,relu $SCHED \
    hydra.sweep.dir=$OUT/activation
# batch norm off x seeds 0,1,2 (3 runs; "on" is the gelu setting above)
python -m gyrodenoise.train -m experiment=ablation_batchnorm model.batch_norm=false $SCHED \
    hydra.sweep.dir=$OUT/batchnorm
# regularisation {0, 0.1} x {0, 0.1} x seeds (9 runs; dropout 0.1 + weight decay 0.1 is the gelu setting above)
python -m gyrodenoise.train -m experiment=ablation_regularization model.dropout=0.0 optim.weight_decay=0.0,0.1 \
    $SCHED hydra.sweep.dir=$OUT/regularization_d0
python -m gyrodenoise.train -m experiment=ablation_regularization model.dropout=0.1 optim.weight_decay=0.0 \
    $SCHED hydra.sweep.dir=$OUT/regularization_d1
# activation: the other smooth ones, elu and silu x seeds 0,1,2 (6 runs)
python -m gyrodenoise.train -m experiment=ablation_activation model.act=elu,silu $SCHED \
    hydra.sweep.dir=$OUT/activation_smooth
# learning-rate schedule: constant lr x seeds 0,1,2 (3 runs; cosine warm restarts is the gelu setting above)
python -m gyrodenoise.train -m experiment=ablation_scheduler optim.scheduler.name=constant $SCHED \
    hydra.sweep.dir=$OUT/scheduler

# direction check at a 2.5x longer schedule (300 epochs, T_0=100: cycles end at 100 and 300), seed 0 only:
# the paper's setting, relu, batch norm off, no dropout and no weight decay (4 runs)
LONG="trainer.max_epochs=300 optim.scheduler.T_0=100 trainer.check_val_every_n_epoch=20 seed=0"
python -m gyrodenoise.train -m dataset=euroc model.act=gelu,relu $LONG hydra.sweep.dir=$OUT/long/activation
python -m gyrodenoise.train -m dataset=euroc model.batch_norm=false $LONG hydra.sweep.dir=$OUT/long/batchnorm
python -m gyrodenoise.train -m dataset=euroc model.dropout=0.0 optim.weight_decay=0.0 $LONG hydra.sweep.dir=$OUT/long/no_regularization
