"""Global localization with MRPT's `pf-localization` app on the scans that
`mapc eval --dump` wrote (`<run>-scans.jsonl`, `<run>-truth.txt`).

For each query scan: a CARMEN log with the same FLASER line repeated STEPS
times at constant odometry (zero motion), converted by `carmen2rawlog`, then
`pf-localization` with a uniform prior over the map's free space. The
per-step mean estimates and times are read from the app's log.

The map given to MRPT (see README.md, "MRPT map"):
- free cells in the main free region with clearance >= robot radius (the same
  rule the query poses and our sites obey): free (254); the uniform prior
  (`init_PDF_mode=0`) samples only cells with freeness > 0.7, i.e. these;
- other free cells: 205 (MRPT "unknown", 0.5: neither prior nor obstacle);
- occupied/unknown cells next to free space: occupied (0); the interior of
  obstacle/unknown blocks: 205. A likelihood-field model scores a particle
  inside a solid block as a perfect match (every end point on an obstacle),
  so only the boundary is given as obstacles.
"""
import gzip
import json
import math
import os
import re
import struct
import subprocess
import time

import numpy as np
from scipy import ndimage

# Likelihood options as MRPT 2.5 serializes them inside a COccupancyGridMap2D
# (likelihoodMethod .. rayTracing_stdHit), with the values ros-map-yaml2mrpt
# writes. A `.gridmap` file carries these options and pf-localization uses
# them, NOT the ini's [MetricMap_occupancyGrid_00_likelihoodOpts].
LIK_FMT = '<iffffIf?fIf?If'
LIK_DEFAULTS = (4, 0.35, 0.95, 0.05, 81.0, 5, 0.3, False, 2.5, 10, 1.5, True, 10, 1.0)

INI = """
[KLD_options]
KLD_binSize_PHI_deg=10
KLD_binSize_XY=0.10
KLD_delta=0.01
KLD_epsilon={kld_epsilon}
KLD_maxSampleSize={particles}
KLD_minSampleSize=150
KLD_minSamplesPerBin=0

[PF_options]
# 0: standard proposal; 3 (auxiliary optimal) was too slow (> 10 min/query).
PF_algorithm=0
resamplingMethod=0
adaptiveSampleSize=1
BETA=0.5
sampleSize=1
# Observation likelihood raised to this power (tempering): the same scan is
# fed STEPS times, so the filter does not collapse on the first update.
powFactor={pow_factor}

[DummyOdometryParams]
minStdXY={min_std_xy}
minStdPHI={min_std_phi_deg}

[LocalizationExperiment]
use_3D_poses=false
map_file={map_file}
rawlog_file={rawlog}
logOutput_dir={out}
3DSceneFrequency=-1
experimentRepetitions=1
particles_count={particles}
init_PDF_mode=0
init_PDF_min_x={x0}
init_PDF_max_x={x1}
init_PDF_min_y={y0}
init_PDF_max_y={y1}
SHOW_PROGRESS_3D_REAL_TIME=false
SAVE_STATS_ONLY=false

[MetricMap]
occupancyGrid_count=1
gasGrid_count=0
landmarksMap_count=0
pointsMap_count=0
beaconMap_count=0
likelihoodMapSelection=-1

[MetricMap_occupancyGrid_00_creationOpts]
resolution={resolution}
"""

DEFAULTS = dict(particles=300000, steps=30, pow_factor=0.1, kld_epsilon=0.05,
                min_std_xy=0.05, min_std_phi_deg=1.5,
                lf_std_hit=0.10, lf_max_corrs=1.0, lf_decimation=2, lf_z_random=0.3)


def make_map(stages_dir, work, robot_radius):
    """The 3-level PGM + YAML for MRPT, converted with ros-map-yaml2mrpt."""
    st = json.load(open(os.path.join(stages_dir, 'stages.json')))
    res = st['resolution']
    cells = np.load(os.path.join(stages_dir, 'cells.npy'))
    sq = np.load(os.path.join(stages_dir, 'sqdist.npy'))
    blocked = cells != 0
    ok = (~blocked) & (np.sqrt(sq) * res + 0.5 * res >= robot_radius)
    lab, _ = ndimage.label(ok)
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    region = lab == sizes.argmax()
    edge = blocked & ndimage.binary_dilation(~blocked, structure=np.ones((3, 3), bool))
    img = np.full(cells.shape, 205, np.uint8)
    img[edge] = 0
    img[region] = 254
    img = img[::-1]  # PGM rows top first; our rows bottom first
    h, w = img.shape
    with open(os.path.join(work, 'map.pgm'), 'wb') as f:
        f.write(b'P5\n%d %d\n255\n' % (w, h) + img.tobytes())
    ox, oy = st.get('origin', [0.0, 0.0, 0.0])[:2]
    with open(os.path.join(work, 'map.yaml'), 'w') as f:
        f.write(f'image: map.pgm\nresolution: {res}\norigin: [{ox}, {oy}, 0.0]\n'
                'negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n')
    subprocess.run(['ros-map-yaml2mrpt', '-w', '-q', '-i', 'map.yaml'], cwd=work,
                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, check=True)
    return dict(resolution=res, bounds=(ox, ox + w * res, oy, oy + h * res),
                prior_cells=int(region.sum()), edge_cells=int(edge.sum()))


def patch_likelihood(src, dst, p):
    b = gzip.open(src).read()
    pat = struct.pack(LIK_FMT, *LIK_DEFAULTS)
    if b.count(pat) != 1:
        raise RuntimeError(f'{src}: likelihood options not found exactly once (MRPT version?)')
    new = struct.pack(LIK_FMT, 4, p['lf_std_hit'], 1.0 - p['lf_z_random'], p['lf_z_random'],
                      p['range_max'], p['lf_decimation'], p['lf_max_corrs'],
                      False, 2.5, 10, 1.5, True, 10, 1.0)
    with gzip.open(dst, 'wb') as f:
        f.write(b.replace(pat, new))


def run_query(k, scan, p, work, mp):
    n = len(scan['ranges'])
    inc = scan['angle_increment']
    rmax = scan['range_max']
    # MRPT: ray i at -aperture/2 + i * aperture / (n - 1); CARMEN FLASER:
    # aperture = resolution * n. Ours: angle_min + i * inc with angle_min =
    # -pi for a full turn, so aperture = (n - 1) * inc, and the sensor is
    # yawed by angle_min + aperture / 2 (= -inc/2 here).
    aperture = (n - 1) * inc
    res_deg = math.degrees(aperture) / n
    yaw = scan['angle_min'] + aperture / 2
    ranges = ' '.join('%.4f' % (r if r is not None else rmax) for r in scan['ranges'])
    log = os.path.join(work, f'q{k}.log')
    with open(log, 'w') as f:
        f.write(f'PARAM robot_front_laser_max {rmax}\n')
        f.write(f'PARAM laser_front_laser_resolution {res_deg:.10f}\n')
        for s in range(p['steps']):
            f.write(f'FLASER {n} {ranges} 0 0 {yaw:.10f} 0 0 0 {s}.0 sim {s}.0\n')
    raw = os.path.join(work, f'q{k}.rawlog')
    subprocess.run(['carmen2rawlog', '-w', '-q', '-i', log, '-o', raw],
                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, check=True)
    x0, x1, y0, y1 = mp['bounds']
    ini = os.path.join(work, f'q{k}.ini')
    with open(ini, 'w') as f:
        f.write(INI.format(map_file=os.path.join(work, 'map-lik.gridmap.gz'), rawlog=raw,
                           out=os.path.join(work, f'out{k}'), x0=x0, x1=x1, y0=y0, y1=y1,
                           resolution=mp['resolution'], **{kk: p[kk] for kk in (
                               'particles', 'pow_factor', 'kld_epsilon', 'min_std_xy',
                               'min_std_phi_deg')}))
    t0 = time.perf_counter()
    pr = subprocess.run(['pf-localization', ini], stdin=subprocess.DEVNULL,
                        capture_output=True, text=True)
    wall = time.perf_counter() - t0
    out = pr.stdout + pr.stderr
    ests = [tuple(map(float, m)) for m in
            re.findall(r'PDF estimation: \(([-\d.]+),([-\d.]+),([-\d.]+)deg\)', out)]
    times = [float(m) / 1000 for m in re.findall(r'Done in ([\d.]+)ms', out)]
    parts = [int(m) for m in re.findall(r'Executing ParticleFilter on (\d+) particles', out)]
    if pr.returncode != 0 or not ests:
        tail = '\n'.join(out.strip().splitlines()[-15:])
        raise RuntimeError(f'pf-localization failed on query {k} (exit {pr.returncode}):\n{tail}')
    return ests, times, parts, wall


def err(e, t):
    d = math.hypot(e[0] - t[0], e[1] - t[1])
    a = abs((math.radians(e[2]) - t[2] + math.pi) % (2 * math.pi) - math.pi)
    return d, a


def run(scans_path, truth_path, stages_dir, work, params=None, log=print):
    p = dict(DEFAULTS)
    p.update(params or {})
    os.makedirs(work, exist_ok=True)
    mp = make_map(stages_dir, work, p.get('robot_radius', 0.2))
    scans = [json.loads(l) for l in open(scans_path) if l.strip()]
    truth = {int(l.split()[0]): list(map(float, l.split()[3:6])) for l in open(truth_path) if l.strip()}
    p['range_max'] = scans[0]['range_max']
    patch_likelihood(os.path.join(work, 'map.gridmap.gz'), os.path.join(work, 'map-lik.gridmap.gz'), p)
    rows = []
    for k, scan in enumerate(scans):
        t = truth[k]
        ests, times, parts, wall = run_query(k, scan, p, work, mp)
        errs = [err(e, t) for e in ests]
        okf = [d < 0.3 and a < math.radians(5) for d, a in errs]
        conv = next((i for i in range(len(okf)) if all(okf[i:])), None)
        # ests[i] is the estimate after PF step i (times[i]).
        row = dict(k=k, truth=t, final=ests[-1], err_m=errs[-1][0], err_rad=errs[-1][1],
                   ok=okf[-1], converged_step=conv,
                   time_to_converge_s=(sum(times[:conv + 1]) if conv is not None else None),
                   pf_time_s=sum(times), wall_s=wall, particles_first=parts[0] if parts else None,
                   particles_last=parts[-1] if parts else None, steps=len(times))
        rows.append(row)
        log(f'  mrpt q{k:>3}: err {row["err_m"]:7.3f} m {math.degrees(row["err_rad"]):7.2f} deg '
            f'{"ok " if row["ok"] else "BAD"} conv step {conv}  pf {row["pf_time_s"]:.1f} s  wall {wall:.1f} s '
            f'particles {row["particles_first"]}->{row["particles_last"]}')
    return dict(params=p, map=mp, rows=rows)
