//! Scan preparation, the first step shared by the compiler and the runtime:
//! beam-ordered points are split into surfaces at depth jumps, isolated points
//! are dropped, points are resampled to a roughly uniform spacing along each
//! surface (so a wall seen from near and from far gives the same density), and
//! each kept point gets a unit tangent (paper eq. 1, taken over a short
//! stretch of the surface rather than the two immediate neighbours).

use crate::math::{dist2, norm};
use crate::params::Params;

/// How many dense points on either side are used to estimate a tangent, at most.
const TANGENT_REACH: usize = 6;
/// Tangent stretch half-length (m).
const TANGENT_RADIUS: f32 = 0.25;

/// True when `beams` beams `angle_increment` radians apart close a full turn
/// (to within one and a half beams), so the last beam neighbours the first.
#[inline]
pub fn covers_full_turn(angle_increment: f32, beams: usize) -> bool {
    let inc = libm::fabsf(angle_increment);
    inc * beams as f32 >= 2.0 * core::f32::consts::PI - 1.5 * inc
}

/// True when consecutive beam points `a`, `b` lie on different surfaces.
#[inline]
pub fn is_jump(a: [f32; 2], b: [f32; 2], jump_distance: f32) -> bool {
    if !(a[0].is_finite() && b[0].is_finite()) {
        return true;
    }
    let d2 = dist2(a, b);
    // The allowed gap grows with range: consecutive beams at range r on a wall
    // seen obliquely are several r * dtheta apart.
    let r = norm(a).min(norm(b));
    let lim = jump_distance + 0.05 * r;
    d2 > lim * lim
}

/// Prepares `dense` (beam-ordered sensor-frame points; a non-finite x marks a
/// missing beam). `wrap` says the scan covers the full circle, so the last
/// beam neighbours the first. Writes up to `out_pts.len()` points and their
/// unit tangents; returns how many.
pub fn prepare(
    dense: &[[f32; 2]],
    wrap: bool,
    params: &Params,
    out_pts: &mut [[f32; 2]],
    out_tan: &mut [[f32; 2]],
) -> usize {
    prepare_with(dense, wrap, params, 0.0, out_pts, out_tan)
}

/// As [`prepare`], leaving out every *foreground surface* at most
/// `foreground` metres across (0: none): a surface (a run of linked beams
/// between depth jumps) whose end points are at most that far apart, at
/// most twice that long along it, and whose neighbouring beams on both
/// sides reach farther or return nothing ([`foreground_surface`]).
/// A person or a box standing in the open is one; so is a pillar. At the
/// edge of a partial field of view the side beyond is unknown, and a
/// surface there is kept.
pub fn prepare_with(
    dense: &[[f32; 2]],
    wrap: bool,
    params: &Params,
    foreground: f32,
    out_pts: &mut [[f32; 2]],
    out_tan: &mut [[f32; 2]],
) -> usize {
    let n = dense.len();
    let cap = out_pts
        .len()
        .min(out_tan.len())
        .min(params.prep.max_points as usize);
    if n < 3 || cap == 0 {
        return 0;
    }
    let jd = params.prep.jump_distance;
    let next = |i: usize| next_beam(i, n, wrap);
    let prev = |i: usize| prev_beam(i, n, wrap);
    let linked = |i: usize, j: Option<usize>| match j {
        Some(j) => !is_jump(dense[i], dense[j], jd),
        None => false,
    };
    // A start index: in a wrapped scan, begin right after a jump so no surface
    // is split in two; if there is none (a closed room), begin at 0.
    let mut start = 0;
    if wrap {
        for i in 0..n {
            if !linked(i, prev(i)) {
                start = i;
                break;
            }
        }
    }
    // Total surface length, to widen the spacing if it would give too many points.
    let mut length = 0.0f32;
    for i in 0..n {
        if linked(i, next(i)) {
            length += libm::sqrtf(dist2(dense[i], dense[next(i).unwrap_or(i)]));
        }
    }
    let spacing = params.prep.resample_spacing.max(length / cap as f32 * 1.02);
    let sp2 = spacing * spacing;

    let mut count = 0;
    let mut last: Option<[f32; 2]> = None;
    let mut skip = 0usize;
    for s in 0..n {
        let i = (start + s) % n;
        let p = dense[i];
        if skip > 0 {
            skip -= 1;
            continue;
        }
        if !p[0].is_finite() {
            last = None;
            continue;
        }
        let has_prev = linked(i, prev(i));
        let has_next = linked(i, next(i));
        if foreground > 0.0 && !has_prev && has_next {
            if let Some(len) = foreground_surface(dense, i, wrap, jd, foreground) {
                skip = len;
                last = None;
                continue;
            }
        }
        if !has_prev && !has_next {
            // Isolated return: an outlier or a thin object; no tangent either.
            last = None;
            continue;
        }
        let keep = match last {
            None => true,
            Some(l) => !has_prev || dist2(l, p) >= sp2,
        };
        if !keep {
            continue;
        }
        if let Some(t) = tangent(dense, i, wrap, jd) {
            if count < cap {
                out_pts[count] = p;
                out_tan[count] = t;
                count += 1;
                last = Some(p);
            }
        }
    }
    count
}

/// When beam `i` of `dense` starts a *foreground surface* (see
/// [`prepare_with`]: a run of linked beams whose end points are at most
/// `width` m apart, at most twice that long along it (so a room that
/// surrounds the sensor but for a narrow gap is not one), and whose
/// neighbouring beams on both sides reach farther or return nothing; a
/// single return counts), the number of beams after
/// `i` in it; else `None`. `i` must start a surface (not linked to the
/// beam before it). `jump_distance` (m) splits surfaces ([`is_jump`]).
pub fn foreground_surface(
    dense: &[[f32; 2]],
    i: usize,
    wrap: bool,
    jump_distance: f32,
    width: f32,
) -> Option<usize> {
    let n = dense.len();
    let next = |k: usize| next_beam(k, n, wrap);
    let prev = |k: usize| prev_beam(k, n, wrap);
    let p = *dense.get(i)?;
    if !p[0].is_finite() {
        return None;
    }
    let mut b = i;
    let mut len = 0usize;
    let mut along = 0.0f32;
    while len < n {
        match next(b) {
            Some(j) if j != i && !is_jump(dense[b], dense[j], jump_distance) => {
                along += libm::sqrtf(dist2(dense[b], dense[j]));
                b = j;
                len += 1;
            }
            _ => break,
        }
    }
    let farther = |side: Option<usize>, end: usize| match side {
        Some(k) => !dense[k][0].is_finite() || norm(dense[k]) > norm(dense[end]),
        None => false,
    };
    (dist2(p, dense[b]) <= width * width
        && along <= 2.0 * width
        && farther(prev(i), i)
        && farther(next(b), b))
    .then_some(len)
}

/// Marks in `out` (one flag per beam of `dense`, 1 = foreground, 0 = not)
/// the beams of every foreground surface at most `width` m across
/// ([`foreground_surface`]; `width` 0 marks none); returns how many beams
/// are marked. The verification does not charge a short beam of one
/// ([`crate::verify::Vicinity::occluded`]): people, boxes and chairs the
/// map does not have.
pub fn foreground_mask(
    dense: &[[f32; 2]],
    wrap: bool,
    jump_distance: f32,
    width: f32,
    out: &mut [u8],
) -> usize {
    let n = dense.len().min(out.len());
    out[..n].fill(0);
    if n < 3 || !(width > 0.0) {
        return 0;
    }
    let dense = &dense[..n];
    let mut marked = 0;
    for i in 0..n {
        let starts = match prev_beam(i, n, wrap) {
            Some(j) => is_jump(dense[j], dense[i], jump_distance),
            None => true,
        };
        if !starts {
            continue;
        }
        if let Some(len) = foreground_surface(dense, i, wrap, jump_distance, width) {
            for k in 0..=len {
                out[(i + k) % n] = 1;
            }
            marked += len + 1;
        }
    }
    marked
}

/// The beam after `i` of `n`: `i + 1`, or the first after the last when the
/// scan wraps.
fn next_beam(i: usize, n: usize, wrap: bool) -> Option<usize> {
    if i + 1 < n {
        Some(i + 1)
    } else if wrap {
        Some(0)
    } else {
        None
    }
}

/// The beam before `i` of `n`: `i - 1`, or the last before the first when
/// the scan wraps.
fn prev_beam(i: usize, n: usize, wrap: bool) -> Option<usize> {
    if i > 0 {
        Some(i - 1)
    } else if wrap {
        Some(n - 1)
    } else {
        None
    }
}

/// Unit tangent at dense point `i`, from the farthest linked points within
/// [`TANGENT_RADIUS`] on each side, oriented along increasing beam index.
fn tangent(dense: &[[f32; 2]], i: usize, wrap: bool, jd: f32) -> Option<[f32; 2]> {
    let n = dense.len();
    let r2 = TANGENT_RADIUS * TANGENT_RADIUS;
    let step = |k: usize, fwd: bool| {
        if fwd {
            next_beam(k, n, wrap)
        } else {
            prev_beam(k, n, wrap)
        }
    };
    let mut ends = [i, i];
    for (e, fwd) in ends.iter_mut().zip([false, true]) {
        let mut k = i;
        for _ in 0..TANGENT_REACH {
            match step(k, fwd) {
                Some(j)
                    if j != i
                        && !is_jump(dense[k], dense[j], jd)
                        && dist2(dense[i], dense[j]) <= r2 =>
                {
                    k = j
                }
                _ => break,
            }
        }
        // Always allow the immediate linked neighbour, however far.
        if k == i {
            if let Some(j) = step(i, fwd) {
                if !is_jump(dense[i], dense[j], jd) {
                    k = j;
                }
            }
        }
        *e = k;
    }
    let d = [
        dense[ends[1]][0] - dense[ends[0]][0],
        dense[ends[1]][1] - dense[ends[0]][1],
    ];
    let l = norm(d);
    if ends[0] == ends[1] || !(l > 1e-6) {
        return None;
    }
    Some([d[0] / l, d[1] / l])
}

/// Sensor-frame points of a range scan: `ranges[k]` at angle
/// `angle_min + k * angle_increment`; out-of-limits or non-finite ranges give
/// a NaN point (missing beam). Writes `min(ranges.len(), out.len())` points.
pub fn ranges_to_points(
    ranges: &[f32],
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    out: &mut [[f32; 2]],
) -> usize {
    let n = ranges.len().min(out.len());
    for (k, (o, &r)) in out.iter_mut().zip(ranges).enumerate().take(n) {
        *o = if r.is_finite() && r >= range_min && r <= range_max && r > 0.0 {
            let a = angle_min + k as f32 * angle_increment;
            [r * libm::cosf(a), r * libm::sinf(a)]
        } else {
            [f32::NAN, f32::NAN]
        };
    }
    n
}

/// Sensor-frame points (m) of a reference scan: `ranges` (m, one per beam
/// of the database's reference sensor `params.sensor`) through
/// [`ranges_to_points`] with that sensor's beam angles and range limits.
/// Writes `min(ranges.len(), out.len())` points.
pub fn reference_points(ranges: &[f32], params: &Params, out: &mut [[f32; 2]]) -> usize {
    let s = &params.sensor;
    ranges_to_points(
        ranges,
        s.angle_min,
        s.angle_increment,
        s.range_min,
        s.range_max,
        out,
    )
}
