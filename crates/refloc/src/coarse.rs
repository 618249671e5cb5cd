//! Coarse stage (paper section 4): correlation coefficient between the input
//! histogram and every site's (eq. 21-22, [`crate::rank::correlation`]), and
//! the adaptive candidate count.
//!
//! N_C rule (see `docs/ssm.md` for the measurements behind it): the sites are
//! ranked by gamma; every site whose gamma is within `nc_margin` of the best
//! is a candidate, with at least `nc_min` and at most `nc_max` candidates.
//!
//! Partial fields of view (see `docs/ssm.md`): a 180-degree scan's
//! histogram does not resemble a full circle's. The database stores, per
//! site, histograms of windows of its reference scan (widths `win_widths`,
//! `win_headings` headings each). A query narrower than a full turn is
//! cropped to the central part matching the widest stored width it covers,
//! and a site's score is its best correlation over that width's headings.

use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

pub use crate::rank::correlation;
use crate::rank::{self, Scored};

/// A ranked site: index and correlation.
#[derive(Clone, Copy, Debug, Default, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable)]
#[repr(C)]
pub struct Ranked {
    /// Site index.
    pub site: u32,
    /// Correlation coefficient gamma.
    pub gamma: f32,
}

/// Keeps the `top.len()` best sites in `top`, best first (ties: lower site
/// index first). Returns how many entries are filled.
pub fn rank_top<'h>(
    input: &[f32],
    sites: impl Iterator<Item = &'h [f32]>,
    top: &mut [Ranked],
) -> usize {
    rank_top_scores(sites.map(|h| correlation(input, h)), top)
}

/// As [`rank_top`], from each site's score (site index = position).
pub fn rank_top_scores(scores: impl Iterator<Item = f32>, top: &mut [Ranked]) -> usize {
    let mut n = 0;
    for (s, g) in scores.enumerate() {
        insert_unique(top, &mut n, s as u32, g);
    }
    n
}

impl Scored for Ranked {
    fn score(&self) -> f32 {
        self.gamma
    }
    fn key(&self) -> u32 {
        self.site
    }
}

/// Inserts `site` with score `g` into `top[..*n]` (best first, at most
/// `top.len()`), keeping one entry per site: a site already listed keeps the
/// better of its two scores.
fn insert_unique(top: &mut [Ranked], n: &mut usize, site: u32, g: f32) {
    rank::insert_unique(top, n, Ranked { site, gamma: g });
}

/// Ranks the sites for a query histogram computed by [`query_histogram`]
/// with `window`, keeping the `top.len()` best in `top` (best first).
/// Returns how many entries are filled.
///
/// With a coarse-search index for this view ([`crate::index`]), only the
/// sites in the leaves the index search keeps are scored (sublinear in the
/// sites; a window view scores only the (site, heading) entries found, and
/// a site's score is the best of them); without one, every site is scored
/// by [`site_score`].
///
/// Not inlined, so profiles show the coarse ranking on its own.
#[inline(never)]
pub fn rank_sites<D: AsRef<[u8]>>(
    db: &crate::RefDb<D>,
    hist: &[f32],
    window: Option<usize>,
    top: &mut [Ranked],
) -> usize {
    rank_sites_where(db, hist, window, top, None)
}

/// As [`rank_sites`], limited to the sites a prior considers
/// ([`crate::prior::Prior::considers_site`]): with a region, only those
/// sites are scored (exhaustively: a region holds few of them).
pub fn rank_sites_where<D: AsRef<[u8]>>(
    db: &crate::RefDb<D>,
    hist: &[f32],
    window: Option<usize>,
    top: &mut [Ranked],
    prior: Option<&crate::prior::Prior>,
) -> usize {
    if let Some(p) = prior.filter(|p| p.has_region()) {
        let mut n = 0;
        for s in 0..db.site_count() {
            if p.considers_site(db.site_xy(s)) {
                insert_unique(top, &mut n, s as u32, site_score(db, hist, window, s));
            }
        }
        return n;
    }
    use crate::index::ViewKind;
    let kind = match window {
        None => ViewKind::Full,
        Some(w) => ViewKind::Window(w),
    };
    if let Some(index) = db.index() {
        let headings = (db.params().coarse.win_headings as usize).max(1);
        let mut n = 0usize;
        let searched = index.search(kind, hist, |e| {
            let e = e as usize;
            let (site, g) = match kind {
                ViewKind::Full => (e, correlation(hist, db.hist(e))),
                ViewKind::Window(w) => {
                    let (site, h) = (e / headings, e % headings);
                    (site, correlation(hist, db.window_hist(site, w, h)))
                }
            };
            insert_unique(top, &mut n, site as u32, g);
        });
        // `None`: the index has no tree for this view.
        if searched.is_some() {
            return n;
        }
    }
    rank_top_scores(
        (0..db.site_count()).map(|s| site_score(db, hist, window, s)),
        top,
    )
}

/// Applies the N_C rule to a ranked list (best first); returns N_C.
pub fn candidate_count(ranked: &[Ranked], nc_min: usize, nc_max: usize, margin: f32) -> usize {
    let Some(best) = ranked.first() else {
        return 0;
    };
    let within = ranked
        .iter()
        .take_while(|r| r.gamma >= best.gamma - margin)
        .count();
    within.clamp(nc_min, nc_max).min(ranked.len())
}

/// The stored window width a query covering `fov` radians is compared with:
/// `None` for a (nearly) full turn or a database without windows (then the
/// full histograms are used), else the index of the widest stored width not
/// larger than `fov` (the narrowest one when `fov` is narrower than all).
pub fn window_for(params: &crate::Params, fov: f32) -> Option<usize> {
    let n = params.coarse.win_count();
    if n == 0 || !(fov < 2.0 * core::f32::consts::PI * 0.97) {
        return None;
    }
    let mut pick = 0;
    for (i, w) in params.coarse.win_widths[..n].iter().enumerate() {
        if *w <= fov + 0.05 {
            pick = i;
        }
    }
    Some(pick)
}

/// Index range `[a, b)` of the central `width` radians of `n` evenly spaced
/// beams covering `fov` radians (the whole range when `width >= fov`).
pub fn crop_range(n: usize, fov: f32, width: f32) -> (usize, usize) {
    if !(fov > 0.0) || width >= fov || n == 0 {
        return (0, n);
    }
    let keep = ((n as f32) * width / fov) as usize;
    let keep = keep.clamp(1, n);
    let a = (n - keep) / 2;
    (a, a + keep)
}

/// Computes the coarse histogram of a query: `dense` are its beam-ordered
/// sensor-frame points (counter-clockwise), `fov` its coverage (rad), `wrap`
/// whether it is a closed full turn. `pts`/`tan` are working buffers (at
/// least `max_points` long); `out` receives the histogram (at least
/// `max(hist_cells, win_cells)` long). Returns the window used (see
/// [`window_for`]) and the number of histogram cells written.
pub fn query_histogram(
    dense: &[[f32; 2]],
    fov: f32,
    wrap: bool,
    params: &crate::Params,
    pts: &mut [[f32; 2]],
    tan: &mut [[f32; 2]],
    out: &mut [f32],
) -> (Option<usize>, usize) {
    query_histogram_with(dense, fov, wrap, 0.0, params, pts, tan, out)
}

/// Width (m) of the foreground surfaces the second ranking of a rejected
/// scan leaves out ([`query_histogram_with`], the localizer's background
/// pass): the size of a person, a box or a chair seen from one side. Not
/// fitted: in the eighth and ninth sessions' measurements (docs/results.md,
/// "A second ranking without the foreground") this was the one width tried.
pub const FOREGROUND_WIDTH: f32 = 1.0;

/// As [`query_histogram`], leaving the scan's foreground surfaces at most
/// `foreground` metres across out of the histogram
/// ([`crate::prep::prepare_with`]; 0 keeps everything). The sites'
/// histograms keep theirs: this is the query of a scan whose foreground
/// is likely not in the map (people, furniture).
#[allow(clippy::too_many_arguments)]
pub fn query_histogram_with(
    dense: &[[f32; 2]],
    fov: f32,
    wrap: bool,
    foreground: f32,
    params: &crate::Params,
    pts: &mut [[f32; 2]],
    tan: &mut [[f32; 2]],
    out: &mut [f32],
) -> (Option<usize>, usize) {
    match window_for(params, fov) {
        None => {
            let n = crate::prep::prepare_with(dense, wrap, params, foreground, pts, tan);
            crate::pgr::histogram(&pts[..n], &tan[..n], params, out);
            (None, params.coarse.hist_cells())
        }
        Some(w) => {
            let (a, b) = crop_range(dense.len(), fov, params.coarse.win_widths[w]);
            let n = crate::prep::prepare_with(&dense[a..b], false, params, foreground, pts, tan);
            let k = params.coarse.win_cells();
            crate::pgr::histogram_binned(
                &pts[..n],
                &tan[..n],
                params.coarse.win_rho_bins as usize,
                params.coarse.win_theta_bins as usize,
                params.coarse.hist_rho_max,
                out,
            );
            (Some(w), k)
        }
    }
}

/// A site's coarse score for a query histogram computed by
/// [`query_histogram`] with `window`: the correlation with the site's full
/// histogram, or its best correlation over the window's headings.
pub fn site_score<D: AsRef<[u8]>>(
    db: &crate::RefDb<D>,
    hist: &[f32],
    window: Option<usize>,
    site: usize,
) -> f32 {
    match window {
        None => correlation(hist, db.hist(site)),
        Some(w) => {
            let mut best = -1.0f32;
            for h in 0..db.params().coarse.win_headings as usize {
                let g = correlation(hist, db.window_hist(site, w, h));
                if g > best {
                    best = g;
                }
            }
            best
        }
    }
}
