#!/usr/bin/env python3
"""The Python side of `gyrocal allan FILE --json` for the side-by-side benchmark: pandas'
read_csv of the record's `t_s` and `volts` columns, then allantools' overlapping Allan deviation
(`oadev`) at octave taus on the volts as rate (frequency) data, tau0 the median interval.
Prints the curve as JSON (tau, deviation, number of terms) and the times of the two parts on
stderr. Run it under `/usr/bin/time -v` for the whole-process figures (bench/run.sh).

usage: allan_pandas.py FILE.csv
"""
import json
import sys
import time

import allantools
import numpy as np
import pandas as pd


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    df = pd.read_csv(sys.argv[1], usecols=["t_s", "volts"], dtype=np.float64, comment="#")
    t1 = time.perf_counter()
    t = df["t_s"].to_numpy()
    y = df["volts"].to_numpy()
    tau0 = float(np.median(np.diff(t)))
    taus, dev, _err, ns = allantools.oadev(y, rate=1.0 / tau0, data_type="freq", taus="octave")
    t2 = time.perf_counter()
    json.dump(
        {
            "rows": int(len(y)),
            "tau0_s": tau0,
            "curve": [
                {"tau_s": float(a), "deviation": float(d), "n": int(n)}
                for a, d, n in zip(taus, dev, ns)
            ],
        },
        sys.stdout,
        indent=1,
    )
    print(file=sys.stdout)
    print(f"read_csv {t1 - t0:.3f} s, oadev {t2 - t1:.3f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
