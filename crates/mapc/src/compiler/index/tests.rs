use super::*;

/// Histograms of `n` random "sites": a few peaks each, normalized to sum 1.
fn random_hists(n: usize, cells: usize, seed: u64) -> Vec<u8> {
    let mut rng = Rng::new(seed);
    let mut out = Vec::new();
    for _ in 0..n {
        let mut h = vec![0f32; cells];
        for _ in 0..6 {
            let c = rng.below(cells as u64) as usize;
            h[c] += rng.uniform() as f32 + 0.1;
        }
        let s: f32 = h.iter().sum();
        for v in &h {
            out.extend_from_slice(&(v / s).to_le_bytes());
        }
    }
    out
}

fn params() -> Params {
    Params::defaults(362, 30.0)
}

/// Full and window sections for `n` random sites.
fn sections(n: usize, seed: u64) -> (Vec<u8>, Vec<u8>) {
    let p = params();
    let hists = random_hists(n, p.coarse.hist_cells(), seed);
    let per_site = p.coarse.win_count() * p.coarse.win_headings as usize;
    let windows = random_hists(n * per_site, p.coarse.win_cells(), seed + 1);
    (hists, windows)
}

fn small_opts() -> IndexOptions {
    IndexOptions {
        min_sites: 1,
        leaf_size: 8,
        branching: 4,
        ..IndexOptions::default()
    }
}

#[test]
fn below_min_sites_there_is_no_index() {
    let (h, w) = sections(20, 1);
    let opts = IndexOptions {
        min_sites: 21,
        ..IndexOptions::default()
    };
    assert_eq!(build(&h, &w, &params(), 20, &opts).unwrap(), None);
}

#[test]
fn sections_that_disagree_with_the_site_count_are_an_error() {
    let (h, w) = sections(20, 1);
    assert!(build(&h, &w, &params(), 21, &small_opts()).is_err());
    let bad = IndexOptions {
        beam: 0,
        ..small_opts()
    };
    assert!(build(&h, &w, &params(), 20, &bad)
        .unwrap_err()
        .to_string()
        .contains("beam"));
}

#[test]
fn the_index_is_valid_and_holds_every_entry_once() {
    let p = params();
    let n = 300;
    let (h, w) = sections(n, 2);
    let bytes = build(&h, &w, &p, n, &small_opts()).unwrap().unwrap();
    refloc::index::validate(&bytes, &p, n).expect("the runtime accepts it");
    let index = refloc::index::Index::new(&bytes, &p, n).unwrap();
    let kinds: Vec<_> = index.kinds().collect();
    assert_eq!(kinds.len(), 1 + p.coarse.win_count());
    // The leaves of each view partition its entries: every entry in one
    // leaf, once.
    use zerocopy::FromBytes;
    let nv = kinds.len();
    let views = <[IndexView]>::ref_from_bytes(&bytes[16..16 + 16 * nv]).unwrap();
    let total_nodes: usize = views.iter().map(|v| v.node_count.get() as usize).sum();
    let nodes_at = 16 + 16 * nv;
    let nodes =
        <[IndexNode]>::ref_from_bytes(&bytes[nodes_at..nodes_at + 16 * total_nodes]).unwrap();
    let entries_at = nodes_at + 16 * total_nodes;
    let (mut n0, mut e0) = (0usize, 0usize);
    for (v, kind) in views.iter().zip(&kinds) {
        let (nn, ne) = (v.node_count.get() as usize, v.entry_count.get() as usize);
        let mut seen = vec![0u32; ne];
        for node in &nodes[n0..n0 + nn] {
            if node.leaf.get() == 1 {
                let (f, c) = (node.first.get() as usize, node.count.get() as usize);
                assert!(c <= small_opts().leaf_size, "{kind:?}: a leaf of {c}");
                for i in f..f + c {
                    let at = entries_at + 4 * (e0 + i);
                    let e = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
                    seen[e as usize] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&c| c == 1), "{kind:?}");
        // The search visits a part of them.
        let q = vec![1.0 / kind.cells(&p) as f32; kind.cells(&p)];
        let mut visited = 0;
        index.search(*kind, &q, |_| visited += 1).unwrap();
        assert!(visited > 0 && visited < ne, "{kind:?}: {visited} of {ne}");
        n0 += nn;
        e0 += ne;
    }
}

#[test]
fn the_search_finds_the_histogram_it_was_given() {
    let p = params();
    let n = 2000;
    let (h, w) = sections(n, 3);
    let opts = IndexOptions {
        min_sites: 1,
        ..IndexOptions::default()
    };
    let bytes = build(&h, &w, &p, n, &opts).unwrap().unwrap();
    let index = refloc::index::Index::new(&bytes, &p, n).unwrap();
    let k = p.coarse.hist_cells();
    let mut rng = Rng::new(9);
    let (mut found, mut visited) = (0, 0);
    for q in 0..200 {
        // Site q's histogram with 10% multiplicative noise.
        let mut hist: Vec<f32> = h[q * 4 * k..(q + 1) * 4 * k]
            .chunks_exact(4)
            .map(|c| {
                f32::from_le_bytes([c[0], c[1], c[2], c[3]]) * (0.9 + 0.2 * rng.uniform() as f32)
            })
            .collect();
        let s: f32 = hist.iter().sum();
        hist.iter_mut().for_each(|v| *v /= s);
        let mut hit = false;
        index
            .search(refloc::index::ViewKind::Full, &hist, |e| {
                visited += 1;
                hit |= e as usize == q;
            })
            .unwrap();
        found += hit as usize;
    }
    assert!(found >= 196, "found {found} of 200");
    assert!(visited < 200 * n / 4, "visited {visited}");
}

#[test]
fn the_bytes_do_not_depend_on_the_thread_count() {
    let p = params();
    let n = 500;
    let (h, w) = sections(n, 4);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| build(&h, &w, &p, n, &small_opts()).unwrap().unwrap())
    };
    assert_eq!(run(1), run(3));
    let other = IndexOptions {
        seed: 2,
        ..small_opts()
    };
    assert_ne!(run(1), build(&h, &w, &p, n, &other).unwrap().unwrap());
}
