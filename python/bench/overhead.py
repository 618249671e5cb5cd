"""Python overhead of refloc.Localizer.localize against the runtime alone
(`mapc localize --threads 1` time_us) on the same simulated scans, one run.

    python python/bench/overhead.py DB.refdb target/release/mapc

Give a release mapc (the debug profile leaves refloc unoptimized) and the
extension built in release (pip install ./python, maturin develop --release).
Figures: docs/performance.md, "Python binding overhead".
"""
import json, math, statistics, subprocess, sys, time
import tempfile
import numpy as np, refloc
SCANS = tempfile.mkdtemp() + '/scans.jsonl'
db = refloc.RefDb(sys.argv[1]); mapc = sys.argv[2]
loc = refloc.Localizer(db)
scans = []
for i in range(0, db.site_count, max(1, db.site_count // 100)):
    x, y = db.site_position(i)
    r, amin, inc = db.simulate_scan(x + 0.1, y - 0.1, 0.3 + i, beams=362)
    scans.append((r, amin, inc))
with open(SCANS, 'w') as f:
    for k, (r, amin, inc) in enumerate(scans):
        f.write(json.dumps({"id": str(k), "angle_min": amin, "angle_increment": inc, "range_min": 0.0,
                            "range_max": 30.0, "ranges": [None if not math.isfinite(v) else float(v) for v in r]}) + "\n")
py = []
for rep in range(3):
    t = []
    for r, amin, inc in scans:
        t0 = time.perf_counter(); loc.localize(r, amin, inc, range_max=30.0); t.append(time.perf_counter() - t0)
    py.append(t)
pym = [min(v) for v in zip(*py)]
rt = []
for rep in range(3):
    out = subprocess.run([mapc, "localize", sys.argv[1], SCANS, "--threads", "1", "--no-candidates"],
                         capture_output=True, text=True, check=True).stdout
    rt.append([json.loads(l)["time_us"] * 1e-6 for l in out.splitlines()])
rtm = [min(v) for v in zip(*rt)]
a, b = statistics.median(pym), statistics.median(rtm)
print(f"{len(scans)} scans, fastest of 3 each: Python Localizer.localize median {a*1e3:.3f} ms, runtime alone (mapc localize time_us) median {b*1e3:.3f} ms, overhead {100*(a/b-1):+.1f}%")
