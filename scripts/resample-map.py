#!/usr/bin/env python3
"""A ROS map (YAML + PGM) resampled to half or twice its cell size, as a
trinary map: for the cell-size experiments of docs/results.md ("Maps of
other resolutions"). numpy only, no refloc code.

  scripts/resample-map.py MAP.yaml OUT_DIR NAME (--finer | --coarser)

--finer splits every cell in four (the same surfaces, half the cell);
--coarser merges each 2 x 2 cells into one (occupied when any was, free
when all were, else unknown; an odd last row or column, at the map's top
or right, is dropped, so the origin stays). A pixel is occupied or free by
the YAML's thresholds (map_server's trinary rule, `negate` honoured).
Writes OUT_DIR/NAME.pgm and NAME.yaml. The same resampling as `finer` and
`coarser` in tests/real_logs.rs.
"""
import argparse
import os
import re
import sys

import numpy as np


def read_yaml(path):
    """The few keys of a map_server YAML this needs (flat `key: value`)."""
    keys = {}
    for line in open(path):
        m = re.match(r"\s*(\w+)\s*:\s*(.*?)\s*(#.*)?$", line)
        if m:
            keys[m.group(1)] = m.group(2).strip("'\"")
    for k in ("image", "resolution", "origin"):
        if k not in keys:
            sys.exit(f"resample-map: {path} has no {k}")
    return keys


def read_pgm(path):
    data = open(path, "rb").read()
    m = re.match(rb"P5\s+(?:#[^\n]*\n\s*)*(\d+)\s+(?:#[^\n]*\n\s*)*(\d+)\s+(?:#[^\n]*\n\s*)*(\d+)\s", data)
    if not m:
        sys.exit(f"resample-map: {path} is not a binary PGM (P5)")
    w, h, maxval = (int(m.group(i)) for i in (1, 2, 3))
    if maxval > 255:
        sys.exit(f"resample-map: {path}: 16-bit PGMs are not handled")
    px = np.frombuffer(data[m.end():m.end() + w * h], np.uint8)
    if px.size != w * h:
        sys.exit(f"resample-map: {path} ends before its {w} x {h} pixels")
    return px.reshape(h, w), maxval


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("yaml")
    ap.add_argument("out")
    ap.add_argument("name")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--finer", action="store_true")
    g.add_argument("--coarser", action="store_true")
    a = ap.parse_args()
    y = read_yaml(a.yaml)
    img, maxval = read_pgm(os.path.join(os.path.dirname(a.yaml), y["image"]))
    p = (maxval - img.astype(np.float64)) / maxval
    if int(y.get("negate", "0")):
        p = 1.0 - p
    occ = p > float(y.get("occupied_thresh", "0.65"))
    free = p < float(y.get("free_thresh", "0.196"))
    res = float(y["resolution"])
    if a.finer:
        occ = occ.repeat(2, 0).repeat(2, 1)
        free = free.repeat(2, 0).repeat(2, 1)
        res /= 2
    else:
        h, w = occ.shape
        h2, w2 = h // 2, w // 2
        # Image rows run from the top: drop the top row when odd.
        occ = occ[h - 2 * h2:, :2 * w2].reshape(h2, 2, w2, 2).any(axis=(1, 3))
        free = free[h - 2 * h2:, :2 * w2].reshape(h2, 2, w2, 2).all(axis=(1, 3))
        res *= 2
    out = np.full(occ.shape, 205, np.uint8)
    out[free] = 254
    out[occ] = 0
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, a.name + ".pgm"), "wb") as f:
        f.write(b"P5\n%d %d\n255\n" % (out.shape[1], out.shape[0]))
        f.write(out.tobytes())
    with open(os.path.join(a.out, a.name + ".yaml"), "w") as f:
        f.write(f"image: {a.name}.pgm\nresolution: {res}\norigin: {y['origin']}\n"
                "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")


if __name__ == "__main__":
    main()
