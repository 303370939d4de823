#!/usr/bin/env bash
# Issue 9's GPU measurements in one device call (~6 device minutes), for a session that is lent a GPU:
#
#   bash ../shared/tools/gpu-pack euroc                       # here, once: wheels + data into .gpu/
#   pip download --no-deps --only-binary=:all: -d .gpu/whl termcolor==2.4.0     # the authors' code needs it
#   git -C <checkout of mbrossar/denoise-imu-gyro> archive HEAD src | tar x -C .gpu/authors   # (mkdir first)
#   device run, carry [".gpu"], timeout 480:
#     source .gpu/env.sh && CALL=call8 bash benchmarks/gpu_call_issue9.sh
#
# Settings (environment): QUEUE (default queues/gpu_alone_graph.txt; call 7 ran queues/gpu_alone.txt), DEADLINE
# (seconds after which no further training starts), BREAKDOWN=1 (also gpu_step_breakdown.py), TESTS=1 (first the
# tests that need a GPU: tests/test_cuda_graph_step.py, all of which passed in call 10), CALL (names the logs:
# callN_...).
#
# Everything runs one thing at a time (the GPU machine to itself). Order: the GPU tests, the step taken apart
# (gpu_step_breakdown.py, short), gyrodenoise's 1800-epoch run (the queue's first line), the authors'
# code on the same data and schedule (authors_code_timing.py; skipped without .gpu/authors), then the queue's
# further lines while the deadline allows. What it writes comes back as $OUT/results.tar (paths as in the
# repository: unpack at its root, then `python benchmarks/time_to_accuracy.py report`) and $OUT/call.log.
set -uo pipefail
OUT=${OUT:-/tmp/gpu_call_out}
DEADLINE=${DEADLINE:-300}  # seconds after which no further training starts
QUEUE=${QUEUE:-benchmarks/queues/gpu_alone_graph.txt}
mkdir -p "$OUT" /tmp/res/benchmarks/results/time_to_accuracy_runs
start=$(date +%s)
elapsed() { echo $(($(date +%s) - start)); }
{
  nvidia-smi --query-gpu=name,memory.used,utilization.gpu --format=csv
  if [ "${TESTS:-0}" = 1 ]; then
    echo "== the tests that need a GPU ($(elapsed) s)"
    python -m pytest -q -p no:cacheprovider tests/test_cuda_graph_step.py
  fi
  if [ "${BREAKDOWN:-0}" = 1 ]; then
    echo "== step breakdown ($(elapsed) s)"
    python benchmarks/gpu_step_breakdown.py --steps 30 && cp benchmarks/results/gpu_step_breakdown.* /tmp/res/benchmarks/results/
  fi
  echo "== gyrodenoise 1800 epochs alone ($(elapsed) s)"
  grep -v '^#' "$QUEUE" | grep . | head -n 1 > /tmp/first.txt
  python benchmarks/run_queue.py /tmp/first.txt --jobs 1 --threads 4 --out /tmp/gpu_runs --collect /tmp/res \
    --note "gpu_call_issue9.sh: one run at a time on the GPU machine, alone"
  if [ -f .gpu/authors/src/learning.py ]; then
    echo "== the authors' code, 1800 epochs alone ($(elapsed) s)"
    python benchmarks/authors_code_timing.py --authors .gpu/authors --data "$GYRODENOISE_DATA/euroc" \
      --epochs 1800 --json "/tmp/res/benchmarks/results/authors_code_timing_${CALL:-call7}.json"
  fi
  left=$((DEADLINE - $(elapsed)))
  if [ "$left" -gt 0 ]; then
    echo "== the rest of the queue, starting runs for ${left} more s ($(elapsed) s)"
    python benchmarks/run_queue.py "$QUEUE" --jobs 1 --threads 4 --out /tmp/gpu_runs \
      --collect /tmp/res --deadline "$left" --note "gpu_call_issue9.sh: one run at a time on the GPU machine, alone"
  fi
  echo "== done ($(elapsed) s)"
} 2>&1 | tee "$OUT/call.log"
mkdir -p /tmp/res/benchmarks/results/gpu_queue_logs
for f in /tmp/gpu_runs/benchmarks/results/time_to_accuracy_runs/*.log; do
  [ -e "$f" ] && cp "$f" "/tmp/res/benchmarks/results/gpu_queue_logs/${CALL:-call7}_$(basename "$f")"
done
tar cf "$OUT/results.tar" -C /tmp/res .
