#!/bin/sh
# Makes the README's two pictures from a fresh simulated calibration and drift record:
#   certificate.png  the top of a calibration report's first page (report.html)
#   allan.png        the σ(τ) plot of a drift record's Allan page (allan.html)
#   series.png       a temperature series' K(T) and temperature history (series.html)
# Run from anywhere: docs/img/make.sh. Needs chromium (apt-get install chromium) and python3.
# GYROCAL names the binary to use (default: `cargo run -q -p gyrocal --`, the dev build).
# Both runs are on the simulated bench in virtual time (seconds); their directories are
# temporary, and nothing is written to a catalog (GYROCAL_CATALOG=off).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
gyrocal=${GYROCAL:-cargo run -q --manifest-path $root/Cargo.toml -p gyrocal --}
chromium=${CHROMIUM:-chromium}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export GYROCAL_CATALOG=off

# a calibration of a named gyro (the serial on the first page)
# (run from the temporary directory, so that the page shows its run directory as runs/paper)
(cd "$tmp" && $gyrocal run "$root/configs/paper.toml" --simulate --dut-serial HRG-0042 \
    -o runs/paper >/dev/null 2>&1)
# the drift record: 3 h at rest, 167 segments, analysed at the end (allan.html)
(cd "$tmp" && $gyrocal run "$root/configs/drift.toml" --simulate -o runs/drift >/dev/null 2>&1)
# the temperature series: 25 -> -20 -> 60 -> 25 °C, a sweep at each (nine hours, virtual time)
(cd "$tmp" && $gyrocal run "$root/configs/series.toml" --simulate -o runs/series >/dev/null 2>&1)

shot() { # shot OUT.png WIDTH,HEIGHT URL
    "$chromium" --headless --no-sandbox --disable-gpu --hide-scrollbars \
        --force-device-scale-factor=1 --screenshot="$1" --window-size="$2" "$3" \
        >/dev/null 2>&1
}

# the report's first screen: title, the SIMULATED banner, the record and the results table
shot "$here/certificate.png" 1000,975 "file://$tmp/runs/paper/report.html"

# the Allan page's first plot (σ(τ)), alone on a page of its own size
python3 - "$tmp/runs/drift/allan.html" "$tmp/allan-plot.html" <<'PY'
import re, sys
page = open(sys.argv[1], encoding="utf-8").read()
start = page.index("<svg")
end = page.index("</svg>", start) + len("</svg>")
svg = page[start:end]
open(sys.argv[2], "w", encoding="utf-8").write(
    '<!DOCTYPE html><html><head><meta charset="utf-8"><style>body{margin:0}</style></head>'
    "<body>" + svg + "</body></html>")
m = re.match(r'<svg width="(\d+)" height="(\d+)"', svg)
print(f"{m.group(1)},{m.group(2)}" if m else "800,520", file=open(sys.argv[2] + ".size", "w"))
PY
shot "$here/allan.png" "$(cat "$tmp/allan-plot.html.size")" "file://$tmp/allan-plot.html"

# the series' K(T) plot over its temperature history, one page of their size
python3 - "$tmp/runs/series/series.html" "$tmp/series-plots.html" <<'PY'
import re, sys
page = open(sys.argv[1], encoding="utf-8").read()
svgs, w, h = [], 0, 0
for fid in ("plot-k", "plot-history"):
    start = page.index("<svg", page.index(f'id="{fid}"'))
    svg = page[start:page.index("</svg>", start) + len("</svg>")]
    m = re.match(r'<svg width="(\d+)" height="(\d+)"', svg)
    sw, sh = (int(m.group(1)), int(m.group(2))) if m else (800, 450)
    w, h = max(w, sw), h + sh
    svgs.append("<div>" + svg + "</div>")
open(sys.argv[2], "w", encoding="utf-8").write(
    '<!DOCTYPE html><html><head><meta charset="utf-8"><style>body{margin:0}</style></head>'
    "<body>" + "".join(svgs) + "</body></html>")
print(f"{w},{h}", file=open(sys.argv[2] + ".size", "w"))
PY
shot "$here/series.png" "$(cat "$tmp/series-plots.html.size")" "file://$tmp/series-plots.html"

for f in certificate.png allan.png series.png; do
    size=$(wc -c <"$here/$f")
    echo "$f: $size bytes"
    if [ "$size" -gt 256000 ]; then
        echo "$f is over 250 KB: crop it (the window size above)" >&2
        exit 1
    fi
done
