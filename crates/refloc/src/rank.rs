//! Ranking primitives shared by the coarse stage ([`crate::coarse`]) and
//! the coarse-search index ([`crate::index`]): the correlation coefficient
//! of two histograms (paper eq. 21-22) and a bounded best-first list.
//!
//! A leaf module: it imports nothing else of the crate, so `coarse` and
//! `index` both build on it without depending on each other.

/// Correlation coefficient of two histograms with the joint mean of eq. 22:
/// `h_bar = (sum h + sum g) / 2K`. Returns a value in [-1, 1]; 0 when either
/// histogram has no variance about the joint mean (both flat at the same
/// level, or empty) or the result is not finite.
pub fn correlation(h: &[f32], g: &[f32]) -> f32 {
    let k = h.len().min(g.len());
    if k == 0 {
        return 0.0;
    }
    let (h, g) = (&h[..k], &g[..k]);
    // Sums in LANES independent accumulators (then added pairwise), which
    // the compiler turns into vector arithmetic: a single running sum is a
    // chain of dependent additions, one bin at a time. It was most of the
    // coarse stage (docs/performance.md, "Vector sums in the coarse
    // correlation"); the order of the additions changes only rounding.
    let (hc, ht) = lanes(h);
    let (gc, gt) = lanes(g);
    let (mut sh, mut sg) = ([0.0f32; LANES], [0.0f32; LANES]);
    for (a, b) in hc.clone().zip(gc.clone()) {
        for l in 0..LANES {
            sh[l] += a[l];
            sg[l] += b[l];
        }
    }
    for (l, (a, b)) in ht.iter().zip(gt).enumerate() {
        sh[l] += a;
        sg[l] += b;
    }
    let (sh, sg) = (lane_sum(&sh), lane_sum(&sg));
    let mean = (sh + sg) / (2 * k) as f32;
    let (mut num, mut dh, mut dg) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
    for (x, y) in hc.zip(gc) {
        for l in 0..LANES {
            let a = x[l] - mean;
            let b = y[l] - mean;
            num[l] += a * b;
            dh[l] += a * a;
            dg[l] += b * b;
        }
    }
    for (l, (x, y)) in ht.iter().zip(gt).enumerate() {
        let a = x - mean;
        let b = y - mean;
        num[l] += a * b;
        dh[l] += a * a;
        dg[l] += b * b;
    }
    let (num, dh, dg) = (lane_sum(&num), lane_sum(&dh), lane_sum(&dg));
    // A flat histogram has zero variance; rounding leaves a tiny residue that
    // must not be read as signal.
    let eps = 1e-9 * (sh * sh + sg * sg) / k as f32 + f32::MIN_POSITIVE;
    if dh <= eps || dg <= eps {
        return 0.0;
    }
    let den = libm::sqrtf(dh * dg);
    let r = num / den;
    if r.is_finite() {
        r.clamp(-1.0, 1.0)
    } else {
        0.0
    }
}

/// Accumulators of [`correlation`]'s sums.
const LANES: usize = 8;

/// `v` as whole rows of `LANES` values, and the rest.
#[inline]
fn lanes(v: &[f32]) -> (impl Iterator<Item = &[f32; LANES]> + Clone, &[f32]) {
    let c = v.chunks_exact(LANES);
    let rest = c.remainder();
    (c.filter_map(|r| <&[f32; LANES]>::try_from(r).ok()), rest)
}

/// The sum of `LANES` accumulators, added pairwise.
#[inline]
fn lane_sum(v: &[f32; LANES]) -> f32 {
    ((v[0] + v[4]) + (v[1] + v[5])) + ((v[2] + v[6]) + (v[3] + v[7]))
}

/// An entry of a best-first list: a score and the key that breaks ties
/// (lower key first) and, for [`insert_unique`], identifies the entry.
pub trait Scored: Copy {
    /// The score (higher is better).
    fn score(&self) -> f32;
    /// The identity and tie-break key.
    fn key(&self) -> u32;
}

/// True when `a` ranks before `b`: a higher score, or the same score and a
/// lower key.
#[inline]
pub fn ranks_before<T: Scored>(a: &T, b: &T) -> bool {
    a.score() > b.score() || (a.score() == b.score() && a.key() < b.key())
}

/// Keeps `list[..*n]` the best `list.len()` entries seen, best first (see
/// [`ranks_before`]); entries with equal keys may appear more than once.
#[inline]
pub fn insert<T: Scored>(list: &mut [T], n: &mut usize, item: T) {
    insert_with(list, n, item, false);
}

/// As [`insert`], keeping one entry per key: an entry whose key is already
/// listed replaces it only when it ranks before it.
#[inline]
pub fn insert_unique<T: Scored>(list: &mut [T], n: &mut usize, item: T) {
    insert_with(list, n, item, true);
}

#[inline(always)]
fn insert_with<T: Scored>(list: &mut [T], n: &mut usize, item: T, unique: bool) {
    let cap = list.len();
    let filled = (*n).min(cap);
    if cap == 0 || (filled == cap && !ranks_before(&item, &list[cap - 1])) {
        return;
    }
    let existing = if unique {
        list[..filled].iter().position(|e| e.key() == item.key())
    } else {
        None
    };
    let mut pos = match existing {
        Some(p) if !ranks_before(&item, &list[p]) => return,
        Some(p) => p,
        None if filled < cap => {
            *n = filled + 1;
            filled
        }
        None => cap - 1,
    };
    while pos > 0 && ranks_before(&item, &list[pos - 1]) {
        list[pos] = list[pos - 1];
        pos -= 1;
    }
    list[pos] = item;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Copy, Debug, PartialEq)]
    struct E(u32, f32);
    impl Scored for E {
        fn score(&self) -> f32 {
            self.1
        }
        fn key(&self) -> u32 {
            self.0
        }
    }

    fn run(items: &[E], cap: usize, unique: bool) -> Vec<E> {
        let mut list = vec![E(0, 0.0); cap];
        let mut n = 0;
        for &e in items {
            if unique {
                insert_unique(&mut list, &mut n, e);
            } else {
                insert(&mut list, &mut n, e);
            }
        }
        list.truncate(n);
        list
    }

    #[test]
    fn keeps_the_best_in_order_with_ties_by_key() {
        let items = [E(3, 0.5), E(1, 0.9), E(2, 0.5), E(0, 0.1), E(4, 0.7)];
        assert_eq!(run(&items, 3, false), [E(1, 0.9), E(4, 0.7), E(2, 0.5)]);
        assert_eq!(run(&items, 10, false).len(), 5);
        assert!(run(&items, 0, false).is_empty());
    }

    #[test]
    fn unique_keeps_the_better_score_of_a_key() {
        let items = [E(1, 0.2), E(2, 0.5), E(1, 0.8), E(2, 0.4), E(3, 0.1)];
        assert_eq!(run(&items, 2, true), [E(1, 0.8), E(2, 0.5)]);
        assert_eq!(run(&items, 2, false), [E(1, 0.8), E(2, 0.5)]);
        // Not unique: the same key twice.
        assert_eq!(run(&[E(1, 0.2), E(1, 0.3)], 4, false).len(), 2);
        assert_eq!(run(&[E(1, 0.2), E(1, 0.3)], 4, true), [E(1, 0.3)]);
    }

    #[test]
    fn correlation_of_flat_or_empty_histograms_is_zero() {
        assert_eq!(correlation(&[], &[1.0]), 0.0);
        assert_eq!(correlation(&[1.0; 8], &[1.0; 8]), 0.0);
        // The joint mean: a flat histogram against one with less mass is
        // not flat about that mean.
        let g = [0.0, 1.0, 0.0, 2.0, 0.0, 0.0, 1.0, 0.0];
        assert!(correlation(&[1.0; 8], &g) < 0.0);
        let h = [0.0, 1.0, 3.0, 0.0];
        assert!((correlation(&h, &h) - 1.0).abs() < 1e-6);
    }
}
