#!/usr/bin/env bash
# The GPU machine's check of a change (no ROS, no OpenCV there): core-only sm_90 builds of two source trees, then
# test_cuda on the second, the end-to-end benchmarks of both alternating (real pairs at 320x240 and 640x480 twice,
# synthetic pairs, warm streams), the static world's table, and compute-sanitizer memcheck over FILTER.
#   bash scripts/gpu_ab.sh BASE_SRC NEW_SRC REAL_DIR OUT [FILTER]
# BASE_SRC: e.g. `git archive BASE` unpacked; REAL_DIR: `mcflow export-real` folders; OUT: where the reports go
# (test_cuda.txt, bench.txt, stream.txt, memcheck.txt). Binaries build in /tmp/gpu_ab_{base,new}.
set -u
BASE_SRC="$1" NEW_SRC="$2" REAL="$3" OUT="$4"
FILTER="${5:-CudaMotionAccumulator.*:CudaSolveBackend.SolverMatchesCpuOnSyntheticScenes}"
build() {
  cmake -S "$1" -B "$2" -G Ninja -DMCFLOW_WITH_ROS=OFF -DMCFLOW_WITH_OPENCV=OFF -DCMAKE_CUDA_ARCHITECTURES=90 \
    -DCMAKE_BUILD_TYPE=Release >"$2.cfg.log" 2>&1 && ninja -C "$2" $3 >"$2.log" 2>&1
  echo "build $2: rc $?"
  grep -m5 -B2 -A8 " error" "$2.log" | head -40
}
start=$(date +%s)
build "$BASE_SRC" /tmp/gpu_ab_base "mcflow_bench mcflow_bench_stream" &
build "$NEW_SRC" /tmp/gpu_ab_new "mcflow_bench mcflow_bench_stream test_cuda" &
wait
nvidia-smi --query-gpu=name,clocks.max.sm,driver_version --format=csv
export OMP_NUM_THREADS=8
(cd /tmp/gpu_ab_new && timeout 300 ./test_cuda --gtest_brief=1 >"$OUT/test_cuda.txt" 2>&1; echo "test_cuda rc $?" >>"$OUT/test_cuda.txt")
tail -4 "$OUT/test_cuda.txt"
{
  for round in 1 2; do
    for b in base new; do
      for size in 320x240 640x480; do
        echo "=== $b real $size round $round"
        /tmp/gpu_ab_$b/mcflow_bench --backend cuda --real "$REAL" --match $size --repeat 9
      done
    done
  done
  for b in base new; do echo "=== $b synthetic"; /tmp/gpu_ab_$b/mcflow_bench --backend cuda --repeat 5; done
} >"$OUT/bench.txt" 2>&1
{
  for b in base new; do echo "=== $b stream warm"; /tmp/gpu_ab_$b/mcflow_bench_stream --backend cuda --modes warm; done
  echo "=== new world"; /tmp/gpu_ab_new/mcflow_bench_stream --backend cuda --variants 2 --world
} >"$OUT/stream.txt" 2>&1
(cd /tmp/gpu_ab_new && timeout 240 compute-sanitizer --tool memcheck --leak-check full ./test_cuda \
  --gtest_filter="$FILTER" >"$OUT/memcheck.txt" 2>&1; echo "memcheck rc $?" >>"$OUT/memcheck.txt")
tail -3 "$OUT/memcheck.txt"
echo "gpu_ab.sh: $(($(date +%s) - start)) s"
