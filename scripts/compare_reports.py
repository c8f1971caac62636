#!/usr/bin/env python3
"""Compare two diagnose report.json files field by field, ignoring timings
and the file names of the model and records.

    python3 scripts/compare_reports.py A/report.json B/report.json

Prints each differing field and exits 1 when any differs."""
import json
import sys

IGNORED = {"timings", "seconds", "time", "model", "record", "validation_record", "elapsed"}


def walk(a, b, path, out):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k in IGNORED or "time" in k or "seconds" in k:
                continue
            walk(a.get(k), b.get(k), f"{path}.{k}", out)
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            walk(x, y, f"{path}[{i}]", out)
    elif a != b:
        out.append(f"{path}: {a!r} != {b!r}")


def main(fa, fb):
    out = []
    walk(json.load(open(fa)), json.load(open(fb)), "", out)
    for line in out:
        print(line)
    print(f"{len(out)} differing fields")
    return 1 if out else 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
