#!/usr/bin/env python3
"""Simulated laser scans of a ROS map made without any refloc code (numpy
only), for checking the localizer against a simulator it was not built with.

  scripts/independent-sim.py MAP.yaml OUT_DIR [--poses 300] [--seed 5]
      [--beams 360] [--fov 360] [--range-max 30] [--classes static,people,...]
      [--no-return null|max]

For each class it writes OUT_DIR/<class>-scans.jsonl (one
`sensor_msgs/LaserScan`-like JSON object per line, readable by `mapc
localize`) and OUT_DIR/<class>-truth.txt (`k 0 0 x y theta`, the true
sensor pose in the map frame, metres and radians, for `mapc localize
--truth`). The same poses are used for every class.

The world is the map's occupied cells only (a cell is occupied when its
occupancy (255 - value) / 255, or value / 255 with `negate: 1`, exceeds
`occupied_thresh`); free and unknown cells let beams through, and a beam
that leaves the image or passes `--range-max` has no return. Beams are
marched in steps of a quarter cell from the sensor and stop in the first
occupied cell; the range is the distance to the crossing of that cell's
boundary, found by bisection to 1 mm (`--unknown-blocks`: unknown cells
stop beams too). Poses are drawn uniformly among free cells (occupancy
under `free_thresh`) whose centre lies at least 0.3 m from every cell
centre that is not free; headings uniformly.

Classes (each scan independently, from the same seed):
  static         exact ranges
  noise          range noise N(0, 1 cm + 1% of the range; --noise-slope sets
                 the 1%), heading jitter N(0, 0.1 deg) per beam
  people         1 to 10 discs of radius 0.2-0.3 m placed 0.6-6 m from the
                 sensor in free space, plus the noise above
  clutter        1 to 4 square boxes 0.3-1.0 m, 1-5 m away, plus the noise
  dropouts       the noise above, and 1-4 runs of 5-40 beams with no return
                 plus 5% of the other beams dropped at random
  removed        1 to 3 squares of 0.5-1.0 m of the map's occupied cells
                 within 8 m erased from the world (furniture moved away),
                 plus the noise
  shifted        the world shifted by up to 5 cm, turned by up to 0.5 deg
                 and scaled by up to 0.3% about the sensor against the map
                 (a map from another run), plus the noise
  motion         the scan swept in 0.1 s while the robot turns at up to
                 1 rad/s and drives at up to 0.5 m/s; the truth is the pose
                 at the first beam (the LaserScan stamp's convention), plus
                 the noise
  cutshort       the paper's dynamic case as an outside simulator reads it:
                 range noise N(0, 5 mm), and 60 of every 362 beams (the
                 same share of other beam counts), drawn at random, cut
                 short to a uniform fraction of their range
These four are not in the default --classes (added 2026-12-07; cutshort
2026-12-08).
No-returns are written as JSON null (`--no-return null`, the default) or
as the scan's range_max (`--no-return max`, as Stage and some drivers do).
"""
import argparse
import json
import math
import os
import re
import sys
import zlib

import numpy as np

STEP_FRACTION = 0.25
CLEARANCE = 0.3


def read_yaml(path):
    text = open(path).read()
    out = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if ":" not in line:
            continue
        k, v = (s.strip() for s in line.split(":", 1))
        out[k] = v
    res = float(out["resolution"])
    origin = [float(v) for v in re.findall(r"[-+0-9.eE]+", out["origin"])][:3]
    image = out["image"].strip("'\"")
    if not os.path.isabs(image):
        image = os.path.join(os.path.dirname(os.path.abspath(path)), image)
    return (image, res, origin, int(out.get("negate", "0")),
            float(out.get("occupied_thresh", "0.65")), float(out.get("free_thresh", "0.196")))


def read_pgm(path):
    data = open(path, "rb").read()
    fields, i = [], 0
    while len(fields) < 4:
        while data[i:i + 1].isspace():
            i += 1
        if data[i:i + 1] == b"#":
            while data[i:i + 1] not in (b"\n", b""):
                i += 1
            continue
        j = i
        while not data[j:j + 1].isspace():
            j += 1
        fields.append(data[i:j])
        i = j
    if fields[0] != b"P5" or int(fields[3]) > 255:
        sys.exit(f"{path}: only 8-bit binary PGM (P5) maps are read")
    w, h = int(fields[1]), int(fields[2])
    return np.frombuffer(data[i + 1:i + 1 + w * h], dtype=np.uint8).reshape(h, w)


class World:
    def __init__(self, yaml_path, unknown_blocks=False):
        image, self.res, self.origin, negate, occ_t, free_t = read_yaml(yaml_path)
        if abs(self.origin[2]) > 1e-9:
            sys.exit("maps with a rotated origin are not supported")
        img = read_pgm(image).astype(np.float64)
        p = img / 255.0 if negate else (255.0 - img) / 255.0
        # Row 0 of the image is the top of the map: flip so that row = y.
        self.occ = np.flipud(p > occ_t)
        self.free = np.flipud(p < free_t)
        if unknown_blocks:
            self.occ |= ~self.free
        self.h, self.w = self.occ.shape

    def cell(self, x, y):
        return (np.floor((x - self.origin[0]) / self.res).astype(np.int64),
                np.floor((y - self.origin[1]) / self.res).astype(np.int64))

    def occupied(self, x, y):
        cx, cy = self.cell(x, y)
        inside = (cx >= 0) & (cy >= 0) & (cx < self.w) & (cy < self.h)
        out = np.zeros(x.shape, dtype=bool)
        out[inside] = self.occ[cy[inside], cx[inside]]
        return out, inside

    def cast(self, x, y, angles, range_max):
        """Ranges (m) from (x, y) along each angle; inf for no return."""
        step = self.res * STEP_FRACTION
        n = int(range_max / step) + 1
        t = np.arange(1, n + 1) * step
        dx, dy = np.cos(angles), np.sin(angles)
        px = x + dx[:, None] * t[None, :]
        py = y + dy[:, None] * t[None, :]
        hit, inside = self.occupied(px, py)
        hit &= t[None, :] <= range_max
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
        out = np.full(len(angles), np.inf)
        for k in np.nonzero(first >= 0)[0]:
            lo, hi = (first[k]) * step, (first[k] + 1) * step
            for _ in range(16):
                mid = 0.5 * (lo + hi)
                o, _ = self.occupied(np.array([x + dx[k] * mid]), np.array([y + dy[k] * mid]))
                if o[0]:
                    hi = mid
                else:
                    lo = mid
            out[k] = hi
        return out

    def erase_near(self, x, y, rng, n, reach, side):
        """Erases n squares of occupied cells (sides uniform in `side`, m)
        centred on occupied cells within `reach` m of (x, y); returns what
        to restore."""
        cx, cy = self.cell(np.array([x]), np.array([y]))
        k = int(reach / self.res)
        y0, y1 = max(0, cy[0] - k), min(self.h, cy[0] + k + 1)
        x0, x1 = max(0, cx[0] - k), min(self.w, cx[0] + k + 1)
        ys, xs = np.nonzero(self.occ[y0:y1, x0:x1])
        saved = []
        if len(xs) == 0:
            return saved
        for _ in range(n):
            i = rng.integers(len(xs))
            half = int(round(rng.uniform(*side) / self.res / 2))
            ey, ex = y0 + ys[i], x0 + xs[i]
            sl = (slice(max(0, ey - half), ey + half + 1), slice(max(0, ex - half), ex + half + 1))
            saved.append((sl, self.occ[sl].copy()))
            self.occ[sl] = False
        return saved

    def restore(self, saved):
        for sl, old in reversed(saved):
            self.occ[sl] = old

    def poses(self, n, rng):
        # Clearance from every cell that is not free (occupied or unknown):
        # a pose in mapped free space, not on a streak of free cells that a
        # mapping robot's beams drew across an unexplored room. A cell is
        # clear when no non-free cell centre lies within CLEARANCE of its
        # centre (a disc of offsets, applied by shifting the mask).
        blocked = ~self.free
        near = blocked.copy()
        k = int(math.ceil(CLEARANCE / self.res))
        for oy in range(-k, k + 1):
            for ox in range(-k, k + 1):
                if (ox * ox + oy * oy) * self.res ** 2 >= CLEARANCE ** 2 or (ox, oy) == (0, 0):
                    continue
                src = blocked[max(0, -oy):self.h - max(0, oy), max(0, -ox):self.w - max(0, ox)]
                near[max(0, oy):self.h - max(0, -oy), max(0, ox):self.w - max(0, -ox)] |= src
        # The image border counts as not free.
        near[:k, :] = near[-k:, :] = True
        near[:, :k] = near[:, -k:] = True
        ys, xs = np.nonzero(~near)
        if len(xs) == 0:
            sys.exit("no free cell has 0.3 m of free space around it")
        idx = rng.integers(len(xs), size=n)
        return [(self.origin[0] + (xs[i] + 0.5) * self.res,
                 self.origin[1] + (ys[i] + 0.5) * self.res,
                 rng.uniform(-math.pi, math.pi)) for i in idx]


def discs_ranges(x, y, angles, ranges, discs):
    """Shortens ranges hitting any disc (cx, cy, r)."""
    dx, dy = np.cos(angles), np.sin(angles)
    for cx, cy, r in discs:
        fx, fy = x - cx, y - cy
        b = fx * dx + fy * dy
        c = fx * fx + fy * fy - r * r
        disc = b * b - c
        ok = disc >= 0
        tt = -b - np.sqrt(np.where(ok, disc, 0.0))
        ok &= tt > 0
        ranges = np.where(ok & (tt < ranges), tt, ranges)
    return ranges


def boxes_ranges(x, y, angles, ranges, boxes):
    """Shortens ranges hitting any axis-aligned box (x0, y0, x1, y1)."""
    dx, dy = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore", invalid="ignore"):
        for x0, y0, x1, y1 in boxes:
            tx0, tx1 = (x0 - x) / dx, (x1 - x) / dx
            ty0, ty1 = (y0 - y) / dy, (y1 - y) / dy
            tmin = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
            tmax = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
            ok = (tmax >= tmin) & (tmin > 0)
            ranges = np.where(ok & (tmin < ranges), tmin, ranges)
    return ranges


def place_near(world, x, y, rng, dmin, dmax, radius):
    for _ in range(200):
        d, a = rng.uniform(dmin, dmax), rng.uniform(-math.pi, math.pi)
        px, py = x + d * math.cos(a), y + d * math.sin(a)
        ring = np.linspace(0, 2 * math.pi, 12, endpoint=False)
        o, inside = world.occupied(np.append(px + radius * np.cos(ring), px),
                                   np.append(py + radius * np.sin(ring), py))
        if inside.all() and not o.any():
            cx, cy = world.cell(np.array([px]), np.array([py]))
            if world.free[cy[0], cx[0]]:
                return px, py
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map")
    ap.add_argument("out")
    ap.add_argument("--poses", type=int, default=300)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--beams", type=int, default=360)
    ap.add_argument("--fov", type=float, default=360.0, help="degrees")
    ap.add_argument("--range-max", type=float, default=30.0)
    ap.add_argument("--classes", default="static,noise,people,clutter,dropouts")
    ap.add_argument("--no-return", choices=("null", "max"), default="null")
    ap.add_argument("--noise-slope", type=float, default=0.01,
                    help="range noise grows by this share of the range (default 0.01: 1 cm + 1%%)")
    ap.add_argument("--unknown-blocks", action="store_true",
                    help="unknown cells stop beams (default: only occupied cells do)")
    a = ap.parse_args()
    world = World(a.map, a.unknown_blocks)
    rng = np.random.default_rng(a.seed)
    poses = world.poses(a.poses, rng)
    fov = math.radians(a.fov)
    full = a.fov >= 360.0
    inc = fov / a.beams if full else fov / (a.beams - 1)
    amin = -math.pi if full else -fov / 2
    rel = amin + inc * np.arange(a.beams)
    os.makedirs(a.out, exist_ok=True)
    for cls in a.classes.split(","):
        crng = np.random.default_rng([a.seed, zlib.crc32(cls.encode())])
        with open(os.path.join(a.out, f"{cls}-scans.jsonl"), "w") as fs, \
                open(os.path.join(a.out, f"{cls}-truth.txt"), "w") as ft:
            for k, (x, y, th) in enumerate(poses):
                ang = th + rel
                if cls not in ("static", "cutshort"):
                    ang = ang + crng.normal(0.0, math.radians(0.1), a.beams)
                if cls == "shifted":
                    # World = map moved by A(p) = s + k R (p - s) + t about
                    # the sensor s; casting in it from s along d is casting
                    # in the map from A^-1(s) along R^-1 d, ranges times k.
                    t = crng.uniform(-0.05, 0.05, 2)
                    rot = math.radians(crng.uniform(-0.5, 0.5))
                    ks = 1.0 + crng.uniform(-0.003, 0.003)
                    c, s_ = math.cos(-rot), math.sin(-rot)
                    sx, sy = x - (c * t[0] - s_ * t[1]) / ks, y - (s_ * t[0] + c * t[1]) / ks
                    r = world.cast(sx, sy, ang - rot, a.range_max / ks) * ks
                elif cls == "motion":
                    omega = crng.uniform(-1.0, 1.0)
                    v = crng.uniform(0.0, 0.5)
                    tk = 0.1 * np.arange(a.beams) / a.beams
                    r = np.empty(a.beams)
                    for j in range(0, a.beams, 8):
                        tm = tk[j:j + 8].mean()
                        hm = th + omega * tm
                        bx, by = x + v * tm * math.cos(hm), y + v * tm * math.sin(hm)
                        r[j:j + 8] = world.cast(bx, by, ang[j:j + 8] + omega * tk[j:j + 8],
                                                a.range_max)
                elif cls == "removed":
                    saved = world.erase_near(x, y, crng, int(crng.integers(1, 4)), 8.0, (0.5, 1.0))
                    r = world.cast(x, y, ang, a.range_max)
                    world.restore(saved)
                else:
                    r = world.cast(x, y, ang, a.range_max)
                if cls == "people":
                    discs = []
                    for _ in range(crng.integers(1, 11)):
                        rad = crng.uniform(0.2, 0.3)
                        p = place_near(world, x, y, crng, 0.6, 6.0, rad)
                        if p:
                            discs.append((p[0], p[1], rad))
                    r = discs_ranges(x, y, ang, r, discs)
                if cls == "clutter":
                    boxes = []
                    for _ in range(crng.integers(1, 5)):
                        s = crng.uniform(0.3, 1.0)
                        p = place_near(world, x, y, crng, 1.0, 5.0, s * 0.75)
                        if p:
                            boxes.append((p[0] - s / 2, p[1] - s / 2, p[0] + s / 2, p[1] + s / 2))
                    r = boxes_ranges(x, y, ang, r, boxes)
                if cls == "cutshort":
                    fin = np.isfinite(r)
                    r[fin] += crng.normal(0.0, 0.005, fin.sum())
                    cut = crng.choice(a.beams, int(round(60 * a.beams / 362)), replace=False)
                    r[cut] = np.where(np.isfinite(r[cut]), r[cut], a.range_max) * crng.uniform(0.0, 1.0, cut.size)
                elif cls != "static":
                    fin = np.isfinite(r)
                    r[fin] += crng.normal(0.0, 1.0, fin.sum()) * (0.01 + a.noise_slope * r[fin])
                if cls == "dropouts":
                    for _ in range(crng.integers(1, 5)):
                        s, ln = crng.integers(a.beams), crng.integers(5, 41)
                        r[(s + np.arange(ln)) % a.beams] = np.inf
                    r[crng.random(a.beams) < 0.05] = np.inf
                r[(r <= 0) | (r >= a.range_max)] = np.inf
                out = [None if not math.isfinite(v) else round(float(v), 4) for v in r]
                if a.no_return == "max":
                    out = [a.range_max if v is None else v for v in out]
                fs.write(json.dumps({
                    "id": f"{cls} {k}", "angle_min": amin, "angle_increment": inc,
                    "angle_max": amin + inc * (a.beams - 1),
                    "range_min": 0.0, "range_max": a.range_max, "ranges": out}) + "\n")
                ft.write(f"{k} 0 0 {x:.6f} {y:.6f} {math.atan2(math.sin(th), math.cos(th)):.6f}\n")
        print(f"{cls}: {len(poses)} scans -> {a.out}/{cls}-scans.jsonl", file=sys.stderr)


if __name__ == "__main__":
    main()
