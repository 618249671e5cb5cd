"""End-to-end tests of the refloc Python package: compile the shipped office
map, localize scans simulated by `mapc eval --dump` (with their true poses),
and check what the runtime reports and how errors surface."""
import json
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import refloc

ROOT = Path(os.environ.get("REFLOC_ROOT", Path(__file__).resolve().parents[2]))
MAPC = os.environ.get("REFLOC_MAPC", str(ROOT / "target" / "debug" / "mapc"))
MAP = ROOT / "maps" / "office-demo" / "office-demo.yaml"


@pytest.fixture(scope="module")
def db_path(tmp_path_factory):
    out = tmp_path_factory.mktemp("db") / "office.refdb"
    sites = refloc.build(MAP, out)
    assert sites > 10
    return out


@pytest.fixture(scope="module")
def scans(db_path, tmp_path_factory):
    """(LaserScan dict, true pose) pairs from `mapc eval --dump`."""
    d = tmp_path_factory.mktemp("dump")
    subprocess.run(
        [MAPC, "eval", str(db_path), "--poses", "20", "--experiments", "static,dynamic",
         "--no-figures", "--out", str(d / "eval"), "--dump", str(d)],
        check=True, capture_output=True)
    out = []
    for run in ("static", "dynamic"):
        lines = (d / f"{run}-scans.jsonl").read_text().splitlines()
        truth = [list(map(float, l.split()[3:6])) for l in (d / f"{run}-truth.txt").read_text().splitlines()
                 if l.strip() and not l.startswith("#")]
        assert len(lines) == len(truth) == 20
        out += [(json.loads(l), t) for l, t in zip(lines, truth)]
    return out


def ranges_of(s):
    return np.array([math.inf if r is None else r for r in s["ranges"]], dtype=np.float32)


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_localizes_simulated_scans_at_their_true_pose(db_path, scans):
    db = refloc.RefDb(db_path)
    loc = refloc.Localizer(db, max_beams=1024)
    right = 0
    for s, t in scans:
        r = loc.localize(ranges_of(s), s["angle_min"], s["angle_increment"],
                         range_min=s.get("range_min", 0.0), range_max=s["range_max"])
        assert 0.0 <= r.confidence <= 1.0
        assert r.accepted == (r.confidence >= db.accept_confidence)
        assert 1 <= len(r.hypotheses) <= 5
        h0 = r.hypotheses[0]
        assert (h0.x, h0.y, h0.theta) == r.pose and h0.confidence == r.confidence
        cov = r.covariance
        assert cov is not None and cov.shape == (3, 3) and np.allclose(cov, cov.T)
        assert np.all(np.diag(cov) > 0)
        ok = math.hypot(r.x - t[0], r.y - t[1]) < 0.3 and abs(wrap(r.theta - t[2])) < math.radians(5)
        right += r.accepted and ok
    assert right >= 0.9 * len(scans), f"{right} of {len(scans)}"


def test_refdb_localize_matches_the_localizer(db_path, scans):
    db = refloc.RefDb(db_path)
    s, _ = scans[0]
    a = db.localize(ranges_of(s), s["angle_min"], s["angle_increment"], range_max=s["range_max"])
    b = refloc.Localizer(db).localize(list(ranges_of(s).astype(float)), s["angle_min"],
                                      s["angle_increment"], range_max=s["range_max"])
    assert a.pose == b.pose and a.confidence == b.confidence


def test_errors_are_python_exceptions_with_the_runtimes_message(db_path, tmp_path):
    with pytest.raises(OSError):
        refloc.RefDb(tmp_path / "missing.refdb")
    bad = tmp_path / "bad.refdb"
    bad.write_bytes(b"not a refdb at all, just some bytes" * 4)
    with pytest.raises(refloc.RefDbError, match="bad.refdb"):
        refloc.RefDb(bad)
    db = refloc.RefDb(db_path)
    with pytest.raises(refloc.LocalizeError):
        db.localize(np.full(360, np.inf, dtype=np.float32), 0.0, 2 * math.pi / 360, range_max=30.0)
    with pytest.raises(refloc.LocalizeError, match="angle"):
        db.localize(np.ones(360, dtype=np.float32), 0.0, 0.0)
    with pytest.raises(ValueError):
        refloc.Localizer(db, max_beams=0)
    with pytest.raises(refloc.BuildError):
        refloc.build(tmp_path / "nope.yaml", tmp_path / "x.refdb")


def test_simulated_scan_of_a_site_is_found_there(db_path):
    db = refloc.RefDb(db_path)
    x, y = db.site_position(db.site_count // 2)
    ranges, amin, inc = db.simulate_scan(x, y, 0.5, beams=541, fov=math.radians(270))
    assert ranges.dtype == np.float32 and ranges.shape == (541,)
    r = db.localize(ranges, amin, inc, range_max=30.0)
    assert r.accepted and math.hypot(r.x - x, r.y - y) < 0.1 and abs(wrap(r.theta - 0.5)) < 0.05
    with pytest.raises(IndexError):
        db.site_position(db.site_count)
    with pytest.raises(ValueError):
        db.simulate_scan(x, y, 0.0, beams=2)


def test_quickstart_example_runs():
    out = subprocess.run([os.sys.executable, str(ROOT / "python" / "examples" / "quickstart.py")],
                         check=True, capture_output=True, text=True).stdout
    assert "reference sites" in out and "Localization(" in out


@pytest.fixture
def site_scan(db_path):
    """A localizer on the office map and a simulated scan at reference site
    5, heading 0.4 rad: (db, loc, x, y, theta, ranges, angle_min,
    angle_increment)."""
    db = refloc.RefDb(db_path)
    loc = refloc.Localizer(db, max_beams=1024)
    x, y = db.site_position(5)
    th = 0.4
    ranges, amin, inc = db.simulate_scan(x, y, th, beams=360)
    return db, loc, x, y, th, ranges, amin, inc


def test_priors_narrow_the_search(site_scan):
    db, loc, x, y, th, ranges, amin, inc = site_scan
    free = loc.localize(ranges, amin, inc)
    near = loc.localize(ranges, amin, inc, region=(x + 1.0, y, 5.0), heading=(th, math.radians(30)))
    assert free.accepted and near.accepted and math.hypot(near.x - x, near.y - y) < 0.3
    assert abs(near.x - free.x) < 1e-3 and abs(near.y - free.y) < 1e-3
    # A heading window or a region that excludes the true pose: whatever is
    # answered lies inside it (or nothing is).
    try:
        r = loc.localize(ranges, amin, inc, heading=(th + math.pi, math.radians(20)))
        assert abs(wrap(r.theta - th - math.pi)) <= math.radians(20) + 1e-3 or not r.accepted
    except refloc.LocalizeError:
        pass
    try:
        r = loc.localize(ranges, amin, inc, region=(x + 30.0, y + 30.0, 1.0))
        assert math.hypot(r.x - x - 30.0, r.y - y - 30.0) <= 1.0 + 1e-3 or not r.accepted
    except refloc.LocalizeError:
        pass
    with pytest.raises(ValueError):
        loc.localize(ranges, amin, inc, region=(x, y, -1.0))
    with pytest.raises(ValueError):
        db.localize(ranges, amin, inc, heading=(math.nan, 0.1))


def test_a_polygon_region_narrows_the_search(site_scan):
    _, loc, x, y, th, ranges, amin, inc = site_scan
    # A concave L around the true pose (its notch away from it), as pairs
    # and as an N x 2 array: the true pose.
    ell = [(x - 2.0, y - 2.0), (x + 3.0, y - 2.0), (x + 3.0, y + 1.0),
           (x + 1.0, y + 1.0), (x + 1.0, y + 3.0), (x - 2.0, y + 3.0)]
    for region in (ell, np.array(ell), [list(v) for v in ell]):
        r = loc.localize(ranges, amin, inc, region=region, heading=(th, math.radians(30)))
        assert r.accepted and math.hypot(r.x - x, r.y - y) < 0.3, region
    # The same L moved so that the true pose is in its notch: whatever is
    # answered is not the true pose.
    notch = [(vx - 2.0, vy - 2.0) for vx, vy in ell]
    try:
        r = loc.localize(ranges, amin, inc, region=notch)
        assert math.hypot(r.x - x, r.y - y) > 0.3 or not r.accepted
    except refloc.LocalizeError:
        pass
    far = [(x + 500.0, y + 500.0), (x + 501.0, y + 500.0), (x + 500.0, y + 501.0)]
    with pytest.raises(refloc.LocalizeError):
        loc.localize(ranges, amin, inc, region=far)
    # Bad polygons are ValueErrors that say why; other shapes TypeErrors.
    for bad, why in (([(0.0, 0.0), (1.0, 0.0)], "at least 3"),
                     ([(0.0, 0.0), (1.0, math.nan), (0.0, 1.0)], "not finite"),
                     ([(0.0, 0.0), (1.0, 1.0), (2.0, 2.0)], "one line"),
                     ([(float(k), float(k * k)) for k in range(33)], "at most 32")):
        with pytest.raises(ValueError, match=why):
            loc.localize(ranges, amin, inc, region=bad)
    for bad in ([1.0, 2.0, 3.0], "abc", [(0.0, 0.0, 0.0)] * 3):
        with pytest.raises(TypeError):
            loc.localize(ranges, amin, inc, region=bad)


@pytest.fixture(scope="module")
def other_dbs(tmp_path_factory):
    """Two more buildings: synthetic maps (an office and a warehouse of other
    layouts), compiled by the CLI with a short confidence fit."""
    d = tmp_path_factory.mktemp("other")
    out = []
    for kind, seed in (("office", 7), ("warehouse", 3)):
        subprocess.run([MAPC, "synth", "--kind", kind, "--width", "240", "--height", "200",
                        "--seed", str(seed), "--name", kind, "-o", str(d)],
                       check=True, capture_output=True)
        db = d / f"{kind}.refdb"
        subprocess.run([MAPC, "build", "-q", str(d / f"{kind}.yaml"), "-o", str(db),
                        "--fit-queries", "40"], check=True, capture_output=True)
        out.append(db)
    return out


def test_which_map_picks_the_map_the_scan_was_made_on(db_path, other_dbs, tmp_path):
    office, warehouse = (refloc.RefDb(p) for p in other_dbs)
    demo = refloc.RefDb(db_path)
    dbs = [office, demo, warehouse]
    maps = refloc.MapSet(dbs, max_beams=1024)
    assert [d.site_count for d in maps.dbs] == [d.site_count for d in dbs]
    scans = []
    for src, want in ((demo, 1), (office, 0)):
        for k in (src.site_count // 3, 2 * src.site_count // 3):
            x, y = src.site_position(k)
            ranges, amin, inc = src.simulate_scan(x + 0.1, y - 0.1, 0.3 + k, beams=360)
            scans.append((ranges, amin, inc, want, (x + 0.1, y - 0.1)))
    answers = []
    for ranges, amin, inc, want, (x, y) in scans:
        r = maps.localize(ranges, amin, inc)
        confs = [m and m.confidence for m in r.maps]
        assert len(r.maps) == len(r.reasons) == 3
        # Never a wrong map. No map when another one explains the scan about
        # as well (the demo map and the synthetic office are both offices:
        # a scan of one can fit the other at 0.999 too, a toss).
        assert r.map_index in (want, None), (r, confs)
        answers.append(r.map_index)
        if r.map_index is None:
            others = [c for k, c in enumerate(confs) if k != want and c is not None]
            assert max(others) > 0.9, (r, confs)
            continue
        assert r.accepted and r.localization.pose == r.maps[want].pose
        if want == 1:
            # (Not on the synthetic office: a corridor there lets one of
            # these scans slide 1.8 m along it, accepted.)
            assert math.hypot(r.localization.x - x, r.localization.y - y) < 0.3
    assert sum(a is not None for a in answers) >= 2, answers
    # The one-call form gives the same answer.
    ranges, amin, inc, want, _ = scans[0]
    assert refloc.localize_maps(dbs, ranges, amin, inc).map_index == answers[0]
    # The CLI's several-map answer on the same scans: the same map each time.
    jl = tmp_path / "scans.jsonl"
    jl.write_text("".join(json.dumps({
        "id": str(k), "angle_min": amin, "angle_increment": inc, "range_min": 0.0, "range_max": 30.0,
        "ranges": [float(v) if math.isfinite(v) else None for v in ranges]}) + "\n"
        for k, (ranges, amin, inc, _, _) in enumerate(scans)))
    p = subprocess.run([MAPC, "localize", *map(str, other_dbs[:1] + [db_path] + other_dbs[1:]), str(jl)],
                       check=True, capture_output=True, text=True)
    cli = [json.loads(l)["map_index"] for l in p.stdout.splitlines()]
    assert cli == answers
    # A scan no map can localize: no map, a reason for each.
    r = maps.localize(np.full(360, np.inf, dtype=np.float32), 0.0, 2 * math.pi / 360)
    assert r.map_index is None and not r.accepted and r.localization is None
    assert r.maps == [None, None, None] and all(r.reasons)
    with pytest.raises(ValueError):
        refloc.MapSet([])
