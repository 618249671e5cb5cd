"""Compile the shipped office map, simulate a 270-degree scan at a pose the
localizer is not told, and find that pose again.

    python python/examples/quickstart.py [MAP.yaml]
"""
import sys
import tempfile
from pathlib import Path

import refloc

root = Path(__file__).resolve().parents[2]
map_yaml = Path(sys.argv[1]) if len(sys.argv) > 1 else root / "maps" / "office-demo" / "office-demo.yaml"
with tempfile.TemporaryDirectory() as tmp:
    out = Path(tmp) / "map.refdb"
    print(f"compiling {map_yaml.name}: {refloc.build(map_yaml, out)} reference sites")
    db = refloc.RefDb(out)
    # A free pose: the first reference site's position, heading 1 rad.
    ranges, angle_min, inc = db.simulate_scan(*db.site_position(0), 1.0, beams=1081, fov=4.712)
    fix = refloc.Localizer(db).localize(ranges, angle_min, inc, range_max=30.0)
    print(fix)
    for h in fix.hypotheses:
        print("  ", h)
    print("covariance (m, rad):\n", fix.covariance)
