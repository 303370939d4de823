#!/usr/bin/env bash
# One lent GPU call: the tests that need a GPU, then the Section V ablations at seeds 1 and 4
# (benchmarks/queues/ablation_folds_1_4.txt, rule there), 12 trainings at once with one CPU thread each.
#
#   bash ../shared/tools/gpu-pack euroc                 # here, once
#   device run, carry [".gpu"]:  source .gpu/env.sh && DEADLINE=300 bash benchmarks/gpu_call_ablation_folds.sh
#
# QUEUE: another queue of ablation runs (default queues/ablation_folds_1_4.txt; queues/ablation_confirm.txt ran in call 12).
# DEADLINE: seconds after the queue starts after which no further training starts (finished runs are kept; a
# second call resumes the queue, skipping collected runs: give it the first call's results via DONE=folder).
# What it writes comes back under $OUT: results.tar (the run summaries, paths as in the repository: unpack at its
# root; a folder of them does not come back whole, call 10) and call.log.
set -uo pipefail
OUT=${OUT:-/tmp/gpu_call_out}
mkdir -p "$OUT" /tmp/res
start=$(date +%s)
elapsed() { echo $(($(date +%s) - start)); }
{
  nvidia-smi --query-gpu=name,memory.total --format=csv
  if [ "${TESTS:-1}" = 1 ]; then
    echo "== the tests that need a GPU ($(elapsed) s)"
    timeout 240 python -m pytest -q -p no:cacheprovider -rA tests/test_cuda_graph_step.py 2>&1 | tail -n 40
  fi
  echo "== ablation queue ${QUEUE:-benchmarks/queues/ablation_folds_1_4.txt} ($(elapsed) s)"
  python benchmarks/run_queue.py "${QUEUE:-benchmarks/queues/ablation_folds_1_4.txt}" --jobs "${JOBS:-12}" --threads 1 \
    --out /tmp/gpu_runs --collect /tmp/res ${DONE:+--done "$DONE"} --deadline "${DEADLINE:-300}" \
    --note "gpu_call_ablation_folds.sh: ${JOBS:-12} trainings at once, 1 CPU thread each, one GPU machine"
  echo "== done ($(elapsed) s)"
} 2>&1 | tee "$OUT/call.log"
tar cf "$OUT/results.tar" -C /tmp/res .
