#!/usr/bin/python3
"""Column by column, two frontier.csv files of the same settings: the columns whose values differ
(with both values for the timing columns, in microseconds), and whether every other column, every
error column among them, is equal to the digit.
Usage: compare_columns.py BEFORE.csv AFTER.csv"""
import csv
import sys


def main(before_path, after_path):
    before = list(csv.DictReader(open(before_path)))
    after = list(csv.DictReader(open(after_path)))
    if len(before) != len(after):
        print(f"different row counts: {len(before)} and {len(after)}")
        return 1
    differing = set()
    for a, b in zip(before, after):
        differing |= {k for k in a if a[k] != b.get(k)}
    timing = {k for k in differing if k.endswith("_us") or k.endswith("_ms")}
    print("columns that differ:", ", ".join(sorted(differing)) or "none")
    print("of them not timings:", ", ".join(sorted(differing - timing)) or "none")
    for a, b in zip(before, after):
        cells = [f"{k} {a[k]} -> {b[k]}" for k in sorted(timing) if "p50" in k]
        print(f"{a['scene']:13s} {a['setting']:10s} " + "; ".join(cells))
    return 0 if not differing - timing else 1


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
