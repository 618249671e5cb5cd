#!/usr/bin/env python3
"""An occupancy grid (ROS map_server PGM + YAML) made from a CARMEN log's
own corrected poses, and the truth file of every scan in that map's frame.

  scripts/map-from-log.py LOG.gz OUT_DIR NAME [--res 0.05] [--max-range 25]
                          [--map-scans START:END] [--fov 180]

Writes OUT_DIR/NAME.pgm, NAME.yaml and NAME-truth.txt (`mapc localize
--truth` format: `k ipc_timestamp logger_timestamp x y theta`, the log's
corrected pose of its k-th FLASER line, in metres and radians). The map is
made from the FLASER lines START..END (Python slice, default all): every
beam shorter than --max-range marks its end cell hit and the cells it
crosses (up to 1.5 cells short of the end) seen free, once per scan; a cell
is occupied when hit at least twice and in at least 30% of the scans that
saw it, free when seen and not occupied, unknown otherwise.

It is an independent mapper (numpy only, no refloc code), for measuring
localization where the map and the truth come from the same SLAM run, so
the map agrees with the truth (docs/results.md, "Maps made from the logs
themselves"). With --map-scans covering half of the log, the other half's
scans are queries from another time of the same building (people moved,
doors opened and shut, and parts the map's half never saw).
"""
import argparse
import gzip
import math
import os
import sys

import numpy as np


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", help="CARMEN log (.gz or plain) with FLASER lines")
    ap.add_argument("out", help="output directory")
    ap.add_argument("name", help="stem of the output files")
    ap.add_argument("--res", type=float, default=0.05, help="cell size (m)")
    ap.add_argument("--max-range", type=float, default=25.0,
                    help="longest beam drawn (m); longer ones and no-returns are skipped")
    ap.add_argument("--map-scans", default=":", help="FLASER lines the map is made from (START:END)")
    ap.add_argument("--fov", type=float, default=180.0, help="field of view (degrees), first beam at -fov/2")
    return ap.parse_args()


def read_flaser(path):
    opener = gzip.open if path.endswith(".gz") else open
    scans = []
    with opener(path, "rt") as f:
        for line in f:
            t = line.split()
            if not t or t[0] != "FLASER":
                continue
            n = int(t[1])
            ranges = np.array([float(v) for v in t[2:2 + n]])
            x, y, th = (float(v) for v in t[2 + n:5 + n])
            scans.append((ranges, x, y, th, t[8 + n], t[10 + n]))
    return scans


def bearing_step(n, fov):
    """CARMEN's rule (as refloc's scanio): 1, 0.5 or 0.25 degrees when n
    beams fill the field of view to within a step, else fov / (n - 1)."""
    for deg in (1.0, 0.5, 0.25):
        s = math.radians(deg)
        if n * s >= fov - 1e-3 * s and (n - 1) * s <= fov + 1e-3 * s:
            return s
    return fov / max(n - 1, 1)


def main():
    a = parse_args()
    if a.res <= 0 or a.max_range <= 0:
        sys.exit("map-from-log: --res and --max-range must be positive")
    scans = read_flaser(a.log)
    if not scans:
        sys.exit(f"map-from-log: {a.log} has no FLASER lines")
    parts = (a.map_scans.split(":") + [""])[:2]
    use = scans[slice(*[int(v) if v else None for v in parts])]
    if not use:
        sys.exit(f"map-from-log: --map-scans {a.map_scans} selects no scan of {len(scans)}")
    fov = math.radians(a.fov)
    ends = []
    for r, x, y, th, *_ in use:
        ang = th - fov / 2 + bearing_step(len(r), fov) * np.arange(len(r))
        ok = (r > 0.05) & (r < a.max_range)
        ends.append(np.stack([x + r[ok] * np.cos(ang[ok]), y + r[ok] * np.sin(ang[ok])], 1))
    every = np.concatenate(ends + [np.array([[s[1], s[2]] for s in use])])
    lo = every.min(0) - 1.0
    hi = every.max(0) + 1.0
    w = int(math.ceil((hi[0] - lo[0]) / a.res))
    h = int(math.ceil((hi[1] - lo[1]) / a.res))
    hits = np.zeros(h * w, np.int32)
    seen = np.zeros(h * w, np.int32)

    def cells(px, py):
        return ((py - lo[1]) / a.res).astype(np.int64) * w + ((px - lo[0]) / a.res).astype(np.int64)

    for (r, x, y, *_), p in zip(use, ends):
        if len(p) == 0:
            continue
        np.add.at(hits, cells(p[:, 0], p[:, 1]), 1)
        d = np.hypot(p[:, 0] - x, p[:, 1] - y)
        steps = np.arange(0.0, d.max(), a.res / 2)
        frac = steps[None, :] / np.maximum(d[:, None], 1e-9)
        keep = steps[None, :] < d[:, None] - 1.5 * a.res
        sx = x + (p[:, 0:1] - x) * frac
        sy = y + (p[:, 1:2] - y) * frac
        seen[np.unique(cells(sx[keep], sy[keep]))] += 1
    occupied = (hits >= 2) & (hits >= 0.3 * (hits + seen))
    free = (seen >= 1) & ~occupied
    img = np.full(h * w, 205, np.uint8)
    img[free] = 254
    img[occupied] = 0
    img = img.reshape(h, w)[::-1]  # the image's first row is the map's top
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, a.name + ".pgm"), "wb") as f:
        f.write(b"P5\n%d %d\n255\n" % (w, h))
        f.write(img.tobytes())
    with open(os.path.join(a.out, a.name + ".yaml"), "w") as f:
        f.write(f"image: {a.name}.pgm\nresolution: {a.res}\n"
                f"origin: [{lo[0]:.4f}, {lo[1]:.4f}, 0.0]\n"
                "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    with open(os.path.join(a.out, a.name + "-truth.txt"), "w") as f:
        for k, (_, x, y, th, ipc, logger) in enumerate(scans):
            f.write(f"{k} {ipc} {logger} {x:.4f} {y:.4f} {th:.6f}\n")
    print(f"{a.name}: {len(scans)} scans, map from {len(use)}: {w} x {h} cells, "
          f"{int(occupied.sum())} occupied, {int(free.sum())} free", file=sys.stderr)


if __name__ == "__main__":
    main()
