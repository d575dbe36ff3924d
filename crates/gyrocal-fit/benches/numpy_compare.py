#!/usr/bin/env python3
"""The comparison script of issue 16: the least squares `gyrocal fit` does, in pandas + numpy.

    python3 crates/gyrocal-fit/benches/numpy_compare.py FILE.csv

Reads FILE.csv (columns rate_dps, volts; written by
`cargo run --release -p gyrocal-fit --example gen_samples -- N FILE.csv`) with pandas and fits
by numpy.linalg.lstsq the same least-squares models as `gyrocal fit`: linear, quadratic, cubic
(columns scaled by max|rate| as gyrocal does) and the split model (one line for rate >= 0, one
for rate <= 0), and prints K and K0 of each with its SSE. It computes no neuron, no error
surface, no metrics and writes no per-point output, so it does less than `gyrocal fit --json`;
time it as a whole process:

    /usr/bin/time -v python3 crates/gyrocal-fit/benches/numpy_compare.py FILE.csv

Needs `pip install numpy pandas`. The whole-process comparison of issue 24 (continuous rates,
residuals, the JSON size) is bench/run_fit.sh at the repository root, with bench/fit_numpy.py.
"""

import sys

import numpy as np
import pandas as pd


def poly(w, d, degree):
    scale = np.abs(w).max()
    a = np.vander(w / scale, degree + 1, increasing=True)
    c, *_ = np.linalg.lstsq(a, d, rcond=None)
    c = c / scale ** np.arange(degree + 1)
    r = d - np.polynomial.polynomial.polyval(w, c)
    return c, float(r @ r)


def main():
    df = pd.read_csv(sys.argv[1], comment="#", usecols=["rate_dps", "volts"])
    w = df["rate_dps"].to_numpy(dtype=float)
    d = df["volts"].to_numpy(dtype=float)
    for name, degree in (("linear", 1), ("quadratic", 2), ("cubic", 3)):
        c, sse = poly(w, d, degree)
        print(f"{name:10s} K = {c[1]:.7f}  K0 = {c[0]:.6f}  SSE = {sse:.6e}")
    pos, neg = w >= 0, w <= 0
    cp, _ = poly(w[pos], d[pos], 1)
    cn, _ = poly(w[neg], d[neg], 1)
    print(f"split      K+ = {cp[1]:.7f}  K- = {cn[1]:.7f}  K0 = {(cp[0] + cn[0]) / 2:.6f}")
    print(f"points {len(w)}")


if __name__ == "__main__":
    main()
