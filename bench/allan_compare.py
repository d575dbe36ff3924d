#!/usr/bin/env python3
"""Compares the curves of `gyrocal allan --json` (run with --warmup-window 0, so that the whole
record is analysed) and allan_pandas.py on the same file: for each averaging factor m both have,
the relative difference of the deviations and of the numbers of terms. Exit 1 when a deviation
differs by more than 1e-9 relative (the estimators are the same formula; the last digits differ
by summation order). Standard library only.

usage: allan_compare.py GYROCAL.json PANDAS.json
"""
import json
import sys


def main() -> int:
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    with open(sys.argv[1], encoding="utf-8") as f:
        g = json.load(f)
    with open(sys.argv[2], encoding="utf-8") as f:
        p = json.load(f)
    tau0 = p["tau0_s"]
    ours = {pt["m"]: pt for pt in g["curve"]["points"]}
    worst = 0.0
    compared = 0
    for pt in p["curve"]:
        m = round(pt["tau_s"] / tau0)
        if m not in ours:
            continue
        a, b = ours[m]["deviation"], pt["deviation"]
        rel = abs(a - b) / abs(b) if b else abs(a - b)
        worst = max(worst, rel)
        compared += 1
        print(f"m={m:>9} gyrocal {a:.12e} allantools {b:.12e} rel {rel:.1e} terms {ours[m]['n_terms']} {pt['n']}")
    print(f"{compared} averaging factors compared; largest relative difference {worst:.2e}")
    return 0 if compared and worst <= 1e-9 else 1


if __name__ == "__main__":
    sys.exit(main())
