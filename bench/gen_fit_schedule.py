#!/usr/bin/env python3
"""Writes a schedule data file for the fit benchmarks: raw samples at the paper's 19 rates.

    python3 bench/gen_fit_schedule.py N OUT.csv [SEED]

N points (N may be written 1e6), each at one of the paper's rates (0, +-0.1, +-0.3, +-0.7,
+-1, +-3, +-7, +-10, +-15, +-20 deg/s) drawn uniformly, so the file is in shuffled order, not
grouped by step; D = 0.0088 + 0.3612 w + 2e-6 w^2 + N(0, 1e-3), 7 decimals; columns
rate_dps,volts. The same distribution as
`cargo run --release -p gyrocal-fit --example gen_samples -- N OUT.csv SEED` (another
generator, so not the same bytes). Standard library only; seeded.
"""

import random
import sys

RATES = [-20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0,
         0.1, 0.3, 0.7, 1.0, 3.0, 7.0, 10.0, 15.0, 20.0]


def main():
    if len(sys.argv) < 3:
        sys.exit("usage: gen_fit_schedule.py N OUT.csv [SEED]")
    n = int(float(sys.argv[1]))
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    rng = random.Random(seed)
    choice, gauss = rng.choice, rng.gauss
    with open(sys.argv[2], "w", buffering=1 << 20) as out:
        out.write("rate_dps,volts\n")
        lines = []
        for _ in range(n):
            w = choice(RATES)
            d = 0.0088 + 0.3612 * w + 2e-6 * w * w + gauss(0.0, 1e-3)
            lines.append(f"{w},{d:.7f}\n")
            if len(lines) == 100_000:
                out.writelines(lines)
                lines.clear()
        out.writelines(lines)


if __name__ == "__main__":
    main()
