#!/usr/bin/env python3
"""Writes a continuous-rate data file for the fit benchmarks (issue 24).

    python3 bench/gen_fit_continuous.py N OUT.csv [SEED]

N points (N may be written 1e6), each at a rate drawn uniformly from [-20, 20] deg/s and
written with 6 decimals, as a rate table's *measured* rate per reading would be: 10^6 lines
hold about 987 600 distinct rates, so nothing repeats and `gyrocal fit` summarises over rate
bins. The output is a gyro with a small even-order nonlinearity plus 1 mV of Gaussian noise,
D = 0.0088 + 0.3612 w + 2e-6 w^2 + N(0, 1e-3), written with 7 decimals; columns
rate_dps,volts (about 20 bytes a line: 10^7 lines are 205 MB). The same distribution as
`cargo run --release -p gyrocal-fit --example gen_samples -- N OUT.csv SEED continuous`,
not the same bytes (another generator). Standard library only; seeded, so reproducible.
"""

import random
import sys


def main():
    if len(sys.argv) < 3:
        sys.exit("usage: gen_fit_continuous.py N OUT.csv [SEED]")
    n = int(float(sys.argv[1]))
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    rng = random.Random(seed)
    uniform, gauss = rng.uniform, rng.gauss
    with open(sys.argv[2], "w", buffering=1 << 20) as out:
        out.write("rate_dps,volts\n")
        lines = []
        for _ in range(n):
            w = round(uniform(-20.0, 20.0), 6)
            d = 0.0088 + 0.3612 * w + 2e-6 * w * w + gauss(0.0, 1e-3)
            lines.append(f"{w:.6f},{d:.7f}\n")
            if len(lines) == 100_000:
                out.writelines(lines)
                lines.clear()
        out.writelines(lines)


if __name__ == "__main__":
    main()
