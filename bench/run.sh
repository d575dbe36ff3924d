#!/usr/bin/env bash
# gyrocal's side-by-side benchmarks: whole-process time and peak memory (/usr/bin/time -v) of
# the gyrocal CLI and of the Python scripts doing the same work, on the same generated files.
# bench/README.md says what each section measures and how to read the table.
#
# usage: bench/run.sh [SECTION...]      sections: allan (default: every section)
# environment:
#   GYROCAL      the gyrocal binary (default: target/release/gyrocal, built if missing:
#                about a quarter of an hour on two cores)
#   BENCH_DATA   where the generated files and the outputs go (default /tmp/gyrocal-bench;
#                the allan section's 10^8-row file is 2.6 GB)
#   ALLAN_ROWS   the allan section's sizes (default "1e7 1e8")
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
# prints a row of the table: label, wall seconds, user+system seconds, peak resident MiB.
timed() {
    local label="$1"
    shift
    /usr/bin/time -v "$@" > "$data/$label.out" 2> "$data/$label.time"
    awk -v label="$label" -F': ' '
        /Elapsed \(wall clock\)/ { n = split($2, p, ":"); wall = (n == 3) ? p[1]*3600 + p[2]*60 + p[3] : p[1]*60 + p[2] }
        /User time/ { cpu += $2 }
        /System time/ { cpu += $2 }
        /Maximum resident set size/ { rss = $2 / 1024 }
        END { printf "| %-28s | %8.2f | %8.2f | %8.0f |\n", label, wall, cpu, rss }
    ' "$data/$label.time"
}

header() {
    echo
    echo "## $1"
    echo
    echo "| run                          |   wall s |    cpu s | peak MiB |"
    echo "|------------------------------|----------|----------|----------|"
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

SECTIONS=(allan)

selected=("$@")
[[ ${#selected[@]} -gt 0 ]] || selected=("${SECTIONS[@]}")
for s in "${selected[@]}"; do
    if ! declare -F "section_$s" > /dev/null; then
        echo "bench/run.sh: no section $s (sections: ${SECTIONS[*]})" >&2
        exit 2
    fi
    "section_$s"
done
