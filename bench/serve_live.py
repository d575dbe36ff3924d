#!/usr/bin/env python3
"""The live view's figures (issue 27): the latency from a step's end (its steps.csv row
written) to the server-sent event reaching a client, over files (the server polls the roots
every 250 ms) and over PostgreSQL NOTIFY; and what 50 event-stream clients cost a run.

usage:
  serve_live.py latency GYROCAL [POSTGRES_URL]   # ≥ 20 steps each way; median and max
  serve_live.py cost GYROCAL [REPS]              # the paper plan, 0 vs 50 clients, REPS each

Latency: a paced simulated run (--sim-time-scale 2) of 24 rates; a thread polls steps.csv every
2 ms and notes when each row appears; the event-stream thread notes when each event naming the
run arrives; a row's latency is the first event after it (the run writes live.json and
publishes to the catalog right after the row, so the first event after the row carries it).

Cost: `gyrocal run configs/paper.toml --simulate --json` (virtual time: the printed ratio to
the physical bound is on the run clock) under a separate `gyrocal serve` over the run's root,
with 0 or 50 clients holding /api/events, and with `--serve` in-process plus 50 clients; the
wall time of the whole process and the ratio it prints. Standard library only.
"""
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def env():
    e = {k: v for k, v in os.environ.items()
         if not (k.startswith("GYROCAL_") or k.startswith("XDG_") or k in ("HOME", "RUST_LOG"))}
    e["GYROCAL_CATALOG"] = "off"
    return e


def start_serve(gyrocal, args, cwd):
    p = subprocess.Popen([gyrocal, "serve", "--port", "0"] + args, cwd=cwd, env=env(),
                         stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    line = p.stdout.readline()
    port = int(re.search(r"http://[^:]+:(\d+)/", line).group(1))
    return p, port


def sse(port, name, arrivals, stop):
    s = socket.create_connection(("127.0.0.1", port))
    s.sendall(b"GET /api/events HTTP/1.1\r\nHost: x\r\n\r\n")
    s.settimeout(0.5)
    buf = b""
    while not stop.is_set():
        try:
            chunk = s.recv(65536)
        except socket.timeout:
            continue
        if not chunk:
            break
        now = time.monotonic()
        buf += chunk
        while b"\n\n" in buf:
            ev, buf = buf.split(b"\n\n", 1)
            if name is None or name.encode() in ev or b'"all":true' in ev:
                arrivals.append(now)
    s.close()


def rows(path, seen, stop):
    last = 0
    while not stop.is_set():
        try:
            with open(path, "rb") as f:
                n = sum(1 for l in f.read().splitlines() if l and not l.startswith(b"#")) - 1
        except OSError:
            n = 0
        now = time.monotonic()
        while last < n:
            last += 1
            seen.append(now)
        time.sleep(0.002)


def latency_once(gyrocal, how, url, tmp):
    plan = os.path.join(tmp, "lat.toml")
    text = open(os.path.join(ROOT, "configs/quick.toml")).read()
    # 24 rates within the quick plan's table (max 20 °/s)
    rates = ", ".join(str(r) for r in [0, 1, -1, 2, -2, 3, -3, 5, -5, 7, -7, 10, -10, 12, -12,
                                       15, -15, 17, -17, 19, -19, 20, -20, 0])
    text = text.replace("rates_dps = [0, 1, -1, 10, -10]", f"rates_dps = [{rates}]")
    open(plan, "w").write(text)
    name = f"lat-{how}-{os.getpid()}-{int(time.time() * 1000)}"
    root = os.path.join(tmp, "root-" + how)
    os.makedirs(root, exist_ok=True)
    view = os.path.join(tmp, "view")
    os.makedirs(view, exist_ok=True)
    if how == "files":
        serve, port = start_serve(gyrocal, ["--no-catalog", "--root", root], view)
        catalog = "off"
    else:
        serve, port = start_serve(gyrocal, ["--catalog", url], view)
        catalog = url
    arrivals, seen, stop = [], [], threading.Event()
    t1 = threading.Thread(target=sse, args=(port, name, arrivals, stop), daemon=True)
    t1.start()
    time.sleep(0.5)
    out = os.path.join(root, name)
    t2 = threading.Thread(target=rows, args=(os.path.join(out, "steps.csv"), seen, stop),
                          daemon=True)
    t2.start()
    subprocess.run([gyrocal, "run", plan, "--simulate", "--sim-time-scale", "2", "--catalog",
                    catalog, "--out", out], env=env(), check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)
    stop.set()
    serve.kill()
    serve.wait()
    lat = []
    for t in seen:
        after = [a for a in arrivals if a >= t]
        if after:
            lat.append((after[0] - t) * 1000.0)
    return lat, len(seen)


def latency(gyrocal, url):
    with tempfile.TemporaryDirectory() as tmp:
        ways = [("files", None)] + ([("postgres", url)] if url else [])
        for how, u in ways:
            lat, n = latency_once(gyrocal, how, u, tmp)
            print(f"{how}: {len(lat)} of {n} steps: median {statistics.median(lat):.1f} ms, "
                  f"max {max(lat):.1f} ms, min {min(lat):.1f} ms")


def hold(port, n, stop):
    socks = []
    for _ in range(n):
        s = socket.create_connection(("127.0.0.1", port))
        s.sendall(b"GET /api/events HTTP/1.1\r\nHost: x\r\n\r\n")
        s.setblocking(False)
        socks.append(s)
    while not stop.is_set():
        for s in socks:
            try:
                s.recv(65536)
            except (BlockingIOError, OSError):
                pass
        time.sleep(0.02)
    for s in socks:
        s.close()


def paper_run(gyrocal, out, extra, clients_on_serve=0):
    t0 = time.monotonic()
    p = subprocess.Popen([gyrocal, "run", os.path.join(ROOT, "configs/paper.toml"), "--simulate",
                          "--json", "--out", out] + extra, env=env(),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stop = threading.Event()
    if "--serve" in extra:
        # the in-process view's URL comes on stderr before the first step
        line = p.stderr.readline()
        while line and not line.startswith("live view: "):
            line = p.stderr.readline()
        port = int(re.search(r"http://[^:]+:(\d+)/", line).group(1))
        if clients_on_serve:
            threading.Thread(target=hold, args=(port, clients_on_serve, stop),
                             daemon=True).start()
    stdout, _ = p.communicate()
    wall = time.monotonic() - t0
    stop.set()
    doc = json.loads(stdout)
    ratio = doc.get("timing", {}).get("ratio") if isinstance(doc.get("timing"), dict) else None
    return wall, ratio, doc


def cost(gyrocal, reps):
    with tempfile.TemporaryDirectory() as tmp:
        root = os.path.join(tmp, "runs")
        os.makedirs(root)
        serve, port = start_serve(gyrocal, ["--no-catalog", "--root", root], tmp)
        results = {}
        for label, clients in [("separate server, 0 clients", 0),
                               ("separate server, 50 clients", 50)]:
            stop = threading.Event()
            if clients:
                threading.Thread(target=hold, args=(port, clients, stop), daemon=True).start()
                time.sleep(1.0)
            walls, ratios = [], []
            for i in range(reps):
                w, r, _ = paper_run(gyrocal, os.path.join(root, f"{clients}-{i}"), [])
                walls.append(w)
                ratios.append(r)
            stop.set()
            results[label] = (walls, ratios)
        serve.kill()
        serve.wait()
        for clients in (0, 50):
            walls, ratios = [], []
            for i in range(reps):
                w, r, _ = paper_run(gyrocal, os.path.join(root, f"inproc-{clients}-{i}"),
                                    ["--serve"], clients)
                walls.append(w)
                ratios.append(r)
            results[f"--serve in-process, {clients} clients"] = (walls, ratios)
        for label, (walls, ratios) in results.items():
            sd = statistics.stdev(walls) if len(walls) > 1 else 0.0
            print(f"{label}: wall {statistics.mean(walls):.3f} s ± {sd:.3f} (min "
                  f"{min(walls):.3f}, max {max(walls):.3f}); ratio printed {sorted(set(ratios))}")


def main():
    if len(sys.argv) < 3 or sys.argv[1] not in ("latency", "cost"):
        print(__doc__, file=sys.stderr)
        return 2
    if sys.argv[1] == "latency":
        latency(sys.argv[2], sys.argv[3] if len(sys.argv) > 3 else None)
    else:
        cost(sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 5)
    return 0


if __name__ == "__main__":
    sys.exit(main())
