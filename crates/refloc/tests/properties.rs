//! Property tests (proptest) of the runtime's geometric kernels, through the
//! public API: random inputs, and on failure a shrunk counterexample.
//!
//! The seeded tests in `src/tests.rs` and `src/raycast/tests.rs` check the
//! same kernels on fixed worlds and poses (and the full path from a range
//! scan through `prep`, with a loose L1 tolerance); these add random
//! coverage with tolerances derived from where floating-point rounding can
//! legitimately change an answer, so most cases are checked exactly:
//!
//! * PGR values `(rho, theta)` of a pair are those of the exact geometry and
//!   do not change under a rigid motion of the scan;
//! * the PGR histogram of a prepared scan does not change under a rigid
//!   motion, except for votes that lie within rounding distance of a bin
//!   edge (counted in f64 on the original scan; each can move one bin);
//! * the least-squares pose step recovers a rigid transform from noise-free
//!   correspondences, ignoring correspondences outside the threshold;
//! * ray casting agrees with a slow reference that steps densely along the
//!   ray, on random grids.
//!
//! Case counts are kept small (the whole suite runs in CI on 2 cores); set
//! `PROPTEST_CASES` for a longer run.

use proptest::collection::vec;
use proptest::prelude::*;
use refloc::raycast::{self, BitGrid};
use refloc::{pgr, prep, ssm, wrap_angle, Params, Pose2};
use std::f32::consts::PI;

fn cases(n: u32) -> ProptestConfig {
    ProptestConfig {
        cases: n,
        ..ProptestConfig::default()
    }
}

/// A rigid motion: any heading, translation within 20 m.
fn rigid() -> impl Strategy<Value = Pose2> {
    (-20.0f32..20.0, -20.0f32..20.0, -PI..PI).prop_map(|(x, y, t)| Pose2::new(x, y, t))
}

/// The rotation part of `t` applied to a direction.
fn turn(t: &Pose2, v: [f32; 2]) -> [f32; 2] {
    Pose2::new(0.0, 0.0, t.theta).apply(v)
}

fn unit(a: f32) -> [f32; 2] {
    [a.cos(), a.sin()]
}

/// Exact (f64) `(rho, theta)` of the pair (i, j) with unit tangent `u` at i.
fn pgr_f64(pi: [f32; 2], u: [f32; 2], pj: [f32; 2]) -> (f64, f64) {
    let d = [pj[0] as f64 - pi[0] as f64, pj[1] as f64 - pi[1] as f64];
    let (ux, uy) = (u[0] as f64, u[1] as f64);
    let n = ux.hypot(uy);
    let (ux, uy) = (ux / n, uy / n);
    (
        d[0].hypot(d[1]),
        (ux * d[1] - uy * d[0]).atan2(ux * d[0] + uy * d[1]),
    )
}

/// |a - b| for angles, in [0, pi].
fn angle_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(2.0 * std::f64::consts::PI);
    d.min(2.0 * std::f64::consts::PI - d)
}

proptest! {
    #![proptest_config(cases(256))]

    /// `pgr::pgr` gives the exact geometry (the angle to within the 1e-5 rad
    /// of its atan2 approximation) and the same values after a rigid motion
    /// of both points and the tangent.
    #[test]
    fn pgr_values_are_exact_and_invariant_under_rigid_motion(
        pi in (-15.0f32..15.0, -15.0f32..15.0),
        pj in (-15.0f32..15.0, -15.0f32..15.0),
        a in -PI..PI,
        t in rigid(),
    ) {
        let (pi, pj, u) = ([pi.0, pi.1], [pj.0, pj.1], unit(a));
        let (rho_true, th_true) = pgr_f64(pi, u, pj);
        prop_assume!(rho_true > 0.01);
        // Rounding of coordinates up to ~50 m in f32: a few 1e-6 m; the
        // angle then moves by that over rho.
        let pos_tol = 2e-5;
        let th_tol = 2e-5 + 2.0 * pos_tol / rho_true;
        let (rho, th) = pgr::pgr(pi, u, pj);
        prop_assert!((rho as f64 - rho_true).abs() <= pos_tol, "rho {rho} vs {rho_true}");
        prop_assert!(angle_gap(th as f64, th_true) <= th_tol, "theta {th} vs {th_true}");
        let (rho2, th2) = pgr::pgr(t.apply(pi), turn(&t, u), t.apply(pj));
        prop_assert!((rho2 - rho).abs() as f64 <= 2.0 * pos_tol, "rho {rho} -> {rho2}");
        prop_assert!(
            angle_gap(th2 as f64, th as f64) <= 2.0 * th_tol,
            "theta {th} -> {th2}"
        );
    }
}

/// Dense beam-ordered points of a full 360-degree scan in a random scene: a
/// smooth room outline (a few harmonics) with up to three objects in front
/// of it, which make depth jumps.
fn scan_points() -> impl Strategy<Value = Vec<[f32; 2]>> {
    (
        90usize..=360,
        2.0f32..6.0,
        vec((0.0f32..0.6, 0.0f32..6.3), 1..4),
        vec((0.0f32..6.3, 0.1f32..0.6, 0.3f32..0.8), 0..4),
    )
        .prop_map(|(beams, base, harmonics, objects)| {
            (0..beams)
                .map(|k| {
                    let phi = k as f32 * 2.0 * PI / beams as f32;
                    let mut r = base;
                    for (h, (amp, phase)) in harmonics.iter().enumerate() {
                        r += amp * base * 0.3 * ((h + 2) as f32 * phi + phase).sin();
                    }
                    for &(at, width, scale) in &objects {
                        if angle_gap(phi as f64, at as f64) < width as f64 / 2.0 {
                            r *= scale;
                        }
                    }
                    let r = r.clamp(0.3, 12.0);
                    [r * phi.cos(), r * phi.sin()]
                })
                .collect()
        })
}

/// Counts the votes of the histogram of (`pts`, `tan`) that lie within
/// rounding distance of a bin edge, from the exact (f64) pair geometry.
/// Position rounding after a rigid motion is below `pos_tol` metres; the
/// angle moves by at most `pos_tol / rho` plus the atan2 approximation's
/// own variation.
fn votes_near_an_edge(
    pts: &[[f32; 2]],
    tan: &[[f32; 2]],
    rho_bins: usize,
    theta_bins: usize,
    rho_max: f32,
    pos_tol: f64,
) -> usize {
    let rho_w = rho_max as f64 / rho_bins as f64;
    let th_w = 2.0 * std::f64::consts::PI / theta_bins as f64;
    let near_rho = |rho: f64| {
        // Edges at k * rho_w for k in 1..rho_bins; beyond rho_max there are none.
        rho < rho_max as f64 + pos_tol && {
            let f = rho / rho_w;
            (f - f.round()).abs() * rho_w < pos_tol && f.round() >= 1.0
        }
    };
    let near_theta = |theta: f64, rho: f64| {
        // Edges at -pi + (k - 1/2) w: the offset from an edge is
        // (theta + pi + w / 2) mod w.
        let tol = 5e-5 + 2.0 * pos_tol / rho;
        let f = (theta + std::f64::consts::PI + th_w / 2.0).rem_euclid(th_w);
        f.min(th_w - f) < tol
    };
    let mut near = 0;
    for i in 0..pts.len() {
        for j in (i + 1)..pts.len() {
            let (rho, t_ij) = pgr_f64(pts[i], tan[i], pts[j]);
            let (_, t_ji) = pgr_f64(pts[j], tan[j], pts[i]);
            for t in [t_ij, t_ji] {
                if rho < 1e-3 || near_rho(rho) || near_theta(t, rho) {
                    near += 1;
                }
            }
        }
    }
    near
}

fn l1(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs() as f64).sum()
}

proptest! {
    #![proptest_config(cases(48))]

    /// The PGR histogram of a prepared scan (points input, full turn) is
    /// unchanged by a rigid motion of the scan, with the database's binning
    /// and with a random one. Only votes within rounding distance of a bin
    /// edge may move, each changing the L1 distance by at most 2 / votes;
    /// with none (the usual case) the histograms are bit-identical.
    #[test]
    fn pgr_histogram_is_invariant_under_rigid_motion(
        dense in scan_points(),
        t in rigid(),
        rho_bins in 1usize..=24,
        theta_bins in 2usize..=36,
        rho_max in 1.0f32..20.0,
    ) {
        let p = Params::defaults(dense.len() as u32, 30.0);
        let m = p.prep.max_points as usize;
        let (mut pts, mut tan) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
        let n = prep::prepare(&dense, true, &p, &mut pts, &mut tan);
        prop_assume!(n >= 10);
        let (pts, tan) = (&pts[..n], &tan[..n]);
        let moved: Vec<[f32; 2]> = pts.iter().map(|&q| t.apply(q)).collect();
        let turned: Vec<[f32; 2]> = tan.iter().map(|&u| turn(&t, u)).collect();
        let pos_tol = 2e-5;
        for (rb, tb, rmax) in [
            (p.coarse.hist_rho_bins as usize, p.coarse.hist_theta_bins as usize, p.coarse.hist_rho_max),
            (rho_bins, theta_bins, rho_max),
        ] {
            let k = rb * tb;
            let (mut h, mut hm) = (vec![0f32; k], vec![0f32; k]);
            let votes = pgr::histogram_binned(pts, tan, rb, tb, rmax, &mut h);
            let votes_m = pgr::histogram_binned(&moved, &turned, rb, tb, rmax, &mut hm);
            prop_assert_eq!(votes, n * (n - 1));
            prop_assert_eq!(votes_m, votes);
            let near = votes_near_an_edge(pts, tan, rb, tb, rmax, pos_tol);
            let d = l1(&h, &hm);
            let allowed = 2.0 * near as f64 / votes as f64;
            prop_assert!(
                d <= allowed + 1e-6,
                "{rb} x {tb} bins to {rmax} m: L1 {d}, {near} of {votes} votes near an edge"
            );
            if near == 0 {
                prop_assert_eq!(&h, &hm);
            }
        }
    }
}

proptest! {
    #![proptest_config(cases(128))]

    /// `ssm::least_squares` recovers a rigid transform from noise-free
    /// correspondences (in any order), and leaves out correspondences
    /// farther than the threshold from the prior pose. Tolerances follow
    /// from f32 rounding of the centroids (sums of up to 40 coordinates)
    /// and the 1e-5 rad of the atan2 approximation (see below).
    #[test]
    fn least_squares_recovers_a_rigid_transform(
        q in vec((-10.0f32..10.0, -10.0f32..10.0), 2..40),
        t in rigid(),
        outliers in vec((any::<prop::sample::Index>(), 1.0f32..5.0, -PI..PI), 0..10),
        shuffle_seed in any::<u64>(),
    ) {
        let q: Vec<[f32; 2]> = q.into_iter().map(|(x, y)| [x, y]).collect();
        let n = q.len();
        let c = q.iter().fold([0.0f64; 2], |c, p| [c[0] + p[0] as f64, c[1] + p[1] as f64]);
        let c = [c[0] / n as f64, c[1] / n as f64];
        let spread = (q
            .iter()
            .map(|p| (p[0] as f64 - c[0]).powi(2) + (p[1] as f64 - c[1]).powi(2))
            .sum::<f64>()
            / n as f64)
            .sqrt();
        prop_assume!(spread > 0.5);
        // Inliers map exactly; each outlier pairs a point with a target
        // 1 to 5 m from its image.
        let mut r: Vec<[f32; 2]> = q.iter().map(|&p| t.apply(p)).collect();
        let mut acc: Vec<[u16; 2]> = (0..n as u16).map(|i| [i, i]).collect();
        for (which, off, dir) in &outliers {
            let i = which.index(n);
            let p = r[i];
            r.push([p[0] + off * dir.cos(), p[1] + off * dir.sin()]);
            acc.push([i as u16, (r.len() - 1) as u16]);
        }
        // A fixed shuffle of the pairs from the generated seed.
        let mut s = shuffle_seed | 1;
        for k in (1..acc.len()).rev() {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            acc.swap(k, (s % (k as u64 + 1)) as usize);
        }
        // Tolerances. Centroids: f32 sums of n coordinates of magnitude up
        // to m, off by at most n eps m / 2 each. The angle is insensitive
        // to a common shift of the points to first order, so it carries the
        // atan2 approximation (< 1e-5 rad) and rounding; the translation
        // `rc - R qc` carries both centroids' errors and the angle's error
        // times |qc|.
        let eps = f32::EPSILON as f64;
        let max_abs = |v: &[[f32; 2]]| {
            v.iter().flatten().fold(0.0f64, |m, &x| m.max(x.abs() as f64))
        };
        let (mq, mr) = (max_abs(&q), max_abs(&r[..n]));
        let th_tol = 1e-5 + 64.0 * eps;
        let qc_norm = c[0].hypot(c[1]);
        let xy_tol = n as f64 * eps * (mq + mr) / 2.0 + qc_norm * th_tol + 8.0 * eps * mr;
        // Prior at the truth, threshold 0.5 m: every outlier is left out.
        let (fit, inl) = ssm::least_squares(&acc, &q, &r, &t, 0.25).expect("a fit");
        prop_assert_eq!(inl as usize, n);
        let check = |fit: &Pose2| -> Result<(), TestCaseError> {
            prop_assert!(((fit.x - t.x).abs() as f64) <= xy_tol, "x {} vs {} (tol {xy_tol})", fit.x, t.x);
            prop_assert!(((fit.y - t.y).abs() as f64) <= xy_tol, "y {} vs {} (tol {xy_tol})", fit.y, t.y);
            prop_assert!(
                (wrap_angle(fit.theta - t.theta).abs() as f64) <= th_tol,
                "theta {} vs {} (tol {th_tol})", fit.theta, t.theta
            );
            Ok(())
        };
        check(&fit)?;
        // The inliers alone, no prior, an infinite threshold: the same fit.
        let inliers: Vec<[u16; 2]> = acc.iter().copied().filter(|a| a[1] < n as u16).collect();
        let (fit, inl) = ssm::least_squares(&inliers, &q, &r, &Pose2::default(), f32::INFINITY)
            .expect("a fit");
        prop_assert_eq!(inl as usize, n);
        check(&fit)?;
        // Fewer than two pairs within the threshold: no fit.
        prop_assert!(ssm::least_squares(&inliers[..1], &q, &r, &t, 0.25).is_none());
    }
}

/// A random occupancy grid: `(width, height, cells)`, `cells[cy * w + cx]`
/// true when blocked.
fn grid() -> impl Strategy<Value = (u32, u32, Vec<bool>)> {
    (1u32..=40, 1u32..=40, 0.0f64..0.5).prop_flat_map(|(w, h, p)| {
        (
            Just(w),
            Just(h),
            vec(prop::bool::weighted(p), (w * h) as usize),
        )
    })
}

fn pack(w: u32, h: u32, cells: &[bool]) -> Vec<u32> {
    let mut words = vec![0u32; BitGrid::words_for(w, h)];
    for (i, &b) in cells.iter().enumerate() {
        if b {
            words[i / 32] |= 1 << (i % 32);
        }
    }
    words
}

/// Step of the dense reference (cells).
const STEP: f64 = 1e-3;

/// The slow reference: walks the ray in steps of [`STEP`] cells (f64) and
/// returns the first step whose point lies in a blocked cell, or `None`
/// when the ray leaves the grid or passes `max` first.
fn march(w: u32, h: u32, cells: &[bool], o: [f64; 2], d: [f64; 2], max: f64) -> Option<f64> {
    let mut k = 0u64;
    loop {
        let t = k as f64 * STEP;
        if t > max {
            return None;
        }
        let (x, y) = (o[0] + t * d[0], o[1] + t * d[1]);
        if x < 0.0 || y < 0.0 || x >= w as f64 || y >= h as f64 {
            return None;
        }
        if cells[y as usize * w as usize + x as usize] {
            return Some(t);
        }
        k += 1;
    }
}

/// Where the ray `o + t d` is inside cell `(cx, cy)`: `(t_in, t_out)` (slab
/// method, f64); empty when `t_in > t_out`.
fn slab(o: [f64; 2], d: [f64; 2], cx: u32, cy: u32) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for (k, c) in [cx, cy].into_iter().enumerate() {
        let (a, b) = (c as f64, c as f64 + 1.0);
        if d[k] == 0.0 {
            if !(o[k] >= a && o[k] <= b) {
                return (1.0, 0.0);
            }
        } else {
            let (t0, t1) = ((a - o[k]) / d[k], (b - o[k]) / d[k]);
            lo = lo.max(t0.min(t1));
            hi = hi.min(t0.max(t1));
        }
    }
    (lo, hi)
}

proptest! {
    #![proptest_config(cases(64))]

    /// `raycast::cast_dir` against dense stepping on a random grid:
    /// * it never passes a blocked cell the stepping enters: a hit no later
    ///   than the reference's (up to 1e-3 cell);
    /// * every hit is real: the cell it stops in (from `traverse`) is
    ///   blocked, the ray meets that cell's square at the returned distance,
    ///   within `max_cells`.
    /// A hit well before the reference's is therefore a corner the ray clips
    /// for less than one step, which stepping can miss.
    #[test]
    fn cast_agrees_with_dense_stepping(
        (w, h, cells) in grid(),
        rays in vec((0.0f64..1.0, 0.0f64..1.0, -PI..PI, 0.5f32..80.0), 1..8),
    ) {
        let words = pack(w, h, &cells);
        let g = BitGrid::new(w, h, &words).unwrap();
        let eps = 1e-3;
        for (fu, fv, a, max) in rays {
            let (u, v) = ((fu * w as f64) as f32, (fv * h as f64) as f32);
            prop_assume!((u as f64) < w as f64 && (v as f64) < h as f64);
            let (dx, dy) = (a.cos(), a.sin());
            let (o, d) = ([u as f64, v as f64], [dx as f64, dy as f64]);
            let reference = march(w, h, &cells, o, d, max as f64);
            let got = raycast::cast_dir(&g, u, v, dx, dy, max);
            let at = format!("ray from ({u}, {v}) at {a} rad, max {max}: cast {got:?}, stepping {reference:?}");
            if let Some(tr) = reference {
                prop_assert!(matches!(got, Some(t) if t as f64 <= tr + eps), "missed a cell: {at}");
            }
            if let Some(t) = got {
                let mut hit = None;
                raycast::traverse(w, h, u, v, dx, dy, max, |cx, cy, tt| {
                    if cells[(cy * w + cx) as usize] {
                        hit = Some((cx, cy, tt));
                        false
                    } else {
                        true
                    }
                });
                let (cx, cy, tt) = hit.expect("traverse finds the cell cast hit");
                prop_assert_eq!(tt, t, "{}", at);
                let (t_in, t_out) = slab(o, d, cx, cy);
                prop_assert!(t_in <= t_out + eps, "the ray misses cell ({cx}, {cy}): {at}");
                prop_assert!(
                    (t as f64 - t_in.max(0.0)).abs() <= eps,
                    "enters ({cx}, {cy}) at {t_in}, not {t}: {at}"
                );
                prop_assert!(t <= max + eps as f32, "{}", at);
            }
        }
    }
}

/// A star-shaped simple polygon: 3 to 32 vertices at increasing angles
/// around (cx, cy), each at its own radius (0.5 to 10 m).
fn star_polygon() -> impl Strategy<Value = Vec<[f32; 2]>> {
    (
        -50.0f32..50.0,
        -50.0f32..50.0,
        vec(
            (0.1f32..1.0, 0.5f32..10.0),
            3..=refloc::prior::MAX_POLYGON_VERTICES,
        ),
    )
        .prop_map(|(cx, cy, steps)| {
            let total: f32 = steps.iter().map(|s| s.0).sum();
            let mut a = 0.0f32;
            steps
                .iter()
                .map(|&(da, r)| {
                    a += da * 2.0 * PI / total;
                    [cx + r * a.cos(), cy + r * a.sin()]
                })
                .collect()
        })
}

/// Even-odd point-in-polygon and distance to the edges, in f64.
fn inside_f64(v: &[[f32; 2]], p: [f64; 2]) -> (bool, f64) {
    let (mut inside, mut dist) = (false, f64::INFINITY);
    for (i, a) in v.iter().enumerate() {
        let b = v[(i + 1) % v.len()];
        let (ax, ay, bx, by) = (a[0] as f64, a[1] as f64, b[0] as f64, b[1] as f64);
        if (ay > p[1]) != (by > p[1]) && p[0] < ax + (p[1] - ay) * (bx - ax) / (by - ay) {
            inside = !inside;
        }
        let (dx, dy) = (bx - ax, by - ay);
        let t = (((p[0] - ax) * dx + (p[1] - ay) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
        dist = dist.min((p[0] - ax - t * dx).hypot(p[1] - ay - t * dy));
    }
    (inside, dist)
}

proptest! {
    #![proptest_config(cases(256))]

    /// Polygon priors never panic, whatever the numbers (NaN, infinities,
    /// huge values, too few or too many vertices): the constructor refuses
    /// or accepts, and an accepted polygon answers every query.
    #[test]
    fn polygon_priors_never_panic(
        xy in vec(any::<f32>(), 0..80),
        p in (any::<f32>(), any::<f32>(), any::<f32>()),
    ) {
        let from_flat = refloc::Polygon::from_flat(&xy);
        let pairs: Vec<[f32; 2]> = xy.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
        prop_assert_eq!(from_flat.is_ok(), refloc::Polygon::new(&pairs).is_ok() && xy.len() % 2 == 0);
        if let Ok(poly) = from_flat {
            let prior = refloc::Prior { polygon: Some(poly), ..refloc::Prior::NONE };
            prop_assert!(prior.is_valid() && prior.has_region());
            let _ = prior.considers_site([p.0, p.1]);
            let _ = prior.allows(&Pose2::new(p.0, p.1, p.2));
            let _ = poly.distance_to_boundary([p.0, p.1]);
        }
    }

    /// On star-shaped polygons, `contains` is the even-odd rule computed in
    /// f64 for points more than 1 mm from an edge, holds every vertex and
    /// edge midpoint, and `distance_to_boundary` is the f64 distance.
    #[test]
    fn point_in_polygon_matches_an_f64_reference(
        v in star_polygon(),
        p in (-70.0f32..70.0, -70.0f32..70.0),
    ) {
        let poly = refloc::Polygon::new(&v).unwrap();
        let (inside, dist) = inside_f64(&v, [p.0 as f64, p.1 as f64]);
        let d = poly.distance_to_boundary([p.0, p.1]) as f64;
        prop_assert!((d - dist).abs() <= 1e-4 + 1e-5 * dist, "distance {} vs {}", d, dist);
        if dist > 1e-3 {
            prop_assert_eq!(poly.contains([p.0, p.1]), inside);
        }
        for (i, a) in v.iter().enumerate() {
            let b = v[(i + 1) % v.len()];
            prop_assert!(poly.contains(*a), "vertex {:?}", a);
            let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
            prop_assert!(poly.contains(mid), "edge midpoint {:?}", mid);
        }
    }
}
