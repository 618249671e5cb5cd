//! Building the coarse-search index (`refloc::index`): a tree of clusters
//! over the sites' histograms, so the runtime's coarse ranking scores a few
//! hundred histograms instead of every site's on large maps.
//!
//! One tree per view: the full histograms (entry = site), and each stored
//! window width (entry = site x heading). A node with more than `leaf_size`
//! members is split into at most `branching` clusters by spherical k-means
//! on the mean-centred, unit-length histograms (the correlation coefficient
//! of two histograms that each sum to 1 is the cosine of those vectors):
//! k-means++ seeding and Lloyd iterations on a sample of the members, then
//! every member goes to its nearest centre. Each node stores the mean
//! histogram of its members, which the runtime correlates with the query.
//!
//! Deterministic: every random choice comes from a stream of the build seed
//! named by the node's path in the tree, and parallel work (member
//! assignment, subtrees) only computes independent values, so the bytes do
//! not depend on the thread count.

use rayon::prelude::*;
use refloc::format::{
    IndexHeader, IndexNode, IndexView, INDEX_BEAM_MAX, INDEX_CHILDREN_MAX, INDEX_DEPTH_MAX,
    INDEX_LEAVES_MAX,
};
use refloc::params::Params;
use serde::Serialize;
use zerocopy::little_endian::U32;
use zerocopy::IntoBytes;

use crate::compiler::rng::Rng;

/// Options of the index build.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IndexOptions {
    /// Build an index only for maps with at least this many sites (smaller
    /// maps are ranked exhaustively, which is exact and already fast).
    pub min_sites: usize,
    /// Most children of a node (2..=64).
    pub branching: usize,
    /// A node with at most this many members is a leaf.
    pub leaf_size: usize,
    /// Search: internal nodes kept per level (1..=32).
    pub beam: u32,
    /// Search: leaves whose entries are scored (1..=64).
    pub leaves: u32,
    /// Lloyd iterations per split.
    pub iterations: usize,
    /// Seed of the k-means choices.
    pub seed: u64,
}

impl Default for IndexOptions {
    fn default() -> Self {
        IndexOptions {
            min_sites: 1500,
            branching: 16,
            leaf_size: 32,
            beam: 8,
            leaves: 24,
            iterations: 6,
            seed: 1,
        }
    }
}

/// Why index options or inputs were refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum IndexError {
    /// `branching` outside 2..=`INDEX_CHILDREN_MAX`.
    #[error("index branching must be 2..={max}, got {0}", max = INDEX_CHILDREN_MAX)]
    Branching(usize),
    /// `leaf_size` of 0.
    #[error("index leaf size must be at least 1")]
    LeafSize,
    /// `beam` outside 1..=`INDEX_BEAM_MAX`.
    #[error("index beam must be 1..={max}, got {0}", max = INDEX_BEAM_MAX)]
    Beam(u32),
    /// `leaves` outside 1..=`INDEX_LEAVES_MAX`.
    #[error("index leaves must be 1..={max}, got {0}", max = INDEX_LEAVES_MAX)]
    Leaves(u32),
    /// The histogram sections' lengths (bytes) do not match the site count.
    #[error("index: histogram sections ({hists} and {windows} bytes) do not match {sites} sites")]
    Sections {
        /// Full-view histogram section (bytes).
        hists: usize,
        /// Window histogram section (bytes).
        windows: usize,
        /// Sites.
        sites: usize,
    },
}

impl IndexOptions {
    /// Checks the ranges the runtime accepts.
    pub fn validate(&self) -> Result<(), IndexError> {
        if !(2..=INDEX_CHILDREN_MAX).contains(&self.branching) {
            return Err(IndexError::Branching(self.branching));
        }
        if self.leaf_size == 0 {
            return Err(IndexError::LeafSize);
        }
        if !(1..=INDEX_BEAM_MAX as u32).contains(&self.beam) {
            return Err(IndexError::Beam(self.beam));
        }
        if !(1..=INDEX_LEAVES_MAX as u32).contains(&self.leaves) {
            return Err(IndexError::Leaves(self.leaves));
        }
        Ok(())
    }
}

/// The histograms of one view, read in place from a section's bytes
/// (little-endian `f32`): vector `i` is histogram `(i / group) * slots +
/// slot) * group + i % group` of the section. The full histograms are
/// `group = 1, slots = 1`; window width `w` is `group = headings`, `slots =
/// widths`, `slot = w`.
struct Vectors<'a> {
    bytes: &'a [u8],
    cells: usize,
    count: usize,
    group: usize,
    slots: usize,
    slot: usize,
}

impl Vectors<'_> {
    fn get(&self, i: usize, out: &mut [f32]) {
        let h = ((i / self.group) * self.slots + self.slot) * self.group + i % self.group;
        let b = &self.bytes[h * 4 * self.cells..(h + 1) * 4 * self.cells];
        for (o, c) in out.iter_mut().zip(b.chunks_exact(4)) {
            *o = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        }
    }
}

/// A built tree node.
enum Node {
    Leaf(Vec<u32>),
    Inner(Vec<Tree>),
}

struct Tree {
    /// Mean histogram of the members (sums to 1 like theirs).
    centroid: Vec<f32>,
    node: Node,
}

/// Mean-centred, unit-length copies of the vectors (zero for a flat one).
fn units(v: &Vectors<'_>) -> Vec<f32> {
    let k = v.cells;
    let mut out = vec![0f32; v.count * k];
    out.par_chunks_mut(k).enumerate().for_each(|(i, u)| {
        v.get(i, u);
        let mean = u.iter().sum::<f32>() / k as f32;
        let mut n2 = 0f32;
        for x in u.iter_mut() {
            *x -= mean;
            n2 += *x * *x;
        }
        let inv = if n2 > 0.0 { 1.0 / n2.sqrt() } else { 0.0 };
        for x in u.iter_mut() {
            *x *= inv;
        }
    });
    out
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn normalize(c: &mut [f32]) {
    let n = dot(c, c).sqrt();
    if n > 0.0 {
        c.iter_mut().for_each(|x| *x /= n);
    }
}

fn nearest(u: &[f32], centres: &[Vec<f32>]) -> (usize, f32) {
    let mut best = (0usize, f32::NEG_INFINITY);
    for (j, c) in centres.iter().enumerate() {
        let s = dot(u, c);
        if s > best.1 {
            best = (j, s);
        }
    }
    best
}

/// Splits `members` into at most `k` groups (none empty, at least two).
fn split(
    units: &[f32],
    cells: usize,
    members: &[u32],
    k: usize,
    opts: &IndexOptions,
    rng: &mut Rng,
) -> Vec<Vec<u32>> {
    let u = |m: u32| &units[m as usize * cells..(m as usize + 1) * cells];
    // Sample without replacement (partial Fisher-Yates).
    let s = members.len().min(48 * k);
    let mut sample = members.to_vec();
    for i in 0..s {
        let j = i + rng.below((sample.len() - i) as u64) as usize;
        sample.swap(i, j);
    }
    sample.truncate(s);
    // k-means++ seeding on the sample (distance 1 - cos).
    let mut centres: Vec<Vec<f32>> = vec![u(sample[rng.below(s as u64) as usize]).to_vec()];
    let mut d: Vec<f32> = sample
        .iter()
        .map(|&m| (1.0 - dot(u(m), &centres[0])).max(0.0))
        .collect();
    while centres.len() < k {
        let total: f64 = d.iter().map(|&x| x as f64).sum();
        if total.is_nan() || total <= 0.0 {
            break;
        }
        let mut t = rng.uniform() * total;
        let mut pick = s - 1;
        for (i, &x) in d.iter().enumerate() {
            t -= x as f64;
            if t < 0.0 {
                pick = i;
                break;
            }
        }
        let c = u(sample[pick]).to_vec();
        for (di, &m) in d.iter_mut().zip(&sample) {
            *di = di.min((1.0 - dot(u(m), &c)).max(0.0));
        }
        centres.push(c);
    }
    // Lloyd iterations on the sample.
    for _ in 0..opts.iterations {
        let mut sums = vec![vec![0f32; cells]; centres.len()];
        for &m in &sample {
            let (j, _) = nearest(u(m), &centres);
            sums[j].iter_mut().zip(u(m)).for_each(|(a, b)| *a += b);
        }
        for (c, mut sum) in centres.iter_mut().zip(sums) {
            if sum.iter().any(|&x| x != 0.0) {
                normalize(&mut sum);
                *c = sum;
            }
        }
    }
    // Every member to its nearest centre.
    let assign: Vec<usize> = members
        .par_iter()
        .map(|&m| nearest(u(m), &centres).0)
        .collect();
    let mut groups = vec![Vec::new(); centres.len()];
    for (&m, &j) in members.iter().zip(&assign) {
        groups[j].push(m);
    }
    groups.retain(|g| !g.is_empty());
    if groups.len() < 2 {
        // Identical vectors: any split keeps the search correct.
        let per = members.len().div_ceil(k.max(2));
        return members.chunks(per).map(|c| c.to_vec()).collect();
    }
    groups
}

fn build_tree(
    vecs: &Vectors<'_>,
    units: &[f32],
    members: Vec<u32>,
    opts: &IndexOptions,
    seed: u64,
    depth: usize,
) -> Tree {
    let cells = vecs.cells;
    let mut centroid = vec![0f32; cells];
    let mut h = vec![0f32; cells];
    for &m in &members {
        vecs.get(m as usize, &mut h);
        centroid.iter_mut().zip(&h).for_each(|(a, b)| *a += b);
    }
    let inv = 1.0 / members.len().max(1) as f32;
    centroid.iter_mut().for_each(|a| *a *= inv);
    // A leaf at the runtime's deepest level whatever its size (only
    // pathological splits, one member at a time, get there).
    if members.len() <= opts.leaf_size || depth >= INDEX_DEPTH_MAX {
        return Tree {
            centroid,
            node: Node::Leaf(members),
        };
    }
    let k = members
        .len()
        .div_ceil(opts.leaf_size)
        .clamp(2, opts.branching);
    let mut rng = Rng::new(seed);
    let groups = split(units, cells, &members, k, opts, &mut rng);
    let children: Vec<Tree> = groups
        .into_par_iter()
        .enumerate()
        .map(|(i, g)| {
            let child_seed = Rng::stream(seed, i as u64 + 1).next_u64();
            build_tree(vecs, units, g, opts, child_seed, depth + 1)
        })
        .collect();
    Tree {
        centroid,
        node: Node::Inner(children),
    }
}

/// Nodes in breadth-first order (children contiguous, after their parent),
/// the leaves' entries, and the centroids in node order.
fn flatten(root: &Tree) -> (Vec<IndexNode>, Vec<u32>, Vec<f32>) {
    let mut order: Vec<&Tree> = vec![root];
    let mut nodes = Vec::new();
    let mut entries = Vec::new();
    let mut cents = Vec::new();
    let mut i = 0;
    while i < order.len() {
        let t = order[i];
        cents.extend_from_slice(&t.centroid);
        let (first, count, leaf) = match &t.node {
            Node::Leaf(m) => {
                let first = entries.len();
                entries.extend_from_slice(m);
                (first, m.len(), 1)
            }
            Node::Inner(ch) => {
                let first = order.len();
                order.extend(ch.iter());
                (first, ch.len(), 0)
            }
        };
        nodes.push(IndexNode {
            first: U32::new(first as u32),
            count: U32::new(count as u32),
            leaf: U32::new(leaf),
            reserved: U32::new(0),
        });
        i += 1;
    }
    (nodes, entries, cents)
}

/// The index section for a database with `sites` sites whose histogram
/// section bytes are `hists` and window section bytes `windows`, or `None`
/// when the map has fewer than `opts.min_sites` sites.
pub fn build(
    hists: &[u8],
    windows: &[u8],
    params: &Params,
    sites: usize,
    opts: &IndexOptions,
) -> Result<Option<Vec<u8>>, IndexError> {
    opts.validate()?;
    if sites < opts.min_sites || sites == 0 {
        return Ok(None);
    }
    let (nw, nh, wc) = (
        params.coarse.win_count(),
        params.coarse.win_headings as usize,
        params.coarse.win_cells(),
    );
    let full = params.coarse.hist_cells();
    if hists.len() != sites * full * 4 || windows.len() != sites * nw * nh * wc * 4 {
        return Err(IndexError::Sections {
            hists: hists.len(),
            windows: windows.len(),
            sites,
        });
    }
    let mut views: Vec<(u32, Vectors<'_>)> = vec![(
        0,
        Vectors {
            bytes: hists,
            cells: full,
            count: sites,
            group: 1,
            slots: 1,
            slot: 0,
        },
    )];
    if nh > 0 && wc > 0 {
        for w in 0..nw {
            views.push((
                1 + w as u32,
                Vectors {
                    bytes: windows,
                    cells: wc,
                    count: sites * nh,
                    group: nh,
                    slots: nw,
                    slot: w,
                },
            ));
        }
    }
    let mut view_recs = Vec::new();
    let (mut nodes, mut entries, mut cents) = (Vec::new(), Vec::new(), Vec::new());
    for (kind, vecs) in &views {
        let n = vecs.count;
        let u = units(vecs);
        let seed = Rng::stream(opts.seed, *kind as u64).next_u64();
        let tree = build_tree(vecs, &u, (0..n as u32).collect(), opts, seed, 0);
        drop(u);
        let (nd, en, ce) = flatten(&tree);
        view_recs.push(IndexView {
            kind: U32::new(*kind),
            node_count: U32::new(nd.len() as u32),
            entry_count: U32::new(en.len() as u32),
            reserved: U32::new(0),
        });
        nodes.extend(nd);
        entries.extend(en);
        cents.extend(ce);
    }
    let header = IndexHeader {
        view_count: U32::new(view_recs.len() as u32),
        beam: U32::new(opts.beam),
        leaves: U32::new(opts.leaves),
        reserved: U32::new(0),
    };
    let mut out = Vec::with_capacity(
        16 + 16 * (view_recs.len() + nodes.len()) + 4 * (entries.len() + cents.len()),
    );
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(view_recs.as_bytes());
    out.extend_from_slice(nodes.as_bytes());
    for e in &entries {
        out.extend_from_slice(&e.to_le_bytes());
    }
    for c in &cents {
        out.extend_from_slice(&c.to_le_bytes());
    }
    Ok(Some(out))
}

#[cfg(test)]
mod tests;
