#!/usr/bin/env python3
"""The wall time of each test binary of a `cargo test` log, slowest first, so that the slow ones are seen.

usage: test-times.py LOG [--top N]

Each binary starts with cargo's `Running <target> (<path>)` (or `Doc-tests <crate>`) line and ends with libtest's
`test result: ... finished in <seconds>s`: the seconds libtest measured around the binary's tests (process start
and the listing before them are not counted). Prints a Markdown table: binary, tests run, seconds, share.
"""
import re
import sys

RUNNING = re.compile(r"^\s*(?:Running (.+?) \((\S+)\)\s*$|Doc-tests (\S+))")
RESULT = re.compile(r"test result: \w+\. (\d+) passed; (\d+) failed; (\d+) ignored;.* finished in ([0-9.]+)s")


def binaries(lines):
    """`(name, tests run, seconds)` of each binary whose result line the log holds."""
    current = None
    for line in lines:
        started = RUNNING.search(line)
        if started:
            target, path, doc = started.groups()
            if doc:
                current = f"doc-tests {doc}"
            elif target.startswith("unittests"):
                # `unittests src/lib.rs` names no crate: the binary's file name does (`dggt_scene-<hash>`).
                current = path.rsplit("/", 1)[-1].rsplit("-", 1)[0] + " (unit tests)"
            else:
                current = target
            continue
        result = RESULT.search(line)
        if result and current is not None:
            passed, failed, _ignored, seconds = result.groups()
            yield current, int(passed) + int(failed), float(seconds)
            current = None


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    top = int(sys.argv[sys.argv.index("--top") + 1]) if "--top" in sys.argv else None
    with open(sys.argv[1], encoding="utf-8", errors="replace") as log:
        rows = sorted(binaries(log), key=lambda row: -row[2])
    if not rows:
        sys.exit(f"{sys.argv[1]}: no test results found")
    total = sum(seconds for _, _, seconds in rows)
    print(f"test binaries: {len(rows)}, {total:.0f} s in their tests")
    print("| binary | tests | seconds | share |")
    print("|---|---:|---:|---:|")
    for name, tests, seconds in rows[:top]:
        print(f"| {name} | {tests} | {seconds:.1f} | {100 * seconds / total:.1f} % |")


if __name__ == "__main__":
    main()
