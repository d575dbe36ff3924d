#!/usr/bin/env bash
# gyrocal's side-by-side benchmarks: whole-process time and peak memory (/usr/bin/time -v) of
# the gyrocal CLI and of the Python scripts doing the same work, on the same generated files.
# bench/README.md says what each section measures and how to read the table.
#
# usage: bench/run.sh [SECTION...]      sections: fit, allan (default: every section)
# environment:
#   GYROCAL      the gyrocal binary (default: target/release/gyrocal, built if missing:
#                about a quarter of an hour on two cores)
#   BENCH_DATA   where the generated files and the outputs go (default /tmp/gyrocal-bench;
#                the allan section's 10^8-row file is 2.6 GB)
#   ALLAN_ROWS   the allan section's sizes (default "1e7 1e8")
#   FIT_POINTS   the fit section's continuous-rate sizes (default "1e6 1e7"; the 10^7 gyrocal
#                run under a 2 GiB address-space cap, `ulimit -v 2097152`, as issue 24 asks;
#                the 19-rate schedule is always 10^6 points)
#   BENCH_VENV   the Python venv (bench/setup.sh; default /tmp/gyrocal-bench-venv)
#
# Each section is independent: a function section_NAME, listed in SECTIONS.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/.." && pwd)"
data="${BENCH_DATA:-/tmp/gyrocal-bench}"
mkdir -p "$data"
python="$("$here/setup.sh" | tail -n 1)/bin/python"

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

# allan: `gyrocal allan FILE --json` against pandas read_csv + allantools oadev (octave),
# on records of t_s,volts (bench/gen_allan.py); then the curves compared (whole record: the
# warm-up detection off) and, for the largest size, the bounded-memory path (--streaming).
section_allan() {
    local gyrocal
    gyrocal="$(gyrocal_bin)"
    header "allan"
    for n in ${ALLAN_ROWS:-1e7 1e8}; do
        local csv="$data/allan_$n.csv"
        [[ -s "$csv" ]] || "$python" "$here/gen_allan.py" "$n" "$csv"
        cat "$csv" > /dev/null # both sides start from the page cache
        timed "gyrocal_allan_$n" "$gyrocal" allan "$csv" --json
        timed "gyrocal_allan_${n}_streaming" "$gyrocal" allan "$csv" --json --streaming
        timed "pandas_allantools_$n" "$python" "$here/allan_pandas.py" "$csv"
        "$gyrocal" allan "$csv" --json --warmup-window 0 > "$data/gyrocal_allan_${n}_whole.json"
        "$python" "$here/allan_compare.py" "$data/gyrocal_allan_${n}_whole.json" \
            "$data/pandas_allantools_$n.out" | tail -n 1
    done
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

SECTIONS=(fit allan)

selected=("$@")
[[ ${#selected[@]} -gt 0 ]] || selected=("${SECTIONS[@]}")
for s in "${selected[@]}"; do
    if ! declare -F "section_$s" > /dev/null; then
        echo "bench/run.sh: no section $s (sections: ${SECTIONS[*]})" >&2
        exit 2
    fi
    "section_$s"
done
