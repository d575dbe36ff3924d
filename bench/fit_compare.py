#!/usr/bin/env python3
"""Compares `gyrocal fit --json` with bench/fit_numpy.py's output on the same file.

    python3 bench/fit_compare.py GYROCAL.json NUMPY.out

Prints, for the linear, quadratic and cubic least-squares fits, the relative differences of
K, K0 and the SSE, and exits 1 when one is above 1e-9 (two least-squares solvers on the same
data agree far closer than that). Standard library only.
"""

import json
import re
import sys


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: fit_compare.py GYROCAL.json NUMPY.out")
    with open(sys.argv[1]) as f:
        doc = json.load(f)
    theirs = {}
    with open(sys.argv[2]) as f:
        for line in f:
            m = re.match(r"(\w+)\s+K = (\S+)\s+K0 = (\S+)\s+SSE = (\S+)", line)
            if m:
                theirs[m.group(1)] = tuple(float(x) for x in m.group(2, 3, 4))
    worst = 0.0
    for fit in doc["fits"]:
        if fit["method"] != "least-squares" or fit["model"] not in theirs:
            continue
        k, k0, sse = theirs[fit["model"]]
        rel = [abs(a - b) / abs(b) for a, b in
               ((fit["scale_factor"], k), (fit["bias"], k0), (fit["sse"], sse))]
        worst = max(worst, *rel)
        print(f"{fit['model']:10s} dK/K {rel[0]:.1e}  dK0/K0 {rel[1]:.1e}  dSSE/SSE {rel[2]:.1e}")
    print(f"largest relative difference {worst:.1e} ({'agree' if worst <= 1e-9 else 'DISAGREE'})")
    sys.exit(0 if worst <= 1e-9 else 1)


if __name__ == "__main__":
    main()
