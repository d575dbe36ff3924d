#!/bin/sh
# Makes the pictures of `gyrocal serve` (the lab's live view) for README.md, taken in headless
# Chromium against a paced simulated calibration:
#   serve-dashboard.png  the dashboard while the run is under way (phase, step n/N, ETA, table)
#   serve-run.png        that run's page mid-run: the step table filling in, the fit line and
#                        the residuals drawn from the steps so far
#   serve-gyro.png       the gyro page of its serial: the catalog's history with the trends
#                        (simulated runs included: ?include_simulated=1)
# Run from anywhere: docs/img/make-serve.sh. Needs chromium (apt-get install chromium) and
# python3. GYROCAL names the binary (default: the dev build through `cargo run`). Everything
# is in a temporary directory with a catalog of its own (SQLite), removed at the end.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
gyrocal=${GYROCAL:-cargo run -q --manifest-path $root/Cargo.toml -p gyrocal --}
chromium=${CHROMIUM:-chromium}
tmp=$(mktemp -d)
serve_pid=""
run_pid=""
cleanup() {
    [ -n "$run_pid" ] && kill "$run_pid" 2>/dev/null || true
    [ -n "$serve_pid" ] && kill "$serve_pid" 2>/dev/null || true
    wait 2>/dev/null || true
    rm -rf "$tmp"
}
trap cleanup EXIT
export GYROCAL_CATALOG="sqlite:$tmp/catalog.sqlite" XDG_CONFIG_HOME="$tmp/config"
cd "$tmp"

# three earlier calibrations of the gyro, for its history (virtual time: a second each), each
# with other simulated noise (the plan's [simulation] seed), as three days at the bench would be
for i in 2 3 4; do
    sed "s/^seed = 1$/seed = $i/" "$root/configs/paper.toml" >"$tmp/paper-$i.toml"
    $gyrocal run "$tmp/paper-$i.toml" --simulate --dut-serial HRG-0042 \
        -o "runs/earlier-$i" >/dev/null 2>&1
done

$gyrocal serve --root runs --port 0 >"$tmp/serve.out" 2>"$tmp/serve.err" &
serve_pid=$!
url=""
for _ in $(seq 1 100); do
    url=$(sed -n 's/^gyrocal serve: \(http[^ ]*\)$/\1/p' "$tmp/serve.out")
    [ -n "$url" ] && break
    sleep 0.1
done
[ -n "$url" ] || { echo "gyrocal serve did not start: $(cat "$tmp/serve.err")" >&2; exit 1; }

# the calibration the pictures follow: the paper's 19 rates paced at 20x (about 30 s)
$gyrocal run "$root/configs/paper.toml" --simulate --sim-time-scale 20 --dut-serial HRG-0042 \
    -o runs/paper-live >/dev/null 2>&1 &
run_pid=$!

# waits until the run's live state has recorded $1 steps
steps_done() {
    python3 - "$tmp/runs/paper-live/live.json" "$1" <<'PY'
import json, sys, time
for _ in range(1200):
    try:
        if json.load(open(sys.argv[1]))["steps_done"] >= int(sys.argv[2]):
            sys.exit(0)
    except (OSError, ValueError, KeyError):
        pass
    time.sleep(0.05)
sys.exit("the run did not reach step " + sys.argv[2])
PY
}

shot() { # shot OUT.png WIDTH,HEIGHT URL
    "$chromium" --headless --no-sandbox --disable-gpu --hide-scrollbars \
        --force-device-scale-factor=1 --timeout=3000 \
        --screenshot="$1" --window-size="$2" "$3" >/dev/null 2>&1
}

steps_done 5
shot "$here/serve-dashboard.png" 1000,560 "$url"
steps_done 12
shot "$here/serve-run.png" 1000,1500 "${url%/}/run/0/paper-live"
wait "$run_pid" || true
run_pid=""
shot "$here/serve-gyro.png" 1200,1250 "${url%/}/gyro/HRG-0042?include_simulated=1"

for f in serve-dashboard.png serve-run.png serve-gyro.png; do
    size=$(wc -c <"$here/$f")
    echo "$f: $size bytes"
    if [ "$size" -gt 256000 ]; then
        echo "$f is over 250 KB: crop it (the window size above)" >&2
        exit 1
    fi
done
