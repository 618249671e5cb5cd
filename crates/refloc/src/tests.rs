//! Geometry and property tests across modules, the localizer's input
//! robustness, and the small hand-built database ([`fixture`]) that the
//! unit tests of other modules (e.g. `db::tests`) share.

use core::f32::consts::{FRAC_PI_2, PI};
use std::vec;
use std::vec::Vec;

use crate::coarse::{self, Ranked};
use crate::localize::{LocalizeError, AFFINITY_CAP};
use crate::params::Params;
use crate::ssm::{self, Affinity, SsmWork, DESC_LEN};
use crate::{
    localize, pgr, prep, scratch_size, wrap_angle, MapFrame, Pose2, RangeScan, RefDb, Scan,
};

/// A tiny world and a valid `.refdb` of it, built by hand with
/// `format::encode` (no compiler involved).
///
/// The world is a 6 m x 4 m room (60 x 40 cells of 0.1 m) with an inner wall,
/// a shelf and a pillar, placed with a rotated origin; three sites; a
/// 180-beam 360-degree reference sensor.
pub(crate) mod fixture {
    use std::vec;
    use std::vec::Vec;

    use zerocopy::little_endian::{F32, U32, U64};
    use zerocopy::IntoBytes;

    use crate::format::{self, MetaRecord, SectionKind, SiteRecord};
    use crate::params::Params;
    use crate::raycast::{cast, BitGrid};
    use crate::{pgr, prep, MapFrame, Pose2};

    /// Grid width (cells).
    pub(crate) const W: u32 = 60;
    /// Grid height (cells).
    pub(crate) const H: u32 = 40;
    /// Reference beams.
    pub(crate) const BEAMS: u32 = 180;
    /// Reference range (m).
    pub(crate) const RANGE_MAX: f32 = 10.0;
    /// Site cells.
    pub(crate) const SITE_CELLS: [[u32; 2]; 3] = [[10, 20], [35, 20], [50, 33]];

    /// SplitMix64: a small deterministic generator for the tests.
    pub(crate) struct Prng(u64);

    impl Prng {
        pub(crate) fn new(seed: u64) -> Self {
            Prng(seed ^ 0x6A09_E667_F3BC_C908)
        }
        pub(crate) fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        /// Uniform in [0, 1).
        pub(crate) fn unit(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
        }
        /// Uniform in [lo, hi).
        pub(crate) fn range(&mut self, lo: f32, hi: f32) -> f32 {
            (lo as f64 + (hi - lo) as f64 * self.unit()) as f32
        }
        /// Uniform in [0, n); 0 when n == 0.
        pub(crate) fn below(&mut self, n: usize) -> usize {
            ((self.next_u64() as u128 * n as u128) >> 64) as usize
        }
    }

    /// Bytes copied into a `u32`-backed buffer at byte offset `off`, so the
    /// start address is 4-byte aligned exactly when `off % 4 == 0`.
    pub(crate) struct Aligned {
        words: Vec<u32>,
        off: usize,
        len: usize,
    }

    impl Aligned {
        pub(crate) fn new(bytes: &[u8]) -> Self {
            Self::at(bytes, 0)
        }
        pub(crate) fn at(bytes: &[u8], off: usize) -> Self {
            let mut words = vec![0u32; (bytes.len() + off).div_ceil(4) + 1];
            words.as_mut_bytes()[off..off + bytes.len()].copy_from_slice(bytes);
            Aligned {
                words,
                off,
                len: bytes.len(),
            }
        }
        pub(crate) fn bytes(&self) -> &[u8] {
            &self.words.as_bytes()[self.off..self.off + self.len]
        }
        pub(crate) fn bytes_mut(&mut self) -> &mut [u8] {
            &mut self.words.as_mut_bytes()[self.off..self.off + self.len]
        }
    }

    pub(crate) fn params() -> Params {
        Params::defaults(BEAMS, RANGE_MAX)
    }

    pub(crate) fn frame() -> MapFrame {
        MapFrame {
            resolution: 0.1,
            origin: Pose2::new(-1.0, 0.5, 0.3),
        }
    }

    /// The world's beam-stopping cells.
    pub(crate) fn blocked(cx: u32, cy: u32) -> bool {
        let border = cx == 0 || cy == 0 || cx == W - 1 || cy == H - 1;
        let inner_wall = cx == 20 && cy < 23;
        let shelf = (30..50).contains(&cx) && (10..12).contains(&cy);
        let pillar = (40..44).contains(&cx) && (25..29).contains(&cy);
        let nook = (5..9).contains(&cx) && (31..33).contains(&cy);
        border || inner_wall || shelf || pillar || nook
    }

    pub(crate) fn grid_words() -> Vec<u32> {
        let mut words = vec![0u32; BitGrid::words_for(W, H)];
        for cy in 0..H {
            for cx in 0..W {
                if blocked(cx, cy) {
                    let i = (cy * W + cx) as usize;
                    words[i / 32] |= 1 << (i % 32);
                }
            }
        }
        words
    }

    /// Map-frame site positions (cell centres).
    pub(crate) fn site_xy() -> Vec<[f32; 2]> {
        let f = frame();
        SITE_CELLS
            .iter()
            .map(|c| f.to_map([c[0] as f32 + 0.5, c[1] as f32 + 0.5]))
            .collect()
    }

    /// Ranges (m, `INFINITY` for no return) of a sensor at map-frame `pose`
    /// with `beams` beams from `angle_min` in steps of `inc`.
    pub(crate) fn scan_at(pose: Pose2, beams: usize, angle_min: f32, inc: f32) -> Vec<f32> {
        scan_along(pose, beams, |k| pose.theta + angle_min + k as f32 * inc)
    }

    /// Ranges (m, `INFINITY` for no return) of `beams` beams cast from the
    /// position of `pose`, beam `k` along the map-frame bearing
    /// `bearing(k)` (rad).
    pub(crate) fn scan_along(
        pose: Pose2,
        beams: usize,
        bearing: impl Fn(usize) -> f32,
    ) -> Vec<f32> {
        let words = grid_words();
        let grid = BitGrid::new(W, H, &words).expect("grid words");
        let f = frame();
        let uv = f.to_cells([pose.x, pose.y]);
        (0..beams)
            .map(|k| {
                let a = f.angle_to_cells(bearing(k));
                match cast(&grid, uv[0], uv[1], a, RANGE_MAX / f.resolution) {
                    Some(t) => t * f.resolution,
                    None => f32::INFINITY,
                }
            })
            .collect()
    }

    /// A full-circle scan of `beams` beams at `pose` (angle_min = -pi).
    pub(crate) fn full_scan_at(pose: Pose2, beams: usize) -> Vec<f32> {
        let inc = 2.0 * core::f32::consts::PI / beams as f32;
        scan_at(pose, beams, -core::f32::consts::PI, inc)
    }

    /// Normalized PGR histogram of a reference scan, as the compiler makes it.
    pub(crate) fn histogram(ranges: &[f32], p: &Params) -> Vec<f32> {
        let mut dense = vec![[0f32; 2]; ranges.len()];
        let n = prep::reference_points(ranges, p, &mut dense);
        let m = p.prep.max_points as usize;
        let (mut pts, mut tan) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
        let k = prep::prepare(&dense[..n], true, p, &mut pts, &mut tan);
        let mut h = vec![0f32; p.coarse.hist_cells()];
        if pgr::histogram(&pts[..k], &tan[..k], p, &mut h) == 0 {
            let flat = 1.0 / h.len() as f32;
            h.iter_mut().for_each(|v| *v = flat);
        }
        h
    }

    /// The sections of the tiny database, in file order (built once).
    pub(crate) fn sections() -> Vec<(SectionKind, Vec<u8>)> {
        static SECTIONS: std::sync::OnceLock<Vec<(SectionKind, Vec<u8>)>> =
            std::sync::OnceLock::new();
        SECTIONS.get_or_init(build_sections).clone()
    }

    fn build_sections() -> Vec<(SectionKind, Vec<u8>)> {
        let p = params();
        let f = frame();
        let sites = site_xy();
        let meta = MetaRecord {
            width: U32::new(W),
            height: U32::new(H),
            resolution: F32::new(f.resolution),
            origin_x: F32::new(f.origin.x),
            origin_y: F32::new(f.origin.y),
            origin_yaw: F32::new(f.origin.theta),
            site_count: U32::new(sites.len() as u32),
            unknown_blocks: U32::new(1),
            free_cells: U64::new(
                (0..H)
                    .flat_map(|cy| (0..W).map(move |cx| (cx, cy)))
                    .filter(|&(cx, cy)| !blocked(cx, cy))
                    .count() as u64,
            ),
            reserved: [0; 24],
        };
        // Neighbours: a chain 0 - 1 - 2.
        let neighbours: [u32; 4] = [1, 0, 2, 1];
        let ranges = [(0u32, 1u32), (1, 2), (3, 1)];
        let site_records: Vec<SiteRecord> = sites
            .iter()
            .zip(ranges)
            .map(|(xy, (start, count))| SiteRecord {
                x: F32::new(xy[0]),
                y: F32::new(xy[1]),
                clearance: F32::new(0.5),
                kind: U32::new(0),
                neighbor_start: U32::new(start),
                neighbor_count: U32::new(count),
            })
            .collect();
        // Signed distance map, brute force: from a free cell's centre to the
        // nearest blocked centre minus half a cell; inside an obstacle, minus
        // (the distance to the nearest free centre less half a cell).
        let cells: Vec<(f32, f32, bool)> = (0..H)
            .flat_map(|cy| (0..W).map(move |cx| (cx as f32, cy as f32, blocked(cx, cy))))
            .collect();
        let nearest = |x: f32, y: f32, want: bool| {
            cells
                .iter()
                .filter(|c| c.2 == want)
                .map(|c| (c.0 - x).powi(2) + (c.1 - y).powi(2))
                .fold(f32::INFINITY, f32::min)
                .sqrt()
        };
        let dist: Vec<u8> = cells
            .iter()
            .map(|&(x, y, b)| {
                let d = if b {
                    -(nearest(x, y, false) - 0.5).max(0.0)
                } else {
                    nearest(x, y, true) - 0.5
                };
                format::dist_encode(d)
            })
            .collect();
        let mut scans = Vec::new();
        let mut hists = Vec::new();
        let mut windows = Vec::new();
        for xy in &sites {
            let r = full_scan_at(Pose2::new(xy[0], xy[1], 0.0), BEAMS as usize);
            hists.extend(histogram(&r, &p));
            windows.extend(window_histograms(&r, &p));
            scans.extend(r);
        }
        let features = features_section(&scans, &p);
        // Every kind the format knows, in its order: a new kind fails to
        // compile here until the fixture makes it.
        SectionKind::ALL
            .iter()
            .map(|&k| {
                let bytes = match k {
                    SectionKind::Meta => meta.as_bytes().to_vec(),
                    SectionKind::Params => p.to_record().as_bytes().to_vec(),
                    SectionKind::Grid => grid_words().as_bytes().to_vec(),
                    SectionKind::Dist => dist.clone(),
                    SectionKind::Sites => site_records.as_bytes().to_vec(),
                    SectionKind::Neighbors => neighbours.as_bytes().to_vec(),
                    SectionKind::Scans => scans.as_bytes().to_vec(),
                    SectionKind::Hists => hists.as_bytes().to_vec(),
                    SectionKind::Manifest => br#"{"generator":"refloc unit tests"}"#.to_vec(),
                    SectionKind::Windows => windows.as_bytes().to_vec(),
                    SectionKind::Index => tiny_index(&p, &hists, &windows, sites.len()),
                    SectionKind::Decision => format::DecisionRecord::of(&crate::Decision::DEFAULT)
                        .as_bytes()
                        .to_vec(),
                    SectionKind::Features => features.clone(),
                };
                (k, bytes)
            })
            .collect()
    }

    /// The features section of reference scans `scans` (`BEAMS` ranges per
    /// site, concatenated), computed by the runtime's own
    /// [`crate::localize::reference_features`] and laid out by
    /// [`format::FeaturesLayout`].
    pub(crate) fn features_section(scans: &[f32], p: &Params) -> Vec<u8> {
        let m = p.prep.max_points as usize;
        let (mut offsets, mut pts, mut tans, mut descs) = (vec![0u32], vec![], vec![], vec![]);
        for r in scans.chunks(p.sensor.beams as usize) {
            let mut dense = vec![[0f32; 2]; r.len()];
            let (mut rp, mut rt) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
            let mut rd = vec![0 as crate::ssm::DescBin; m * crate::ssm::DESC_LEN];
            let n =
                crate::localize::reference_features(r, p, &mut dense, &mut rp, &mut rt, &mut rd);
            offsets.push(offsets[offsets.len() - 1] + n as u32);
            pts.extend_from_slice(&rp[..n]);
            tans.extend_from_slice(&rt[..n]);
            descs.extend_from_slice(&rd[..n * crate::ssm::DESC_LEN]);
        }
        let sites = offsets.len() as u64 - 1;
        let layout = format::FeaturesLayout::new(sites, pts.len() as u64).expect("small");
        let mut out = offsets.as_bytes().to_vec();
        out.resize(layout.points_at, 0);
        out.extend_from_slice(pts.as_bytes());
        out.extend_from_slice(tans.as_bytes());
        out.extend_from_slice(descs.as_bytes());
        assert_eq!(out.len(), layout.len);
        out
    }

    /// A coarse-search index for the fixture: per view (full, then each
    /// window width), a root with two leaves splitting the entries in
    /// halves; centroids are the members' mean histograms.
    pub(crate) fn tiny_index(p: &Params, hists: &[f32], windows: &[f32], sites: usize) -> Vec<u8> {
        use crate::format::{IndexHeader, IndexNode, IndexView};
        let node = |first: u32, count: u32, leaf: u32| IndexNode {
            first: U32::new(first),
            count: U32::new(count),
            leaf: U32::new(leaf),
            reserved: U32::new(0),
        };
        let (nw, nh, wc) = (
            p.coarse.win_count(),
            p.coarse.win_headings as usize,
            p.coarse.win_cells(),
        );
        // (kind, entry histograms) per view.
        let mut views: Vec<(u32, Vec<&[f32]>)> =
            vec![(0, hists.chunks(p.coarse.hist_cells()).collect())];
        for w in 0..nw {
            let mut v = Vec::new();
            for s in 0..sites {
                for h in 0..nh {
                    let i = (s * nw + w) * nh + h;
                    v.push(&windows[i * wc..(i + 1) * wc]);
                }
            }
            views.push((1 + w as u32, v));
        }
        let (mut recs, mut nodes, mut entries, mut cents) =
            (Vec::new(), Vec::new(), Vec::<u32>::new(), Vec::<f32>::new());
        for (kind, hs) in &views {
            let n = hs.len();
            let half = n / 2;
            let mean = |r: core::ops::Range<usize>| {
                let mut m = vec![0f32; hs[0].len()];
                for h in &hs[r.clone()] {
                    m.iter_mut()
                        .zip(h.iter())
                        .for_each(|(a, b)| *a += b / r.len() as f32);
                }
                m
            };
            recs.push(IndexView {
                kind: U32::new(*kind),
                node_count: U32::new(3),
                entry_count: U32::new(n as u32),
                reserved: U32::new(0),
            });
            nodes.extend([
                node(1, 2, 0),
                node(0, half as u32, 1),
                node(half as u32, (n - half) as u32, 1),
            ]);
            entries.extend(0..n as u32);
            cents.extend(mean(0..n));
            cents.extend(mean(0..half));
            cents.extend(mean(half..n));
        }
        let header = IndexHeader {
            view_count: U32::new(recs.len() as u32),
            beam: U32::new(4),
            leaves: U32::new(4),
            reserved: U32::new(0),
        };
        let mut out = header.as_bytes().to_vec();
        out.extend_from_slice(recs.as_bytes());
        out.extend_from_slice(nodes.as_bytes());
        out.extend_from_slice(entries.as_bytes());
        out.extend_from_slice(cents.as_bytes());
        out
    }

    /// Window histograms of a reference scan (heading 0 at the site): for
    /// each used width and each of `win_headings` headings, the normalized
    /// histogram (window bins) of the beams within half the width of it.
    pub(crate) fn window_histograms(ranges: &[f32], p: &Params) -> Vec<f32> {
        let s = &p.sensor;
        let n = ranges.len();
        let mut dense = vec![[0f32; 2]; n];
        prep::reference_points(ranges, p, &mut dense);
        let mut wp = *p;
        wp.coarse.hist_rho_bins = p.coarse.win_rho_bins;
        wp.coarse.hist_theta_bins = p.coarse.win_theta_bins;
        let m = p.prep.max_points as usize;
        let (mut pts, mut tan) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
        let nh = p.coarse.win_headings as usize;
        let mut out = Vec::new();
        for &width in &p.coarse.win_widths[..p.coarse.win_count()] {
            for h in 0..nh {
                let first = h as f32 * 2.0 * core::f32::consts::PI / nh as f32 - width / 2.0;
                let off = |k: usize| {
                    (s.angle_min + k as f32 * s.angle_increment - first)
                        .rem_euclid(2.0 * core::f32::consts::PI)
                };
                let start = (0..n)
                    .min_by(|&a, &b| off(a).total_cmp(&off(b)))
                    .unwrap_or(0);
                let count = ((width / s.angle_increment).round() as usize).min(n);
                let window: Vec<[f32; 2]> = (0..count).map(|j| dense[(start + j) % n]).collect();
                let k = prep::prepare(&window, false, &wp, &mut pts, &mut tan);
                let mut hist = vec![0f32; wp.coarse.hist_cells()];
                if pgr::histogram(&pts[..k], &tan[..k], &wp, &mut hist) == 0 {
                    let flat = 1.0 / hist.len() as f32;
                    hist.iter_mut().for_each(|v| *v = flat);
                }
                out.extend(hist);
            }
        }
        out
    }

    /// Encodes sections into a file image.
    pub(crate) fn encode(sections: &[(SectionKind, Vec<u8>)]) -> Vec<u8> {
        let refs: Vec<(SectionKind, &[u8])> =
            sections.iter().map(|(k, b)| (*k, b.as_slice())).collect();
        let mut out = Vec::new();
        let len = format::encode(&refs, |b: &[u8]| -> Result<(), ()> {
            out.extend_from_slice(b);
            Ok(())
        })
        .expect("encoding into a Vec cannot fail");
        assert_eq!(len as usize, out.len());
        out
    }

    /// The tiny database's file image.
    pub(crate) fn tiny_db_bytes() -> Vec<u8> {
        encode(&sections())
    }
}

use fixture::{Aligned, Prng};

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

fn angle_diff(a: f32, b: f32) -> f32 {
    wrap_angle(a - b).abs()
}

fn l1(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum()
}

fn random_pose(rng: &mut Prng, span: f32) -> Pose2 {
    Pose2::new(
        rng.range(-span, span),
        rng.range(-span, span),
        rng.range(-PI, PI),
    )
}

// ---------------------------------------------------------------------------
// PGR histogram
// ---------------------------------------------------------------------------

/// Beam-ordered sensor-frame points of a full scan in the tiny world.
fn world_points(pose: Pose2, beams: usize) -> Vec<[f32; 2]> {
    let r = fixture::full_scan_at(pose, beams);
    let inc = 2.0 * PI / beams as f32;
    let mut out = vec![[0f32; 2]; beams];
    prep::ranges_to_points(&r, -PI, inc, 0.0, fixture::RANGE_MAX, &mut out);
    out
}

fn points_histogram(dense: &[[f32; 2]], p: &Params) -> Vec<f32> {
    let m = p.prep.max_points as usize;
    let (mut pts, mut tan) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
    let n = prep::prepare(dense, true, p, &mut pts, &mut tan);
    assert!(n >= 50, "only {n} prepared points");
    let mut h = vec![0f32; p.coarse.hist_cells()];
    let votes = pgr::histogram(&pts[..n], &tan[..n], p, &mut h);
    assert_eq!(votes, n * (n - 1));
    let sum: f32 = h.iter().sum();
    assert!(close(sum, 1.0, 1e-4), "histogram sums to {sum}");
    h
}

fn moved(dense: &[[f32; 2]], t: &Pose2) -> Vec<[f32; 2]> {
    dense
        .iter()
        .map(|&p| if p[0].is_finite() { t.apply(p) } else { p })
        .collect()
}

#[test]
fn pgr_histogram_is_invariant_under_rigid_motion() {
    let p = fixture::params();
    let mut rng = Prng::new(1);
    let poses = [
        Pose2::new(0.6, 2.9, 0.4),
        Pose2::new(3.4, 3.2, -2.0),
        Pose2::new(3.0, 4.6, 1.0),
    ];
    let mut worst_rot = 0.0f32;
    let mut worst_rigid = 0.0f32;
    for pose in poses {
        let dense = world_points(pose, 360);
        let h = points_histogram(&dense, &p);
        for _ in 0..6 {
            // Rotation about the sensor: ranges unchanged, exact invariance
            // up to rounding at bin boundaries.
            let rot = Pose2::new(0.0, 0.0, rng.range(-PI, PI));
            let d = l1(&h, &points_histogram(&moved(&dense, &rot), &p));
            worst_rot = worst_rot.max(d);
            // A general rigid motion also changes each point's range, which
            // the depth-jump threshold uses: a few links may flip.
            let t = random_pose(&mut rng, 0.5);
            let d = l1(&h, &points_histogram(&moved(&dense, &t), &p));
            worst_rigid = worst_rigid.max(d);
        }
    }
    // Measured: up to 0.016 (rotation) and 0.025 (rigid). Even a pure
    // rotation, which leaves the prepared points identical, moves some votes:
    // theta bin edges fall on 0 and +-pi, exactly where pairs of points on the
    // same straight wall land (about 18% of the pairs here), so rounding
    // decides their bin.
    assert!(
        worst_rot < 0.03,
        "rotation changed the histogram by L1 {worst_rot}"
    );
    assert!(
        worst_rigid < 0.04,
        "rigid motion changed the histogram by L1 {worst_rigid}"
    );
}

#[test]
fn pgr_histogram_tells_a_scene_from_its_mirror_image() {
    let p = fixture::params();
    for pose in [Pose2::new(0.6, 2.9, 0.4), Pose2::new(3.4, 3.2, -2.0)] {
        let dense = world_points(pose, 360);
        let h = points_histogram(&dense, &p);
        // The mirrored scene seen by a counter-clockwise scanner: mirror the
        // points and reverse the beam order.
        let mirrored: Vec<[f32; 2]> = dense.iter().rev().map(|q| [q[0], -q[1]]).collect();
        let hm = points_histogram(&mirrored, &p);
        let d = l1(&h, &hm);
        assert!(d > 0.15, "mirror image histogram too close: L1 {d}");
        let rot = points_histogram(&moved(&dense, &Pose2::new(0.0, 0.0, 1.0)), &p);
        assert!(coarse::correlation(&h, &rot) > coarse::correlation(&h, &hm));
    }
}

// ---------------------------------------------------------------------------
// SSM: least squares and RANSAC
// ---------------------------------------------------------------------------

#[test]
fn least_squares_recovers_a_rigid_transform_exactly() {
    let mut rng = Prng::new(2);
    let (mut worst_xy, mut worst_th) = (0.0f32, 0.0f32);
    for _ in 0..200 {
        let t = random_pose(&mut rng, 5.0);
        let n = 3 + rng.below(40);
        let q: Vec<[f32; 2]> = (0..n)
            .map(|_| [rng.range(-5.0, 5.0), rng.range(-5.0, 5.0)])
            .collect();
        let r: Vec<[f32; 2]> = q.iter().map(|&p| t.apply(p)).collect();
        let acc: Vec<[u16; 2]> = (0..n as u16).map(|i| [i, i]).collect();
        let (pose, inl) = ssm::least_squares(&acc, &q, &r, &Pose2::default(), f32::INFINITY)
            .expect("a fit from >= 2 correspondences");
        assert_eq!(inl as usize, n);
        worst_xy = worst_xy.max((pose.x - t.x).abs()).max((pose.y - t.y).abs());
        worst_th = worst_th.max(angle_diff(pose.theta, t.theta));
    }
    assert!(worst_xy < 1e-4, "translation error {worst_xy} m");
    assert!(worst_th < 1e-5, "rotation error {worst_th} rad");
    // Fewer than two correspondences: no fit.
    let q = [[0.0f32, 0.0]];
    assert!(ssm::least_squares(&[[0, 0]], &q, &q, &Pose2::default(), 1.0).is_none());
}

/// An irregular point set along a few walls, with tangents: distinct local
/// descriptors, like a real prepared scan. Points are spaced more than the
/// RANSAC threshold apart, so a correspondence shifted to a neighbouring
/// point is an outlier and the final fit uses only exact ones (with closer
/// spacing such shifted matches count as inliers and bias the fit by a few
/// millimetres, which is the method, not an error).
fn synthetic_prepared(rng: &mut Prng) -> (Vec<[f32; 2]>, Vec<[f32; 2]>) {
    let corners = [
        [-4.0f32, -3.0],
        [3.5, -3.0],
        [3.5, 0.5],
        [1.5, 0.5],
        [1.5, 2.5],
        [-2.0, 3.2],
        [-4.0, 1.0],
    ];
    let (mut pts, mut tan) = (Vec::new(), Vec::new());
    for k in 0..corners.len() {
        let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
        let d = [b[0] - a[0], b[1] - a[1]];
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        let u = [d[0] / len, d[1] / len];
        let mut s = rng.range(0.05, 0.2);
        while s < len - 0.05 && pts.len() < 150 {
            pts.push([a[0] + u[0] * s, a[1] + u[1] * s]);
            tan.push(u);
            s += rng.range(0.25, 0.45);
        }
    }
    (pts, tan)
}

#[test]
fn ransac_match_recovers_a_rigid_transform_from_exact_correspondences() {
    let p = fixture::params();
    let mut rng = Prng::new(3);
    let np = p.prep.max_points as usize;
    let tent = np * p.ssm.tentative_k as usize;
    let (mut qdesc, mut rdesc) = (
        vec![0 as ssm::DescBin; np * DESC_LEN],
        vec![0 as ssm::DescBin; np * DESC_LEN],
    );
    let mut tbuf = vec![[0u16; 2]; tent];
    let mut ends = vec![0f32; 4 * tent];
    let mut aff = vec![Affinity::default(); AFFINITY_CAP];
    let (mut x, mut y, mut order) = (vec![0f32; tent], vec![0f32; tent], vec![0u16; tent]);
    let mut acc = vec![[0u16; 2]; np];
    let mut flags = vec![0u8; 3 * np + tent];
    let mut rcols = vec![0 as ssm::DescBin; np * DESC_LEN];
    let (mut rsum, mut shared, mut dist) = (vec![0u32; np], vec![0u16; np], vec![0u32; np]);
    for _ in 0..8 {
        let (q_pts, q_tan) = synthetic_prepared(&mut rng);
        let t = random_pose(&mut rng, 4.0);
        let r_pts: Vec<[f32; 2]> = q_pts.iter().map(|&v| t.apply(v)).collect();
        let rot = Pose2::new(0.0, 0.0, t.theta);
        let r_tan: Vec<[f32; 2]> = q_tan.iter().map(|&v| rot.apply(v)).collect();
        ssm::descriptors(&q_pts, &q_tan, p.ssm.desc_radius, &mut qdesc);
        ssm::descriptors(&r_pts, &r_tan, p.ssm.desc_radius, &mut rdesc);
        let mut work = SsmWork {
            qdesc: &mut qdesc,
            tent: &mut tbuf,
            ends: &mut ends,
            aff: &mut aff,
            x: &mut x,
            y: &mut y,
            order: &mut order,
            acc: &mut acc,
            flags: &mut flags,
            bins: ssm::BinWork {
                cols: &mut rcols,
                sums: &mut rsum,
                shared: &mut shared,
                dist: &mut dist,
            },
        };
        let m = ssm::match_scans(&q_pts, &q_tan, &r_pts, &r_tan, &rdesc, &p, &mut work)
            .expect("SSM finds the transform");
        assert!(m.inliers >= p.ssm.min_inliers);
        assert!(
            (m.pose.x - t.x).abs() < 1e-4 && (m.pose.y - t.y).abs() < 1e-4,
            "pose {:?} vs truth {:?}",
            m.pose,
            t
        );
        assert!(
            angle_diff(m.pose.theta, t.theta) < 1e-5,
            "pose {:?} vs truth {:?}",
            m.pose,
            t
        );
    }
}

// ---------------------------------------------------------------------------
// Coarse stage
// ---------------------------------------------------------------------------

fn random_hist(rng: &mut Prng, k: usize) -> Vec<f32> {
    let mut h: Vec<f32> = (0..k)
        .map(|_| {
            if rng.below(3) == 0 {
                rng.range(0.0, 1.0)
            } else {
                0.0
            }
        })
        .collect();
    h[rng.below(k)] += 0.5;
    let s: f32 = h.iter().sum();
    h.iter_mut().for_each(|v| *v /= s);
    h
}

#[test]
fn correlation_properties() {
    let mut rng = Prng::new(4);
    let k = 576;
    for _ in 0..200 {
        let h = random_hist(&mut rng, k);
        let g = random_hist(&mut rng, k);
        assert!(close(coarse::correlation(&h, &h), 1.0, 1e-5));
        let (a, b) = (coarse::correlation(&h, &g), coarse::correlation(&g, &h));
        assert!(close(a, b, 1e-6), "not symmetric: {a} vs {b}");
        assert!((-1.0..=1.0).contains(&a));
        // Unnormalized non-negative inputs stay in range too.
        let s: Vec<f32> = g.iter().map(|v| v * rng.range(0.0, 50.0)).collect();
        let c = coarse::correlation(&h, &s);
        assert!((-1.0..=1.0).contains(&c), "{c}");
    }
    let flat = vec![1.0 / k as f32; k];
    let h = random_hist(&mut rng, k);
    // A flat histogram correlates with nothing (up to the rounding of its
    // sum, which is not exactly 1 in f32).
    assert!(coarse::correlation(&flat, &h).abs() < 1e-5);
    assert!(coarse::correlation(&h, &flat).abs() < 1e-5);
    // With an exactly representable 1/K the two flat histograms give 0/0.
    let flat512 = vec![1.0 / 512.0; 512];
    assert_eq!(coarse::correlation(&flat512, &flat512), 0.0);
    assert_eq!(coarse::correlation(&[], &[]), 0.0);
    let mut nan = h.clone();
    nan[3] = f32::NAN;
    assert_eq!(coarse::correlation(&nan, &h), 0.0);
}

#[test]
fn correlation_of_two_flat_histograms_is_zero() {
    let k = 576;
    let flat = vec![1.0 / k as f32; k];
    assert_eq!(coarse::correlation(&flat, &flat), 0.0);
}

#[test]
fn rank_top_returns_the_best_in_order_with_ties_by_index() {
    let mut rng = Prng::new(5);
    let k = 64;
    for round in 0..50 {
        let input = random_hist(&mut rng, k);
        let n = rng.below(40);
        // Sites drawn from a small pool so equal histograms (ties) are common.
        let pool: Vec<Vec<f32>> = (0..6).map(|_| random_hist(&mut rng, k)).collect();
        let sites: Vec<&[f32]> = (0..n)
            .map(|_| pool[rng.below(pool.len())].as_slice())
            .collect();
        let mut want: Vec<Ranked> = sites
            .iter()
            .enumerate()
            .map(|(i, h)| Ranked {
                site: i as u32,
                gamma: coarse::correlation(&input, h),
            })
            .collect();
        want.sort_by(|a, b| b.gamma.total_cmp(&a.gamma).then(a.site.cmp(&b.site)));
        let cap = [0, 1, 3, 5, 64][round % 5];
        let mut top = vec![Ranked::default(); cap];
        let got = coarse::rank_top(&input, sites.iter().copied(), &mut top);
        assert_eq!(got, cap.min(n));
        assert_eq!(&top[..got], &want[..got], "round {round}");
    }
}

#[test]
fn candidate_count_applies_the_margin_and_clamps() {
    let ranked = |g: &[f32]| -> Vec<Ranked> {
        g.iter()
            .enumerate()
            .map(|(i, &gamma)| Ranked {
                site: i as u32,
                gamma,
            })
            .collect()
    };
    let r = ranked(&[0.9, 0.85, 0.7, 0.6, 0.2, 0.1, 0.0, -0.1]);
    assert_eq!(coarse::candidate_count(&r, 1, 8, 0.25), 3);
    assert_eq!(
        coarse::candidate_count(&r, 5, 8, 0.25),
        5,
        "raised to nc_min"
    );
    assert_eq!(
        coarse::candidate_count(&r, 1, 2, 0.25),
        2,
        "capped at nc_max"
    );
    assert_eq!(
        coarse::candidate_count(&r, 1, 8, 10.0),
        8,
        "all within the margin"
    );
    assert_eq!(
        coarse::candidate_count(&r, 1, 100, 10.0),
        8,
        "never past the list"
    );
    assert_eq!(
        coarse::candidate_count(&r[..3], 5, 30, 0.0),
        3,
        "nc_min capped by the list"
    );
    assert_eq!(coarse::candidate_count(&[], 5, 30, 0.25), 0);
}

// ---------------------------------------------------------------------------
// Frames
// ---------------------------------------------------------------------------

#[test]
fn pose_compose_and_inverse_round_trip() {
    let mut rng = Prng::new(6);
    for _ in 0..2000 {
        let a = random_pose(&mut rng, 50.0);
        let b = random_pose(&mut rng, 50.0);
        let p = [rng.range(-20.0, 20.0), rng.range(-20.0, 20.0)];
        for id in [a.compose(&a.inverse()), a.inverse().compose(&a)] {
            assert!(id.x.abs() < 1e-4 && id.y.abs() < 1e-4, "{id:?}");
            assert!(angle_diff(id.theta, 0.0) < 1e-6, "{id:?}");
        }
        let ab = a.compose(&b);
        let (l, r) = (ab.apply(p), a.apply(b.apply(p)));
        assert!(close(l[0], r[0], 1e-3) && close(l[1], r[1], 1e-3));
        let back = a.inverse().apply(a.apply(p));
        assert!(close(back[0], p[0], 1e-3) && close(back[1], p[1], 1e-3));
        // (a b)^-1 = b^-1 a^-1
        let (i1, i2) = (ab.inverse(), b.inverse().compose(&a.inverse()));
        assert!(close(i1.x, i2.x, 1e-3) && close(i1.y, i2.y, 1e-3));
        assert!(angle_diff(i1.theta, i2.theta) < 1e-5);
        for q in [a, b, ab, i1] {
            assert!(q.theta > -PI && q.theta <= PI, "{q:?}");
        }
    }
}

#[test]
fn map_frame_round_trips_with_a_rotated_origin() {
    let mut rng = Prng::new(7);
    for _ in 0..500 {
        let f = MapFrame {
            resolution: rng.range(0.01, 0.5),
            origin: random_pose(&mut rng, 100.0),
        };
        let o = [f.origin.x, f.origin.y];
        let c = f.to_cells(o);
        assert!(c[0].abs() < 1e-3 && c[1].abs() < 1e-3);
        // One cell along the grid's +x axis is `resolution` metres along the
        // origin's heading.
        let ex = f.to_map([1.0, 0.0]);
        let want = [
            o[0] + f.resolution * f.origin.theta.cos(),
            o[1] + f.resolution * f.origin.theta.sin(),
        ];
        assert!(close(ex[0], want[0], 1e-4) && close(ex[1], want[1], 1e-4));
        for _ in 0..10 {
            let p = [rng.range(-150.0, 150.0), rng.range(-150.0, 150.0)];
            let q = f.to_map(f.to_cells(p));
            assert!(
                close(q[0], p[0], 2e-4) && close(q[1], p[1], 2e-4),
                "{p:?} -> {q:?}"
            );
            let uv = [rng.range(0.0, 2000.0), rng.range(0.0, 2000.0)];
            let back = f.to_cells(f.to_map(uv));
            let tol = 2e-4 / f.resolution.min(1.0) * 4.0;
            assert!(
                close(back[0], uv[0], tol) && close(back[1], uv[1], tol),
                "{uv:?} -> {back:?}"
            );
        }
        let th = rng.range(-PI, PI);
        assert_eq!(f.angle_to_cells(th), th - f.origin.theta);
    }
}

#[test]
fn wrap_angle_lands_in_range_and_keeps_the_direction() {
    let mut rng = Prng::new(8);
    for k in 0..20000 {
        let a = match k % 4 {
            0 => rng.range(-10.0, 10.0),
            1 => rng.range(-1e4, 1e4),
            2 => (rng.below(41) as f32 - 20.0) * PI,
            _ => (rng.below(41) as f32 - 20.0) * FRAC_PI_2,
        };
        let w = wrap_angle(a);
        assert!(w > -PI && w <= PI, "wrap_angle({a}) = {w}");
        let tol = 1e-6 * a.abs().max(1.0) + 1e-6;
        assert!(
            close(w.sin(), a.sin(), tol * 4.0) && close(w.cos(), a.cos(), tol * 4.0),
            "wrap_angle({a}) = {w}"
        );
    }
    assert_eq!(wrap_angle(PI), PI);
    assert_eq!(wrap_angle(-PI), PI);
    assert_eq!(wrap_angle(0.0), 0.0);
    assert!(wrap_angle(f32::NAN).is_nan());
    let big = wrap_angle(1e30);
    assert!(big > -PI && big <= PI);
}

// ---------------------------------------------------------------------------
// localize: input robustness
// ---------------------------------------------------------------------------

fn tiny_db() -> Aligned {
    Aligned::new(&fixture::tiny_db_bytes())
}

fn ranges_scan(ranges: &[f32]) -> Scan<'_> {
    Scan::Ranges(RangeScan {
        angle_min: -PI,
        angle_increment: 2.0 * PI / ranges.len().max(1) as f32,
        range_min: 0.05,
        range_max: fixture::RANGE_MAX,
        ranges,
    })
}

fn run(db: &RefDb<&[u8]>, scan: &Scan<'_>) -> Result<Pose2, LocalizeError> {
    let mut scratch = vec![0u8; scratch_size(db.params(), scan.len())];
    localize(db, scan, &mut scratch).map(|l| l.pose)
}

/// A scan from a known pose in the tiny world.
fn truth_and_scan() -> (Pose2, Vec<f32>) {
    let truth = Pose2::new(0.9, 2.8, 0.7);
    (truth, fixture::full_scan_at(truth, 362))
}

#[test]
fn fixture_database_localizes_a_clean_scan() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).expect("fixture is valid");
    db.verify().expect("fixture checksums");
    let (truth, ranges) = truth_and_scan();
    let pose = run(&db, &ranges_scan(&ranges)).expect("localizes");
    assert!(
        (pose.x - truth.x).abs() < 0.15
            && (pose.y - truth.y).abs() < 0.15
            && angle_diff(pose.theta, truth.theta) < 0.05,
        "pose {pose:?} vs truth {truth:?}"
    );
}

/// A beam reported at exactly `range_max` is "no return", as Stage and
/// CARMEN logs report a beam that hit nothing: the same answer as with NaN
/// there, not an arc of false surface at the sensor's reach.
#[test]
fn a_range_of_range_max_is_no_return() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (truth, full) = truth_and_scan();
    let (mut nan, mut at_max) = (full.clone(), full.clone());
    for k in 40..140 {
        nan[k] = f32::NAN;
        at_max[k] = fixture::RANGE_MAX;
    }
    let answer = |ranges: &[f32]| {
        let scan = ranges_scan(ranges);
        let mut scratch = vec![0u8; scratch_size(db.params(), scan.len())];
        let l = localize(&db, &scan, &mut scratch).expect("localizes");
        (l.pose, l.confidence, l.valid_points)
    };
    let (a, b) = (answer(&nan), answer(&at_max));
    assert_eq!(a, b);
    assert!((a.0.x - truth.x).abs() < 0.15 && (a.0.y - truth.y).abs() < 0.15);
}

#[test]
fn localize_rejects_scans_without_enough_returns() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let n = 362;
    let cases: [(&str, Vec<f32>); 6] = [
        ("empty", vec![]),
        ("all NaN", vec![f32::NAN; n]),
        ("all +inf", vec![f32::INFINITY; n]),
        ("negative", vec![-1.5; n]),
        ("below range_min", vec![0.01; n]),
        ("all at range_max", vec![fixture::RANGE_MAX; n]),
    ];
    for (what, ranges) in &cases {
        match run(&db, &ranges_scan(ranges)) {
            Err(LocalizeError::NotEnoughPoints { valid: 0, needed }) => {
                assert_eq!(needed, db.params().prep.min_valid_points as usize, "{what}")
            }
            other => panic!("{what}: {other:?}"),
        }
    }
    // Exactly one fewer valid return than needed.
    let (_, full) = truth_and_scan();
    let need = db.params().prep.min_valid_points as usize;
    let mut few = vec![f32::NAN; n];
    for k in 0..need - 1 {
        few[k * 7] = full[k * 7];
    }
    assert!(few.iter().filter(|r| r.is_finite()).count() == need - 1);
    assert_eq!(
        run(&db, &ranges_scan(&few)),
        Err(LocalizeError::NotEnoughPoints {
            valid: need - 1,
            needed: need
        })
    );
    // Point input: empty, all non-finite.
    for pts in [
        vec![],
        vec![[f32::NAN, 1.0]; 100],
        vec![[f32::INFINITY, 0.0]; 100],
    ] {
        let scan = Scan::Points {
            points: &pts,
            range_max: 10.0,
        };
        assert!(matches!(
            run(&db, &scan),
            Err(LocalizeError::NotEnoughPoints { valid: 0, .. })
        ));
    }
}

#[test]
fn localize_survives_a_scan_of_max_range_readings() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    // Readings one ulp under range_max count as returns (a circle of
    // points); whatever the answer, it is a value or a typed error, not a
    // panic.
    let ranges = vec![fixture::RANGE_MAX * (1.0 - f32::EPSILON); 362];
    if let Ok(p) = run(&db, &ranges_scan(&ranges)) {
        assert!(p.x.is_finite() && p.y.is_finite() && p.theta.is_finite());
    }
    // At range_max (how many drivers report a beam that hit nothing) and
    // past it: no returns at all.
    for r in [fixture::RANGE_MAX, fixture::RANGE_MAX * 1.001] {
        let ranges = vec![r; 362];
        assert!(matches!(
            run(&db, &ranges_scan(&ranges)),
            Err(LocalizeError::NotEnoughPoints { valid: 0, .. })
        ));
    }
}

#[test]
fn localize_rejects_a_scan_larger_than_the_scratch() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let mut scratch = vec![0u8; scratch_size(db.params(), 362)];
    let ranges = vec![2.0f32; 100_000];
    let scan = ranges_scan(&ranges);
    match localize(&db, &scan, &mut scratch) {
        Err(LocalizeError::TooManyBeams { beams, capacity }) => {
            assert_eq!(beams, 100_000);
            assert_eq!(capacity, 362);
        }
        Err(LocalizeError::ScratchTooSmall { .. }) => {}
        other => panic!("{:?}", other.map(|l| l.pose)),
    }
}

#[test]
fn localize_rejects_bad_beam_geometry() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (_, ranges) = truth_and_scan();
    let base = match ranges_scan(&ranges) {
        Scan::Ranges(r) => r,
        Scan::Points { .. } => unreachable!(),
    };
    let mut bad = Vec::new();
    for inc in [
        0.0,
        -0.0,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e30,
        -1e30,
        1.0,
    ] {
        bad.push(RangeScan {
            angle_increment: inc,
            ..base
        });
    }
    for am in [f32::NAN, f32::INFINITY] {
        bad.push(RangeScan {
            angle_min: am,
            ..base
        });
    }
    for (rmin, rmax) in [
        (0.0, f32::NAN),
        (0.0, 0.0),
        (0.0, -1.0),
        (f32::NAN, 10.0),
        (-1.0, 10.0),
        (0.0, f32::INFINITY),
    ] {
        bad.push(RangeScan {
            range_min: rmin,
            range_max: rmax,
            ..base
        });
    }
    for r in bad {
        match run(&db, &Scan::Ranges(r)) {
            Err(LocalizeError::BadScan(what)) => assert!(!what.is_empty()),
            other => panic!("{r:?}: {other:?}"),
        }
    }
    for range_max in [f32::NAN, 0.0, -3.0, f32::INFINITY] {
        let pts = [[1.0f32, 0.0]; 50];
        let scan = Scan::Points {
            points: &pts,
            range_max,
        };
        assert!(
            matches!(run(&db, &scan), Err(LocalizeError::BadScan(_))),
            "{range_max}"
        );
    }
    // A clockwise scan (negative increment) is fine.
    let (truth, _) = truth_and_scan();
    let rev: Vec<f32> = ranges.iter().rev().copied().collect();
    let cw = RangeScan {
        angle_min: base.angle_min + (ranges.len() - 1) as f32 * base.angle_increment,
        angle_increment: -base.angle_increment,
        ranges: &rev,
        ..base
    };
    let pose = run(&db, &Scan::Ranges(cw)).expect("clockwise scan");
    assert!(
        (pose.x - truth.x).abs() < 0.15 && (pose.y - truth.y).abs() < 0.15,
        "{pose:?}"
    );
}

#[test]
fn localize_rejects_a_scratch_too_small() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (_, ranges) = truth_and_scan();
    let scan = ranges_scan(&ranges);
    let needed = scratch_size(db.params(), ranges.len());
    assert_eq!(
        localize(&db, &scan, &mut []).map(|l| l.pose),
        Err(LocalizeError::ScratchTooSmall { needed, got: 0 })
    );
    for len in [1, 64, needed / 2, needed - 16, needed - 1] {
        let mut scratch = vec![0u8; len];
        match localize(&db, &scan, &mut scratch) {
            Err(LocalizeError::ScratchTooSmall { needed: n, got }) => {
                assert_eq!((n, got), (needed, len))
            }
            Err(LocalizeError::TooManyBeams { beams, capacity }) => {
                assert_eq!(beams, ranges.len());
                assert!(capacity < beams);
            }
            other => panic!("{len} bytes: {:?}", other.map(|l| l.pose)),
        }
    }
}

#[test]
fn localize_scratch_one_byte_short_reports_the_beams_it_can_take() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (_, ranges) = truth_and_scan();
    let needed = scratch_size(db.params(), ranges.len());
    let mut scratch = vec![0u8; needed - 1];
    // Documented: a scratch that can take some scan, but not this many beams,
    // reports how many it can take.
    assert_eq!(
        localize(&db, &ranges_scan(&ranges), &mut scratch).map(|l| l.pose),
        Err(LocalizeError::TooManyBeams {
            beams: ranges.len(),
            capacity: ranges.len() - 1
        })
    );
    assert!(scratch_size(db.params(), ranges.len() - 1) < needed);
}

#[test]
fn localize_works_in_a_misaligned_scratch() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (_, ranges) = truth_and_scan();
    let scan = ranges_scan(&ranges);
    let needed = scratch_size(db.params(), ranges.len());
    let mut aligned = vec![0u64; needed.div_ceil(8) + 1];
    let want = {
        use zerocopy::IntoBytes;
        let l = localize(&db, &scan, &mut aligned.as_mut_bytes()[..needed]).expect("aligned");
        (l.pose, l.site, l.candidates.to_vec())
    };
    let mut buf = vec![0u8; needed + 16];
    let got = localize(&db, &scan, &mut buf[1..]).expect("misaligned scratch");
    assert_eq!((got.pose, got.site, got.candidates.to_vec()), want);
    for off in 1..8 {
        // Exactly `needed` bytes, at every misalignment.
        let mut raw = vec![0u64; needed.div_ceil(8) + 2];
        use zerocopy::IntoBytes;
        let s = &mut raw.as_mut_bytes()[off..off + needed];
        let got = localize(&db, &scan, s).expect("misaligned, exact size");
        assert_eq!(
            (got.pose, got.site, got.candidates.to_vec()),
            want,
            "offset {off}"
        );
    }
}

// ---------------------------------------------------------------------------
// verify: free-space check and short-beam weight
// ---------------------------------------------------------------------------

/// `n` beams 0.001 rad apart, starting along the grid's +u axis from the
/// centre of cell (u, v), all with range `range`, scored against the
/// fixture database's verifier.
fn beams(db: &RefDb<&[u8]>, cell: [f32; 2], range: f32, n: usize) -> crate::verify::Vicinity {
    let grid = db.grid();
    let frame = db.frame();
    let p = frame.to_map(cell);
    let sensor = Pose2::new(p[0], p[1], frame.origin.theta);
    crate::verify::Verifier::new(db, &grid, fixture::RANGE_MAX)
        .score(&sensor, (0..n).map(|k| (k as f32 * 0.001, range)))
}

#[test]
fn verifier_tells_a_wall_seen_through_from_long_beams_ending_on_a_surface() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let p = db.params();
    assert!(
        p.verify.through_max > 0.0 && p.verify.through_run == 3,
        "the check is on by default"
    );
    let run = p.verify.through_run as usize;
    // From (10.5, 15.5) the inner wall (u = 20) is 0.95 m away along +u.
    let start = [10.5, 15.5];
    let hit = beams(&db, start, 0.95, run);
    assert_eq!((hit.short, hit.long, hit.through), (0, 0, 0), "{hit:?}");
    assert!(hit.score > 4.4 * run as f32, "{hit:?}");
    // 0.3 m past the wall: long, but less than through_excess (0.5 m) past it.
    let long = beams(&db, start, 1.25, run);
    assert_eq!((long.long, long.through), (run as u32, 0), "{long:?}");
    // 1.5 m past the wall, ending in free space 0.35 m from the nearest
    // surface: through the wall, once the run is long enough.
    let through = beams(&db, start, 2.45, run);
    assert_eq!(
        (through.long, through.through),
        (run as u32, run as u32),
        "{through:?}"
    );
    assert!(!through.free_space_ok(0.5) && through.free_space_ok(1.0));
    assert!(through.free_space_ok(0.0), "0 turns the check off");
    let isolated = beams(&db, start, 2.45, run - 1);
    assert_eq!(
        isolated.through, 0,
        "a shorter run is a spurious return: {isolated:?}"
    );
    let longer = beams(&db, start, 2.45, run + 2);
    assert_eq!(longer.through, run as u32 + 2, "{longer:?}");
    // Past the wall all the way to the far border: long by metres, but the
    // end points lie on a surface of the map, so not through.
    let border = beams(&db, start, 4.85, run);
    assert_eq!((border.long, border.through), (run as u32, 0), "{border:?}");
    // Far beyond the map: through (outside the grid is away from surfaces).
    let outside = beams(&db, start, 9.0, run);
    assert_eq!(outside.through, run as u32, "{outside:?}");
    // Short: in front of the wall.
    let short = beams(&db, start, 0.5, run);
    assert_eq!((short.short, short.long, short.through), (run as u32, 0, 0));
}

#[test]
fn evidence_takes_a_share_of_a_hit_per_short_beam() {
    let v = crate::verify::Vicinity {
        score: 90.0,
        threshold: 45.0,
        pairs: 20,
        short: 4,
        long: 0,
        through: 0,
        occluded: 0,
    };
    assert_eq!(v.evidence(0.0, 0.0), 90.0);
    assert_eq!(v.evidence(0.5, 0.0), 90.0 - 4.0 * 4.5 * 0.5);
    assert_eq!(v.evidence(1.0, 0.0), 90.0 - 4.0 * 4.5);
    // The 16 beams that are not short fit at 90 / (4.5 x 16) = 1.25 >= 0.9:
    // the short beams are occlusions and cost nothing.
    assert_eq!(v.evidence(1.0, 0.9), 90.0);
    let loose = crate::verify::Vicinity { score: 45.0, ..v };
    assert_eq!(loose.evidence(1.0, 0.9), 45.0 - 4.0 * 4.5);
    // Short beams of a person in front of a fitting wall cost nothing.
    let hidden = crate::verify::Vicinity {
        occluded: 3,
        ..loose
    };
    assert_eq!(hidden.evidence(1.0, 0.9), 45.0 - 4.5);
}

/// A `n x n` grid with its column `wall` occupied, at `res` m cells: its
/// occupancy as [`crate::raycast::BitGrid`] words, its distance map as the
/// compiler encodes it ([`crate::refine::tests::encode_walls`]), and its
/// frame.
fn walled_grid(n: u32, wall: u32, res: f32) -> (Vec<u32>, Vec<u8>, MapFrame) {
    let mut words = vec![0u32; crate::raycast::BitGrid::words_for(n, n)];
    for cy in 0..n {
        let i = (cy * n + wall) as usize;
        words[i / 32] |= 1 << (i % 32);
    }
    let dist = crate::refine::tests::encode_walls(n as i32, n as i32, |x, _| x == wall as i32);
    let frame = MapFrame {
        resolution: res,
        origin: Pose2::new(0.0, 0.0, 0.0),
    };
    (words, dist, frame)
}

#[test]
fn on_a_coarse_map_a_grazing_beam_ending_inside_the_wall_cell_fits() {
    use crate::verify::{coarse_reach, Verifier, REFERENCE_CELL};
    assert_eq!(coarse_reach(REFERENCE_CELL), 0.0);
    assert_eq!(coarse_reach(0.025), 0.0);
    assert!((coarse_reach(0.1) - 0.4).abs() < 1e-6);
    let (n, wall) = (120u32, 30u32);
    // The sensor 5.5 cells before the wall's face; one beam `g` rad off the
    // face, ending `past_face` m behind it (perpendicular).
    let d_face = 5.5f32;
    let beam = |res: f32, g: f32, past_face: f32| {
        let (words, dist, frame) = walled_grid(n, wall, res);
        let grid = crate::raycast::BitGrid::new(n, n, &words).unwrap();
        let dm = crate::refine::DistMap::new(n, n, &dist, frame);
        let verifier = Verifier {
            grid: &grid,
            frame,
            dist: Some(dm),
            open: Some(dm),
            range_max: 30.0,
            sigma_d: 0.05,
            accept_ratio: 0.5,
            through_excess: 0.5,
            through_run: 3,
        };
        let sensor = Pose2::new((wall as f32 - d_face) * res, 3.5 * res, 0.0);
        let dir = [libm::sinf(g), libm::cosf(g)];
        let range = (d_face * res + past_face) / libm::sinf(g);
        verifier.score_dirs(&sensor, core::iter::once((dir, range)))
    };
    let deg = |d: f32| d.to_radians();
    // The surface in the middle of the wall's cells (a map of coarse cells
    // marks the cell a surface runs through), met 10 degrees off: at 0.1 m
    // cells the beam runs 0.29 m past the cast and fits by its end point.
    let v = beam(0.1, deg(10.0), 0.05);
    assert_eq!((v.long, v.short), (0, 0), "{v:?}");
    assert!(v.score > 3.9, "{v:?}");
    // The same 0.29 m past the cast on a map of 0.05 m cells (the surface
    // at the back of the wall's cell): no reach there, a long beam.
    let v = beam(0.05, deg(10.0), 0.05);
    assert_eq!((v.long, v.score), (1, 0.0), "{v:?}");
    // Within the reach (0.35 m past the face) but ending in the free space
    // 0.2 m behind the wall: long.
    let v = beam(0.1, deg(60.0), 0.3);
    assert_eq!((v.long, v.score), (1, 0.0), "{v:?}");
    // Ending in the wall's cell, but 0.57 m past the cast (5 degrees off):
    // beyond the reach, long.
    let v = beam(0.1, deg(5.0), 0.05);
    assert_eq!((v.long, v.score), (1, 0.0), "{v:?}");
}

#[test]
fn short_beams_of_a_person_before_a_fitting_wall_are_occluded() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let grid = db.grid();
    let frame = db.frame();
    let p = frame.to_map([10.5, 15.5]);
    let sensor = Pose2::new(p[0], p[1], frame.origin.theta);
    let verifier = crate::verify::Verifier::new(&db, &grid, fixture::RANGE_MAX);
    // From (10.5, 15.5) the inner wall is 0.95 m away along +u; `ranges`
    // are the beams in scan order, `fg` marks the foreground ones.
    let score = |ranges: &[f32], fg: &[bool]| {
        let beams = ranges.iter().zip(fg).enumerate().map(|(k, (&r, &f))| {
            let a = k as f32 * 0.001;
            ([a.cos(), a.sin()], r, f)
        });
        verifier.score_marked(&sensor, beams)
    };
    let marks = [false, false, true, true, true, false, false];
    // A person 0.5 m away between beams that fit the wall.
    let person = [0.95, 0.95, 0.5, 0.5, 0.5, 0.95, 0.95];
    let v = score(&person, &marks);
    assert_eq!((v.short, v.occluded), (3, 3), "{v:?}");
    assert!(v.evidence(1.0, 2.0) > v.score - 0.1, "{v:?}");
    // The same short beams not marked as foreground: charged.
    let v = score(&person, &[false; 7]);
    assert_eq!((v.short, v.occluded), (3, 0), "{v:?}");
    // Beside it, the beams do not fit (0.3 m past the wall): a wrong pose.
    let misfit = [1.25, 1.25, 0.5, 0.5, 0.5, 1.25, 1.25];
    let v = score(&misfit, &marks);
    assert_eq!((v.short, v.occluded), (3, 0), "{v:?}");
    // One side fits, the other does not: charged.
    let one_side = [0.95, 0.95, 0.5, 0.5, 0.5, 1.25, 1.25];
    assert_eq!(score(&one_side, &marks).occluded, 0);
    // At the end of the scan there is no beam after it: charged.
    let at_end = [0.95, 0.95, 0.95, 0.95, 0.5, 0.5, 0.5];
    let end_marks = [false, false, false, false, true, true, true];
    assert_eq!(score(&at_end, &end_marks).occluded, 0);
    // Beams without a return between the person and the wall are skipped.
    let gap = [0.95, f32::NAN, 0.5, 0.5, 0.5, f32::NAN, 0.95];
    assert_eq!(score(&gap, &marks).occluded, 3);
    // `score_dirs` marks nothing.
    let plain = person.iter().enumerate().map(|(k, &r)| {
        let a = k as f32 * 0.001;
        ([a.cos(), a.sin()], r)
    });
    assert_eq!(verifier.score_dirs(&sensor, plain).occluded, 0);
}

#[test]
fn localize_does_not_accept_a_pose_that_sees_through_walls() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (_, mut ranges) = truth_and_scan();
    let clean = {
        let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
        let l = localize(&db, &ranges_scan(&ranges), &mut scratch).unwrap();
        (l.accepted, l.free_space_ok, l.through_beams)
    };
    assert_eq!(clean, (true, true, 0));
    // Runs of 4 beams in every 16 return 1 m beyond the surface they
    // should have hit.
    for (k, r) in ranges.iter_mut().enumerate() {
        if k % 16 < 4 {
            *r += 1.0;
        }
    }
    let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
    let l = localize(&db, &ranges_scan(&ranges), &mut scratch).unwrap();
    assert!(!l.accepted && !l.free_space_ok, "{l:?}");
    assert!(l.through_beams as f32 > db.params().verify.through_max * l.valid_points as f32);
    assert!(l
        .candidates
        .iter()
        .all(|c| c.free_space_ok == 0 || c.vicinity <= c.vicinity_threshold));
}

#[test]
fn localize_rejects_range_min_not_below_range_max() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (_, ranges) = truth_and_scan();
    for (lo, hi) in [(5.0, 5.0), (6.0, 5.0)] {
        let scan = Scan::Ranges(RangeScan {
            angle_min: -PI,
            angle_increment: 2.0 * PI / ranges.len() as f32,
            range_min: lo,
            range_max: hi,
            ranges: &ranges,
        });
        assert!(
            matches!(run(&db, &scan), Err(LocalizeError::BadScan(_))),
            "{lo} {hi}"
        );
    }
}

/// Localizes the fixture's clean scan ([`truth_and_scan`]) with `prior`:
/// the pose, whether it is accepted, the candidates examined.
fn fixture_with_prior(prior: Option<crate::Prior>) -> Result<(Pose2, bool, usize), LocalizeError> {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (_, ranges) = truth_and_scan();
    let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
    crate::localize_with_prior(&db, &ranges_scan(&ranges), &mut scratch, prior)
        .map(|l| (l.pose, l.accepted, l.candidates.len()))
}

#[test]
fn a_prior_limits_the_answer_to_its_region_and_heading_window() {
    use crate::Prior;
    let (truth, _) = truth_and_scan();
    let run = fixture_with_prior;
    let (free, ..) = run(None).unwrap();
    // Around the truth, the right heading: the same answer.
    let near = Prior::circle(truth.x + 0.5, truth.y, 1.5).with_heading(truth.theta, 0.3);
    let (p, accepted, _) = run(Some(near)).unwrap();
    assert!(accepted && (p.x - free.x).abs() < 1e-4 && (p.y - free.y).abs() < 1e-4);
    // A heading window that excludes the truth: no answer is the truth.
    let wrong_heading = Prior::NONE.with_heading(truth.theta + 2.0, 0.3);
    match run(Some(wrong_heading)) {
        Ok((p, ..)) => assert!(wrong_heading.allows(&p), "{p:?} outside the window"),
        Err(e) => assert!(matches!(e, LocalizeError::NoMatch { .. }), "{e}"),
    }
    // A region far from every site ranks none.
    let nowhere = Prior::circle(1000.0, 1000.0, 1.0);
    assert!(matches!(
        run(Some(nowhere)),
        Err(LocalizeError::NoMatch { candidates: 0 })
    ));
    // Nonsense is refused.
    let bad = Prior::circle(0.0, 0.0, -1.0);
    assert_eq!(run(Some(bad)).unwrap_err(), LocalizeError::BadPrior);
}

#[test]
fn a_polygon_prior_keeps_the_answer_inside_it_and_excludes_it_elsewhere() {
    use crate::Prior;
    let (truth, _) = truth_and_scan();
    let run = fixture_with_prior;
    let (free, ..) = run(None).unwrap();
    let (x, y) = (truth.x, truth.y);
    // A concave L around the truth (its notch on the far side): the same
    // answer.
    let ell = [
        [x - 1.0, y - 1.0],
        [x + 2.0, y - 1.0],
        [x + 2.0, y + 0.5],
        [x + 0.5, y + 0.5],
        [x + 0.5, y + 2.0],
        [x - 1.0, y + 2.0],
    ];
    let around = Prior::polygon(&ell).unwrap();
    let (p, accepted, _) = run(Some(around)).unwrap();
    assert!(accepted && (p.x - free.x).abs() < 1e-4 && (p.y - free.y).abs() < 1e-4);
    // The same L moved so the truth sits in its notch: whatever is
    // answered lies inside the L, so it is not the truth.
    let notch = ell.map(|v| [v[0] - 1.5, v[1] - 1.5]);
    let elsewhere = Prior::polygon(&notch).unwrap();
    assert!(!elsewhere.allows(&truth));
    match run(Some(elsewhere)) {
        Ok((p, ..)) => {
            assert!(elsewhere.allows(&p), "{p:?} outside the polygon");
            assert!((p.x - x).hypot(p.y - y) > 0.2, "{p:?} is the truth");
        }
        Err(e) => assert!(matches!(e, LocalizeError::NoMatch { .. }), "{e}"),
    }
    // Far from every site: no site is ranked.
    let far = Prior::polygon(&[[1000.0, 1000.0], [1001.0, 1000.0], [1000.0, 1001.0]]).unwrap();
    assert!(matches!(
        run(Some(far)),
        Err(LocalizeError::NoMatch { candidates: 0 })
    ));
    // A circle and a polygon at once is refused.
    let both = Prior {
        radius: 2.0,
        ..around
    };
    assert_eq!(run(Some(both)).unwrap_err(), LocalizeError::BadPrior);
}

/// Ranges of the fixture seen from `truth` by a scanner of `n` beams that
/// turns by `skew` (rad) over its sweep, `truth` being the pose at the
/// sweep's middle.
fn turning_scan(truth: Pose2, n: usize, skew: f32) -> Vec<f32> {
    let inc = 2.0 * PI / n as f32;
    fixture::scan_along(truth, n, |k| {
        truth.theta - PI + k as f32 * inc + skew * crate::refine::sweep_fraction(k, n)
    })
}

/// A scan taken while turning: the answer is refitted with the turn (its
/// skew) and lands on the pose at the middle of the sweep; a still scan
/// keeps a rigid fit.
#[test]
fn a_scan_taken_while_turning_is_fitted_with_its_skew() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (truth, still) = truth_and_scan();
    let n = still.len();
    let skew = 0.1f32;
    let turning = turning_scan(truth, n, skew);
    let mut scratch = vec![0u8; scratch_size(db.params(), n)];
    let l = localize(&db, &ranges_scan(&turning), &mut scratch).unwrap();
    assert!((l.skew - skew).abs() < 0.02, "skew {}", l.skew);
    let err = (l.pose.x - truth.x).hypot(l.pose.y - truth.y);
    assert!(
        err < 0.05 && angle_diff(l.pose.theta, truth.theta) < 0.02,
        "{:?}",
        l.pose
    );
    assert!(l.accepted, "confidence {}", l.confidence);
    let l = localize(&db, &ranges_scan(&still), &mut scratch).unwrap();
    assert_eq!(l.skew, 0.0);
}

/// With range noise (5 mm + 0.5% of the range, about N(0, 1) from twelve
/// uniforms) the noise stays in both the rigid and the skewed fit's cost:
/// a turn of 0.1 rad leaves about 0.54 of the rigid cost in this small
/// room, and is taken ([`crate::localize::SKEW_COST_RATIO`]; at half, it
/// was not), while a still scan with the same noise (about 0.95) keeps a
/// rigid fit or a skew too small to matter (under 0.01 rad: the refit can
/// also take up what the rigid refinement's last steps left).
#[test]
fn a_noisy_scan_taken_while_turning_is_fitted_with_its_skew() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (truth, still) = truth_and_scan();
    let n = still.len();
    let mut rng = Prng::new(16);
    let mut noisy = |ranges: Vec<f32>| -> Vec<f32> {
        ranges
            .into_iter()
            .map(|r| {
                let z: f32 = (0..12).map(|_| rng.range(0.0, 1.0)).sum::<f32>() - 6.0;
                r + z * (0.005 + 0.005 * r)
            })
            .collect()
    };
    let mut scratch = vec![0u8; scratch_size(db.params(), n)];
    for skew in [0.1f32, -0.12] {
        let turning = noisy(turning_scan(truth, n, skew));
        let l = localize(&db, &ranges_scan(&turning), &mut scratch).unwrap();
        assert!((l.skew - skew).abs() < 0.03, "skew {} for {skew}", l.skew);
        assert!(
            (l.pose.x - truth.x).hypot(l.pose.y - truth.y) < 0.1,
            "{:?}",
            l.pose
        );
    }
    for _ in 0..3 {
        let still = noisy(still.clone());
        let l = localize(&db, &ranges_scan(&still), &mut scratch).unwrap();
        assert!(l.skew.abs() < 0.01, "skew {}", l.skew);
    }
}

#[test]
fn only_a_pose_that_explains_part_of_the_scan_is_refined() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (truth, ranges) = truth_and_scan();
    let scan = ranges_scan(&ranges);
    let mut scratch = vec![0u8; scratch_size(db.params(), scan.len())];
    let mut loc = crate::Localizer::new(&db, &mut scratch, scan.len()).unwrap();
    loc.prepare(&scan).unwrap();
    let max = |v: &crate::verify::Vicinity| crate::verify::HIT_SCORE * v.pairs as f32;
    let p = *db.params();
    let evidence =
        |v: &crate::verify::Vicinity| v.evidence(p.verify.short_weight, p.verify.occlusion_fit);
    // A few centimetres and a degree off: refined towards the truth.
    let near = Pose2::new(truth.x + 0.04, truth.y - 0.03, truth.theta + 0.02);
    let before = loc.verify_pose(&near);
    assert!(evidence(&before) >= crate::localize::REFINE_GATE * max(&before));
    let (refined, v) = loc.refine_if_promising(near);
    assert_ne!(refined, near);
    let err = |q: &Pose2| (q.x - truth.x).hypot(q.y - truth.y);
    assert!(err(&refined) < err(&near), "{refined:?}");
    assert_eq!(v, loc.verify_pose(&refined));
    assert!(evidence(&v) > evidence(&before));
    // Turned half a turn, the scan fits almost nowhere: kept as it is.
    let wrong = Pose2::new(truth.x, truth.y, truth.theta + PI);
    let w = loc.verify_pose(&wrong);
    assert!(
        evidence(&w) < crate::localize::REFINE_GATE * max(&w),
        "{w:?}"
    );
    let (kept, vk) = loc.refine_if_promising(wrong);
    assert_eq!(kept, wrong);
    assert_eq!(vk, w);
}

/// A crowd in front of the walls: beams that end short of the map cost
/// the evidence, so a nearly right SSM pose of a crowded scan can have
/// almost none. In a crowded scan the gate also reads the vicinity score
/// M, which they do not lower, and the pose is refined.
#[test]
fn a_crowded_scan_s_nearly_right_pose_is_refined() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (truth, mut ranges) = truth_and_scan();
    // People: every other run of 20 beams (20 degrees) ends 0.7 m away,
    // about 0.25 m across, in front of the walls.
    for (k, r) in ranges.iter_mut().enumerate() {
        if (k / 20) % 2 == 0 && r.is_finite() {
            *r = r.min(0.7);
        }
    }
    let scan = ranges_scan(&ranges);
    let mut scratch = vec![0u8; scratch_size(db.params(), scan.len())];
    let mut loc = crate::Localizer::new(&db, &mut scratch, scan.len()).unwrap();
    loc.prepare(&scan).unwrap();
    assert!(loc.crowded());
    let p = *db.params();
    let max = |v: &crate::verify::Vicinity| crate::verify::HIT_SCORE * v.pairs as f32;
    let evidence =
        |v: &crate::verify::Vicinity| v.evidence(p.verify.short_weight, p.verify.occlusion_fit);
    let near = Pose2::new(truth.x + 0.12, truth.y - 0.09, truth.theta + 0.05);
    let before = loc.verify_pose(&near);
    assert!(
        evidence(&before) < crate::localize::REFINE_GATE * max(&before),
        "{before:?}"
    );
    assert!(before.score >= crate::localize::CROWDED_REFINE_GATE * max(&before));
    let (refined, v) = loc.refine_if_promising(near);
    let err = |q: &Pose2| (q.x - truth.x).hypot(q.y - truth.y);
    assert!(err(&refined) < 0.5 * err(&near), "{refined:?}");
    assert!(angle_diff(refined.theta, truth.theta) < 0.01, "{refined:?}");
    assert!(evidence(&v) > evidence(&before), "{v:?} {before:?}");
}

/// Each group reads its fields of the params record and writes them back:
/// a record whose every 4-byte field holds a distinct non-zero value
/// survives the trip, so no field is left out of a group's `write_record`.
#[test]
fn params_record_round_trips_every_field() {
    use crate::format::ParamsRecord;
    use zerocopy::{FromBytes, IntoBytes};
    let words: Vec<u32> = (1..=(core::mem::size_of::<ParamsRecord>() / 4) as u32).collect();
    for selection in [0u32, 1] {
        let mut r = ParamsRecord::read_from_bytes(words.as_bytes()).unwrap();
        r.selection = selection.into();
        let p = Params::from_record(&r).unwrap();
        assert_eq!(
            p.to_record().as_bytes(),
            r.as_bytes(),
            "selection {selection}"
        );
    }
    let d = Params::defaults(362, 30.0);
    assert_eq!(Params::from_record(&d.to_record()), Ok(d));
}

// ---------------------------------------------------------------------------
// Foreground surfaces and the background pass
// ---------------------------------------------------------------------------

/// A closed room of radius `wall` m around the sensor (`n` beams over the
/// full turn), with the beams `from..to` stopped at `near` m by something
/// standing in front of the wall.
fn room_with_blocker(n: usize, wall: f32, near: f32, from: usize, to: usize) -> Vec<[f32; 2]> {
    (0..n)
        .map(|k| {
            let a = -PI + k as f32 * 2.0 * PI / n as f32;
            let r = if (from..to).contains(&k) { near } else { wall };
            [r * a.cos(), r * a.sin()]
        })
        .collect()
}

fn prepared_ranges(dense: &[[f32; 2]], wrap: bool, foreground: f32) -> Vec<f32> {
    let p = fixture::params();
    let m = p.prep.max_points as usize;
    let (mut pts, mut tan) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
    let n = prep::prepare_with(dense, wrap, &p, foreground, &mut pts, &mut tan);
    pts[..n].iter().map(|q| q[0].hypot(q[1])).collect()
}

#[test]
fn foreground_surfaces_are_left_out_and_walls_kept() {
    // A person 1 m away (0.3 m across) in front of a wall 4 m away.
    let person = room_with_blocker(360, 4.0, 1.0, 100, 117);
    let all = prepared_ranges(&person, true, 0.0);
    let bg = prepared_ranges(&person, true, 1.0);
    assert!(all.iter().any(|&r| r < 1.5), "the person is prepared");
    assert!(
        bg.iter().all(|&r| r > 3.9),
        "the person is left out: {bg:?}"
    );
    // The wall is kept whole: the points lost are the person's only.
    let walls = |v: &[f32]| v.iter().filter(|&&r| r > 3.9).count();
    assert!(
        walls(&bg) + 1 >= walls(&all),
        "{} vs {}",
        walls(&bg),
        walls(&all)
    );
    // 0 leaves everything in: `prepare` itself.
    let p = fixture::params();
    let m = p.prep.max_points as usize;
    let (mut pts, mut tan) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
    assert_eq!(
        prep::prepare(&person, true, &p, &mut pts, &mut tan),
        all.len()
    );
    // Wider than the limit (1.3 m across): kept.
    let wide = room_with_blocker(360, 4.0, 1.0, 100, 176);
    assert!(prepared_ranges(&wide, true, 1.0).iter().any(|&r| r < 1.5));
    // A recess (the neighbours are nearer, not farther): kept.
    let recess = room_with_blocker(360, 1.0, 4.0, 100, 104);
    assert!(prepared_ranges(&recess, true, 1.0).iter().any(|&r| r > 3.9));
    // At the edge of a partial view the far side is unknown: kept.
    let edge: Vec<[f32; 2]> = person[100..200].to_vec();
    assert!(prepared_ranges(&edge, false, 1.0).iter().any(|&r| r < 1.5));
    // The same person in the middle of a partial view: left out.
    let middle: Vec<[f32; 2]> = person[60..200].to_vec();
    assert!(prepared_ranges(&middle, false, 1.0)
        .iter()
        .all(|&r| r > 3.9));
}

#[test]
fn foreground_mask_marks_the_person_and_nothing_else() {
    let p = fixture::params();
    let jd = p.prep.jump_distance;
    let person = room_with_blocker(360, 4.0, 1.0, 100, 117);
    let mut mask = vec![9u8; 360];
    assert_eq!(prep::foreground_mask(&person, true, jd, 1.0, &mut mask), 17);
    assert!(mask
        .iter()
        .enumerate()
        .all(|(k, &m)| m == u8::from((100..117).contains(&k))));
    // Width 0 marks nothing (and clears what was there).
    assert_eq!(prep::foreground_mask(&person, true, jd, 0.0, &mut mask), 0);
    assert!(mask.iter().all(|&m| m == 0));
    // Across the wrap of a full turn: marked on both ends.
    let across = room_with_blocker(360, 4.0, 1.0, 0, 9);
    let mut rotated = across[5..].to_vec();
    rotated.extend_from_slice(&across[..5]);
    assert_eq!(prep::foreground_mask(&rotated, true, jd, 1.0, &mut mask), 9);
    assert!(mask[355..].iter().all(|&m| m == 1) && mask[..4].iter().all(|&m| m == 1));
    assert_eq!(mask.iter().filter(|&&m| m == 1).count(), 9);
    // Too wide, a recess, or at the edge of a partial view: not foreground.
    let wide = room_with_blocker(360, 4.0, 1.0, 100, 176);
    assert_eq!(prep::foreground_mask(&wide, true, jd, 1.0, &mut mask), 0);
    let recess = room_with_blocker(360, 1.0, 4.0, 100, 104);
    assert_eq!(prep::foreground_mask(&recess, true, jd, 1.0, &mut mask), 0);
    let edge: Vec<[f32; 2]> = person[100..200].to_vec();
    assert_eq!(prep::foreground_mask(&edge, false, jd, 1.0, &mut mask), 0);
    // A single return in front of the wall is foreground too.
    let single = room_with_blocker(360, 4.0, 1.0, 50, 51);
    assert_eq!(prep::foreground_mask(&single, true, jd, 1.0, &mut mask), 1);
    assert_eq!(mask[50], 1);
}

/// The tiny database ranking `nc` candidates at a time (N_C = `nc`).
fn fixed_candidates_db(nc: u32) -> Aligned {
    use crate::format::SectionKind;
    use zerocopy::IntoBytes;
    let mut p = fixture::params();
    p.coarse.nc_min = nc;
    p.coarse.nc_max = nc;
    let sections: Vec<_> = fixture::sections()
        .into_iter()
        .map(|(k, b)| match k {
            SectionKind::Params => (k, p.to_record().as_bytes().to_vec()),
            _ => (k, b),
        })
        .collect();
    Aligned::new(&fixture::encode(&sections))
}

/// The sites the background pass should add after `first`: the N_C best
/// by the histogram without foreground (scored site by site here), less
/// those in `first`, in rank order.
fn expected_background(db: &RefDb<&[u8]>, ranges: &[f32], first: &[u32]) -> Vec<u32> {
    let take = db.params().coarse.nc_max as usize;
    expected_more(db, ranges, first, coarse::FOREGROUND_WIDTH, take)
}

/// The `take` best sites by the histogram of the scan without foreground
/// surfaces `foreground` m across (scored site by site here), less those in
/// `first`, in rank order.
fn expected_more(
    db: &RefDb<&[u8]>,
    ranges: &[f32],
    first: &[u32],
    foreground: f32,
    take: usize,
) -> Vec<u32> {
    let p = db.params();
    let n = ranges.len();
    let inc = 2.0 * PI / n as f32;
    let dense: Vec<[f32; 2]> = ranges
        .iter()
        .enumerate()
        .map(|(k, &r)| {
            let a = -PI + k as f32 * inc;
            [r * a.cos(), r * a.sin()]
        })
        .collect();
    let m = p.prep.max_points as usize;
    let (mut pts, mut tan) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
    let mut h = vec![0f32; p.coarse.hist_cells().max(p.coarse.win_cells())];
    let (window, cells) = coarse::query_histogram_with(
        &dense,
        2.0 * PI,
        true,
        foreground,
        p,
        &mut pts,
        &mut tan,
        &mut h,
    );
    let mut scored: Vec<(u32, f32)> = (0..db.site_count())
        .map(|s| (s as u32, coarse::site_score(db, &h[..cells], window, s)))
        .collect();
    scored.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    scored
        .iter()
        .take(take)
        .map(|s| s.0)
        .filter(|s| !first.contains(s))
        .collect()
}

#[test]
fn only_a_rejected_answer_gets_the_background_pass_and_it_adds_new_sites() {
    let buf = fixed_candidates_db(1);
    let db = RefDb::new(buf.bytes()).expect("valid");
    // A clean scan: accepted from the first ranking's one candidate.
    let (truth, ranges) = truth_and_scan();
    let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
    let l = localize(&db, &ranges_scan(&ranges), &mut scratch).expect("localizes");
    assert!(l.accepted);
    assert_eq!(
        l.candidates.len(),
        1,
        "no background pass for an accepted answer"
    );
    assert!((l.pose.x - truth.x).abs() < 0.15 && (l.pose.y - truth.y).abs() < 0.15);

    // Scans whose first answer is rejected: nonsense, and the clean scan
    // with a person in front of the sensor hiding a sixth of it. The
    // background pass appends exactly the sites its own ranking gives that
    // the first did not.
    let buf = fixed_candidates_db(2);
    let db = RefDb::new(buf.bytes()).expect("valid");
    let mut rng = fixture::Prng::new(11);
    let junk: Vec<f32> = (0..362).map(|_| rng.range(0.5, 3.0)).collect();
    let mut person = ranges.clone();
    for r in &mut person[150..210] {
        *r = 0.4;
    }
    let (mut added, mut rejected) = (0, 0);
    for scan in [&junk, &person] {
        let mut scratch = vec![0u8; scratch_size(db.params(), scan.len())];
        let mut loc = crate::Localizer::new(&db, &mut scratch, scan.len()).unwrap();
        loc.prepare(&ranges_scan(scan)).unwrap();
        let nc = loc.rank();
        assert_eq!(nc, 2);
        let model = db.decision().expect("the fixture has a model");
        let mut search = crate::select::Search::new(db.params()).with_decision(model);
        for c in 0..nc {
            if loc.examine(c).is_some_and(|e| e.has_pose != 0) {
                search.record(loc.candidates(c + 1), loc.ranked()[c].gamma);
            }
        }
        let first: Vec<u32> = loc.ranked()[..nc].iter().map(|r| r.site).collect();
        if loc.answer_accepted(&search, nc) {
            continue;
        }
        rejected += 1;
        let total = loc.rank_background(nc);
        let new: Vec<u32> = loc.ranked()[nc..total].iter().map(|r| r.site).collect();
        assert_eq!(new, expected_background(&db, scan, &first));
        assert_eq!(
            &loc.ranked()[..nc]
                .iter()
                .map(|r| r.site)
                .collect::<Vec<_>>(),
            &first
        );
        added += new.len();
    }
    assert!(
        rejected > 0 && added > 0,
        "{rejected} rejected, {added} added"
    );
}

#[test]
fn a_crowded_rejected_scan_gets_the_deeper_pass_and_discounted_odds() {
    use crate::localize::{CROWDED_SHARE, DEEPER_MAX, DEEPER_ODDS};
    let buf = fixed_candidates_db(1);
    let db = RefDb::new(buf.bytes()).expect("valid");
    let model = db.decision().expect("the fixture has a model");
    let (_, clean) = truth_and_scan();
    // Five people close to the sensor, 12 beams each: a sixth of the scan
    // on foreground surfaces.
    let mut crowd = clean.clone();
    for k in 0..5 {
        for r in &mut crowd[20 + 70 * k..32 + 70 * k] {
            *r = 0.35;
        }
    }
    let mut deeper = 0;
    for (scan, crowded) in [(&clean, false), (&crowd, true)] {
        let mut scratch = vec![0u8; scratch_size(db.params(), scan.len())];
        let mut loc = crate::Localizer::new(&db, &mut scratch, scan.len()).unwrap();
        let prepared = loc.prepare(&ranges_scan(scan)).unwrap();
        assert_eq!(loc.crowded(), crowded, "{prepared:?}");
        assert_eq!(
            loc.crowded(),
            prepared.foreground as f32 >= CROWDED_SHARE * prepared.valid as f32
        );
        if !crowded {
            continue;
        }
        let nc = loc.rank();
        let mut search = crate::select::Search::new(db.params()).with_decision(model);
        let run = |loc: &mut crate::Localizer<'_, '_, &[u8]>,
                   search: &mut crate::select::Search,
                   from: usize,
                   to: usize| {
            for c in from..to {
                if loc.examine(c).is_some_and(|e| e.has_pose != 0) {
                    search.record(loc.candidates(c + 1), loc.ranked()[c].gamma);
                }
            }
        };
        run(&mut loc, &mut search, 0, nc);
        let total = loc.rank_background(nc);
        run(&mut loc, &mut search, nc, total);
        let first: Vec<u32> = loc.ranked()[..total].iter().map(|r| r.site).collect();
        // The deeper pass appends the first ranking's next sites, in its
        // order, less those already examined.
        let end = loc.rank_deeper(total);
        let new: Vec<u32> = loc.ranked()[total..end].iter().map(|r| r.site).collect();
        let take = db.params().coarse.nc_max as usize + DEEPER_MAX;
        let mut expected = expected_more(&db, scan, &first, 0.0, take);
        expected.truncate(DEEPER_MAX);
        assert_eq!(new, expected);
        assert!(!new.is_empty(), "the fixture has sites left to add");
        run(&mut loc, &mut search, total, end);
        // After it, the answer's confidence has its odds divided by
        // DEEPER_ODDS, and accepted still means at least the threshold.
        if let Some(best) = search.best() {
            let cands = loc.candidates(end);
            let p = search.confidence(cands, best);
            let odds = p / (1.0 - p) / DEEPER_ODDS;
            let discounted = odds / (1.0 + odds);
            assert_eq!(
                loc.answer_accepted(&search, end),
                cands[best].has_pose != 0 && discounted >= model.threshold,
                "confidence {p}, discounted {discounted}"
            );
        }
        deeper += 1;
    }
    assert_eq!(deeper, 1);
}

#[test]
fn a_short_reach_scan_examines_every_candidate() {
    let buf = tiny_db();
    let db = RefDb::new(buf.bytes()).unwrap();
    let (truth, ranges) = truth_and_scan();
    let run_with = |range_max: f32| {
        let scan = Scan::Ranges(RangeScan {
            range_max,
            ..match ranges_scan(&ranges) {
                Scan::Ranges(r) => r,
                _ => unreachable!(),
            }
        });
        let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
        let mut loc = crate::Localizer::new(&db, &mut scratch, ranges.len()).unwrap();
        loc.prepare(&scan).unwrap();
        let short = loc.short_reach();
        let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
        let l = localize(&db, &scan, &mut scratch).unwrap();
        (
            short,
            l.pose,
            l.candidates.iter().filter(|c| c.has_pose != 0).count(),
        )
    };
    // The room is at most 7.2 m across: every wall is within both reaches.
    let (short, pose, posed) = run_with(fixture::RANGE_MAX);
    assert!(!short);
    assert!(
        posed < db.site_count(),
        "the full reach stops early: {posed}"
    );
    assert!((pose.x - truth.x).abs() < 0.15 && (pose.y - truth.y).abs() < 0.15);
    let reach = crate::localize::SHORT_REACH * fixture::RANGE_MAX - 0.1;
    let (short, pose, posed) = run_with(reach);
    assert!(short);
    assert!((pose.x - truth.x).abs() < 0.15 && (pose.y - truth.y).abs() < 0.15);
    // Every site (three) was matched: nothing stopped the search.
    assert_eq!(posed, db.site_count());
}

#[test]
fn short_reach_is_under_half_the_reference_reach() {
    use crate::localize::is_short_reach;
    // A TurtleBot3-like 3.5 m sensor on a database of 30 m reference scans.
    assert!(is_short_reach(3.5, 30.0));
    // Half the reference reach is not short; the real logs' 30-80 m never are.
    assert!(!is_short_reach(15.0, 30.0));
    assert!(!is_short_reach(80.0, 30.0));
    // A NaN reach is never short (the scan is rejected before that).
    assert!(!is_short_reach(f32::NAN, 30.0));
}
