#!/usr/bin/env bash
# The GPU comparison in one command: dggt-rs's compute suite at the release's scale, then the same work on the
# DGGT release and gsplat (run by this machine's PyTorch), then the table with the ratios (docs/BENCHMARKS.md).
#
#   scripts/gpu-bench.sh OUT_DIR [--release-src DIR] [--device wgpu|cuda] [--dggt BINARY] [--longest-budget-s S]
#
# --release-src: the release's source tree (the folder holding `dggt/`); without it only gsplat is timed.
# --device:      our backend (default wgpu; `cuda` needs a build with `--features cuda`).
# --dggt:        the dggt binary (default: target/release/dggt, built with the device's feature).
# Outputs in OUT_DIR: ours/compute.json, reference.json, compute.md (the table), and each step's log.
set -euo pipefail

usage() { sed -n '4,9p' "$0" >&2; exit 2; }
[[ $# -ge 1 ]] || usage
out=$1
shift
release_src=""
device="wgpu"
dggt="target/release/dggt"
longest_budget=240
while [[ $# -gt 0 ]]; do
    case $1 in
        --release-src) release_src=$2; shift 2 ;;
        --device) device=$2; shift 2 ;;
        --dggt) dggt=$2; shift 2 ;;
        --longest-budget-s) longest_budget=$2; shift 2 ;;
        *) usage ;;
    esac
done
[[ -x $dggt ]] || { echo "no dggt binary at $dggt (cargo build --release --features $device)" >&2; exit 1; }
mkdir -p "$out/ours"
here=$(cd "$(dirname "$0")" && pwd)

echo "== dggt-rs on $device" >&2
"$dggt" bench compute --device "$device" --scale full --longest-budget-s "$longest_budget" --out "$out/ours" \
    2>&1 | tee "$out/ours.log"

echo "== the release and gsplat" >&2
reference_args=(--out "$out/reference.json" --gsplat --longest-budget-s "$longest_budget")
[[ -n $release_src ]] && reference_args+=(--release-src "$release_src")
python3 "$here/reference_bench.py" "${reference_args[@]}" 2>&1 | tee "$out/reference.log"

"$dggt" bench table --ours "$out/ours/compute.json" --reference "$out/reference.json" --out "$out/compute.md"
