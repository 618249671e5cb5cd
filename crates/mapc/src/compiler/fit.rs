//! Fitting the logistic weights `w` of the pairwise potential (paper eq. 4)
//! on the map's own data: query scans are simulated near reference sites with
//! sensor noise, tentative correspondences are formed exactly as the runtime
//! forms them, each is labelled correct when the known true transform puts the
//! input point within `CORRECT_DIST` of its reference partner, and every pair
//! of correspondences that passes the runtime's rho pre-filter becomes one
//! sample: features `(1, drho^2, dtheta^2)`, label "both correct". The weights
//! are the maximum-likelihood logistic regression (Newton / IRLS, with a tiny
//! ridge term for stability).

use refloc::params::Params;
use refloc::raycast::BitGrid;
use refloc::ssm::{self, DESC_LEN};
use refloc::{prep, MapFrame, Pose2};

use crate::compiler::rng::Rng;
use crate::compiler::sim::{self, Lidar, Noise};

/// A correspondence counts as correct within this distance (m).
pub const CORRECT_DIST: f32 = 0.15;

/// What the fit saw and found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FitReport {
    /// Simulated queries used.
    pub queries: usize,
    /// Pair samples.
    pub samples: usize,
    /// Positive samples.
    pub positives: usize,
    /// Fitted weights (bias, 1/m^2, 1/rad^2).
    pub w: [f32; 3],
    /// Seed used.
    pub seed: u64,
}

/// Simulates `queries` scans around sites (uniformly chosen), and fits `w`.
/// `site_xy` gives site positions (m); `site_scans[s]` their reference ranges.
#[allow(clippy::too_many_arguments)]
pub fn fit_weights(
    grid: &BitGrid<'_>,
    frame: &MapFrame,
    clearance_ok: &dyn Fn([f32; 2]) -> bool,
    site_xy: &[[f32; 2]],
    site_scans: &[Vec<f32>],
    params: &Params,
    queries: usize,
    seed: u64,
) -> FitReport {
    let s = &params.sensor;
    let ref_lidar = Lidar {
        beams: s.beams as usize,
        angle_min: s.angle_min,
        angle_increment: s.angle_increment,
        range_min: s.range_min,
        range_max: s.range_max,
    };
    let mut rng = Rng::new(seed);
    let p = params.prep.max_points as usize;
    let mut qp = vec![[0f32; 2]; p];
    let mut qt = vec![[0f32; 2]; p];
    let mut rp = vec![[0f32; 2]; p];
    let mut rt = vec![[0f32; 2]; p];
    let mut qd = vec![0 as ssm::DescBin; p * DESC_LEN];
    let mut rd = vec![0 as ssm::DescBin; p * DESC_LEN];
    let mut tent = vec![[0u16; 2]; p * params.ssm.tentative_k as usize];
    let mut xs: Vec<[f32; 2]> = Vec::new();
    let mut ys: Vec<f32> = Vec::new();
    let mut used = 0;
    let max_samples = 400_000usize;
    if site_xy.is_empty() {
        return FitReport {
            queries: 0,
            samples: 0,
            positives: 0,
            w: params.ssm.w,
            seed,
        };
    }
    for _ in 0..queries * 4 {
        if used >= queries {
            break;
        }
        let si = rng.below(site_xy.len() as u64) as usize;
        let c = site_xy[si];
        let r = rng.range(0.0, 2.0) as f32;
        let a = rng.range(-std::f64::consts::PI, std::f64::consts::PI) as f32;
        let pos = [c[0] + r * a.cos(), c[1] + r * a.sin()];
        if !clearance_ok(pos) {
            continue;
        }
        let heading = rng.range(-std::f64::consts::PI, std::f64::consts::PI) as f32;
        let sensor = Pose2::new(pos[0], pos[1], heading);
        let mut ranges = sim::virtual_scan(grid, frame, &sensor, &ref_lidar);
        sim::add_noise(
            &mut ranges,
            &ref_lidar,
            &Noise {
                range_sigma: 0.01,
                short_outliers: 20,
            },
            &mut rng,
        );
        let mut dense = vec![[0f32; 2]; ranges.len()];
        let n = prep::ranges_to_points(
            &ranges,
            s.angle_min,
            s.angle_increment,
            s.range_min,
            s.range_max,
            &mut dense,
        );
        let nq = prep::prepare(&dense[..n], true, params, &mut qp, &mut qt);
        let mut rdense = vec![[0f32; 2]; site_scans[si].len()];
        let m = prep::ranges_to_points(
            &site_scans[si],
            s.angle_min,
            s.angle_increment,
            s.range_min,
            s.range_max,
            &mut rdense,
        );
        let nr = prep::prepare(&rdense[..m], true, params, &mut rp, &mut rt);
        if nq < 8 || nr < 8 {
            continue;
        }
        used += 1;
        ssm::descriptors(&qp[..nq], &qt[..nq], params.ssm.desc_radius, &mut qd);
        ssm::descriptors(&rp[..nr], &rt[..nr], params.ssm.desc_radius, &mut rd);
        let nl = ssm::tentative(nq, nr, params.ssm.tentative_k as usize, &qd, &rd, &mut tent);
        // True transform: query sensor frame -> site frame (heading 0 at the site).
        let truth = Pose2::new(c[0], c[1], 0.0).inverse().compose(&sensor);
        let correct: Vec<bool> = tent[..nl]
            .iter()
            .map(|&[i, ii]| {
                let p = truth.apply(qp[i as usize]);
                let q = rp[ii as usize];
                ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt() < CORRECT_DIST
            })
            .collect();
        // Every positive pair, and a deterministic subsample of the negatives.
        for a in 0..nl {
            for b in (a + 1)..nl {
                let Some((drho, dth2)) = ssm::pair_deformation(
                    &qp,
                    &qt,
                    &rp,
                    &rt,
                    tent[a],
                    tent[b],
                    params.ssm.max_rho_dev,
                ) else {
                    continue;
                };
                let pos = correct[a] && correct[b];
                if !pos && rng.below(8) != 0 {
                    continue;
                }
                if xs.len() < max_samples {
                    xs.push([drho * drho, dth2]);
                    // Negatives are subsampled 1 in 8: weight them back.
                    ys.push(if pos { 1.0 } else { 0.0 });
                }
            }
        }
    }
    let positives = ys.iter().filter(|&&y| y > 0.5).count();
    let w = if positives > 10 && positives < ys.len() {
        logistic_irls(&xs, &ys, 8.0)
    } else {
        params.ssm.w
    };
    FitReport {
        queries: used,
        samples: xs.len(),
        positives,
        w,
        seed,
    }
}

/// Logistic regression `P(y=1) = sigmoid(w0 + w1 x0 + w2 x1)` by Newton's
/// method; negatives carry weight `neg_weight` (they were subsampled).
pub fn logistic_irls(xs: &[[f32; 2]], ys: &[f32], neg_weight: f64) -> [f32; 3] {
    let mut w = [0f64; 3];
    for _ in 0..50 {
        let mut g = [0f64; 3];
        let mut h = [[0f64; 3]; 3];
        for (x, &y) in xs.iter().zip(ys) {
            let f = [1.0, x[0] as f64, x[1] as f64];
            let z = w[0] + w[1] * f[1] + w[2] * f[2];
            let p = 1.0 / (1.0 + (-z).exp());
            let sw = if y > 0.5 { 1.0 } else { neg_weight };
            for a in 0..3 {
                g[a] += sw * (y as f64 - p) * f[a];
                for b in 0..3 {
                    h[a][b] += sw * p * (1.0 - p) * f[a] * f[b];
                }
            }
        }
        for (a, row) in h.iter_mut().enumerate() {
            row[a] += 1e-6 * (1.0 + row[a]);
        }
        let Some(step) = solve3(&h, &g) else { break };
        let mut done = true;
        for a in 0..3 {
            w[a] += step[a];
            if step[a].abs() > 1e-6 * (1.0 + w[a].abs()) {
                done = false;
            }
        }
        if done {
            break;
        }
    }
    [w[0] as f32, w[1] as f32, w[2] as f32]
}

fn solve3(h: &[[f64; 3]; 3], g: &[f64; 3]) -> Option<[f64; 3]> {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(h);
    if d.abs() < 1e-300 || !d.is_finite() {
        return None;
    }
    let mut out = [0.0; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut m = *h;
        for r in 0..3 {
            m[r][k] = g[r];
        }
        *o = det(&m) / d;
    }
    Some(out)
}
