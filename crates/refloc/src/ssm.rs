//! Spectral scan matching (paper section 3) between two prepared scans.
//!
//! 1. *Tentative correspondences*: each input point is paired with the
//!    `tentative_k` reference points whose local PGR descriptor (a small
//!    histogram of (rho, theta) to the points within `desc_radius`) is
//!    closest in L1. This prunes the n x m pairs to n * k.
//! 2. *Affinity*: G_ab = logistic(w . g) (eq. 3-4) for pairs of
//!    correspondences whose rho agree within `max_rho_dev` and that keep the
//!    mapping one-to-one; everything else is 0. Stored sparse (upper-triangle
//!    coordinate list, capped).
//! 3. *Leading eigenvector* by power iteration from the uniform vector.
//! 4. *Binarization*: greedy in decreasing x, with conflict removal; E is
//!    x^T G x of the binary x.
//! 5. *RANSAC* on pairs of accepted correspondences, then least squares
//!    (Arun et al.; in 2D the SVD of the 2x2 cross-covariance has the closed
//!    form used here, with det = +1 enforced).
//!
//! The pose maps input points into the reference scan's frame: p = R r + q.

use crate::math::{dist2, norm, signed_angle};
use crate::params::Params;
use crate::Pose2;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

/// Descriptor rho bins.
pub const DESC_RHO: usize = 4;
/// Descriptor theta bins.
pub const DESC_THETA: usize = 8;
/// Descriptor length.
pub const DESC_LEN: usize = DESC_RHO * DESC_THETA;

/// One non-zero affinity entry (a < b).
#[derive(Clone, Copy, Debug, Default, FromBytes, IntoBytes, KnownLayout, Immutable)]
#[repr(C)]
pub struct Affinity {
    /// First correspondence.
    pub a: u16,
    /// Second correspondence.
    pub b: u16,
    /// G_ab.
    pub g: f32,
}

/// Working memory for one match, carved from the localizer's scratch.
pub struct SsmWork<'a> {
    /// Input descriptors, `max_points * DESC_LEN`.
    pub qdesc: &'a mut [f32],
    /// Reference descriptors, `max_points * DESC_LEN`.
    pub rdesc: &'a mut [f32],
    /// Tentative correspondences (input index, reference index).
    pub tent: &'a mut [[u16; 2]],
    /// Sparse affinity.
    pub aff: &'a mut [Affinity],
    /// Eigenvector estimate.
    pub x: &'a mut [f32],
    /// Power iteration buffer.
    pub y: &'a mut [f32],
    /// Sort order.
    pub order: &'a mut [u16],
    /// Accepted correspondences.
    pub acc: &'a mut [[u16; 2]],
    /// Flags: input point used / reference point used / correspondence accepted.
    pub flags: &'a mut [u8],
}

/// What one SSM run found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SsmResult {
    /// Input-scan frame to reference-scan frame (m, rad).
    pub pose: Pose2,
    /// Matching score E = x^T G x of the binary assignment.
    pub score: f32,
    /// Correspondences accepted by binarization.
    pub matched: u32,
    /// RANSAC / least-squares inliers.
    pub inliers: u32,
    /// Tentative correspondences considered.
    pub tentative: u32,
    /// Non-zero affinity entries (upper triangle).
    pub nonzeros: u32,
}

/// Computes the local descriptor of every point of a prepared scan.
pub fn descriptors(pts: &[[f32; 2]], tan: &[[f32; 2]], radius: f32, out: &mut [f32]) {
    let n = pts.len().min(tan.len()).min(out.len() / DESC_LEN);
    let r2 = radius * radius;
    for v in out[..n * DESC_LEN].iter_mut() {
        *v = 0.0;
    }
    for i in 0..n {
        let mut count = 0u32;
        let row = &mut out[i * DESC_LEN..(i + 1) * DESC_LEN];
        for j in 0..n {
            if i == j {
                continue;
            }
            let d = [pts[j][0] - pts[i][0], pts[j][1] - pts[i][1]];
            let d2 = d[0] * d[0] + d[1] * d[1];
            if !(d2 < r2) {
                continue;
            }
            let rho = libm::sqrtf(d2);
            let th = signed_angle(tan[i], d);
            let c = crate::pgr::cell(rho, th, DESC_RHO, DESC_THETA, radius);
            row[c] += 1.0;
            count += 1;
        }
        if count > 0 {
            let s = 1.0 / count as f32;
            for v in row.iter_mut() {
                *v *= s;
            }
        }
    }
}

/// Runs SSM between input (`q_*`) and reference (`r_*`) prepared scans whose
/// descriptors are already in `work.qdesc` / `work.rdesc`. `None` when no pose
/// with at least `min_inliers` inliers was found.
pub fn match_scans(
    q_pts: &[[f32; 2]],
    q_tan: &[[f32; 2]],
    r_pts: &[[f32; 2]],
    r_tan: &[[f32; 2]],
    params: &Params,
    work: &mut SsmWork<'_>,
) -> Option<SsmResult> {
    let nq = q_pts.len().min(q_tan.len()).min(u16::MAX as usize);
    let nr = r_pts.len().min(r_tan.len()).min(u16::MAX as usize);
    if nq < 2 || nr < 2 {
        return None;
    }
    let nl = tentative(
        nq,
        nr,
        params.ssm.tentative_k as usize,
        work.qdesc,
        work.rdesc,
        work.tent,
    );
    let nl = nl.min(work.x.len()).min(work.y.len()).min(work.order.len());
    // 2. Sparse affinity.
    let mut nnz = 0usize;
    let cap = work.aff.len();
    'outer: for a in 0..nl {
        for b in (a + 1)..nl {
            let Some((drho, dth2)) = pair_deformation(
                q_pts,
                q_tan,
                r_pts,
                r_tan,
                work.tent[a],
                work.tent[b],
                params.ssm.max_rho_dev,
            ) else {
                continue;
            };
            let g = affinity(&params.ssm.w, drho, dth2);
            if g < AFFINITY_FLOOR {
                continue;
            }
            if nnz >= cap {
                break 'outer;
            }
            work.aff[nnz] = Affinity {
                a: a as u16,
                b: b as u16,
                g,
            };
            nnz += 1;
        }
    }
    if nnz == 0 {
        return None;
    }
    let aff = &work.aff[..nnz];
    // 3. Leading eigenvector by power iteration.
    let x = &mut work.x[..nl];
    let y = &mut work.y[..nl];
    let x0 = 1.0 / libm::sqrtf(nl as f32);
    for v in x.iter_mut() {
        *v = x0;
    }
    for _ in 0..params.ssm.power_iters {
        for v in y.iter_mut() {
            *v = 0.0;
        }
        for e in aff {
            let (a, b) = (e.a as usize, e.b as usize);
            y[a] += e.g * x[b];
            y[b] += e.g * x[a];
        }
        let n = libm::sqrtf(y.iter().map(|v| v * v).sum::<f32>());
        if !(n > 0.0) {
            return None;
        }
        let mut change = 0.0f32;
        for (xv, yv) in x.iter_mut().zip(y.iter()) {
            let nv = yv / n;
            change += libm::fabsf(nv - *xv);
            *xv = nv;
        }
        if change < 1e-5 {
            break;
        }
    }
    // 4. Greedy binarization with conflict removal.
    let order = &mut work.order[..nl];
    for (o, v) in order.iter_mut().enumerate() {
        *v = o as u16;
    }
    order.sort_unstable_by(|&a, &b| x[b as usize].total_cmp(&x[a as usize]).then(a.cmp(&b)));
    let xmax = x[order[0] as usize];
    let (used, rest) = work.flags.split_at_mut(nq.min(work.flags.len()));
    let (used_r, accf) = rest.split_at_mut(nr.min(rest.len()));
    if used.len() < nq || used_r.len() < nr || accf.len() < nl {
        return None;
    }
    used.fill(0);
    used_r.fill(0);
    accf[..nl].fill(0);
    let mut na = 0usize;
    for &o in order.iter() {
        let xv = x[o as usize];
        if !(xv > 0.0) || xv < params.ssm.binarize_frac * xmax {
            break;
        }
        let [i, ii] = work.tent[o as usize];
        if used[i as usize] != 0 || used_r[ii as usize] != 0 || na >= work.acc.len() {
            continue;
        }
        used[i as usize] = 1;
        used_r[ii as usize] = 1;
        accf[o as usize] = 1;
        work.acc[na] = [i, ii];
        na += 1;
    }
    let mut score = 0.0f32;
    for e in aff {
        if accf[e.a as usize] != 0 && accf[e.b as usize] != 0 {
            score += 2.0 * e.g;
        }
    }
    let acc = &work.acc[..na];
    // 5. RANSAC on pairs, then least squares.
    let (pose, inliers) = ransac(acc, q_pts, r_pts, params)?;
    Some(SsmResult {
        pose,
        score,
        matched: na as u32,
        inliers,
        tentative: nl as u32,
        nonzeros: nnz as u32,
    })
}

/// Fills `out` with tentative correspondences: for each of the `nq` input
/// points, the `k` reference points (of `nr`) with the closest descriptors
/// (L1). Returns how many were written.
pub fn tentative(
    nq: usize,
    nr: usize,
    k: usize,
    qdesc: &[f32],
    rdesc: &[f32],
    out: &mut [[u16; 2]],
) -> usize {
    let k = k.min(nr).min(crate::params::MAX_TENTATIVE_K as usize);
    if k == 0 {
        return 0;
    }
    let nq = nq.min(qdesc.len() / DESC_LEN).min(u16::MAX as usize);
    let nr = nr.min(rdesc.len() / DESC_LEN).min(u16::MAX as usize);
    let mut nl = 0usize;
    let mut best = [(f32::INFINITY, 0u16); crate::params::MAX_TENTATIVE_K as usize];
    for i in 0..nq {
        if nl + k > out.len() {
            break;
        }
        let qd = &qdesc[i * DESC_LEN..(i + 1) * DESC_LEN];
        for b in best[..k].iter_mut() {
            *b = (f32::INFINITY, 0);
        }
        for j in 0..nr {
            let rd = &rdesc[j * DESC_LEN..(j + 1) * DESC_LEN];
            let mut d = 0.0f32;
            for t in 0..DESC_LEN {
                d += libm::fabsf(qd[t] - rd[t]);
            }
            if d < best[k - 1].0 {
                let mut p = k - 1;
                while p > 0 && d < best[p - 1].0 {
                    best[p] = best[p - 1];
                    p -= 1;
                }
                best[p] = (d, j as u16);
            }
        }
        for b in &best[..k] {
            if b.0.is_finite() {
                out[nl] = [i as u16, b.1];
                nl += 1;
            }
        }
    }
    nl
}

/// The deformation between correspondences `a = (i, i')` and `b = (j, j')`
/// (eq. 3 without the constant): `(drho, dtheta2)` where `drho = rho_ij -
/// rho_i'j'` and `dtheta2` is the mean over both orders of the squared chord
/// between the unit vectors of `theta_ij` and `theta_i'j'`,
/// `|e^(i theta_ij) - e^(i theta_i'j')|^2 = 2 - 2 cos(dtheta)`, which equals
/// `dtheta^2` to within 1% below 0.35 rad and needs no arctangent.
/// `None` when they conflict (share a point) or `|drho| >= max_rho_dev`.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn pair_deformation(
    q_pts: &[[f32; 2]],
    q_tan: &[[f32; 2]],
    r_pts: &[[f32; 2]],
    r_tan: &[[f32; 2]],
    a: [u16; 2],
    b: [u16; 2],
    max_rho_dev: f32,
) -> Option<(f32, f32)> {
    let ([i, ii], [j, jj]) = (a, b);
    if i == j || ii == jj {
        return None;
    }
    let (i, ii, j, jj) = (i as usize, ii as usize, j as usize, jj as usize);
    let (pi, ri, pj, rj) = (
        *q_pts.get(i)?,
        *r_pts.get(ii)?,
        *q_pts.get(j)?,
        *r_pts.get(jj)?,
    );
    let dq = [pj[0] - pi[0], pj[1] - pi[1]];
    let dr = [rj[0] - ri[0], rj[1] - ri[1]];
    let (lq, lr) = (norm(dq), norm(dr));
    let drho = lq - lr;
    if !(libm::fabsf(drho) < max_rho_dev) || lq.is_nan() || lr.is_nan() || lq <= 0.0 || lr <= 0.0 {
        return None;
    }
    // cos of the angle difference at i (tangent u_i vs u_i') and at j (with -d).
    let cos_at = |u: [f32; 2], v: [f32; 2], sign: f32| {
        // (u . d, u x d) / |d| for the input and the reference, then their dot.
        let (cq, sq) = (
            sign * (u[0] * dq[0] + u[1] * dq[1]) / lq,
            sign * (u[0] * dq[1] - u[1] * dq[0]) / lq,
        );
        let (cr, sr) = (
            sign * (v[0] * dr[0] + v[1] * dr[1]) / lr,
            sign * (v[0] * dr[1] - v[1] * dr[0]) / lr,
        );
        cq * cr + sq * sr
    };
    let c1 = cos_at(*q_tan.get(i)?, *r_tan.get(ii)?, 1.0);
    let c2 = cos_at(*q_tan.get(j)?, *r_tan.get(jj)?, -1.0);
    Some((drho, 2.0 - (c1 + c2)))
}

/// The logistic pairwise potential of eq. 4: `1 / (1 + exp(-(w0 + w1 drho^2 + w2 dtheta^2)))`.
#[inline]
pub fn affinity(w: &[f32; 3], drho: f32, dth2: f32) -> f32 {
    let z = w[0] + w[1] * drho * drho + w[2] * dth2;
    // Below this z the potential is under AFFINITY_FLOOR: skip the exponential.
    if z < AFFINITY_FLOOR_Z {
        return 0.0;
    }
    1.0 / (1.0 + libm::expf(-z))
}

/// Affinities below this are treated as 0 (not stored).
pub const AFFINITY_FLOOR: f32 = 1e-3;
/// `logit(AFFINITY_FLOOR)`.
const AFFINITY_FLOOR_Z: f32 = -6.906_755;

/// Pose from two correspondences: rotation that aligns the input pair's
/// direction with the reference pair's, translation through the first point.
fn pose_from_pair(q1: [f32; 2], q2: [f32; 2], r1: [f32; 2], r2: [f32; 2]) -> Pose2 {
    let a = crate::math::atan2(r1[1] - r2[1], r1[0] - r2[0])
        - crate::math::atan2(q1[1] - q2[1], q1[0] - q2[0]);
    let (s, c) = (libm::sinf(a), libm::cosf(a));
    Pose2::new(
        r1[0] - (c * q1[0] - s * q1[1]),
        r1[1] - (s * q1[0] + c * q1[1]),
        a,
    )
}

fn count_inliers(
    acc: &[[u16; 2]],
    q: &[[f32; 2]],
    r: &[[f32; 2]],
    pose: &Pose2,
    thr2: f32,
) -> (u32, f32) {
    let mut n = 0;
    let mut res = 0.0;
    for &[i, ii] in acc {
        let p = pose.apply(q[i as usize]);
        let d2 = dist2(p, r[ii as usize]);
        if d2 < thr2 {
            n += 1;
            res += d2;
        }
    }
    (n, res)
}

/// Least-squares rigid fit (Arun et al.) of the correspondences within
/// `thr2` of `pose`; `None` with fewer than 2.
pub fn least_squares(
    acc: &[[u16; 2]],
    q: &[[f32; 2]],
    r: &[[f32; 2]],
    pose: &Pose2,
    thr2: f32,
) -> Option<(Pose2, u32)> {
    let (mut n, mut qc, mut rc) = (0u32, [0.0f32; 2], [0.0f32; 2]);
    for &[i, ii] in acc {
        let (qi, ri) = (q[i as usize], r[ii as usize]);
        if dist2(pose.apply(qi), ri) < thr2 {
            n += 1;
            qc = [qc[0] + qi[0], qc[1] + qi[1]];
            rc = [rc[0] + ri[0], rc[1] + ri[1]];
        }
    }
    if n < 2 {
        return None;
    }
    let inv = 1.0 / n as f32;
    qc = [qc[0] * inv, qc[1] * inv];
    rc = [rc[0] * inv, rc[1] * inv];
    let (mut sdot, mut scross) = (0.0f32, 0.0f32);
    for &[i, ii] in acc {
        let (qi, ri) = (q[i as usize], r[ii as usize]);
        if dist2(pose.apply(qi), ri) < thr2 {
            let (a, b) = (
                [qi[0] - qc[0], qi[1] - qc[1]],
                [ri[0] - rc[0], ri[1] - rc[1]],
            );
            sdot += a[0] * b[0] + a[1] * b[1];
            scross += a[0] * b[1] - a[1] * b[0];
        }
    }
    let th = crate::math::atan2(scross, sdot);
    let (s, c) = (libm::sinf(th), libm::cosf(th));
    Some((
        Pose2::new(
            rc[0] - (c * qc[0] - s * qc[1]),
            rc[1] - (s * qc[0] + c * qc[1]),
            th,
        ),
        n,
    ))
}

fn ransac(
    acc: &[[u16; 2]],
    q: &[[f32; 2]],
    r: &[[f32; 2]],
    params: &Params,
) -> Option<(Pose2, u32)> {
    let n = acc.len();
    if n < 2 {
        return None;
    }
    let thr2 = params.ssm.ransac_threshold * params.ssm.ransac_threshold;
    let mut rng = params.ssm.ransac_seed as u64 ^ 0x9E37_79B9_7F4A_7C15;
    let mut next = |m: usize| {
        // xorshift64*
        rng ^= rng >> 12;
        rng ^= rng << 25;
        rng ^= rng >> 27;
        ((rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 32) as usize) % m
    };
    let mut best: Option<(Pose2, u32, f32)> = None;
    for _ in 0..params.ssm.ransac_iters {
        let a = next(n);
        let b = next(n);
        if a == b {
            continue;
        }
        let (q1, q2) = (q[acc[a][0] as usize], q[acc[b][0] as usize]);
        let (r1, r2) = (r[acc[a][1] as usize], r[acc[b][1] as usize]);
        // The two pairs must agree in length and be long enough to fix a rotation.
        let (lq, lr) = (libm::sqrtf(dist2(q1, q2)), libm::sqrtf(dist2(r1, r2)));
        if lq < 0.5 || libm::fabsf(lq - lr) > params.ssm.max_rho_dev {
            continue;
        }
        let pose = pose_from_pair(q1, q2, r1, r2);
        let (cnt, res) = count_inliers(acc, q, r, &pose, thr2);
        let better = match best {
            None => true,
            Some((_, bc, br)) => cnt > bc || (cnt == bc && res < br),
        };
        if better {
            best = Some((pose, cnt, res));
        }
    }
    let (mut pose, _, _) = best?;
    let mut inliers = 0;
    for _ in 0..3 {
        let (p, m) = least_squares(acc, q, r, &pose, thr2)?;
        pose = p;
        inliers = m;
    }
    if inliers < params.ssm.min_inliers {
        return None;
    }
    Some((pose, inliers))
}
