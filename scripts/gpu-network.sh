#!/usr/bin/env bash
# The network on a GPU for a build without autotune (`--features vulkan-backend,gpu-fusion`, or any build with
# nothing to tune): every network workload in one process, so that each kernel is compiled once for all of them
# (wgpu compiles kernels per process), then one forward pass with CubeCL's per-kernel profile. Bounded: the suite
# gets three quarters of the budget, the profile the rest; each keeps what it finished when stopped.
#
#   scripts/gpu-network.sh OUT_DIR --dggt BIN [--device wgpu|cuda] [--budget-s S] [--longest-frames N]
#                          [--workloads LIST] [--raster-tests BIN] [--scale full|reduced]
#
# --workloads:    the suite's workloads (default forward,train-step,raster,longest).
# --scale:        `full` (the release's sizes, default) or `reduced` (the tiny network: the script checked on a CPU's
#                 software driver).
# --raster-tests: the rasteriser's test binary (`cargo test --features ... --test raster --no-run`): its GPU tests
#                 run first (the kernels' paths a software driver lacks, such as plane operations, checked
#                 against the host on this card), and the rasteriser's per-stage times are logged after the suite.
#
# Outputs in OUT_DIR: machine.txt; suite/compute.json and suite/compute.md (forward on 4 and 12 frames in f32 and
# f16, the training step, the rasteriser, whether N frames fit in one f16 forward: the first run of each beside
# the median of the timed runs), suite.log, compile.log (every kernel the suite compiled, with its time);
# raster-tests.log and raster-stages.log with --raster-tests; profile.log (the forward in f32: each kernel's count
# and time, CubeCL's `basic` profile, which waits for the device after every kernel) and profile-run.log.
set -uo pipefail

usage() { sed -n '7,21p' "$0" >&2; exit 2; }
[[ $# -ge 1 && $1 != -* ]] || usage
out=$(mkdir -p "$1" && cd "$1" && pwd)
shift
dggt=""
device="wgpu"
budget=360
longest=150
workloads="forward,train-step,raster,longest"
raster_tests=""
scale="full"
while [[ $# -gt 0 ]]; do
    case $1 in
        --dggt) dggt=$2; shift 2 ;;
        --device) device=$2; shift 2 ;;
        --budget-s) budget=$2; shift 2 ;;
        --longest-frames) longest=$2; shift 2 ;;
        --workloads) workloads=$2; shift 2 ;;
        --raster-tests) raster_tests=$2; shift 2 ;;
        --scale) scale=$2; shift 2 ;;
        *) usage ;;
    esac
done
[[ -x $dggt ]] || { echo "no dggt binary at '$dggt'" >&2; exit 1; }
[[ -z $raster_tests || -x $raster_tests ]] || { echo "no raster test binary at '$raster_tests'" >&2; exit 1; }
[[ ! -e cubecl.toml ]] || { echo "cubecl.toml exists here: this script writes its own" >&2; exit 1; }
trap 'rm -f cubecl.toml' EXIT
deadline=$(($(date +%s) + budget))

here=$(cd "$(dirname "$0")" && pwd)
"$here/gpu-machine.sh" "$dggt" "$device" > "$out/machine.txt"

# Runs `dggt bench compute` until `limit` seconds have passed; what it measured by then stays in its folder.
bench() {
    local name=$1 limit=$2
    shift 2
    echo "== $name (at most $limit s)" >&2
    local started=$(date +%s)
    timeout --signal=INT --kill-after=10 "$limit" "$dggt" bench compute --device "$device" --scale "$scale" \
        --out "$out/$name" --overwrite "$@" > "$out/$name.log" 2>&1
    echo "== $name: exit $? after $(($(date +%s) - started)) s" | tee -a "$out/parts.txt" >&2
    grep -E '^  [a-z]' "$out/$name.log" >&2
}

if [[ -n $raster_tests ]]; then
    # Without the cases that read the shared parity vectors (the device machine may not have them).
    echo "== raster-tests" >&2
    timeout 120 env DGGT_TEST_DEVICE="$device" "$raster_tests" --test-threads=1 --skip shared_reference cube:: \
        tile_cubes:: radix:: batches:: > "$out/raster-tests.log" 2>&1
    echo "== raster-tests: exit $?" | tee -a "$out/parts.txt" >&2
    grep -E "^test result|FAILED|panicked" "$out/raster-tests.log" >&2
fi

printf '[compilation.logger]\nlevel = "basic"\nfile = "%s"\n' "$out/compile.log" > cubecl.toml
left=$((deadline - $(date +%s)))
bench suite $((left * 3 / 4)) --workloads "$workloads" --precisions f32,f16 --repeat 3 \
    --warmup 1 --longest-precisions f16 --longest-frames "$longest" --longest-budget-s $((left / 6))
rm -f cubecl.toml

if [[ -n $raster_tests ]]; then
    # The rasteriser once more, waiting after each stage and logging its time (DGGT_SPLAT_STAGE_TIMES).
    export DGGT_SPLAT_STAGE_TIMES=1
    bench raster-stages 40 --workloads raster --repeat 1 --warmup 1
fi

printf '[profiling.logger]\nlevel = "basic"\nfile = "%s"\n' "$out/profile.log" > cubecl.toml
left=$((deadline - $(date +%s) - 5))
((left > 20)) && bench profile-run "$left" --workloads forward --precisions f32 --repeat 1 --warmup 1
[[ -f $out/suite/compute.md ]] && cat "$out/suite/compute.md"
