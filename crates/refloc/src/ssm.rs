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

use crate::math::dist2;
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
    pub qdesc: &'a mut [DescBin],
    /// Tentative correspondences (input index, reference index).
    pub tent: &'a mut [[u16; 2]],
    /// Their end points as four arrays of `tent.len()` each: input x, input
    /// y, reference x, reference y (m), for the affinity's first test.
    pub ends: &'a mut [f32],
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
    /// The arrays of [`tentative_by_bins`]; with room for fewer than `nr`
    /// reference points ([`BinWork::capacity`]) the match uses
    /// [`tentative`] instead.
    pub bins: BinWork<'a>,
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

/// One descriptor bin: the share of a point's neighbours that fall in it,
/// in units of `1 / DESC_SCALE` (a descriptor's bins sum to about
/// [`DESC_SCALE`]). Integers make the L1 distance of [`tentative`] a sum of
/// absolute differences, which vector units do 8 or more at a time (bytes
/// were tried and lost precision that mattered: docs/performance.md).
pub type DescBin = u16;

/// What a descriptor's bins sum to (to within rounding).
pub const DESC_SCALE: u32 = 65535;

/// `tan(pi / 8)`: the descriptor's theta bins are 45 degrees wide, centred
/// on multiples of 45 degrees (as [`crate::pgr::cell`] centres its bins), so
/// their edges lie at 22.5 degrees from an axis or a diagonal.
const TAN_EIGHTH_PI: f32 = 0.414_213_57;

// The comparisons of `theta_octant` are written for 8 theta bins.
const _: () = assert!(DESC_THETA == 8);

/// The theta bin (0..8) of a direction at `(dot, cross)` from a point's
/// tangent: the bin of [`crate::pgr::cell`] for `theta = atan2(cross, dot)`
/// (bin 0 is centred on pi, bin 4 on 0), found by comparisons instead of an
/// arctangent.
#[inline]
fn theta_octant(dot: f32, cross: f32) -> usize {
    let (ac, as_) = (libm::fabsf(dot), libm::fabsf(cross));
    if as_ <= TAN_EIGHTH_PI * ac {
        // Along the tangent: 0 (bin 4) or pi (bin 0).
        if dot > 0.0 {
            4
        } else {
            0
        }
    } else if ac <= TAN_EIGHTH_PI * as_ {
        // Across it: +pi/2 (bin 6) or -pi/2 (bin 2).
        if cross > 0.0 {
            6
        } else {
            2
        }
    } else {
        match (dot > 0.0, cross > 0.0) {
            (true, true) => 5,
            (false, true) => 7,
            (false, false) => 1,
            (true, false) => 3,
        }
    }
}

/// Computes the local descriptor of every point of a prepared scan: for
/// point `i`, the (rho, theta) histogram of the points within `radius` (m)
/// (`DESC_RHO` equal rho bins, `DESC_THETA` theta bins around `i`'s
/// tangent, the binning of [`crate::pgr::cell`]), normalized to sum
/// [`DESC_SCALE`] and rounded to integers. A point with no neighbour has an
/// all-zero descriptor.
pub fn descriptors(pts: &[[f32; 2]], tan: &[[f32; 2]], radius: f32, out: &mut [DescBin]) {
    let n = pts.len().min(tan.len()).min(out.len() / DESC_LEN);
    out[..n * DESC_LEN].fill(0);
    // Squared rho bin edges: rho < (k+1) r / DESC_RHO.
    let mut edges = [0.0f32; DESC_RHO];
    for (k, e) in edges.iter_mut().enumerate() {
        let v = radius * (k + 1) as f32 / DESC_RHO as f32;
        *e = v * v;
    }
    let r2 = edges[DESC_RHO - 1];
    let rho_bin = |d2: f32| {
        edges
            .iter()
            .take(DESC_RHO - 1)
            .filter(|&&e| d2 >= e)
            .count()
    };
    // One row at a time: counts (at most n - 1 per bin), then shares.
    let mut counts = [0u16; DESC_LEN];
    for i in 0..n {
        counts.fill(0);
        let (pi, ui) = (pts[i], tan[i]);
        let mut total = 0u32;
        for (j, pj) in pts[..n].iter().enumerate() {
            if i == j {
                continue;
            }
            let d = [pj[0] - pi[0], pj[1] - pi[1]];
            let d2 = d[0] * d[0] + d[1] * d[1];
            if !(d2 < r2) {
                continue;
            }
            let dot = ui[0] * d[0] + ui[1] * d[1];
            let cross = ui[0] * d[1] - ui[1] * d[0];
            let c = rho_bin(d2) * DESC_THETA + theta_octant(dot, cross);
            counts[c] = counts[c].saturating_add(1);
            total += 1;
        }
        let row = &mut out[i * DESC_LEN..(i + 1) * DESC_LEN];
        for (o, &c) in row.iter_mut().zip(counts.iter()) {
            // Rounded share; c <= total, so the result is at most DESC_SCALE.
            // Most bins are empty and stay 0 without a division (so does a
            // row with no neighbour).
            if c != 0 {
                if let Some(v) = (c as u32 * DESC_SCALE + total / 2).checked_div(total) {
                    *o = v as DescBin;
                }
            }
        }
    }
}

/// The descriptors of `d`, one row of [`DESC_LEN`] bins each.
fn rows(d: &[DescBin]) -> impl Iterator<Item = &[DescBin; DESC_LEN]> {
    d.chunks_exact(DESC_LEN)
        .filter_map(|c| <&[DescBin; DESC_LEN]>::try_from(c).ok())
}

/// L1 distance of two descriptors (in units of `1 / DESC_SCALE`).
#[inline]
pub fn desc_distance(a: &[DescBin; DESC_LEN], b: &[DescBin; DESC_LEN]) -> u32 {
    let mut d = 0u32;
    for t in 0..DESC_LEN {
        d += a[t].abs_diff(b[t]) as u32;
    }
    d
}

/// Runs SSM between input (`q_*`) and reference (`r_*`) prepared scans; the
/// input's descriptors are already in `work.qdesc`, the reference's are
/// `rdesc` ([`DESC_LEN`] bins per reference point: computed per candidate,
/// or stored in the database). `None` when no pose with at least
/// `min_inliers` inliers was found.
pub fn match_scans(
    q_pts: &[[f32; 2]],
    q_tan: &[[f32; 2]],
    r_pts: &[[f32; 2]],
    r_tan: &[[f32; 2]],
    rdesc: &[DescBin],
    params: &Params,
    work: &mut SsmWork<'_>,
) -> Option<SsmResult> {
    let nq = q_pts.len().min(q_tan.len()).min(u16::MAX as usize);
    let nr = r_pts.len().min(r_tan.len()).min(u16::MAX as usize);
    if nq < 2 || nr < 2 {
        return None;
    }
    let k = params.ssm.tentative_k as usize;
    let nl = if work.bins.capacity() >= nr {
        tentative_by_bins(nq, nr, k, work.qdesc, rdesc, &mut work.bins, work.tent)
    } else {
        tentative(nq, nr, k, work.qdesc, rdesc, work.tent)
    };
    let nl = nl
        .min(work.x.len())
        .min(work.y.len())
        .min(work.order.len())
        .min(work.ends.len() / 4)
        .min(work.flags.len());
    // 2. Sparse affinity. Most pairs fail the rho test; it is first run on
    // the end points laid out as arrays (which the compiler vectorises),
    // then the pairs that pass get the rest of `pair_deformation` from the
    // same arrays ([`pair_deformation_from_ends`]), with each
    // correspondence's tangent turn (`x` and `y` hold it until the power
    // iteration).
    let (qx, rest) = work.ends.split_at_mut(nl);
    let (qy, rest) = rest.split_at_mut(nl);
    let (rx, rest) = rest.split_at_mut(nl);
    let ry = &mut rest[..nl];
    let (turn_c, turn_s) = (&mut work.x[..nl], &mut work.y[..nl]);
    for (a, &[i, ii]) in work.tent[..nl].iter().enumerate() {
        let (q, r) = (q_pts[i as usize], r_pts[ii as usize]);
        (qx[a], qy[a], rx[a], ry[a]) = (q[0], q[1], r[0], r[1]);
        [turn_c[a], turn_s[a]] = tangent_turn(q_tan[i as usize], r_tan[ii as usize]);
    }
    let reject = &mut work.flags[..nl];
    let dev = params.ssm.max_rho_dev;
    let k2 = 2.0 * dev * dev;
    let mut nnz = 0usize;
    let cap = work.aff.len();
    'outer: for a in 0..nl {
        let (qxa, qya, rxa, rya) = (qx[a], qy[a], rx[a], ry[a]);
        let lo = a + 1;
        let ends = qx[lo..]
            .iter()
            .zip(&qy[lo..])
            .zip(rx[lo..].iter().zip(&ry[lo..]));
        for (m, ((&x, &y), (&u, &v))) in reject[lo..].iter_mut().zip(ends) {
            let (dqx, dqy, drx, dry) = (x - qxa, y - qya, u - rxa, v - rya);
            let (lq2, lr2) = (dqx * dqx + dqy * dqy, drx * drx + dry * dry);
            let diff = lq2 - lr2;
            *m = (diff * diff >= k2 * (lq2 + lr2)) as u8;
        }
        // The pairs that pass, eight flags at a time: most words are all
        // rejections, and the others give their passes by bit tricks
        // rather than a hard-to-predict branch per pair.
        let [i, ii] = work.tent[a];
        let turn_a = [turn_c[a], turn_s[a]];
        for b in passing(&reject[..nl], lo) {
            let [j, jj] = work.tent[b];
            if i == j || ii == jj {
                continue;
            }
            let dq = [qx[b] - qxa, qy[b] - qya];
            let dr = [rx[b] - rxa, ry[b] - rya];
            let turns = [turn_a[0] + turn_c[b], turn_a[1] + turn_s[b]];
            let Some((drho, dth2)) = pair_deformation_from_ends(dq, dr, turns, dev) else {
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
    // The entries come in runs of equal `a` (the affinity loop's outer
    // index), so y[a] is summed in a register over its run; the runs'
    // lengths are counted once (in `order`, free until the binarization;
    // a run is shorter than `nl`, so it fits a u16).
    let runs = &mut work.order[..nl];
    runs.fill(0);
    for e in aff {
        runs[e.a as usize] += 1;
    }
    for _ in 0..params.ssm.power_iters {
        for v in y.iter_mut() {
            *v = 0.0;
        }
        let mut rest = aff;
        for (a, &len) in runs.iter().enumerate() {
            if len == 0 {
                continue;
            }
            let (run, more) = rest.split_at(len as usize);
            rest = more;
            let xa = x[a];
            let mut ya = 0.0f32;
            for e in run {
                let b = e.b as usize;
                ya += e.g * x[b];
                y[b] += e.g * xa;
            }
            y[a] += ya;
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
    // 4. Greedy binarization with conflict removal, in decreasing x (the
    // lower index first on a tie) while x is positive and at least
    // `binarize_frac` of the largest. Only those entries are sorted (a
    // tenth of them or so): for finite x they are the prefix of the whole
    // order the loop would stop after, and a NaN largest x (total order)
    // stops it at once, as it would.
    let xmax = x.iter().copied().fold(f32::NEG_INFINITY, |m, v| {
        if v.total_cmp(&m).is_gt() {
            v
        } else {
            m
        }
    });
    let floor = params.ssm.binarize_frac * xmax;
    let mut kept = 0usize;
    if xmax > 0.0 {
        for (o, &xv) in x.iter().enumerate() {
            if xv > 0.0 && !(xv < floor) {
                work.order[kept] = o as u16;
                kept += 1;
            }
        }
    }
    let order = &mut work.order[..kept];
    order.sort_unstable_by(|&a, &b| x[b as usize].total_cmp(&x[a as usize]).then(a.cmp(&b)));
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

/// The indices `b >= lo` of `reject` (flags of 0 and 1) whose flag is 0, in
/// increasing order.
fn passing(reject: &[u8], lo: usize) -> impl Iterator<Item = usize> + '_ {
    const ONES: u64 = 0x0101_0101_0101_0101;
    let lo = lo.min(reject.len());
    // Whole words from the first multiple of 8 at or after `lo`; the bytes
    // before it and the tail one at a time.
    let head_end = lo.next_multiple_of(8).min(reject.len());
    let words = reject[head_end..].chunks_exact(8);
    let tail_start = reject.len() - words.remainder().len();
    let head = (lo..head_end).filter(move |&b| reject[b] == 0);
    let body = words.enumerate().flat_map(move |(w, c)| {
        let mut word = [0u8; 8];
        word.copy_from_slice(c);
        // A byte of `keep` is 1 where the flag is 0.
        let mut keep = !u64::from_le_bytes(word) & ONES;
        let base = head_end + 8 * w;
        core::iter::from_fn(move || {
            if keep == 0 {
                return None;
            }
            let b = base + keep.trailing_zeros() as usize / 8;
            keep &= keep - 1;
            Some(b)
        })
    });
    let tail = (tail_start..reject.len()).filter(move |&b| reject[b] == 0);
    head.chain(body).chain(tail)
}

/// Fills `out` with tentative correspondences: for each of the `nq` input
/// points, the `k` reference points (of `nr`) with the closest descriptors
/// ([`desc_distance`]; the lower index on a tie). Returns how many were
/// written.
pub fn tentative(
    nq: usize,
    nr: usize,
    k: usize,
    qdesc: &[DescBin],
    rdesc: &[DescBin],
    out: &mut [[u16; 2]],
) -> usize {
    let k = k.min(nr).min(crate::params::MAX_TENTATIVE_K as usize);
    if k == 0 {
        return 0;
    }
    let nr = nr.min(rdesc.len() / DESC_LEN).min(u16::MAX as usize);
    let mut nl = 0usize;
    let mut best = [(u32::MAX, 0u16); crate::params::MAX_TENTATIVE_K as usize];
    for (i, q) in rows(qdesc).take(nq.min(u16::MAX as usize)).enumerate() {
        if nl + k > out.len() {
            break;
        }
        let dists = rows(rdesc).take(nr).map(|r| desc_distance(q, r));
        nl += k_closest(dists, &mut best[..k], i as u16, &mut out[nl..]);
    }
    nl
}

/// Writes `[i, j]` to `out` for the `best.len()` smallest of `dists` (the
/// lower `j` on a tie), closest first; returns how many (fewer when
/// `dists` is shorter). `out` must have room for `best.len()`.
#[inline]
fn k_closest(
    dists: impl Iterator<Item = u32>,
    best: &mut [(u32, u16)],
    i: u16,
    out: &mut [[u16; 2]],
) -> usize {
    let Some(last) = best.len().checked_sub(1) else {
        return 0;
    };
    best.fill((u32::MAX, 0));
    for (j, d) in dists.enumerate() {
        if d < best[last].0 {
            let mut p = last;
            while p > 0 && d < best[p - 1].0 {
                best[p] = best[p - 1];
                p -= 1;
            }
            best[p] = (d, j as u16);
        }
    }
    let mut n = 0;
    for (b, o) in best.iter().filter(|b| b.0 != u32::MAX).zip(out.iter_mut()) {
        *o = [i, b.1];
        n += 1;
    }
    n
}

/// Working arrays of [`tentative_by_bins`], `nr` reference points long
/// (`cols` `nr * DESC_LEN`).
pub struct BinWork<'a> {
    /// The reference descriptors transposed: bin `t` of point `j` at
    /// `t * nr + j`.
    pub cols: &'a mut [DescBin],
    /// Each reference descriptor's sum of bins.
    pub sums: &'a mut [u32],
    /// The reference points' shared mass with the input point at hand.
    pub shared: &'a mut [u16],
    /// Their distances to it.
    pub dist: &'a mut [u32],
}

impl BinWork<'_> {
    /// How many reference points the arrays have room for.
    pub fn capacity(&self) -> usize {
        (self.cols.len() / DESC_LEN)
            .min(self.sums.len())
            .min(self.shared.len())
            .min(self.dist.len())
    }
}

/// [`tentative`] with the same output (the same distances and ties), in
/// a fraction of the work: the L1 distance of two descriptors is
/// `sum(a) + sum(b) - 2 sum_t min(a_t, b_t)`, and an input descriptor has
/// few non-empty bins (a point's neighbours lie along its surface), so each
/// input point takes, for each of its non-empty bins, the minimum against
/// one column of the transposed reference descriptors, all reference
/// points at once (which the vector unit does eight at a time), rather than
/// all 32 bins of every pair. The reference is transposed once per match.
/// Arrays shorter than `nr` limit the reference points searched.
pub fn tentative_by_bins(
    nq: usize,
    nr: usize,
    k: usize,
    qdesc: &[DescBin],
    rdesc: &[DescBin],
    work: &mut BinWork<'_>,
    out: &mut [[u16; 2]],
) -> usize {
    let k = k.min(nr).min(crate::params::MAX_TENTATIVE_K as usize);
    let nr = nr
        .min(rdesc.len() / DESC_LEN)
        .min(u16::MAX as usize)
        .min(work.capacity());
    if k == 0 || nr == 0 {
        return 0;
    }
    let (cols, sums, shared, dist) = (
        &mut work.cols[..nr * DESC_LEN],
        &mut work.sums[..nr],
        &mut work.shared[..nr],
        &mut work.dist[..nr],
    );
    for (j, r) in rows(rdesc).take(nr).enumerate() {
        let mut s = 0u32;
        for (t, &v) in r.iter().enumerate() {
            cols[t * nr + j] = v;
            s += v as u32;
        }
        sums[j] = s;
    }
    let mut nl = 0usize;
    let mut best = [(u32::MAX, 0u16); crate::params::MAX_TENTATIVE_K as usize];
    for (i, q) in rows(qdesc).take(nq.min(u16::MAX as usize)).enumerate() {
        if nl + k > out.len() {
            break;
        }
        // shared = sum_t min(q_t, r_t) over q's non-empty bins, in 16-bit
        // lanes: it is at most sum(q), which rounding can put a little
        // over u16::MAX, so the adds saturate and a saturated sum is
        // computed again exactly ...
        shared.fill(0);
        let mut sq = 0u32;
        for (&qt, col) in q.iter().zip(cols.chunks_exact(nr)) {
            if qt == 0 {
                continue;
            }
            sq += qt as u32;
            for (d, &r) in shared.iter_mut().zip(col) {
                *d = d.saturating_add(qt.min(r));
            }
        }
        // ... and the L1 distance is sum(q) + sum(r) - 2 shared (a sum of
        // minima is at most either sum, so nothing wraps).
        let mut saturated = false;
        for ((d, &m), &s) in dist.iter_mut().zip(shared.iter()).zip(sums.iter()) {
            *d = sq + s - 2 * m as u32;
            saturated |= m == u16::MAX;
        }
        if saturated {
            for ((d, &m), r) in dist.iter_mut().zip(shared.iter()).zip(rows(rdesc)) {
                if m == u16::MAX {
                    *d = desc_distance(q, r);
                }
            }
        }
        nl += k_closest(
            dist.iter().copied(),
            &mut best[..k],
            i as u16,
            &mut out[nl..],
        );
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
    let (lq2, lr2) = (dq[0] * dq[0] + dq[1] * dq[1], dr[0] * dr[0] + dr[1] * dr[1]);
    if !(lq2 > 0.0 && lr2 > 0.0) {
        return None;
    }
    // Most pairs fail the rho test; reject them before any square root:
    // (lq + lr)^2 <= 2 (lq^2 + lr^2), so (lq^2 - lr^2)^2 >= 2 dev^2 (lq^2 +
    // lr^2) implies |lq - lr| >= dev.
    let diff = lq2 - lr2;
    if diff * diff >= 2.0 * max_rho_dev * max_rho_dev * (lq2 + lr2) {
        return None;
    }
    let (lq, lr) = (libm::sqrtf(lq2), libm::sqrtf(lr2));
    let drho = lq - lr;
    if !(libm::fabsf(drho) < max_rho_dev) {
        return None;
    }
    // cos of the angle difference at i (tangent u_i vs u_i', direction d)
    // and at j (with -d): with a = u . d and c = u x d on each side,
    // (a_q a_r + c_q c_r) / (lq lr); the sign of d cancels in the product.
    let side = |u: [f32; 2], v: [f32; 2]| {
        (u[0] * dq[0] + u[1] * dq[1]) * (v[0] * dr[0] + v[1] * dr[1])
            + (u[0] * dq[1] - u[1] * dq[0]) * (v[0] * dr[1] - v[1] * dr[0])
    };
    let sum = side(*q_tan.get(i)?, *r_tan.get(ii)?) + side(*q_tan.get(j)?, *r_tan.get(jj)?);
    Some((drho, 2.0 - sum / (lq * lr)))
}

/// The turn from input tangent `u` to reference tangent `v`, as the unit
/// complex number `conj(u) v` = `(u . v, u x v)`.
#[inline]
fn tangent_turn(u: [f32; 2], v: [f32; 2]) -> [f32; 2] {
    [u[0] * v[0] + u[1] * v[1], u[0] * v[1] - u[1] * v[0]]
}

/// [`pair_deformation`] of two correspondences that share no point, from
/// `dq` (the input pair's difference, `p_j - p_i`), `dr` (the reference
/// pair's, `r_j' - r_i'`) and `turns`, the sum of both correspondences'
/// tangent turns (the cosine and sine of the turn from the input point's
/// tangent to the reference point's). Each of the chord's two sides is
/// `(u . dq)(v . dr) + (u x dq)(v x dr)` = `Re[conj(u) v dq conj(dr)]`, so
/// their sum is `Re[turns * dq conj(dr)]`: a few products per pair instead
/// of four tangent reads and two sides.
#[inline]
pub fn pair_deformation_from_ends(
    dq: [f32; 2],
    dr: [f32; 2],
    turns: [f32; 2],
    max_rho_dev: f32,
) -> Option<(f32, f32)> {
    let (lq2, lr2) = (dq[0] * dq[0] + dq[1] * dq[1], dr[0] * dr[0] + dr[1] * dr[1]);
    if !(lq2 > 0.0 && lr2 > 0.0) {
        return None;
    }
    let (lq, lr) = (libm::sqrtf(lq2), libm::sqrtf(lr2));
    let drho = lq - lr;
    if !(libm::fabsf(drho) < max_rho_dev) {
        return None;
    }
    let p = [dq[0] * dr[0] + dq[1] * dr[1], dq[1] * dr[0] - dq[0] * dr[1]];
    let sum = turns[0] * p[0] - turns[1] * p[1];
    Some((drho, 2.0 - sum / (lq * lr)))
}

/// The logistic pairwise potential of eq. 4: `1 / (1 + exp(-(w0 + w1 drho^2 + w2 dtheta^2)))`.
#[inline]
pub fn affinity(w: &[f32; 3], drho: f32, dth2: f32) -> f32 {
    let z = w[0] + w[1] * drho * drho + w[2] * dth2;
    // Below this z the potential is under AFFINITY_FLOOR: skip the exponential.
    if z < AFFINITY_FLOOR_Z {
        return 0.0;
    }
    1.0 / (1.0 + crate::math::exp(-z))
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
    let pose = pose.with_trig();
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
    let placed = pose.with_trig();
    for &[i, ii] in acc {
        let (qi, ri) = (q[i as usize], r[ii as usize]);
        if dist2(placed.apply(qi), ri) < thr2 {
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
        if dist2(placed.apply(qi), ri) < thr2 {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tests::fixture::Prng;
    use core::f32::consts::PI;

    #[test]
    fn octants_are_the_bins_of_pgr_cell() {
        // Directions away from the bin edges (22.5 + 45 k degrees) land in
        // the bin the arctangent-based binning gives.
        let mut g = Prng::new(7);
        for _ in 0..5000 {
            let t = g.range(-PI, PI);
            let to_edge = libm::fabsf(libm::remainderf(t - PI / 8.0, PI / 4.0));
            if to_edge < 1e-3 {
                continue;
            }
            let r = g.range(0.01, 3.0);
            let (dot, cross) = (r * libm::cosf(t), r * libm::sinf(t));
            let want = crate::pgr::cell(0.0, t, 1, DESC_THETA, 1.0);
            assert_eq!(theta_octant(dot, cross), want, "theta {t}");
        }
        // Straight ahead and straight behind sit in the middle of bins 4 and 0.
        assert_eq!(theta_octant(1.0, 0.0), 4);
        assert_eq!(theta_octant(-1.0, 0.0), 0);
        assert_eq!(theta_octant(-1.0, -0.0), 0);
    }

    #[test]
    fn descriptors_are_shares_of_the_neighbours() {
        // Points on a line 0.1 m apart, tangent along it, and one far away.
        let mut pts: [[f32; 2]; 12] = [[0.0; 2]; 12];
        for (k, p) in pts.iter_mut().enumerate().take(11) {
            *p = [0.1 * k as f32, 0.0];
        }
        pts[11] = [50.0, 50.0];
        let tan = [[1.0f32, 0.0]; 12];
        let mut out = [0 as DescBin; 12 * DESC_LEN];
        descriptors(&pts, &tan, 2.0, &mut out);
        let row = |i: usize| &out[i * DESC_LEN..(i + 1) * DESC_LEN];
        for i in 0..11 {
            let sum: u32 = row(i).iter().map(|&v| v as u32).sum();
            assert!(
                sum.abs_diff(DESC_SCALE) <= DESC_LEN as u32 / 2,
                "row {i} sums {sum}"
            );
        }
        // The first point sees all 10 others straight ahead (bin 4), within
        // 0.5 m (rho bin 0: 4 of them) and 0.5-1.0 m (rho bin 1: 5), 1.0 m
        // (rho bin 2: 1).
        let r0 = row(0);
        assert_eq!(r0[4] as u32, (4 * DESC_SCALE + 5) / 10);
        assert_eq!(r0[DESC_THETA + 4] as u32, (5 * DESC_SCALE + 5) / 10);
        assert_eq!(r0[2 * DESC_THETA + 4] as u32, (DESC_SCALE + 5) / 10);
        // The last point sees them behind it (bin 0); the lone point nothing.
        assert!(row(10)[0] > 0 && row(10)[4] == 0);
        assert!(row(11).iter().all(|&v| v == 0));
        // Disjoint rows are as far apart as descriptors get (to rounding).
        let far = desc_distance(
            row(0).try_into().expect("a row"),
            row(10).try_into().expect("a row"),
        );
        assert!(far.abs_diff(2 * DESC_SCALE) <= DESC_LEN as u32, "{far}");
    }

    #[test]
    fn passing_lists_the_zero_flags_from_lo_in_order() {
        let mut seed = 7u32;
        for len in [0usize, 1, 7, 8, 9, 16, 23, 40] {
            let flags: Vec<u8> = (0..len)
                .map(|_| {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (seed >> 29 != 0) as u8
                })
                .collect();
            for lo in 0..=len + 1 {
                let want: Vec<usize> = (lo..len).filter(|&b| flags[b] == 0).collect();
                assert_eq!(
                    passing(&flags, lo).collect::<Vec<_>>(),
                    want,
                    "len {len} lo {lo}"
                );
            }
        }
    }

    #[test]
    fn tentative_equals_a_sort_of_all_distances() {
        // Pseudo-random descriptors with many equal distances (few values).
        let mut seed = 12345u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            ((seed >> 24) % 4) as DescBin * 9000
        };
        let (nr, nq) = (23, 11);
        let r: Vec<DescBin> = (0..nr * DESC_LEN).map(|_| next()).collect();
        let q: Vec<DescBin> = (0..nq * DESC_LEN).map(|_| next()).collect();
        let row = |d: &[DescBin], i: usize| -> [DescBin; DESC_LEN] {
            d[i * DESC_LEN..][..DESC_LEN].try_into().unwrap()
        };
        for k in 1..=3 {
            let mut want = Vec::new();
            for i in 0..nq {
                let mut d: Vec<(u32, usize)> = (0..nr)
                    .map(|j| (desc_distance(&row(&q, i), &row(&r, j)), j))
                    .collect();
                // Ties go to the lower reference index.
                d.sort();
                want.extend(d[..k].iter().map(|&(_, j)| [i as u16, j as u16]));
            }
            let mut out = [[0u16; 2]; 64];
            let n = tentative(nq, nr, k, &q, &r, &mut out);
            assert_eq!(&out[..n], &want[..], "k {k}");
            let mut out = [[0u16; 2]; 64];
            let n = by_bins(nq, nr, k, &q, &r, &mut out);
            assert_eq!(&out[..n], &want[..], "by bins, k {k}");
        }
        // Room for fewer rows than asked: whole rows only.
        let mut out = [[0u16; 2]; 5];
        assert_eq!(tentative(nq, nr, 2, &q, &r, &mut out), 4);
        assert_eq!(by_bins(nq, nr, 2, &q, &r, &mut out), 4);
    }

    /// [`tentative_by_bins`] with arrays of its own.
    fn by_bins(
        nq: usize,
        nr: usize,
        k: usize,
        q: &[DescBin],
        r: &[DescBin],
        out: &mut [[u16; 2]],
    ) -> usize {
        let (mut cols, mut sums, mut shared, mut dist) = (
            vec![0; nr * DESC_LEN],
            vec![0u32; nr],
            vec![0u16; nr],
            vec![0u32; nr],
        );
        let mut work = BinWork {
            cols: &mut cols,
            sums: &mut sums,
            shared: &mut shared,
            dist: &mut dist,
        };
        tentative_by_bins(nq, nr, k, q, r, &mut work, out)
    }

    #[test]
    fn tentative_by_bins_is_exact_where_the_shared_mass_saturates() {
        // Rows of real descriptors (sums up to DESC_SCALE + rounding), some
        // nearly equal with sums over u16::MAX: the shared mass of those
        // pairs saturates its 16-bit lane and must be recomputed.
        let mut seed = 4242u32;
        let mut rnd = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        let row = |rnd: &mut dyn FnMut() -> u32, over: bool| {
            let mut v = [0 as DescBin; DESC_LEN];
            let bins = 1 + (rnd() % 8) as usize;
            let mut left = DESC_SCALE;
            for b in 0..bins {
                let t = (rnd() as usize) % DESC_LEN;
                let share = if b + 1 == bins {
                    left
                } else {
                    rnd() % (left + 1)
                };
                v[t] = v[t].saturating_add(share as DescBin);
                left -= share;
            }
            if over {
                // The rounding of up to DESC_LEN bins, all upwards.
                for b in v.iter_mut().filter(|b| **b > 0 && **b < DescBin::MAX) {
                    *b += 1;
                }
            }
            v
        };
        let (nq, nr) = (40, 60);
        let mut q = Vec::new();
        let mut r = Vec::new();
        for i in 0..nq {
            let a = row(&mut rnd, i % 2 == 0);
            q.extend_from_slice(&a);
        }
        for j in 0..nr {
            // Every third reference row a copy of an input row, rounded up.
            if j % 3 == 0 {
                let i = (j / 3) % nq;
                let mut a: [DescBin; DESC_LEN] = q[i * DESC_LEN..][..DESC_LEN].try_into().unwrap();
                for b in a.iter_mut().filter(|b| **b > 0 && **b < DescBin::MAX) {
                    *b += 1;
                }
                r.extend_from_slice(&a);
            } else {
                r.extend_from_slice(&row(&mut rnd, j % 2 == 1));
            }
        }
        // A pair that saturates next to one that does not: q sums 16 over
        // u16::MAX; reference 1 equals it (distance 0, shared mass over the
        // lane's range), reference 0 is 2 away. Taking the saturated sum as
        // it is would put reference 1 at 32 and choose reference 0.
        let mut one = [0 as DescBin; DESC_LEN];
        one[3] = 40000;
        one[12] = 25551;
        let mut near = one;
        near[3] -= 1;
        near[20] = 1;
        let both: Vec<DescBin> = near.iter().chain(one.iter()).copied().collect();
        let mut out = [[0u16; 2]; 1];
        assert_eq!(tentative(1, 2, 1, &one, &both, &mut out), 1);
        assert_eq!(out[0], [0, 1]);
        assert_eq!(by_bins(1, 2, 1, &one, &both, &mut out), 1);
        assert_eq!(out[0], [0, 1]);
        for k in [1, 2, 4] {
            let (mut a, mut b) = ([[0u16; 2]; 256], [[0u16; 2]; 256]);
            let na = tentative(nq, nr, k, &q, &r, &mut a);
            let nb = by_bins(nq, nr, k, &q, &r, &mut b);
            assert_eq!(&a[..na], &b[..nb], "k {k}");
        }
    }

    #[test]
    fn tentative_keeps_the_k_closest_with_the_lower_index_on_ties() {
        let mut q = [0 as DescBin; DESC_LEN];
        q[0] = 100;
        let mut r = [0 as DescBin; 4 * DESC_LEN];
        // Distances to q: 40, 0, 40, 200.
        r[0] = 60;
        r[DESC_LEN] = 100;
        r[2 * DESC_LEN] = 140;
        r[3 * DESC_LEN + 5] = 100;
        let mut out = [[0u16; 2]; 4];
        assert_eq!(tentative(1, 4, 2, &q, &r, &mut out), 2);
        assert_eq!(&out[..2], &[[0, 1], [0, 0]]);
        assert_eq!(tentative(1, 4, 3, &q, &r, &mut out), 3);
        assert_eq!(out[2], [0, 2]);
    }

    #[test]
    fn pair_deformation_rejects_exactly_the_pairs_whose_lengths_differ() {
        // The test without square roots must keep every pair the plain
        // |lq - lr| < dev test keeps, and give the plain formula's values.
        let mut g = Prng::new(11);
        let dev = 0.3;
        let (mut kept, mut rejected) = (0, 0);
        for _ in 0..20000 {
            let mut p = || [g.range(-5.0, 5.0), g.range(-5.0, 5.0)];
            let (q, r) = ([p(), p()], [p(), p()]);
            let mut unit = |_| {
                let a = g.range(-PI, PI);
                [libm::cosf(a), libm::sinf(a)]
            };
            let (qt, rt) = ([unit(0), unit(1)], [unit(2), unit(3)]);
            // Half the time make the reference pair the input pair moved, so
            // many pairs pass.
            let r = if g.range(0.0, 1.0) < 0.5 {
                let s = g.range(-0.4, 0.4);
                [
                    r[0],
                    [
                        r[0][0] + (q[1][0] - q[0][0]) * (1.0 + s * 0.1),
                        r[0][1] + (q[1][1] - q[0][1]),
                    ],
                ]
            } else {
                r
            };
            let lq = libm::sqrtf(dist2(q[0], q[1]));
            let lr = libm::sqrtf(dist2(r[0], r[1]));
            let got = pair_deformation(&q, &qt, &r, &rt, [0, 0], [1, 1], dev);
            // The same from the ends and the tangent turns (to rounding).
            let turns = {
                let (t0, t1) = (tangent_turn(qt[0], rt[0]), tangent_turn(qt[1], rt[1]));
                [t0[0] + t1[0], t0[1] + t1[1]]
            };
            let from_ends = pair_deformation_from_ends(
                [q[1][0] - q[0][0], q[1][1] - q[0][1]],
                [r[1][0] - r[0][0], r[1][1] - r[0][1]],
                turns,
                dev,
            );
            match (got, from_ends) {
                (Some(a), Some(b)) => {
                    assert!(libm::fabsf(a.0 - b.0) < 1e-6, "{a:?} vs {b:?}");
                    assert!(libm::fabsf(a.1 - b.1) < 1e-5, "{a:?} vs {b:?}");
                }
                (None, None) => {}
                // Only a pair on the edge of the rho test may differ.
                (a, b) => assert!(
                    libm::fabsf(libm::fabsf(lq - lr) - dev) < 1e-4,
                    "{a:?} {b:?}"
                ),
            }
            if libm::fabsf(lq - lr) < dev * 0.999 {
                let (drho, dth2) = got.expect("a pair with close lengths is kept");
                assert!(libm::fabsf(drho - (lq - lr)) < 1e-4);
                let dq = [q[1][0] - q[0][0], q[1][1] - q[0][1]];
                let dr = [r[1][0] - r[0][0], r[1][1] - r[0][1]];
                let ang = |u: [f32; 2], d: [f32; 2]| {
                    crate::math::atan2(u[0] * d[1] - u[1] * d[0], u[0] * d[0] + u[1] * d[1])
                };
                let a1 = ang(qt[0], dq) - ang(rt[0], dr);
                let a2 = ang(qt[1], [-dq[0], -dq[1]]) - ang(rt[1], [-dr[0], -dr[1]]);
                let want = 2.0 - libm::cosf(a1) - libm::cosf(a2);
                assert!(libm::fabsf(dth2 - want) < 1e-3, "{dth2} vs {want}");
                kept += 1;
            } else if libm::fabsf(lq - lr) > dev * 1.001 {
                assert!(got.is_none());
                rejected += 1;
            }
        }
        assert!(
            kept > 1000 && rejected > 1000,
            "{kept} kept, {rejected} rejected"
        );
        // A correspondence pair that shares a point conflicts.
        let pts = [[0.0f32, 0.0], [1.0, 0.0]];
        let tan = [[1.0f32, 0.0]; 2];
        assert!(pair_deformation(&pts, &tan, &pts, &tan, [0, 0], [0, 1], dev).is_none());
        assert!(pair_deformation(&pts, &tan, &pts, &tan, [0, 0], [1, 1], dev).is_some());
    }
}
