#!/usr/bin/env bash
# Issue 9's GPU measurements in one device call (~8 device minutes), for a session that is lent a GPU:
#
#   bash ../shared/tools/gpu-pack euroc                       # here, once: wheels + data into .gpu/
#   device run, carry [".gpu"], timeout 600:
#     source .gpu/env.sh && bash benchmarks/gpu_call_issue9.sh
#
# then copy what comes back under $OUT into the repository (results/ files and time_to_accuracy_runs/*.json) and run
# `python benchmarks/time_to_accuracy.py report` here. Order: the loop overhead and the step variants first (short),
# then the 1800-epoch runs one at a time with nothing else running (queues/gpu_alone.txt), stopped by a deadline so
# that the call ends inside its 600 s.
set -euo pipefail
OUT=${OUT:-/tmp/gpu_call_out}
mkdir -p "$OUT"
nvidia-smi --query-gpu=name,memory.used,utilization.gpu --format=csv | tee "$OUT/gpu_before.csv"
python benchmarks/epoch_overhead.py --device cuda --rounds 3 --label "GPU call (gpu_call_issue9.sh)" 2>&1 | tail -20
python benchmarks/step_variants.py --device cuda 2>&1 | tail -20
mkdir -p "$OUT/results"
cp benchmarks/results/epoch_overhead.* benchmarks/results/step_variants* "$OUT/results/"
# alone: one training at a time; the deadline leaves room for one 1800-epoch run (~80 s) and its test
python benchmarks/run_queue.py benchmarks/queues/gpu_alone.txt --jobs 1 --threads 4 --out /tmp/gpu_runs \
  --collect "$OUT" --deadline 330 --note "gpu_call_issue9.sh: one run at a time on the GPU machine, alone"
