#!/usr/bin/env python3
"""What burn's kernel cache says a GPU run spent compiling and tuning.

burn's `persistence` (the GPU features) keeps the tuned choices in an SQLite database, `target/environment/<name>.db`
of the checkout (CI: `$CARGO_TARGET_DIR/kernel-environment/`). For each process that changed it, the database also
records every kernel compiled and every key tuned, with what it cost (CBOR values). This prints, per such session,
what it compiled and tuned, then the kernels whose compiles cost the most. A key's tuning time includes compiling the
candidates it timed, and a tuning inside another (a fused kernel's, around a matmul's) counts in both.

Usage: python3 scripts/kernel-cache-report.py [DB] [--top N]   (needs `pip install cbor2`)
"""

import argparse
import collections
import datetime
import sqlite3
import sys

try:
    import cbor2
except ImportError:
    sys.exit("kernel-cache-report: the records are CBOR; install the reader with `pip install cbor2`")


def seconds(duration):
    """A Rust `Duration` as CBOR (`secs`, `nanos`) in seconds."""
    return duration["secs"] + duration["nanos"] / 1e9


def records(db, kind):
    """The decoded records of `kind` (`sessions`, `compilation`, `autotune`)."""
    rows = db.execute("select value from entries where namespace = ?", (f"records/v1/{kind}",))
    return [cbor2.loads(value) for (value,) in rows]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db", nargs="?", default="target/environment/default.db")
    parser.add_argument("--top", type=int, default=10, help="how many of the costliest kernels to list")
    args = parser.parse_args()
    try:
        db = sqlite3.connect(f"file:{args.db}?mode=ro", uri=True)
        sessions = records(db, "sessions")
    except sqlite3.Error as error:
        sys.exit(f"kernel-cache-report: {args.db}: {error} (expected burn's kernel cache database)")

    compiled = collections.defaultdict(lambda: [0, 0.0])
    by_kernel = collections.defaultdict(lambda: [0, 0.0])
    for record in records(db, "compilation"):
        cost = seconds(record["record"]["duration"])
        compiled[record["stamp"]["session"]][0] += 1
        compiled[record["stamp"]["session"]][1] += cost
        kernel = record["record"]["kernel"].split("<")[0]
        by_kernel[kernel][0] += 1
        by_kernel[kernel][1] += cost
    tuned = collections.defaultdict(lambda: [0, 0.0])
    for record in records(db, "autotune"):
        tuned[record["stamp"]["session"]][0] += 1
        tuned[record["stamp"]["session"]][1] += seconds(record["record"]["wall"])

    print("| session started (UTC) | kernels compiled | compiling (s) | keys tuned | tuning (s) |")
    print("|---|---:|---:|---:|---:|")
    for session in sorted(sessions, key=lambda s: s["started_unix_ms"]):
        started = datetime.datetime.fromtimestamp(session["started_unix_ms"] / 1000, datetime.timezone.utc)
        (kernels, compiling), (keys, tuning) = compiled[session["id"]], tuned[session["id"]]
        print(f"| {started:%Y-%m-%d %H:%M:%S} | {kernels} | {compiling:.1f} | {keys} | {tuning:.1f} |")
    print(f"\nThe {args.top} costliest kernels over every session:\n")
    print("| kernel | compiles | seconds |")
    print("|---|---:|---:|")
    for kernel, (count, cost) in sorted(by_kernel.items(), key=lambda item: -item[1][1])[: args.top]:
        print(f"| `{kernel}` | {count} | {cost:.1f} |")


if __name__ == "__main__":
    main()
