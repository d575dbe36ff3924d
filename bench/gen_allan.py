#!/usr/bin/env python3
"""Writes a drift record CSV for the allan benchmarks: header `t_s,volts`, N rows.

t_s = i * tau0 (written with 6 decimals), volts = a gyro's output at rest: a bias, white noise
(angle random walk) and a random walk (rate random walk), written with 9 significant digits,
as a multimeter log. Deterministic (seeded), written in blocks of 10^6 rows so that 10^8 rows
(about 2.6 GB) need no more memory than 10^6.

usage: gen_allan.py N OUT.csv [--tau0 0.01] [--seed 7]
"""
import argparse
import sys

import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n", type=float, help="rows (1e7 is accepted)")
    ap.add_argument("out", help="output CSV")
    ap.add_argument("--tau0", type=float, default=0.01)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    n = int(a.n)
    rng = np.random.default_rng(a.seed)
    block = 1_000_000
    walk = 0.0
    with open(a.out, "w", encoding="ascii", newline="\n") as f:
        f.write("t_s,volts\n")
        for start in range(0, n, block):
            k = min(block, n - start)
            i = np.arange(start, start + k, dtype=np.float64)
            t = i * a.tau0
            rw = walk + np.cumsum(rng.normal(0.0, 2e-7, k))
            walk = float(rw[-1])
            v = 0.0125 + rng.normal(0.0, 1e-4, k) + rw
            lines = [f"{tt:.6f},{vv:.9g}\n" for tt, vv in zip(t.tolist(), v.tolist())]
            f.write("".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
