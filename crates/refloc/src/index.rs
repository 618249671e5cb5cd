//! Coarse-search index: sublinear ranking of the sites on large maps.
//!
//! Exhaustive coarse ranking correlates the query histogram with every
//! site's (O(sites)); on a campus-sized map that dominates the query. A
//! database may carry an index ([`crate::format::SectionKind::Index`], built
//! by `mapc build` for maps with many sites): per *view* (the full
//! histograms, and each stored window width with its (site, heading)
//! histograms), a tree of clusters whose nodes hold the mean histogram of
//! their members.
//!
//! Search is a beam search: from the root, every child of the kept nodes is
//! scored by [`crate::rank::correlation`] with its centroid; the best
//! `beam` internal nodes go down a level, and the best `leaves` leaves met on
//! the way are kept. The entries of the kept leaves are then scored exactly,
//! as the exhaustive ranking would score them. Work per query is
//! O(beam x children x depth + leaves x leaf size) histograms, with the depth
//! logarithmic in the sites. The price is recall: a site in a leaf that was
//! not kept is not ranked (measured in `docs/scaling.md`).
//!
//! Everything here reads the validated section in place; [`validate`] runs
//! once in [`crate::RefDb::new`], after which [`Index::search`] cannot read
//! out of bounds or loop forever (every child index is greater than its
//! parent's, so each level moves strictly down the node array), and its work
//! is bounded by `INDEX_DEPTH_MAX` levels of `beam` x `INDEX_CHILDREN_MAX`
//! centroids whatever the file holds.

use zerocopy::FromBytes;

use crate::format::{
    IndexHeader, IndexNode, IndexView, INDEX_BEAM_MAX, INDEX_CHILDREN_MAX, INDEX_DEPTH_MAX,
    INDEX_LEAVES_MAX,
};
use crate::params::Params;

/// Which histograms a view indexes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewKind {
    /// The full (360-degree) histograms; entry = site.
    Full,
    /// Window width slot `w`; entry = `site * win_headings + heading`.
    Window(usize),
}

impl ViewKind {
    fn from_raw(v: u32, params: &Params) -> Option<ViewKind> {
        match v {
            0 => Some(ViewKind::Full),
            k if (k as usize) <= params.coarse.win_count() => {
                Some(ViewKind::Window(k as usize - 1))
            }
            _ => None,
        }
    }

    /// Histogram cells of this view's entries.
    pub fn cells(self, params: &Params) -> usize {
        match self {
            ViewKind::Full => params.coarse.hist_cells(),
            ViewKind::Window(_) => params.coarse.win_cells(),
        }
    }

    /// Entries of this view in a database of `sites` sites.
    fn entries_for(self, params: &Params, sites: usize) -> u64 {
        match self {
            ViewKind::Full => sites as u64,
            ViewKind::Window(_) => sites as u64 * params.coarse.win_headings as u64,
        }
    }
}

/// A validated view of the index section.
#[derive(Clone, Copy)]
pub struct Index<'a> {
    header: IndexHeader,
    views: &'a [IndexView],
    nodes: &'a [IndexNode],
    entries: &'a [u32],
    centroids: &'a [f32],
    params: &'a Params,
}

/// One view's slices.
#[derive(Clone, Copy)]
struct View<'a> {
    nodes: &'a [IndexNode],
    entries: &'a [u32],
    centroids: &'a [f32],
    cells: usize,
}

impl View<'_> {
    fn centroid(&self, node: usize) -> &[f32] {
        self.centroids
            .get(node * self.cells..(node + 1) * self.cells)
            .unwrap_or(&[])
    }
}

/// The parts of an index section: header, views, nodes, entries, centroids.
type Parts<'a> = (
    IndexHeader,
    &'a [IndexView],
    &'a [IndexNode],
    &'a [u32],
    &'a [f32],
);

/// Splits `bytes` into header, views, nodes, entries and centroids, with
/// every length exact. `Err` names the problem.
fn split<'a>(bytes: &'a [u8], params: &Params, sites: usize) -> Result<Parts<'a>, &'static str> {
    let (header, rest) =
        IndexHeader::read_from_prefix(bytes).map_err(|_| "index header truncated")?;
    let nv = header.view_count.get() as usize;
    if nv == 0 || nv > 1 + params.coarse.win_count() {
        return Err("index view count");
    }
    let beam = header.beam.get() as usize;
    let leaves = header.leaves.get() as usize;
    if !(1..=INDEX_BEAM_MAX).contains(&beam) || !(1..=INDEX_LEAVES_MAX).contains(&leaves) {
        return Err("index search widths");
    }
    let (views, rest) =
        <[IndexView]>::ref_from_prefix_with_elems(rest, nv).map_err(|_| "index views truncated")?;
    let (mut nodes_n, mut entries_n, mut cents_n) = (0u64, 0u64, 0u64);
    for (i, v) in views.iter().enumerate() {
        let kind = ViewKind::from_raw(v.kind.get(), params).ok_or("index view kind")?;
        if views[..i].iter().any(|o| o.kind.get() == v.kind.get()) {
            return Err("duplicate index view");
        }
        let n = v.node_count.get() as u64;
        if n == 0 {
            return Err("index view without nodes");
        }
        if v.entry_count.get() as u64 != kind.entries_for(params, sites) {
            return Err("index view entry count");
        }
        nodes_n += n;
        entries_n += v.entry_count.get() as u64;
        cents_n += n * kind.cells(params) as u64;
    }
    let want = nodes_n as u128 * 16 + entries_n as u128 * 4 + cents_n as u128 * 4;
    if want != rest.len() as u128 {
        return Err("index section length");
    }
    let (nodes, rest) = <[IndexNode]>::ref_from_prefix_with_elems(rest, nodes_n as usize)
        .map_err(|_| "index nodes")?;
    let (entries, rest) = <[u32]>::ref_from_prefix_with_elems(rest, entries_n as usize)
        .map_err(|_| "index entries alignment")?;
    let centroids = <[f32]>::ref_from_bytes(rest).map_err(|_| "index centroids alignment")?;
    Ok((header, views, nodes, entries, centroids))
}

/// Checks an index section against the database's parameters and site
/// count: exact lengths, view kinds, node links (children after their
/// parent, within the view), leaf entry ranges, entry values, finite
/// centroids. O(section). An empty section is valid (no index).
pub fn validate(bytes: &[u8], params: &Params, sites: usize) -> Result<(), &'static str> {
    if bytes.is_empty() {
        return Ok(());
    }
    let index = Index::from_parts(split(bytes, params, sites)?, params);
    for (kind, view) in index.each_view() {
        let (nn, ne) = (view.nodes.len() as u64, view.entries.len() as u64);
        for (i, n) in view.nodes.iter().enumerate() {
            let (first, count) = (n.first.get() as u64, n.count.get() as u64);
            match n.leaf.get() {
                0 => {
                    if count == 0 || count > INDEX_CHILDREN_MAX as u64 {
                        return Err("index node child count");
                    }
                    if first <= i as u64 || first + count > nn {
                        return Err("index node children");
                    }
                }
                1 => {
                    if first + count > ne {
                        return Err("index leaf entries");
                    }
                }
                _ => return Err("index node flag"),
            }
        }
        let limit = kind.entries_for(params, sites);
        if view.entries.iter().any(|&e| e as u64 >= limit) {
            return Err("index entry value");
        }
        if view.centroids.iter().any(|c| !c.is_finite()) {
            return Err("index centroid value");
        }
    }
    Ok(())
}

impl<'a> Index<'a> {
    /// The index of a database whose section was checked by [`validate`];
    /// `None` when the section is empty or malformed.
    pub fn new(bytes: &'a [u8], params: &'a Params, sites: usize) -> Option<Index<'a>> {
        if bytes.is_empty() {
            return None;
        }
        Some(Index::from_parts(split(bytes, params, sites).ok()?, params))
    }

    /// The stored views, in order.
    pub fn kinds(&self) -> impl Iterator<Item = ViewKind> + '_ {
        self.each_view().map(|(kind, _)| kind)
    }

    /// (internal nodes kept per level, leaves scored) of the search.
    pub fn widths(&self) -> (usize, usize) {
        (
            self.header.beam.get() as usize,
            self.header.leaves.get() as usize,
        )
    }

    /// Total nodes over all views.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    fn from_parts(
        (header, views, nodes, entries, centroids): Parts<'a>,
        params: &'a Params,
    ) -> Self {
        Index {
            header,
            views,
            nodes,
            entries,
            centroids,
            params,
        }
    }

    /// Every view with its slices, in order: each view's nodes, entries and
    /// centroids follow the previous view's (the one place that lays them
    /// out; a view whose slices would not fit ends the walk).
    fn each_view(&self) -> impl Iterator<Item = (ViewKind, View<'a>)> + '_ {
        self.views
            .iter()
            .scan((0usize, 0usize, 0usize), |(n0, e0, c0), v| {
                let kind = ViewKind::from_raw(v.kind.get(), self.params)?;
                let (nn, ne) = (v.node_count.get() as usize, v.entry_count.get() as usize);
                let cells = kind.cells(self.params);
                let view = View {
                    nodes: self.nodes.get(*n0..*n0 + nn)?,
                    entries: self.entries.get(*e0..*e0 + ne)?,
                    centroids: self.centroids.get(*c0..*c0 + nn * cells)?,
                    cells,
                };
                *n0 += nn;
                *e0 += ne;
                *c0 += nn * cells;
                Some((kind, view))
            })
    }

    fn view(&self, want: ViewKind) -> Option<View<'a>> {
        self.each_view()
            .find(|(kind, _)| *kind == want)
            .map(|(_, view)| view)
    }

    /// True when the index has a tree for `kind`.
    pub fn has(&self, kind: ViewKind) -> bool {
        self.view(kind).is_some()
    }

    /// Beam search of view `kind` for histogram `hist`: calls `visit` with
    /// every entry of the kept leaves (a well-formed index holds each entry in
    /// one leaf; a malformed one may repeat entries, never out of range). Returns the
    /// number of centroids scored, or `None` when the index has no such view.
    pub fn search(
        &self,
        kind: ViewKind,
        hist: &[f32],
        mut visit: impl FnMut(u32),
    ) -> Option<usize> {
        let view = self.view(kind)?;
        let (beam, leaves) = self.widths();
        let mut front = [Slot::EMPTY; INDEX_BEAM_MAX];
        let mut next = [Slot::EMPTY; INDEX_BEAM_MAX];
        let mut kept = [Slot::EMPTY; INDEX_LEAVES_MAX];
        let (mut nf, mut nk) = (0usize, 0usize);
        let mut scored = 0usize;
        let root = view.nodes.first()?;
        if root.leaf.get() == 1 {
            kept[0] = Slot {
                node: 0,
                score: 1.0,
            };
            nk = 1;
        } else {
            front[0] = Slot {
                node: 0,
                score: 1.0,
            };
            nf = 1;
        }
        // At most INDEX_DEPTH_MAX levels of at most `beam` x 64 centroids.
        let mut depth = 0;
        while nf > 0 && depth < INDEX_DEPTH_MAX {
            depth += 1;
            let mut nn = 0usize;
            for f in &front[..nf] {
                let Some(node) = view.nodes.get(f.node as usize) else {
                    continue;
                };
                let first = node.first.get() as usize;
                let count = node.count.get() as usize;
                for c in first..first.saturating_add(count).min(view.nodes.len()) {
                    let s = crate::rank::correlation(hist, view.centroid(c));
                    scored += 1;
                    let slot = Slot {
                        node: c as u32,
                        score: s,
                    };
                    if view.nodes[c].leaf.get() == 1 {
                        insert(&mut kept[..leaves], &mut nk, slot);
                    } else {
                        insert(&mut next[..beam], &mut nn, slot);
                    }
                }
            }
            front[..nn].copy_from_slice(&next[..nn]);
            nf = nn;
        }
        for k in &kept[..nk] {
            let Some(leaf) = view.nodes.get(k.node as usize) else {
                continue;
            };
            let first = leaf.first.get() as usize;
            let count = leaf.count.get() as usize;
            let end = first.saturating_add(count).min(view.entries.len());
            for &e in view.entries.get(first..end).unwrap_or(&[]) {
                visit(e);
            }
        }
        Some(scored)
    }
}

#[derive(Clone, Copy)]
struct Slot {
    node: u32,
    score: f32,
}

impl Slot {
    const EMPTY: Slot = Slot {
        node: 0,
        score: f32::NEG_INFINITY,
    };
}

impl crate::rank::Scored for Slot {
    fn score(&self) -> f32 {
        self.score
    }
    fn key(&self) -> u32 {
        self.node
    }
}

/// Keeps `list[..*n]` the best `list.len()` slots, best first (ties: lower
/// node first).
fn insert(list: &mut [Slot], n: &mut usize, s: Slot) {
    crate::rank::insert(list, n, s);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coarse::{self, Ranked};
    use crate::format::SectionKind;
    use crate::tests::fixture::{self, Aligned};
    use crate::{DbErrorKind, RefDb};

    fn index_bytes() -> Vec<u8> {
        fixture::sections()
            .into_iter()
            .find(|(k, _)| *k == SectionKind::Index)
            .unwrap()
            .1
    }

    fn with_index(bytes: Vec<u8>) -> Vec<u8> {
        let mut s = fixture::sections();
        for (k, b) in s.iter_mut() {
            if *k == SectionKind::Index {
                *b = bytes.clone();
            }
        }
        fixture::encode(&s)
    }

    fn put(b: &mut [u8], at: usize, v: u32) {
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
    }

    /// Byte offset of node `i` (in the first view) in the section.
    fn node_at(b: &[u8], i: usize) -> usize {
        let views = u32::from_le_bytes(b[0..4].try_into().unwrap()) as usize;
        16 + 16 * views + 16 * i
    }

    #[test]
    fn the_fixture_index_ranks_as_the_exhaustive_search() {
        let bytes = fixture::encode(&fixture::sections());
        let buf = Aligned::new(&bytes);
        let db = RefDb::new(buf.bytes()).unwrap();
        let index = db.index().expect("the fixture has an index");
        assert_eq!(index.kinds().count(), 1 + db.params().coarse.win_count());
        for s in 0..db.site_count() {
            // The site's own histogram (and window 0, heading 3) as query.
            for (window, hist) in [(None, db.hist(s)), (Some(0), db.window_hist(s, 0, 3))] {
                let mut a = [Ranked::default(); 8];
                let mut b = [Ranked::default(); 8];
                let na = coarse::rank_sites(&db, hist, window, &mut a);
                let nb = coarse::rank_top_scores(
                    (0..db.site_count()).map(|i| coarse::site_score(&db, hist, window, i)),
                    &mut b,
                );
                assert_eq!(na, db.site_count());
                assert_eq!(a[..na], b[..nb], "site {s} window {window:?}");
                assert_eq!(a[0].site, s as u32);
            }
        }
    }

    #[test]
    fn a_narrow_search_scores_one_leaf() {
        let mut b = index_bytes();
        put(&mut b, 8, 1); // leaves = 1
        let bytes = with_index(b);
        let buf = Aligned::new(&bytes);
        let db = RefDb::new(buf.bytes()).unwrap();
        let index = db.index().unwrap();
        let mut seen = 0;
        let scored = index
            .search(ViewKind::Full, db.hist(0), |e| {
                // Site 0 is alone in the first leaf, whose centroid is its
                // own histogram.
                assert_eq!(e, 0);
                seen += 1;
            })
            .unwrap();
        assert_eq!((seen, scored), (1, 2));
    }

    #[test]
    fn malformed_indexes_are_rejected_by_name() {
        let good = index_bytes();
        let n0 = node_at(&good, 0);
        let n1 = node_at(&good, 1);
        type Patch = fn(&mut Vec<u8>, usize, usize);
        let cases: [(&str, Patch); 14] = [
            ("index header truncated", |b, _, _| b.truncate(8)),
            ("index view count", |b, _, _| put(b, 0, 9)),
            ("index view count", |b, _, _| put(b, 0, 0)),
            ("index search widths", |b, _, _| put(b, 4, 0)),
            ("index search widths", |b, _, _| put(b, 8, 65)),
            ("index view kind", |b, _, _| put(b, 16, 7)),
            ("duplicate index view", |b, _, _| put(b, 32, 0)),
            ("index view entry count", |b, _, _| put(b, 24, 2)),
            ("index section length", |b, _, _| {
                b.extend_from_slice(&[0; 4])
            }),
            ("index node children", |b, n0, _| put(b, n0, 0)),
            ("index node children", |b, n0, _| put(b, n0 + 4, 3)),
            ("index node child count", |b, n0, _| put(b, n0 + 4, 0)),
            ("index leaf entries", |b, _, n1| put(b, n1 + 4, 9)),
            ("index node flag", |b, _, n1| put(b, n1 + 8, 2)),
        ];
        for (what, patch) in cases {
            let mut b = good.clone();
            patch(&mut b, n0, n1);
            let bytes = with_index(b);
            let buf = Aligned::new(&bytes);
            let e = RefDb::new(buf.bytes())
                .err()
                .unwrap_or_else(|| panic!("{what}: accepted"));
            assert_eq!(e.kind, DbErrorKind::Value, "{what}: {e}");
            assert_eq!(e.context, what, "{e}");
        }
        // An entry naming a site that does not exist.
        let mut b = good.clone();
        let entries = node_at(&good, 0) + 16 * total_nodes(&good);
        put(&mut b, entries, 3);
        let bytes = with_index(b);
        let e = RefDb::new(Aligned::new(&bytes).bytes()).err().unwrap();
        assert_eq!(e.context, "index entry value");
        // A non-finite centroid.
        let mut b = good.clone();
        let last = b.len() - 4;
        b[last..].copy_from_slice(&f32::NAN.to_le_bytes());
        let bytes = with_index(b);
        let e = RefDb::new(Aligned::new(&bytes).bytes()).err().unwrap();
        assert_eq!(e.context, "index centroid value");
    }

    fn total_nodes(b: &[u8]) -> usize {
        let views = u32::from_le_bytes(b[0..4].try_into().unwrap()) as usize;
        (0..views)
            .map(|v| {
                u32::from_le_bytes(b[16 + 16 * v + 4..16 + 16 * v + 8].try_into().unwrap()) as usize
            })
            .sum()
    }
}
