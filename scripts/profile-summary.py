#!/usr/bin/env python3
"""Where a GPU run's time went, per kernel, from CubeCL's profile log.

With `[profiling.logger] level = "basic"` in a `cubecl.toml` of the working directory (`scripts/gpu-network.sh`
writes one), CubeCL waits for the device after every kernel and logs a line `| <time> | <kernel name> | ...` per
launch. This sums those lines per kernel (the name without its hash suffix, so that the variants of one kernel
count together) and prints the kernels by total time, with their launches and share of the whole.

Usage: python3 scripts/profile-summary.py PROFILE_LOG [--top N] [--width W]
"""

import argparse
import collections
import re
import sys

UNITS_US = {"ns": 1e-3, "µs": 1.0, "us": 1.0, "ms": 1e3, "s": 1e6}


def microseconds(text):
    """`12.5µs`, `3.2ms`, ... in microseconds, or None when the text is no duration."""
    match = re.fullmatch(r"([\d.]+)(ns|µs|us|ms|s)", text.strip())
    return float(match.group(1)) * UNITS_US[match.group(2)] if match else None


def launches(lines):
    """(microseconds, kernel) per profiled launch; the kernel named by the field after the time, hash removed."""
    for line in lines:
        if not line.startswith("| "):
            continue
        fields = [field.strip() for field in line.strip().strip("|").split("|")]
        time = microseconds(fields[0]) if fields else None
        if time is None or len(fields) < 2:
            continue
        yield time, re.sub(r"_[0-9a-f]{8}\b", "", fields[1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log")
    parser.add_argument("--top", type=int, default=15, help="how many kernels to list")
    parser.add_argument("--width", type=int, default=60, help="characters of each kernel's name shown")
    args = parser.parse_args()
    with open(args.log, encoding="utf-8") as file:
        totals = collections.defaultdict(float)
        counts = collections.Counter()
        for time, kernel in launches(file):
            totals[kernel] += time
            counts[kernel] += 1
    if not counts:
        sys.exit(f"profile-summary: {args.log} holds no profiled launches (`| <time> | <kernel>` lines)")
    whole = sum(totals.values())
    print(f"{sum(counts.values())} launches, {whole / 1e3:.1f} ms of kernel time")
    print(f"{'ms':>10} {'share':>6} {'launches':>8}  kernel")
    for kernel, total in sorted(totals.items(), key=lambda item: -item[1])[: args.top]:
        print(f"{total / 1e3:10.1f} {total / whole:6.1%} {counts[kernel]:8d}  {kernel[: args.width]}")


if __name__ == "__main__":
    main()
