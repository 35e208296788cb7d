#!/usr/bin/env bash
# The odometry benchmark on real frames with moving objects composited in (issue 28): the TUM fr1/rpy excerpt as it
# is (static office) and with textured boxes moving in the world composited in (mcflow_bench_odometry composite),
# each run through mc_flow (default, and one rigid motion: dense robust VO) and OpenCV's rgbd odometry (rgbd, icp,
# rgbdicp), scored by `mcflow eval-traj` (ground truth at the colour stamp - 15 ms), and mc_flow's moving masks
# against the boxes' pixels (`mcflow_bench_odometry moving-iou`; on the static frames the boxes' pixels of the
# composited copy: what is flagged there is the room called moving). Prints two markdown tables.
# Builds nothing: build the targets mcflow and mcflow_bench_odometry first (the latter needs OpenCV's contrib rgbd).
#   bash scripts/bench_odometry.sh [TUM_DIR ($MCFLOW_SHARED_DATA/tum_fr1_rpy_0_60)]
#   env: MCFLOW_BUILD_DIR (build), BOXES (2), SEED (1)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="${MCFLOW_BUILD_DIR:-$ROOT/build}"
DATA="${1:-${MCFLOW_SHARED_DATA:-$(cd "$ROOT/.." && pwd)/shared/data}/tum_fr1_rpy_0_60}"
INTRINSICS=517.3,516.5,318.6,255.3  # TUM freiburg1 (the excerpt's README)
export OMP_WAIT_POLICY=passive

find_tool() {
  for candidate in "$BUILD/devel/lib/mc_flow/$1" "$BUILD/$1"; do
    if [ -x "$candidate" ]; then echo "$candidate"; return; fi
  done
  echo "bench_odometry.sh: $1 not found in $BUILD (build it: cmake --build $BUILD --target $1)" >&2
  exit 2
}
MCFLOW=$(find_tool mcflow)
BENCH=$(find_tool mcflow_bench_odometry)
[ -f "$DATA/groundtruth.txt" ] || { echo "bench_odometry.sh: no $DATA/groundtruth.txt" >&2; exit 2; }

work=$(mktemp -d /tmp/mc_flow_bench_odometry.XXXXXX)
cleanup() { rm -rf "$work"; }
trap cleanup EXIT

echo "compositing ${BOXES:-2} moving box(es) into $DATA" >&2
"$BENCH" composite --tum "$DATA" --intrinsics "$INTRINSICS" --out "$work/composited" --boxes "${BOXES:-2}" \
  --seed "${SEED:-1}" 2>/dev/null >&2

rows=""
masks=""
notes=""
# score SEQUENCE METHOD TRAJECTORY [ODOMETRY_CSV]: one table row from mcflow eval-traj (with run-seq's odometry.csv:
# the NEES of each pair's camera motion, median / mean / share inside chi2_6's 95 % interval; 5.35 / 6 / 0.95 when the
# covariances are right).
score() {
  local metrics
  local odometry=()
  [ -n "${4:-}" ] && odometry=(--odometry "$4")
  metrics=$("$MCFLOW" eval-traj --gt "$DATA/groundtruth.txt" --est "$3" --offset -0.015 "${odometry[@]}")
  rows+=$(echo "$metrics" | awk -v s="$1" -v m="$2" '
    $1 == "ate_rmse_m" { ate = $2 } $1 == "rpe_frame_trans_m" { t = $2 } $1 == "rpe_frame_rot_deg" { r = $2 }
    $1 == "nees_median" { nm = $2 } $1 == "nees_mean" { ne = $2 } $1 == "nees_inside95" { ni = $2 }
    END { nees = nm == "" ? "-" : sprintf("%.2f / %.2f / %.2f", nm, ne, ni)
          printf "| %s | %s | %.4f | %.4f | %.3f | %s |\n", s, m, ate, t, r, nees }')$'\n'
}

for sequence in static composited; do
  dir="$DATA"
  [ "$sequence" = composited ] && dir="$work/composited"
  for variant in default one-label; do
    settings=()
    [ "$variant" = one-label ] && settings=(--set initial_labels=1 --set max_splits_per_iteration=0)
    echo "$sequence: mc_flow $variant" >&2
    summary=$("$MCFLOW" run-seq --tum "$dir" --intrinsics "$INTRINSICS" --out "$work/run" "${settings[@]}" 2>/dev/null)
    notes+="$sequence, mc_flow $variant: ${summary%; wrote *}"$'\n'
    score "$sequence" "mc_flow $variant" "$work/run/trajectory.txt" "$work/run/odometry.csv"
    # The moving mask against the composited boxes (on the static frames: the room flagged as moving).
    masks+="| $sequence | mc_flow $variant | "$("$BENCH" moving-iou --composited "$work/composited" --run "$work/run" |
      awk '$1 == "moving_iou" { i = $2 } $1 == "moving_iou_median" { m = $2 } $1 == "box_recall" { r = $2 }
           $1 == "static_flagged" { s = $2 } END { printf "%.3f | %.3f | %.3f | %.3f |", i, m, r, s }')$'\n'
    rm -rf "$work/run"
  done
  for method in rgbd icp rgbdicp; do
    echo "$sequence: OpenCV $method" >&2
    summary=$("$BENCH" opencv --tum "$dir" --intrinsics "$INTRINSICS" --method "$method" --out "$work/opencv.txt" 2>&1)
    notes+="$sequence, OpenCV $method: ${summary%; wrote *}"$'\n'
    score "$sequence" "OpenCV $method" "$work/opencv.txt"
  done
done

echo "| sequence | method | ATE m | RPE trans m/frame | RPE rot deg/frame | NEES median / mean / inside95 |"
echo "|---|---|---|---|---|---|"
printf "%s" "$rows"
echo
echo "| sequence | method | moving-mask IoU (all pairs) | per pair median | box pixels flagged | other pixels flagged |"
echo "|---|---|---|---|---|---|"
printf "%s" "$masks"
echo
grep "box pixels" "$work/composited/composite.txt" | sed 's/^/composited: /'
printf "%s" "$notes"
