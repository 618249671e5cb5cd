//! Caves: unstructured rock inside a bounding wall. Free space is where a
//! smooth fractal noise field is below a threshold, plus chambers on a
//! jittered grid joined by a random spanning tree (and a few loops) of
//! winding tunnels, each carved as a chain of [`Capsule`]s roughened by the
//! same noise.
//!
//! Steps of [`cave`]: [`rock_field`] (noise and its free threshold),
//! [`chambers`], [`tunnels`], then [`rasterise`] in parallel bands of rows
//! (each cell is a pure function of its position, so the result does not
//! depend on the thread count).

use rayon::prelude::*;

use super::draw::{chance, clampi, Outline, Rect, Scale, Span};
use super::{Stats, FREE, OCCUPIED, UNKNOWN};
use crate::compiler::connectivity::UnionFind;
use crate::compiler::rng::Rng;

// ---------------------------------------------------------------------------
// Parameters (m: metres; cells: map cells)
// ---------------------------------------------------------------------------

/// Bounding wall thickness (m).
const OUTER_WALL: f64 = 0.4;
/// Noise octaves: (wavelength in m, relative amplitude); amplitudes are
/// normalised to sum to one.
const OCTAVES: [(f64, f32); 3] = [(4.5, 1.0), (2.2, 0.5), (1.0, 0.25)];
/// Smallest lattice spacing of a noise octave (cells).
const MIN_LATTICE: f64 = 2.0;
/// Width of the band along the bounding wall where rock is added (m).
const FADE_BAND: f64 = 2.5;
/// Noise added at the bounding wall, falling linearly to 0 across the band.
const FADE_STRENGTH: f64 = 0.6;
/// Random noise samples from which the free threshold is taken.
const THRESHOLD_SAMPLES: usize = 4096;
/// Share of the interior that is free before chambers and tunnels (the
/// threshold is this quantile of the samples).
const FREE_QUANTILE: Span = Span::new(0.28, 0.36);

/// Chamber and tunnel radii are at most the shorter interior side divided
/// by this.
const RADIUS_CAP_DIV: f64 = 5.0;
/// Spacing of the chamber grid (m).
const CHAMBER_SPACING: Span = Span::new(9.0, 13.0);
/// Largest offset of a chamber from its grid cell's centre (fraction of
/// the grid cell, per axis).
const CHAMBER_JITTER: f64 = 0.3;
/// Probability that a chamber is big.
const BIG_CHAMBER_CHANCE: f64 = 0.15;
/// Radius of a big chamber (m).
const BIG_CHAMBER_RADIUS: Span = Span::new(3.5, 6.0);
/// Radius of an ordinary chamber (m).
const CHAMBER_RADIUS: Span = Span::new(1.5, 3.5);
/// Radius of the always-carved core of a capsule (fraction of its radius;
/// at least one cell).
const CORE_SHARE: f64 = 0.45;
/// Distance kept between a carved core and the interior's edge (cells).
const CORE_PAD: f64 = 1.5;

/// Probability that a grid edge not in the spanning tree is a tunnel too
/// (a loop).
const LOOP_CHANCE: f64 = 0.2;
/// Capsules per tunnel.
const PIECES: usize = 6;
/// Largest step of a tunnel's random walk (standard deviations).
const WALK_STEP_MAX: f64 = 2.5;
/// Sideways offset of a tunnel per unit of walk (fraction of its length).
const WIGGLE: f64 = 0.09;
/// Times a tunnel point's offset is halved to bring it inside.
const WIGGLE_SHRINKS: usize = 8;
/// Tunnel radius at each capsule end (m).
const TUNNEL_RADIUS: Span = Span::new(0.6, 1.4);

/// Largest radius factor of the noise roughening.
const ROUGH_MAX: f64 = 1.8;
/// Radius factor gained per unit of noise below the threshold.
const ROUGH_GAIN: f64 = 2.0;
/// Tunnel lengths are at least this, to divide by (cells).
const MIN_TUNNEL_LENGTH: f64 = 1e-9;
/// Squared lengths below this are treated as zero (cells²).
const EPS: f64 = 1e-12;
/// Rows per band of the parallel rasterisation.
const BAND: usize = 32;

// ---------------------------------------------------------------------------
// Noise
// ---------------------------------------------------------------------------

/// One octave of 2-D value noise on a lattice of `sp` cells.
struct Octave {
    sp: f64,
    gw: usize,
    gh: usize,
    amp: f32,
    lat: Vec<f32>,
    ix: Vec<u32>,
    tx: Vec<f32>,
}

fn smoothstep(t: f64) -> f64 {
    t * t * (3.0 - 2.0 * t)
}

impl Octave {
    fn new(rng: &mut Rng, w: usize, h: usize, sp: f64, amp: f32) -> Self {
        let sp = sp.max(MIN_LATTICE);
        let gw = (w as f64 / sp) as usize + 2;
        let gh = (h as f64 / sp) as usize + 2;
        let lat = (0..gw * gh).map(|_| rng.uniform() as f32).collect();
        let mut ix = Vec::with_capacity(w);
        let mut tx = Vec::with_capacity(w);
        for x in 0..w {
            let f = (x as f64 + 0.5) / sp;
            let i = (f.floor() as usize).min(gw - 2);
            ix.push(i as u32);
            tx.push(smoothstep((f - i as f64).clamp(0.0, 1.0)) as f32);
        }
        Octave {
            sp,
            gw,
            gh,
            amp,
            lat,
            ix,
            tx,
        }
    }

    fn cell_y(&self, y: f64) -> (usize, f32) {
        let f = y / self.sp;
        let i = (f.max(0.0).floor() as usize).min(self.gh - 2);
        (i, smoothstep((f - i as f64).clamp(0.0, 1.0)) as f32)
    }

    /// Value at a point given in cells (cell centres at i + 0.5).
    fn at(&self, x: f64, y: f64) -> f32 {
        let f = x / self.sp;
        let i = (f.max(0.0).floor() as usize).min(self.gw - 2);
        let t = smoothstep((f - i as f64).clamp(0.0, 1.0)) as f32;
        let (j, u) = self.cell_y(y);
        let l = &self.lat;
        let a = l[j * self.gw + i] + (l[(j + 1) * self.gw + i] - l[j * self.gw + i]) * u;
        let b =
            l[j * self.gw + i + 1] + (l[(j + 1) * self.gw + i + 1] - l[j * self.gw + i + 1]) * u;
        self.amp * (a + (b - a) * t)
    }

    /// Adds this octave's row `y` into `out[x0..x1]`.
    fn add_row(&self, y: usize, x0: usize, x1: usize, col: &mut Vec<f32>, out: &mut [f32]) {
        let (j, u) = self.cell_y(y as f64 + 0.5);
        let (r0, r1) = (&self.lat[j * self.gw..], &self.lat[(j + 1) * self.gw..]);
        col.clear();
        col.extend((0..self.gw).map(|i| r0[i] + (r1[i] - r0[i]) * u));
        let cells = out[x0..x1]
            .iter_mut()
            .zip(&self.ix[x0..x1])
            .zip(&self.tx[x0..x1]);
        for ((o, &i), &t) in cells {
            let (a, b) = (col[i as usize], col[i as usize + 1]);
            *o += self.amp * (a + (b - a) * t);
        }
    }
}

/// Fractal value noise, normalised to [0, 1].
struct Noise {
    octaves: Vec<Octave>,
}

impl Noise {
    fn at(&self, x: f64, y: f64) -> f32 {
        self.octaves.iter().map(|o| o.at(x, y)).sum()
    }

    fn row(&self, y: usize, x0: usize, x1: usize, col: &mut Vec<f32>, out: &mut [f32]) {
        out[x0..x1].fill(0.0);
        for o in &self.octaves {
            o.add_row(y, x0, x1, col, out);
        }
    }
}

/// Extra "rockiness" near the bounding wall, so open areas rarely run flat
/// against it.
struct Fade {
    inner: Rect,
    /// Width of the fade band, cells.
    band: f64,
}

impl Fade {
    fn new(inner: Rect, band: f64) -> Self {
        Fade {
            inner,
            band: band.max(1.0),
        }
    }

    /// Added to the noise at cell (x, y).
    fn at(&self, x: i64, y: i64) -> f32 {
        let r = self.inner;
        let d = (x - r.x0).min(r.x1 - 1 - x).min(y - r.y0).min(r.y1 - 1 - y);
        let f = 1.0 - d as f64 / self.band;
        if f > 0.0 {
            (FADE_STRENGTH * f) as f32
        } else {
            0.0
        }
    }
}

/// The rock field: noise plus fade, free where below `threshold`.
struct RockField {
    noise: Noise,
    fade: Fade,
    threshold: f32,
}

/// Draws the noise of a `w` x `h` map and the threshold that leaves about
/// [`FREE_QUANTILE`] of `inner` free.
fn rock_field(rng: &mut Rng, w: usize, h: usize, inner: Rect, s: Scale) -> RockField {
    let (iw, ih) = (inner.w() as f64, inner.h() as f64);
    let norm: f32 = OCTAVES.iter().map(|o| o.1).sum();
    let fade = Fade::new(inner, s.cf(FADE_BAND));
    let noise = Noise {
        octaves: OCTAVES
            .iter()
            .map(|&(wl, amp)| Octave::new(rng, w, h, s.cf(wl), amp / norm))
            .collect(),
    };
    let mut samples: Vec<f32> = (0..THRESHOLD_SAMPLES)
        .map(|_| {
            let x = inner.x0 as f64 + rng.uniform() * iw;
            let y = inner.y0 as f64 + rng.uniform() * ih;
            noise.at(x, y) + fade.at(x as i64, y as i64)
        })
        .collect();
    samples.sort_by(|a, b| a.total_cmp(b));
    let q = FREE_QUANTILE.sample(rng);
    let threshold = samples[((samples.len() as f64 * q) as usize).min(samples.len() - 1)];
    RockField {
        noise,
        fade,
        threshold,
    }
}

// ---------------------------------------------------------------------------
// Capsules
// ---------------------------------------------------------------------------

/// A carved tunnel piece: the segment a-b swept by a radius varying from
/// `ra` to `rb` (cells), roughened by noise, with an always-carved core.
struct Capsule {
    ax: f64,
    ay: f64,
    bx: f64,
    by: f64,
    ra: f64,
    rb: f64,
    bbox: Rect,
}

impl Capsule {
    fn new(a: (f64, f64), b: (f64, f64), ra: f64, rb: f64) -> Self {
        let m = ra.max(rb).max(1.0) * ROUGH_MAX + 1.0;
        let bbox = Rect::new(
            (a.0.min(b.0) - m).floor() as i64,
            (a.1.min(b.1) - m).floor() as i64,
            (a.0.max(b.0) + m).ceil() as i64 + 1,
            (a.1.max(b.1) + m).ceil() as i64 + 1,
        );
        Capsule {
            ax: a.0,
            ay: a.1,
            bx: b.0,
            by: b.1,
            ra,
            rb,
            bbox,
        }
    }

    /// Largest distance from the segment at which a point can be carved.
    fn reach(&self) -> f64 {
        (self.ra.max(self.rb) * ROUGH_MAX).max(1.0)
    }

    /// The x interval (cells, continuous) within [`Capsule::reach`] of the
    /// segment on the horizontal line `y = yc`, if any. The capsule is
    /// convex, so this is the hull of its two end discs and its band.
    fn span(&self, yc: f64) -> Option<(f64, f64)> {
        let rr = self.reach();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (cx, cy) in [(self.ax, self.ay), (self.bx, self.by)] {
            let dy = yc - cy;
            let q = rr * rr - dy * dy;
            if q > 0.0 {
                let h = q.sqrt();
                lo = lo.min(cx - h);
                hi = hi.max(cx + h);
            }
        }
        let (dx, dy) = (self.bx - self.ax, self.by - self.ay);
        let l2 = dx * dx + dy * dy;
        if l2 > EPS {
            let l = l2.sqrt();
            // Along-segment parameter u(x) in [0, 1] and signed distance
            // p(x) in [-rr, rr] are both linear in x on this line.
            let (mut a, mut b) = (f64::NEG_INFINITY, f64::INFINITY);
            let mut clip = |k: f64, m: f64, p: f64, q: f64| {
                if k.abs() < EPS {
                    if m < p || m > q {
                        b = f64::NEG_INFINITY;
                    }
                } else {
                    let (x1, x2) = ((p - m) / k, (q - m) / k);
                    a = a.max(x1.min(x2));
                    b = b.min(x1.max(x2));
                }
            };
            let ey = yc - self.ay;
            clip(dx / l2, (-self.ax * dx + ey * dy) / l2, 0.0, 1.0);
            clip(-dy / l, (self.ax * dy + ey * dx) / l, -rr, rr);
            if a <= b {
                lo = lo.min(a);
                hi = hi.max(b);
            }
        }
        (lo <= hi).then_some((lo, hi))
    }

    /// Whether the point (cells) is carved, given the noise value `n` there
    /// and the free threshold `t`.
    fn covers(&self, x: f64, y: f64, n: f32, t: f32) -> bool {
        let (dx, dy) = (self.bx - self.ax, self.by - self.ay);
        let l2 = dx * dx + dy * dy;
        let u = if l2 > 0.0 {
            (((x - self.ax) * dx + (y - self.ay) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (px, py) = (self.ax + u * dx - x, self.ay + u * dy - y);
        let d2 = px * px + py * py;
        let r = self.ra + (self.rb - self.ra) * u;
        let core = (CORE_SHARE * r).max(1.0);
        if d2 < core * core {
            return true;
        }
        let k = (1.0 + ROUGH_GAIN * (t - n) as f64).clamp(0.0, ROUGH_MAX);
        d2 < (r * k) * (r * k)
    }
}

// ---------------------------------------------------------------------------
// Layout
// ---------------------------------------------------------------------------

/// The interior inside the bounding wall, for keeping carved cores in.
#[derive(Clone, Copy)]
struct Interior(Rect);

impl Interior {
    /// `p` moved so that a carved core of radius [`CORE_SHARE`] `r` around
    /// it lies inside the interior (its centre when it cannot).
    fn keep_in(self, p: (f64, f64), r: f64) -> (f64, f64) {
        let lim = |v: f64, lo: f64, hi: f64| {
            if lo > hi {
                (lo + hi) / 2.0
            } else {
                v.clamp(lo, hi)
            }
        };
        let (inner, pad) = (self.0, CORE_SHARE * r + CORE_PAD);
        (
            lim(p.0, inner.x0 as f64 + pad, inner.x1 as f64 - pad),
            lim(p.1, inner.y0 as f64 + pad, inner.y1 as f64 - pad),
        )
    }
}

/// Chamber nodes on an `nx` x `ny` grid of the interior, row-major.
struct Chambers {
    nx: usize,
    ny: usize,
    nodes: Vec<(f64, f64)>,
}

/// Places the chambers (one capsule each, added to `caps`); `rcap`: the
/// largest radius (cells).
fn chambers(
    rng: &mut Rng,
    area: Interior,
    s: Scale,
    rcap: f64,
    caps: &mut Vec<Capsule>,
) -> Chambers {
    let inner = area.0;
    let (iw, ih) = (inner.w() as f64, inner.h() as f64);
    let spacing = s.cf(CHAMBER_SPACING.sample(rng));
    let nx = ((iw / spacing).round() as usize).max(1);
    let ny = ((ih / spacing).round() as usize).max(1);
    let (cw, ch) = (iw / nx as f64, ih / ny as f64);
    let mut nodes = Vec::with_capacity(nx * ny);
    let jitter = Span::new(-CHAMBER_JITTER, CHAMBER_JITTER);
    for j in 0..ny {
        for i in 0..nx {
            let x = inner.x0 as f64 + (i as f64 + 0.5 + jitter.sample(rng)) * cw;
            let y = inner.y0 as f64 + (j as f64 + 0.5 + jitter.sample(rng)) * ch;
            let r = if chance(rng, BIG_CHAMBER_CHANCE) {
                s.cf(BIG_CHAMBER_RADIUS.sample(rng))
            } else {
                s.cf(CHAMBER_RADIUS.sample(rng))
            }
            .min(rcap);
            let p = area.keep_in((x, y), r);
            caps.push(Capsule::new(p, p, r, r));
            nodes.push(p);
        }
    }
    Chambers { nx, ny, nodes }
}

/// Joins the chambers by a random spanning tree over grid neighbours
/// (Kruskal over shuffled edges) plus a few loops; each joint is a winding
/// tunnel, added to `caps`.
fn tunnels(
    rng: &mut Rng,
    area: Interior,
    s: Scale,
    rcap: f64,
    ch: &Chambers,
    caps: &mut Vec<Capsule>,
) {
    let (nx, ny) = (ch.nx, ch.ny);
    let mut edges = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let k = j * nx + i;
            if i + 1 < nx {
                edges.push((k, k + 1));
            }
            if j + 1 < ny {
                edges.push((k, k + nx));
            }
        }
    }
    for i in (1..edges.len()).rev() {
        let j = rng.below(i as u64 + 1) as usize;
        edges.swap(i, j);
    }
    let mut sets = UnionFind::new(ch.nodes.len());
    for &(a, b) in &edges {
        let tree = sets.union(a, b);
        if !tree && !chance(rng, LOOP_CHANCE) {
            continue;
        }
        tunnel(rng, area, s, rcap, (ch.nodes[a], ch.nodes[b]), caps);
    }
}

/// A winding tunnel from `ends.0` to `ends.1`: a random-walk bridge of
/// [`PIECES`] capsules, added to `caps`.
fn tunnel(
    rng: &mut Rng,
    area: Interior,
    s: Scale,
    rcap: f64,
    ends: ((f64, f64), (f64, f64)),
    caps: &mut Vec<Capsule>,
) {
    let (pa, pb) = ends;
    let (dx, dy) = (pb.0 - pa.0, pb.1 - pa.1);
    let len = (dx * dx + dy * dy).sqrt().max(MIN_TUNNEL_LENGTH);
    let (nx_, ny_) = (-dy / len, dx / len);
    let mut walk = [0.0f64; PIECES + 1];
    for i in 1..=PIECES {
        walk[i] = walk[i - 1] + rng.normal().clamp(-WALK_STEP_MAX, WALK_STEP_MAX);
    }
    let radii: Vec<f64> = (0..=PIECES)
        .map(|_| s.cf(TUNNEL_RADIUS.sample(rng)).min(rcap))
        .collect();
    let mut pts = vec![pa];
    for (i, wv) in walk.iter().enumerate().take(PIECES).skip(1) {
        let f = i as f64 / PIECES as f64;
        let (bx, by) = (pa.0 + dx * f, pa.1 + dy * f);
        // Shrink the sideways offset until the point is well inside (the
        // straight line between two inside nodes always is).
        let mut off = (wv - f * walk[PIECES]) * WIGGLE * len;
        let mut p = (bx + nx_ * off, by + ny_ * off);
        for _ in 0..WIGGLE_SHRINKS {
            if area.keep_in(p, radii[i]) == p {
                break;
            }
            off *= 0.5;
            p = (bx + nx_ * off, by + ny_ * off);
        }
        pts.push(area.keep_in(p, radii[i]));
    }
    pts.push(pb);
    for k in 0..pts.len() - 1 {
        caps.push(Capsule::new(pts[k], pts[k + 1], radii[k], radii[k + 1]));
    }
}

/// Cave: noise-thresholded rock with chambers on a jittered grid joined by a
/// random spanning tree (plus a few loops) of winding tunnels. Returns the
/// pixels and a free point (image coordinates).
pub(super) fn cave(
    w: usize,
    h: usize,
    rng: &mut Rng,
    s: Scale,
    stats: &mut Stats,
) -> (Vec<u8>, (usize, usize)) {
    let outline = Outline::new(w as i64, h as i64, s, OUTER_WALL);
    let inner = outline.inner;
    let field = rock_field(rng, w, h, inner, s);
    let area = Interior(inner);
    let rcap = ((inner.w() as f64).min(inner.h() as f64) / RADIUS_CAP_DIV).max(1.0);
    let mut caps = Vec::new();
    let ch = chambers(rng, area, s, rcap, &mut caps);
    stats.rooms = ch.nodes.len();
    tunnels(rng, area, s, rcap, &ch, &mut caps);
    let px = rasterise(w, h, &outline, &field, &caps);
    let hint = ch
        .nodes
        .first()
        .map_or((inner.x0 as usize, inner.y0 as usize), |p| {
            (p.0 as usize, p.1 as usize)
        });
    (px, hint)
}

/// The pixels: unknown outside the building, the bounding wall occupied,
/// inside it free where the rock field is below its threshold or a capsule
/// carves, occupied elsewhere. Rasterised in parallel bands of [`BAND`]
/// rows; each cell is a pure function of its position.
fn rasterise(
    w: usize,
    h: usize,
    outline: &Outline,
    field: &RockField,
    caps: &[Capsule],
) -> Vec<u8> {
    let (building, inner) = (outline.building, outline.inner);
    let nbands = h.div_ceil(BAND);
    let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); nbands];
    for (i, c) in caps.iter().enumerate() {
        let y0 = clampi(c.bbox.y0, inner.y0, inner.y1 - 1) as usize;
        let y1 = clampi(c.bbox.y1 - 1, inner.y0, inner.y1 - 1) as usize;
        for b in buckets.iter_mut().take(y1 / BAND + 1).skip(y0 / BAND) {
            b.push(i as u32);
        }
    }
    let mut px = vec![UNKNOWN; w * h];
    let (bx0, bx1) = (building.x0 as usize, building.x1 as usize);
    let (ix0, ix1) = (inner.x0 as usize, inner.x1 as usize);
    let t = field.threshold;
    px.par_chunks_mut(w * BAND)
        .enumerate()
        .for_each(|(bi, chunk)| {
            let mut nrow = vec![0f32; w];
            let mut col = Vec::new();
            for (ry, row) in chunk.chunks_mut(w).enumerate() {
                let y = bi * BAND + ry;
                let yi = y as i64;
                if yi < building.y0 || yi >= building.y1 {
                    continue;
                }
                row[bx0..bx1].fill(OCCUPIED);
                if yi < inner.y0 || yi >= inner.y1 {
                    continue;
                }
                field.noise.row(y, ix0, ix1, &mut col, &mut nrow);
                for (x, v) in nrow.iter_mut().enumerate().take(ix1).skip(ix0) {
                    *v += field.fade.at(x as i64, yi);
                }
                for x in ix0..ix1 {
                    if nrow[x] < t {
                        row[x] = FREE;
                    }
                }
                let yc = y as f64 + 0.5;
                for &ci in &buckets[bi] {
                    let c = &caps[ci as usize];
                    if yi < c.bbox.y0 || yi >= c.bbox.y1 {
                        continue;
                    }
                    let Some((lo, hi)) = c.span(yc) else {
                        continue;
                    };
                    // Cells whose centre x + 0.5 lies in [lo, hi], plus one.
                    let xa = clampi((lo - 0.5).floor() as i64 - 1, inner.x0, inner.x1) as usize;
                    let xb = clampi((hi - 0.5).ceil() as i64 + 2, inner.x0, inner.x1) as usize;
                    for x in xa..xb {
                        if row[x] != FREE && c.covers(x as f64 + 0.5, yc, nrow[x], t) {
                            row[x] = FREE;
                        }
                    }
                }
            }
        });
    px
}
