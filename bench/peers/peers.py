"""Peers side by side: reads what run.sh prepared with mapc, runs the peers
(MRPT pf-localization, Open3D, scipy, scikit-image) on the same data, and
prints one table. Usage: see run.sh."""
import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mrpt_pf  # noqa: E402


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def median(v):
    return float(np.median(v)) if len(v) else float('nan')


def timed(n, f):
    ts, r = [], None
    for _ in range(n):
        t = time.perf_counter()
        r = f()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)), r


# ---------------------------------------------------------------- stages
def stages(d1, d2, repeat):
    from scipy import ndimage
    from skimage.morphology import medial_axis
    s1 = json.load(open(os.path.join(d1, 'stages.json')))
    s2 = json.load(open(os.path.join(d2, 'stages.json'))) if d2 else None
    obstacle = np.load(os.path.join(d1, 'obstacle.npy')).astype(bool)
    sq = np.load(os.path.join(d1, 'sqdist.npy'))
    gvd = np.load(os.path.join(d1, 'gvd.npy')).astype(bool)
    free = ~obstacle
    t_edt, edt = timed(repeat, lambda: ndimage.distance_transform_edt(free))
    t_edt_idx, _ = timed(repeat, lambda: ndimage.distance_transform_edt(free, return_indices=True))
    diff = np.abs(edt - np.sqrt(sq.astype(np.float64)))
    t_ma, (ma, ma_dist) = timed(max(1, repeat // 2), lambda: medial_axis(free, return_distance=True))
    res, rr = s1['resolution'], s1['robot_radius_m']

    def near(a, b, k):
        """Share of a's cells with a b cell within k cells (Chebyshev)."""
        grown = ndimage.binary_dilation(b, structure=np.ones((2 * k + 1, 2 * k + 1), bool))
        return float((a & grown).sum() / max(1, a.sum()))
    ma_clear = ma & (ma_dist * res >= rr)
    # Our GVD ignores "specks": obstacle components (8-connected, not touching
    # the image border) of at most floor(0.05 m^2 / res^2) cells
    # (GvdOptions::min_obstacle_area_m2); the medial axis of the same free
    # space without them:
    lab, _ = ndimage.label(obstacle, structure=np.ones((3, 3), bool))
    sizes = np.bincount(lab.ravel())
    small = sizes <= math.floor(0.05 / (res * res))
    small[0] = False
    small[np.unique(np.r_[lab[0], lab[-1], lab[:, 0], lab[:, -1]])] = False
    speck = small[lab]
    ma_ns = medial_axis(~(obstacle & ~speck))
    return dict(
        cells=[s1['height'], s1['width']],
        ours_edt_1t_s=s1['edt_distances_only_s']['median'],
        ours_edt_feat_1t_s=s1['edt_with_features_s']['median'],
        ours_edt_2t_s=s2['edt_distances_only_s']['median'] if s2 else None,
        ours_edt_feat_2t_s=s2['edt_with_features_s']['median'] if s2 else None,
        scipy_edt_s=t_edt, scipy_edt_indices_s=t_edt_idx,
        edt_max_abs_diff_cells=float(diff.max()), edt_cells_differing_1e3=int((diff > 1e-3).sum()),
        ours_gvd_1t_s=s1['gvd_s']['median'], ours_gvd_2t_s=s2['gvd_s']['median'] if s2 else None,
        skimage_medial_axis_s=t_ma,
        gvd_cells=int(gvd.sum()), medial_axis_cells=int(ma.sum()), medial_axis_cells_clear=int(ma_clear.sum()),
        gvd_in_ma_1=near(gvd, ma, 1), gvd_in_ma_2=near(gvd, ma, 2),
        specks=int(small.sum()), speck_cells=int(speck.sum()),
        gvd_in_ma_nospeck_1=near(gvd, ma_ns, 1), gvd_in_ma_nospeck_2=near(gvd, ma_ns, 2),
        ma_in_gvd_1=near(ma, gvd, 1), ma_in_gvd_2=near(ma, gvd, 2),
        ma_clear_in_gvd_1=near(ma_clear, gvd, 1), ma_clear_in_gvd_2=near(ma_clear, gvd, 2),
        robot_radius_m=rr, resolution=res)


# ---------------------------------------------------------------- E1
def e1(pairs, out_dir, o3d_args):
    import e1_open3d
    out = os.path.join(out_dir, 'e1-open3d.jsonl')
    cmd = [sys.executable, os.path.join(os.path.dirname(os.path.abspath(__file__)), 'e1_open3d.py'),
           pairs, '--out', out] + o3d_args
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f'Open3D E1 failed: {r.stderr[-2000:]}')
    o3d_summary = json.loads(r.stdout)
    ours = []
    for line in open(pairs):
        p = json.loads(line)
        e = p['ours']['err']
        ours.append(((e if e is not None else [9e9, 9e9, 9e9]), False, p['ours']['time_us'] / 1e6))
    o3d_summary['refloc_ssm'] = e1_open3d.stats(ours)
    return o3d_summary


# ---------------------------------------------------------------- ours, localize
def ours_localize(path):
    rows = [json.loads(l) for l in open(path) if l.strip().startswith('{')]
    ok = [bool(r.get('accepted')) and r.get('error_m', 9e9) < 0.3 and r.get('error_rad', 9e9) < math.radians(5)
          for r in rows]
    return dict(n=len(rows), ok=int(sum(ok)), accepted=int(sum(bool(r.get('accepted')) for r in rows)),
                median_err_m=median([r.get('error_m', float('inf')) for r in rows]),
                median_err_deg=median([math.degrees(r.get('error_rad', float('inf'))) for r in rows]),
                median_err_m_ok=median([r['error_m'] for r, o in zip(rows, ok) if o]),
                median_time_ms=median([r['time_us'] / 1e3 for r in rows]),
                mean_time_ms=float(np.mean([r['time_us'] / 1e3 for r in rows])),
                max_time_ms=float(np.max([r['time_us'] / 1e3 for r in rows])))


def mrpt_summary(m):
    rows = m['rows']
    ok = [r for r in rows if r['ok']]
    return dict(n=len(rows), ok=len(ok),
                median_err_m=median([r['err_m'] for r in rows]),
                median_err_deg=median([math.degrees(r['err_rad']) for r in rows]),
                median_err_m_ok=median([r['err_m'] for r in ok]),
                median_converge_s_ok=median([r['time_to_converge_s'] for r in ok if r['time_to_converge_s'] is not None]),
                median_converge_step_ok=median([r['converged_step'] + 1 for r in ok if r['converged_step'] is not None]),
                median_pf_time_s=median([r['pf_time_s'] for r in rows]),
                median_wall_s=median([r['wall_s'] for r in rows]))


# ---------------------------------------------------------------- table
def length(m):
    return f'{m:.2f} m' if m >= 1.0 else f'{1e3 * m:.1f} mm'


def pct(k, n):
    return f'{k}/{n} ({100.0 * k / max(1, n):.0f} %)'


def table(L, M, E, S, info):
    o = []
    o.append('| # | comparison | method | success | error | time |')
    o.append('|---|---|---|---|---|---|')
    o.append(f'| 1 | global localization, {info["map"]}, {L["n"]} {info["scan_set"]} scans '
             f'(success: final pose within 0.3 m and 5 deg; refloc also must accept) '
             f'| refloc `mapc localize` | {pct(L["ok"], L["n"])} '
             f'| median {length(L["median_err_m"])}, {L["median_err_deg"]:.2f} deg (all) '
             f'| {L["median_time_ms"]:.2f} ms median, {L["mean_time_ms"]:.2f} ms mean, {L["max_time_ms"]:.1f} ms max per query |')
    p = info['mrpt_params']
    o.append(f'| 1 | | MRPT 2.5.8 `pf-localization`, {p["particles"]:,} particles uniform over free space, '
             f'{p["steps"]} updates with the same scan, zero motion '
             f'| {pct(M["ok"], M["n"])} '
             f'| median {length(M["median_err_m"])}, {M["median_err_deg"]:.2f} deg (all); '
             f'{length(M["median_err_m_ok"])} (successful) '
             f'| converged (to within the bound, for good) after {M["median_converge_s_ok"]:.2f} s '
             f'/ {M["median_converge_step_ok"]:.1f} updates median (successful; the first update, with all particles, is most of it); '
             f'{M["median_pf_time_s"]:.1f} s PF time for all updates, {M["median_wall_s"]:.1f} s wall per query |')
    names = [('refloc_ssm', 'refloc SSM (`mapc eval` E1)'),
             ('fpfh_ransac', 'Open3D FPFH + RANSAC'),
             ('fpfh_ransac_icp', 'Open3D FPFH + RANSAC + ICP refinement'),
             ('icp', 'Open3D ICP point-to-point from identity')]
    for key, label in names:
        s = E[key]
        m, sd = s['mean_mm_mm_deg'], s['sd_mm_mm_deg']
        o.append(f'| 2 | {"E1 scan-to-scan, " + str(s["n"]) + " pairs (±0.4 m, ±30 deg, 10 mm noise, 60 swap outliers)" if key == "refloc_ssm" else ""} '
                 f'| {label} | {pct(s["ok_0.3m_5deg"], s["n"])} within 0.3 m/5 deg; {pct(s["ok_0.05m_1deg"], s["n"])} within 5 cm/1 deg '
                 f'| mean (sd) x {m[0]:.2f} ({sd[0]:.2f}) mm, y {m[1]:.2f} ({sd[1]:.2f}) mm, '
                 f'theta {m[2]:.3f} ({sd[2]:.3f}) deg (pairs within 0.3 m/5 deg) '
                 f'| {s["median_time_ms"]:.2f} ms median, {s["mean_time_ms"]:.2f} ms mean per pair |')
    h, w = S['cells']
    o.append(f'| 3 | distance transform, {info["map"]} {w} x {h} cells '
             f'| refloc `edt` (distances; with nearest-obstacle indices) '
             f'| max abs difference to scipy {S["edt_max_abs_diff_cells"]:.2g} cells '
             f'({S["edt_cells_differing_1e3"]} cells differ by > 1e-3) '
             f'| exact (same obstacles: occupied, unknown, image border) '
             f'| 1 thread: {1e3 * S["ours_edt_1t_s"]:.1f} ms; {1e3 * S["ours_edt_feat_1t_s"]:.1f} ms with indices; '
             f'2 threads: {1e3 * S["ours_edt_2t_s"]:.1f} ms; {1e3 * S["ours_edt_feat_2t_s"]:.1f} ms |')
    o.append(f'| 3 | | scipy `ndimage.distance_transform_edt` | reference | | '
             f'{1e3 * S["scipy_edt_s"]:.1f} ms; {1e3 * S["scipy_edt_indices_s"]:.1f} ms with indices '
             f'(ours 1 thread is {S["scipy_edt_s"] / S["ours_edt_1t_s"]:.1f}x / '
             f'{S["scipy_edt_indices_s"] / S["ours_edt_feat_1t_s"]:.1f}x faster) |')
    o.append(f'| 3 | GVD / medial axis, same map and obstacles '
             f'| refloc `gvd::extract` (pruned, clearance >= {S["robot_radius_m"]} m) '
             f'| {S["gvd_cells"]} cells; {100 * S["gvd_in_ma_1"]:.1f} % / {100 * S["gvd_in_ma_2"]:.1f} % '
             f'within 1 / 2 cells of a medial-axis cell; {100 * S["gvd_in_ma_nospeck_1"]:.1f} % / '
             f'{100 * S["gvd_in_ma_nospeck_2"]:.1f} % of the medial axis without the {S["specks"]} specks our GVD ignores '
             f'| | 1 thread: {1e3 * S["ours_gvd_1t_s"]:.1f} ms; 2 threads: {1e3 * S["ours_gvd_2t_s"]:.1f} ms (needs the EDT with indices) |')
    o.append(f'| 3 | | scikit-image `morphology.medial_axis` (unpruned) '
             f'| {S["medial_axis_cells"]} cells; {100 * S["ma_in_gvd_1"]:.1f} % / {100 * S["ma_in_gvd_2"]:.1f} % within 1 / 2 cells of our GVD; '
             f'of its {S["medial_axis_cells_clear"]} cells with clearance >= {S["robot_radius_m"]} m: '
             f'{100 * S["ma_clear_in_gvd_1"]:.1f} % / {100 * S["ma_clear_in_gvd_2"]:.1f} % '
             f'| | {1e3 * S["skimage_medial_axis_s"]:.1f} ms, computes its own distance transform '
             f'(ours EDT+GVD 1 thread is {S["skimage_medial_axis_s"] / (S["ours_edt_feat_1t_s"] + S["ours_gvd_1t_s"]):.1f}x faster) |')
    return '\n'.join(o)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--work', required=True)
    ap.add_argument('--map-name', default='Intel')
    ap.add_argument('--scan-set', default='dynamic')
    ap.add_argument('--repeat', type=int, default=11)
    ap.add_argument('--mrpt-particles', type=int, default=mrpt_pf.DEFAULTS['particles'])
    ap.add_argument('--mrpt-steps', type=int, default=mrpt_pf.DEFAULTS['steps'])
    ap.add_argument('--skip-mrpt', action='store_true')
    a = ap.parse_args()
    w = a.work
    data = os.path.join(w, 'data')
    log('== stages: scipy and scikit-image on the same obstacles')
    S = stages(os.path.join(w, 'stages-1t'), os.path.join(w, 'stages-2t'), a.repeat)
    log('== E1: Open3D on the same pairs')
    E = e1(os.path.join(data, 'e1-pairs.jsonl'), w, [])
    L = ours_localize(os.path.join(w, 'ours-localize.jsonl'))
    params = dict(particles=a.mrpt_particles, steps=a.mrpt_steps)
    if a.skip_mrpt:
        M = dict(n=0, ok=0, median_err_m=float('nan'), median_err_deg=float('nan'), median_err_m_ok=float('nan'),
                 median_converge_s_ok=float('nan'), median_converge_step_ok=float('nan'),
                 median_pf_time_s=float('nan'), median_wall_s=float('nan'))
        mr = None
    else:
        log(f'== global localization: MRPT pf-localization on {L["n"]} scans (sequential)')
        mr = mrpt_pf.run(os.path.join(data, f'{a.scan_set}-scans.jsonl'), os.path.join(data, f'{a.scan_set}-truth.txt'),
                         os.path.join(w, 'stages-1t'), os.path.join(w, 'mrpt'), params, log=log)
        M = mrpt_summary(mr)
        params = mr['params']
    full = dict(mrpt_params=params, **mrpt_pf.DEFAULTS)
    full.update(params)
    info = dict(map=a.map_name, scan_set=a.scan_set, mrpt_params=full)
    t = table(L, M, E, S, info)
    with open(os.path.join(w, 'results.json'), 'w') as f:
        json.dump(dict(localize_ours=L, localize_mrpt=M, mrpt_rows=mr['rows'] if mr else None,
                       mrpt_params=full, e1=E, stages=S, python=platform.python_version()), f, indent=1)
    with open(os.path.join(w, 'table.md'), 'w') as f:
        f.write(t + '\n')
    print(t)


if __name__ == '__main__':
    main()
