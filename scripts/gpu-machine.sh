#!/usr/bin/env bash
# What a GPU run ran on, for its records: the date, the card (nvidia-smi, where there is one) and what the dggt
# binary sees on the device.
#
#   scripts/gpu-machine.sh DGGT DEVICE > machine.txt
set -uo pipefail
[[ $# -eq 2 ]] || { sed -n '5p' "$0" >&2; exit 2; }
date -u
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.max.sm --format=csv 2>/dev/null || echo "no nvidia-smi"
"$1" devices --device "$2" 2>&1 | tail -n 5
