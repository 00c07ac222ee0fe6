#!/usr/bin/env bash
# Shows that two builds of `dggt` compute the same things: a shortened main job (12 training steps on the
# bundled fixture) and a reconstruction from its checkpoint, run with each binary, then compared:
#   - metrics.jsonl record by record, timings left out;
#   - every reconstruction file byte for byte (summary.json aside: it holds times and paths);
#   - the checkpoint's model tensors by name, and the optimiser's moments as a multiset (they are keyed by
#     parameter ids drawn at random each run), read from the burn-pack files (needs Python's `cbor2`).
# usage: scripts/same-outputs.sh OLD_DGGT NEW_DGGT WORK_DIR   (WORK_DIR is created; it must not exist)
set -euo pipefail
OLD=$1; NEW=$2; W=$3
REPO="$(cd "$(dirname "$0")/.." && pwd)"
[ -e "$W" ] && { echo "$W exists: give a new folder" >&2; exit 1; }
mkdir -p "$W"
for tag in old new; do
  BIN=$OLD; [ "$tag" = new ] && BIN=$NEW
  (cd "$REPO" && "$BIN" train --config configs/tiny-overfit.toml --steps 12 --out "$W/$tag-run" > "$W/$tag-train.log" 2>&1)
  "$BIN" reconstruct --images "$REPO/data-fixtures/synth-s0" --checkpoint "$W/$tag-run" --cameras 0 --frames 0..8 \
    --every 2 --out "$W/$tag-rec" > "$W/$tag-rec.log" 2>&1
done
untimed() {
  python3 - "$1" <<'PY'
import json, sys
def drop(x):
    if isinstance(x, dict):
        return {k: drop(v) for k, v in x.items() if not (k.endswith('_s') or k in ('stage_s', 'time_s'))}
    return x
for line in open(sys.argv[1]):
    print(json.dumps(drop(json.loads(line)), sort_keys=True))
PY
}
untimed "$W/old-run/metrics.jsonl" > "$W/old-metrics.txt"
untimed "$W/new-run/metrics.jsonl" > "$W/new-metrics.txt"
diff "$W/old-metrics.txt" "$W/new-metrics.txt" && echo "metrics identical ($(wc -l < "$W/new-metrics.txt") records)"
(cd "$W/old-rec" && find . -type f ! -name summary.json | sort | xargs sha256sum) > "$W/old-rec.sha"
(cd "$W/new-rec" && find . -type f ! -name summary.json | sort | xargs sha256sum) > "$W/new-rec.sha"
diff "$W/old-rec.sha" "$W/new-rec.sha" && echo "reconstruction files byte-identical ($(wc -l < "$W/new-rec.sha") files)"
for f in $(cd "$W/new-run" && find . -name model.bpk | sort); do
  echo "$f: $(python3 "$REPO/scripts/bpk_digest.py" names "$W/old-run/$f" "$W/new-run/$f")"
done
for f in $(cd "$W/new-run" && find . -name optimizer.bpk | sort); do
  echo "$f: $(python3 "$REPO/scripts/bpk_digest.py" ids "$W/old-run/$f" "$W/new-run/$f")"
done
