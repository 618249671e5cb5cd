"""E1 scan pairs (from `mapc eval --dump`) registered with Open3D.

Each pair: `reference` and `query` points (sensor frames, NaN where a beam has
no return), true `motion` with reference ~= motion * query. The points are
lifted to 3-D at z = 0. Methods:

  fpfh_ransac      FPFH features + RANSAC global registration (no initial pose)
  fpfh_ransac_icp  the same, refined by point-to-point ICP (the usual pipeline)
  icp              point-to-point ICP from the identity

Normals: a 3-D PCA normal of points on a plane is the plane's normal for every
point, which makes FPFH useless; instead each point gets its 2-D normal (PCA
of its k nearest neighbours in the plane, oriented towards the sensor) lifted
to (nx, ny, 0).

Writes one JSON line per pair and method to --out and prints a summary as
JSON on stdout. Times are wall-clock per pair of the Open3D calls (features of
both scans + registration), single-threaded when OMP_NUM_THREADS=1.
"""
import argparse
import json
import math
import sys
import time

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree


def cloud(pts, k_normal):
    p = np.asarray([q for q in pts if q[0] is not None and q[1] is not None], dtype=float)
    p = p[np.isfinite(p).all(axis=1)]
    tree = cKDTree(p)
    _, nn = tree.query(p, k=min(k_normal, len(p)))
    nb = p[nn] - p[nn].mean(axis=1, keepdims=True)
    cov = np.einsum('nki,nkj->nij', nb, nb)
    _, vecs = np.linalg.eigh(cov)
    n2 = vecs[:, :, 0]  # smallest eigenvalue: the normal in the plane
    flip = (n2 * -p).sum(axis=1) < 0  # towards the sensor at the origin
    n2[flip] *= -1
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(np.c_[p, np.zeros(len(p))])
    pc.normals = o3d.utility.Vector3dVector(np.c_[n2, np.zeros(len(p))])
    return pc


def pose_of(T):
    """(x, y, theta, mirrored): the planar part of a 4x4 transform."""
    return T[0, 3], T[1, 3], math.atan2(T[1, 0], T[0, 0]), T[2, 2] < 0


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('pairs')
    ap.add_argument('--out', required=True)
    ap.add_argument('--limit', type=int, default=0)
    ap.add_argument('--k-normal', type=int, default=10)
    ap.add_argument('--fpfh-radius', type=float, default=1.0)
    ap.add_argument('--fpfh-max-nn', type=int, default=100)
    ap.add_argument('--ransac-dist', type=float, default=0.1)
    ap.add_argument('--ransac-iters', type=int, default=100000)
    ap.add_argument('--ransac-conf', type=float, default=0.999)
    ap.add_argument('--mutual', action='store_true')
    ap.add_argument('--icp-dist', type=float, default=1.0)
    ap.add_argument('--icp-refine-dist', type=float, default=0.1)
    ap.add_argument('--icp-iters', type=int, default=100)
    ap.add_argument('--seed', type=int, default=1)
    a = ap.parse_args()
    o3d.utility.random.seed(a.seed)
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    p2p = o3d.pipelines.registration.TransformationEstimationPointToPoint(False)
    feat = o3d.geometry.KDTreeSearchParamHybrid(radius=a.fpfh_radius, max_nn=a.fpfh_max_nn)
    icp_crit = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=a.icp_iters)
    rows = []
    with open(a.pairs) as f, open(a.out, 'w') as out:
        for n, line in enumerate(f):
            if a.limit and n >= a.limit:
                break
            pr = json.loads(line)
            mx, my, mt = pr['motion']
            src = cloud(pr['query'], a.k_normal)
            dst = cloud(pr['reference'], a.k_normal)
            res = {}
            t0 = time.perf_counter()
            fs = o3d.pipelines.registration.compute_fpfh_feature(src, feat)
            fd = o3d.pipelines.registration.compute_fpfh_feature(dst, feat)
            rr = o3d.pipelines.registration.registration_ransac_based_on_feature_matching(
                src, dst, fs, fd, a.mutual, a.ransac_dist, p2p, 3,
                [o3d.pipelines.registration.CorrespondenceCheckerBasedOnEdgeLength(0.9),
                 o3d.pipelines.registration.CorrespondenceCheckerBasedOnDistance(a.ransac_dist)],
                o3d.pipelines.registration.RANSACConvergenceCriteria(a.ransac_iters, a.ransac_conf))
            t1 = time.perf_counter()
            res['fpfh_ransac'] = (rr.transformation, t1 - t0)
            ri = o3d.pipelines.registration.registration_icp(
                src, dst, a.icp_refine_dist, rr.transformation, p2p, icp_crit)
            t2 = time.perf_counter()
            res['fpfh_ransac_icp'] = (ri.transformation, t2 - t0)
            t3 = time.perf_counter()
            r0 = o3d.pipelines.registration.registration_icp(
                src, dst, a.icp_dist, np.eye(4), p2p, icp_crit)
            res['icp'] = (r0.transformation, time.perf_counter() - t3)
            for name, (T, dt) in res.items():
                x, y, t, mirrored = pose_of(np.asarray(T))
                err = [x - mx, y - my, wrap(t - mt)]
                row = {'k': pr['k'], 'method': name, 'err': err, 'mirrored': bool(mirrored), 'time_s': dt}
                out.write(json.dumps(row) + '\n')
                rows.append(row)
    json.dump(summarize(rows), sys.stdout, indent=1)
    print()


def summarize(rows):
    out = {}
    for name in sorted({r['method'] for r in rows}):
        rs = [r for r in rows if r['method'] == name]
        out[name] = stats([(r['err'], r['mirrored'], r['time_s']) for r in rs])
    return out


def stats(items):
    """items: (err [x, y, theta], mirrored, time_s)."""
    def ok(e, m, pos, deg):
        return (not m) and math.hypot(e[0], e[1]) < pos and abs(e[2]) < math.radians(deg)
    n = len(items)
    good = np.array([e for e, m, _ in items if ok(e, m, 0.3, 5.0)]).reshape(-1, 3)
    fine = sum(ok(e, m, 0.05, 1.0) for e, m, _ in items)
    times = np.array([t for _, _, t in items])
    mean = good.mean(axis=0) if len(good) else np.full(3, np.nan)
    sd = good.std(axis=0, ddof=1) if len(good) > 1 else np.full(3, np.nan)
    return {'n': n, 'ok_0.3m_5deg': len(good), 'ok_0.05m_1deg': int(fine),
            'mean_mm_mm_deg': [mean[0] * 1e3, mean[1] * 1e3, math.degrees(mean[2])],
            'sd_mm_mm_deg': [sd[0] * 1e3, sd[1] * 1e3, math.degrees(sd[2])],
            'median_time_ms': float(np.median(times) * 1e3), 'mean_time_ms': float(times.mean() * 1e3)}


if __name__ == '__main__':
    main()
