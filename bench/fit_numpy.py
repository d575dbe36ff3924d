#!/usr/bin/env python3
"""The reference side of the fit benchmarks (issue 24): pandas + numpy least squares.

    python3 bench/fit_numpy.py FILE.csv

Reads FILE.csv (columns rate_dps, volts) with pandas and fits by numpy.linalg.lstsq the
linear, quadratic and cubic models (columns scaled by max|rate|, as gyrocal does), computing
every point's residuals and the SSE of each; prints K, K0 and the SSE of each model, and the
residuals' largest absolute value. This is what the issue's comparison times: it computes no
split model, no neuron, no error surface, no metrics and writes no JSON, so it does less
than `gyrocal fit FILE --json`. Time it as a whole process:

    /usr/bin/time -v python3 bench/fit_numpy.py FILE.csv

Needs numpy and pandas (bench/requirements.txt; bench/setup.sh makes a venv with them).
"""

import sys

import numpy as np
import pandas as pd


def poly(w, d, degree):
    scale = np.abs(w).max()
    a = np.vander(w / scale, degree + 1, increasing=True)
    c, *_ = np.linalg.lstsq(a, d, rcond=None)
    residuals = d - a @ c
    return c / scale ** np.arange(degree + 1), residuals


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: fit_numpy.py FILE.csv")
    df = pd.read_csv(sys.argv[1], comment="#", usecols=["rate_dps", "volts"])
    w = df["rate_dps"].to_numpy(dtype=float)
    d = df["volts"].to_numpy(dtype=float)
    for name, degree in (("linear", 1), ("quadratic", 2), ("cubic", 3)):
        c, r = poly(w, d, degree)
        print(f"{name:10s} K = {c[1]:.17g}  K0 = {c[0]:.17g}  SSE = {float(r @ r):.17g}"
              f"  max|r| = {np.abs(r).max():.6e}")
    print(f"points {len(w)}")


if __name__ == "__main__":
    main()
