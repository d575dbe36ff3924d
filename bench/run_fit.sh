#!/usr/bin/env bash
# The fit section of gyrocal's side-by-side benchmarks (issue 24): whole-process time and peak
# memory (/usr/bin/time -v) of `gyrocal fit FILE --json` and of pandas + numpy lstsq
# (bench/fit_numpy.py: linear, quadratic, cubic and their residuals) on the same generated
# files, the size of gyrocal's JSON, and the two sides' K, K0 and SSE compared.
#
# Written beside bench/run.sh (the csv helper's, with the allan section): section_fit is meant
# to be one of its SECTIONS; until they are joined it runs on its own.
#
# usage: bench/run_fit.sh
# environment:
#   GYROCAL      the gyrocal binary (default: $CARGO_TARGET_DIR or target/release/gyrocal,
#                built if missing: about a quarter of an hour on two cores)
#   BENCH_DATA   where the generated files and the outputs go (default /tmp/gyrocal-bench;
#                the 10^7-point file is 205 MB)
#   FIT_POINTS   the continuous-rate sizes (default "1e6 1e7")
#   BENCH_VENV   a Python venv with numpy and pandas (bench/setup.sh makes one; default
#                /tmp/gyrocal-bench-venv)
#
# Cases: continuous rates at 10^6 and 10^7 points (the 10^7 gyrocal run under a 2 GiB
# address-space cap, `ulimit -v 2097152`, as the issue asks), and the paper's 19-rate
# schedule at 10^6 points.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/.." && pwd)"
data="${BENCH_DATA:-/tmp/gyrocal-bench}"
mkdir -p "$data"
venv="${BENCH_VENV:-/tmp/gyrocal-bench-venv}"
if [[ -x "$venv/bin/python" ]]; then
    python="$venv/bin/python"
elif [[ -x "$here/setup.sh" ]]; then
    python="$("$here/setup.sh" | tail -n 1)/bin/python"
else
    python=python3
fi

gyrocal_bin() {
    if [[ -n "${GYROCAL:-}" ]]; then
        echo "$GYROCAL"
        return
    fi
    local target="${CARGO_TARGET_DIR:-$repo/target}"
    if [[ ! -x "$target/release/gyrocal" ]]; then
        (cd "$repo" && cargo build --release -p gyrocal --bin gyrocal >&2)
    fi
    echo "$target/release/gyrocal"
}

# timed LABEL CMD...: runs CMD under /usr/bin/time -v, its stdout to $data/LABEL.out, and
# prints a row of the table: label, wall seconds, user+system seconds, peak resident MiB,
# bytes of stdout.
timed() {
    local label="$1"
    shift
    /usr/bin/time -v "$@" > "$data/$label.out" 2> "$data/$label.time"
    local bytes
    bytes="$(stat -c %s "$data/$label.out")"
    awk -v label="$label" -v bytes="$bytes" -F': ' '
        /Elapsed \(wall clock\)/ { n = split($2, p, ":"); wall = (n == 3) ? p[1]*3600 + p[2]*60 + p[3] : p[1]*60 + p[2] }
        /User time/ { cpu += $2 }
        /System time/ { cpu += $2 }
        /Maximum resident set size/ { rss = $2 / 1024 }
        END { printf "| %-34s | %8.2f | %8.2f | %8.0f | %12d |\n", label, wall, cpu, rss, bytes }
    ' "$data/$label.time"
}

header() {
    echo
    echo "## $1"
    echo
    echo "| run                                |   wall s |    cpu s | peak MiB | stdout bytes |"
    echo "|------------------------------------|----------|----------|----------|--------------|"
}

# fit: `gyrocal fit FILE --json` against pandas + numpy lstsq on continuous-rate data
# (bench/gen_fit_continuous.py) and on a 19-rate schedule (bench/gen_fit_schedule.py).
section_fit() {
    local gyrocal
    gyrocal="$(gyrocal_bin)"
    header "fit"
    local cases=()
    for n in ${FIT_POINTS:-1e6 1e7}; do
        cases+=("continuous:$n")
    done
    cases+=("schedule:1e6")
    for case in "${cases[@]}"; do
        local kind="${case%%:*}" n="${case##*:}"
        local csv="$data/fit_${kind}_$n.csv"
        [[ -s "$csv" ]] || "$python" "$here/gen_fit_$kind.py" "$n" "$csv"
        cat "$csv" > /dev/null # both sides start from the page cache
        if [[ "$n" == 1e7 ]]; then
            # the issue's condition: a 2 GiB address-space cap
            timed "gyrocal_fit_${kind}_$n" bash -c 'ulimit -v 2097152 && exec "$0" fit "$1" --json' "$gyrocal" "$csv"
        else
            timed "gyrocal_fit_${kind}_$n" "$gyrocal" fit "$csv" --json
        fi
        timed "numpy_fit_${kind}_$n" "$python" "$here/fit_numpy.py" "$csv"
        "$python" "$here/fit_compare.py" "$data/gyrocal_fit_${kind}_$n.out" \
            "$data/numpy_fit_${kind}_$n.out" | tail -n 1
    done
}

section_fit
