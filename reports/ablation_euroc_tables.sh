#!/usr/bin/env bash
# Tables and plots of reports/ablation_euroc.md from the multirun folders of ablation_euroc_commands.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-multirun/ablation_euroc}
R=reports/ablation_euroc
python -m gyrodenoise.ablation $OUT/activation* --keys model.act --out $R/activation \
    --title "EuRoC: activation (120 epochs, 3 seeds)"
python -m gyrodenoise.ablation $OUT/activation $OUT/batchnorm --keys model.batch_norm --where model.act=gelu \
    --out $R/batchnorm --title "EuRoC: batch norm (120 epochs, 3 seeds)"
python -m gyrodenoise.ablation $OUT/activation $OUT/regularization_d0 $OUT/regularization_d1 \
    --keys model.dropout,optim.weight_decay --where model.act=gelu \
    --out $R/regularization --title "EuRoC: dropout x weight decay (120 epochs, 3 seeds)"
python -m gyrodenoise.ablation $OUT/activation $OUT/scheduler --keys optim.scheduler.name --where model.act=gelu \
    --out $R/scheduler --title "EuRoC: learning-rate schedule (120 epochs, 3 seeds)"
# the 300-epoch direction check (one seed per setting)
python -m gyrodenoise.ablation $OUT/long --keys model.act,model.batch_norm,model.dropout,optim.weight_decay \
    --out $R/long_check --title "EuRoC: 300-epoch check, seed 0"
