#!/usr/bin/env python3
"""Reference vectors for gyrocal-allan, generated once with allantools from PyPI.

    pip install allantools==2024.6 numpy scipy
    python3 make_reference.py            # writes reference.json next to this file

Everything the Rust tests compare against comes from allantools itself (deviations, number of
terms, edf_greenhall, autocorr_noise_id, confidence intervals); the input series are stored in
the JSON so the Rust side needs no random number generator of numpy's.

Rate ("freq") data y with sample interval tau0: allantools integrates it with
frequency2phase (mean removed, cumsum * tau0, leading 0), as gyrocal-allan does.
"""
import json
import os
import sys

import numpy as np
import scipy
import allantools as at
from allantools import ci

TAU0 = 0.1  # s
N = 3000

rng = np.random.default_rng(20240615)


def white_fm(n):
    return 3.0 + 0.5 * rng.standard_normal(n)


def flicker_fm(n):
    # flicker-ish: sum of first-order Gauss-Markov processes with correlation times spread
    # over decades (equal power per decade) plus a little white noise
    y = 0.05 * rng.standard_normal(n)
    for tc in [1.0, 10.0, 100.0, 1000.0]:
        a = np.exp(-1.0 / tc)
        w = rng.standard_normal(n) * np.sqrt(1 - a * a)
        g = np.zeros(n)
        acc = 0.0
        for i in range(n):
            acc = a * acc + w[i]
            g[i] = acc
        y += g
    return -1.5 + y


def rw_fm(n):
    return 10.0 + np.cumsum(0.01 * rng.standard_normal(n)) + 0.2 * rng.standard_normal(n)


series = {"white_fm": white_fm(N), "flicker_fm": flicker_fm(N), "rw_fm": rw_fm(N)}

ESTIMATORS = {"oadev": at.oadev, "adev": at.adev, "mdev": at.mdev, "ohdev": at.ohdev,
              "totdev": at.totdev}
CI_TYPE = {"oadev": "oadev", "adev": "adev", "mdev": "mdev", "ohdev": "ohdev"}
# the 68 % interval is allantools' default, erf(1/sqrt(2))
CIS = {"ci68": ci.ONE_SIGMA_CI, "ci95": 0.95}

out = {
    "generator": "make_reference.py",
    "allantools": at.__version__,
    "numpy": np.__version__,
    "scipy": scipy.__version__,
    "tau0": TAU0,
    "series": {},
}

for name, y in series.items():
    rate = 1.0 / TAU0
    x = at.frequency2phase(y, rate)
    entry = {"y": [float(v) for v in y], "curves": {}}
    for est, fn in ESTIMATORS.items():
        tau_sets = ["octave", "decade"] + (["all"] if name == "white_fm" else [])
        for taus in tau_sets:
            t, d, _e, n = fn(y, rate=rate, data_type="freq", taus=taus)
            pts = []
            for k in range(len(t)):
                m = int(round(t[k] * rate))
                p = {"tau": float(t[k]), "m": m, "dev": float(d[k]), "n": int(n[k])}
                if taus == "octave":
                    dmax = 3 if est == "ohdev" else 2
                    try:
                        a_int, a, dd, rho = ci.autocorr_noise_id(x, m, data_type="phase",
                                                                 dmin=0, dmax=dmax)
                        p["alpha"] = int(a_int)
                        p["rho"] = float(rho)
                    except NotImplementedError:
                        p["alpha"] = None
                    if est in CI_TYPE:
                        for key, c in CIS.items():
                            try:
                                lo, hi = ci.confidence_interval_noiseID(
                                    x, d[k], m, dev_type=CI_TYPE[est], data_type="phase", ci=c)
                                p[key] = [float(lo), float(hi)]
                            except (NotImplementedError, AssertionError):
                                p[key] = None
                pts.append(p)
            entry["curves"][f"{est}/{taus}"] = pts
    out["series"][name] = entry

# edf_greenhall on a grid that reaches every branch (cases 1.1-1.3, 2.1a/b-2.3, 3.1-3.3, 4.2)
edf = []
for d in (2, 3):
    for alpha in range(2, -5, -1):
        if alpha + 2 * d <= 1:
            continue
        for n_phase in (1001, 100001, 10000001):
            for m in (1, 2, 8, 32, 256, 4096, 100000):
                for overlapping, modified in ((False, False), (True, False), (True, True)):
                    if 3 * m > n_phase:
                        continue
                    try:
                        v = ci.edf_greenhall(alpha=alpha, d=d, m=m, N=n_phase,
                                             overlapping=overlapping, modified=modified)
                    except (NotImplementedError, AssertionError):
                        continue
                    v = float(v)
                    if not np.isfinite(v):
                        continue
                    edf.append({"alpha": alpha, "d": d, "m": m, "n": n_phase,
                                "overlapping": overlapping, "modified": modified, "edf": v})
out["edf_greenhall"] = edf

# edf_totdev (NIST SP 1065 Table 7) for N rate samples
out["edf_totdev"] = [{"n": n, "m": m, "alpha": a, "edf": float(ci.edf_totdev(n, m, a))}
                     for n in (1000, 3000) for m in (1, 4, 64, 512) for a in (0, -1, -2)]

# chi-squared quantiles (scipy) for the interval arithmetic
out["chi2_ppf"] = [{"p": p, "df": df, "x": float(scipy.stats.chi2.ppf(p, df))}
                   for p in (0.025, (1 - ci.ONE_SIGMA_CI) / 2, (1 + ci.ONE_SIGMA_CI) / 2, 0.975)
                   for df in (0.7, 1.0, 2.5, 7.3, 30.0, 612.4, 1.0e5)]

path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "reference.json")
with open(path, "w") as f:
    json.dump(out, f, separators=(",", ":"))
print(path, os.path.getsize(path), "bytes", file=sys.stderr)
