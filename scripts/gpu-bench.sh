#!/usr/bin/env bash
# The GPU comparison in one run of bounded length: dggt-rs's compute suite at the release's scale with the build
# users get (burn's fusion and autotune), the DGGT release and gsplat on the same card (run by its PyTorch), the
# build without fusion and autotune beside it, then one table with every ratio (docs/BENCHMARKS.md).
#
#   scripts/gpu-bench.sh OUT_DIR [--dggt BIN] [--baseline-dggt BIN] [--release-src DIR] [--gsplat-src DIR]
#                        [--raster-tests BIN] [--device wgpu|cuda] [--scale full|reduced] [--budget-s S]
#                        [--no-reference] [--reference-records FILE]... [--baseline-records FILE]
#                        [--tuning-cache FILE]
#
# --dggt:          the binary to measure (default target/release/dggt, `cargo build --release --features wgpu`).
# --baseline-dggt: a build without fusion and autotune (`--features wgpu-backend`); its forward and rasteriser
#                  rows appear beside ours with the gain. Without it that part is skipped.
# --release-src:   the DGGT release's source tree (the folder holding `dggt/`); without it only gsplat is timed.
# --gsplat-src:    a gsplat source tree to import (prepended to PYTHONPATH) where gsplat is not installed.
# --raster-tests:  the rasteriser's test binary (`cargo test --features wgpu --test raster --no-run`): its GPU
#                  tests run first, so that the kernels' paths a software driver lacks (plane operations) are
#                  checked against the host on this card (`--device cuda`: through CUDA, DGGT_TEST_DEVICE=cuda).
# --budget-s:      the whole run's wall-clock limit (default 540); each part gets its share and is stopped at
#                  it, keeping the records it finished. Parts in order of importance: ours, the references, the
#                  baseline.
# --no-reference:  skip the release and gsplat (a machine without CUDA PyTorch).
# --reference-records, --baseline-records: records an earlier run on the same card kind wrote (its
#                  reference.json, its baseline's compute.json), shown in the table instead of measuring again, so
#                  that the whole budget goes to our build.
# --tuning-cache:  a tuning cache an earlier run on the same card kind brought back (`tuning-cache.tar`, or the
#                  `.tar.xz` of docs/gpu-bench-<card>/), unpacked as `target/environment` before the first part so
#                  that kernels compiled and shapes tuned then are not compiled and tuned again. A
#                  `target/environment` already there is refused rather than mixed into.
#
# Outputs in OUT_DIR (keep them as docs/gpu-bench-<card>/): ours-*/compute.json, baseline/compute.json,
# reference.json, compute.md (the table), machine.txt, each part's log, raster-stages.log (the rasteriser's time
# per stage, DGGT_SPLAT_STAGE_TIMES) and tuning-cache.tar (what this run compiled and tuned).
set -uo pipefail

usage() { sed -n '6,33p' "$0" >&2; exit 2; }
[[ $# -ge 1 && $1 != -* ]] || usage
out=$1
shift
dggt="target/release/dggt"
baseline=""
release_src=""
gsplat_src=""
raster_tests=""
reference_records=()
baseline_records=""
tuning_cache=""
device="wgpu"
scale="full"
budget=540
reference=1
while [[ $# -gt 0 ]]; do
    case $1 in
        --dggt) dggt=$2; shift 2 ;;
        --baseline-dggt) baseline=$2; shift 2 ;;
        --release-src) release_src=$2; shift 2 ;;
        --gsplat-src) gsplat_src=$2; shift 2 ;;
        --raster-tests) raster_tests=$2; shift 2 ;;
        --device) device=$2; shift 2 ;;
        --scale) scale=$2; shift 2 ;;
        --budget-s) budget=$2; shift 2 ;;
        --no-reference) reference=0; shift ;;
        --reference-records) reference_records+=("$2"); reference=0; shift 2 ;;
        --baseline-records) baseline_records=$2; shift 2 ;;
        --tuning-cache) tuning_cache=$2; shift 2 ;;
        *) usage ;;
    esac
done
[[ -x $dggt ]] || { echo "no dggt binary at $dggt (cargo build --release --features $device)" >&2; exit 1; }
[[ -z $baseline || -x $baseline ]] || { echo "no baseline binary at $baseline" >&2; exit 1; }
[[ -z $raster_tests || -x $raster_tests ]] || { echo "no raster test binary at $raster_tests" >&2; exit 1; }
for file in "${reference_records[@]}" $baseline_records; do
    [[ -f $file ]] || { echo "no record file at $file" >&2; exit 1; }
done
[[ $scale == full || $scale == reduced ]] || usage
if [[ -n $tuning_cache ]]; then
    [[ -f $tuning_cache ]] || { echo "no tuning cache at $tuning_cache" >&2; exit 1; }
    [[ ! -e target/environment ]] || { echo "target/environment exists: move it away to use --tuning-cache" >&2; exit 1; }
    tar -xf "$tuning_cache" target/environment || { echo "$tuning_cache holds no target/environment" >&2; exit 1; }
fi
mkdir -p "$out"
here=$(cd "$(dirname "$0")" && pwd)
deadline=$(($(date +%s) + budget))

# The parts' shares of the budget (they sum to 111); time a part leaves unused goes to the parts after it.
shares_left=111
((reference)) || shares_left=$((shares_left - 30))
[[ -n $baseline ]] || shares_left=$((shares_left - 18))
[[ -n $raster_tests ]] || shares_left=$((shares_left - 8))

# Seconds a part with share $1 may take: that share of what is left for it and the parts after it (less 10 s
# for the table).
allowance() {
    local left=$((deadline - $(date +%s) - 10))
    echo $((left * $1 / shares_left))
}

# Runs one part under its allowance; a part that fails or runs out keeps what it wrote and the run goes on.
part() {
    local name=$1 percent=$2
    shift 2
    local limit
    limit=$(allowance "$percent")
    shares_left=$((shares_left - percent))
    if ((limit < 5)); then
        echo "== $name: skipped, the budget is spent" | tee -a "$out/parts.txt" >&2
        return
    fi
    echo "== $name (at most $limit s)" >&2
    local started=$(date +%s)
    timeout --signal=INT --kill-after=10 "$limit" "$@" > "$out/$name.log" 2>&1
    local status=$?
    echo "== $name: exit $status after $(($(date +%s) - started)) s" | tee -a "$out/parts.txt" >&2
    tail -n 3 "$out/$name.log" >&2
}

"$here/gpu-machine.sh" "$dggt" "$device" > "$out/machine.txt"

# Full scale: the forward in f32 and f16 (bf16 where the device has it: wgpu has not), the longest search asking
# whether 150 frames fit in f16; reduced: the same code at a CPU's scale (the search in f32, which every device has).
if [[ $scale == full ]]; then
    longest=(--longest-frames 150 --longest-precisions f16)
else
    longest=(--longest-frames 2..4 --longest-precisions f32)
fi
common=(bench compute --device "$device" --scale "$scale" --repeat 3 --warmup 1 --overwrite)

if [[ -n $raster_tests ]]; then
    # Without the cases that read the shared parity vectors (the device machine may not have them).
    # On a CUDA device the tests read DGGT_TEST_DEVICE=cuda (the same kernels through CUDA instead of Vulkan).
    part raster-tests 8 env DGGT_TEST_DEVICE="$device" "$raster_tests" --test-threads=1 --skip shared_reference \
        cube:: tile_cubes:: radix:: batches::
fi
part ours-raster 6 "$dggt" "${common[@]}" --out "$out/ours-raster" --workloads raster
# One more raster run that waits after each stage and logs its time (DGGT_SPLAT_STAGE_TIMES), kept out of the table.
part raster-stages 3 env DGGT_SPLAT_STAGE_TIMES=1 "$dggt" bench compute --device "$device" --scale "$scale" \
    --repeat 1 --warmup 1 --overwrite --out "$out/raster-stages" --workloads raster
# Each precision tunes its own kernels on first use: f32 alone first, so that its figures survive a slow tuning.
part ours-forward 12 "$dggt" "${common[@]}" --out "$out/ours-forward" --workloads forward --precisions f32
part ours-forward-half 10 "$dggt" "${common[@]}" --out "$out/ours-forward-half" --workloads forward \
    --precisions f16,bf16
part ours-train-step 10 "$dggt" "${common[@]}" --out "$out/ours-train-step" --workloads train-step
part ours-flow-head 4 "$dggt" "${common[@]}" --out "$out/ours-flow-head" --workloads flow-head
part ours-longest 10 "$dggt" "${common[@]}" --out "$out/ours-longest" --workloads longest \
    --longest-budget-s "$(allowance 6)" "${longest[@]}"

if ((reference)); then
    reference_args=(--out "$out/reference.json" --gsplat)
    [[ -n $release_src ]] && reference_args+=(--release-src "$release_src")
    [[ $scale == reduced ]] && reference_args+=(--reduced)
    part reference 30 env PYTHONUNBUFFERED=1 PYTHONPATH="${gsplat_src}${PYTHONPATH:+:$PYTHONPATH}" \
        python3 "$here/reference_bench.py" "${reference_args[@]}" --workloads forward,train-step,raster
fi

if [[ -n $baseline ]]; then
    part baseline 18 "$baseline" "${common[@]}" --out "$out/baseline" --workloads raster,forward --precisions f32
fi

# The kernels compiled and the choices tuned in this run (burn's persistence, `target/environment` under the
# working directory's workspace), kept so that a later run on the same card kind can start from them.
[[ -d target/environment ]] && tar -cf "$out/tuning-cache.tar" target/environment

table_args=()
for file in "$out"/ours-*/compute.json; do [[ -f $file ]] && table_args+=(--ours "$file"); done
[[ -f $out/baseline/compute.json ]] && table_args+=(--baseline "$out/baseline/compute.json")
[[ -n $baseline_records && ! -f $out/baseline/compute.json ]] && table_args+=(--baseline "$baseline_records")
[[ -f $out/reference.json ]] && table_args+=(--reference "$out/reference.json")
for file in "${reference_records[@]}"; do table_args+=(--reference "$file"); done
((${#table_args[@]})) || { echo "no part wrote records (see $out/*.log)" >&2; exit 1; }
"$dggt" bench table "${table_args[@]}" --out "$out/compute.md" --overwrite
