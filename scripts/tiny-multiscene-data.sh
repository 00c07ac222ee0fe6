#!/usr/bin/env bash
# Generates the 24 synthetic scenes of configs/tiny-multiscene.toml: 12 in drivestudio's Waymo layout and 12 in
# the nuScenes layout, 20 frames of one front camera at 160 x 112 each, into data/tiny-multiscene/ (or $1).
#
#   scripts/tiny-multiscene-data.sh [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-data/tiny-multiscene}"
cargo build --release --locked --quiet
for layout in waymo nuscenes; do
    for i in $(seq 0 11); do
        scene="$out/$layout/$(printf '%03d' "$i")"
        if [ -f "$scene/synth.json" ]; then continue; fi
        if [ "$layout" = waymo ]; then seed=$((100 + i)); else seed=$((200 + i)); fi
        ./target/release/dggt synth --out "$scene" --seed "$seed" --frames 20 --cameras 1 --layout "$layout"
    done
done
echo "24 scenes in $out"
