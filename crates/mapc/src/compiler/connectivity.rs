//! Connectivity on grids and graphs, written once for all of mapc: the
//! 4-connected flood of a region of cells ([`flood4`]) and union-find over
//! indices ([`UnionFind`]). The GVD's hole filling, the sites' largest
//! free region, the evaluation's pose sampling and the synthetic caves'
//! tunnels use them.

/// Floods the 4-connected region of cell `start` of a `width` x `height`
/// grid (cells indexed `y * width + x`), depth first.
///
/// `start` is taken as part of the region (the caller has marked it).
/// For each neighbour `j` (in the grid) of a cell of the region,
/// `enter(j)` says whether `j` joins the region; it must mark `j` so that
/// it answers false for it from then on. `reached(i)` is called once for
/// each cell of the region, `start` first. `stack` is scratch (left empty).
pub fn flood4(
    width: usize,
    height: usize,
    start: usize,
    stack: &mut Vec<u32>,
    mut enter: impl FnMut(usize) -> bool,
    mut reached: impl FnMut(usize),
) {
    stack.clear();
    stack.push(start as u32);
    while let Some(i) = stack.pop() {
        let i = i as usize;
        reached(i);
        let (x, y) = (i % width, i / width);
        let neighbours = [
            (x + 1 < width).then(|| i + 1),
            (x > 0).then(|| i - 1),
            (y + 1 < height).then(|| i + width),
            (y > 0).then(|| i - width),
        ];
        for j in neighbours.into_iter().flatten() {
            if enter(j) {
                stack.push(j as u32);
            }
        }
    }
}

/// Disjoint sets over `0..n` (union-find with path halving). The root of a
/// joined set is the smaller of the two roots, so roots are deterministic.
#[derive(Clone, Debug)]
pub struct UnionFind {
    parent: Vec<usize>,
}

impl UnionFind {
    /// `n` singleton sets.
    pub fn new(n: usize) -> UnionFind {
        UnionFind {
            parent: (0..n).collect(),
        }
    }

    /// The root of `i`'s set.
    pub fn find(&mut self, mut i: usize) -> usize {
        while self.parent[i] != i {
            self.parent[i] = self.parent[self.parent[i]];
            i = self.parent[i];
        }
        i
    }

    /// Joins the sets of `a` and `b`; false when they were one set already.
    pub fn union(&mut self, a: usize, b: usize) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        self.parent[ra.max(rb)] = ra.min(rb);
        true
    }

    /// The number of sets.
    pub fn count(&mut self) -> usize {
        (0..self.parent.len())
            .filter(|&i| self.find(i) == i)
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flood4_takes_exactly_the_4_connected_region() {
        // 4 x 3, '#' blocked: the two free areas touch only diagonally.
        let grid = ["..#.", ".#..", "#..."];
        let cells: Vec<bool> = grid
            .iter()
            .flat_map(|r| r.bytes().map(|b| b == b'.'))
            .collect();
        let mut seen = vec![false; cells.len()];
        seen[0] = true;
        let mut region = Vec::new();
        flood4(
            4,
            3,
            0,
            &mut Vec::new(),
            |j| {
                let take = cells[j] && !seen[j];
                seen[j] |= take;
                take
            },
            |i| region.push(i),
        );
        region.sort_unstable();
        assert_eq!(region, vec![0, 1, 4]);
    }

    #[test]
    fn union_find_joins_and_counts() {
        let mut u = UnionFind::new(6);
        assert!(u.union(4, 2));
        assert!(u.union(2, 5));
        assert!(!u.union(5, 4));
        assert!(u.union(0, 1));
        assert_eq!(u.find(5), 2);
        assert_eq!(u.find(1), 0);
        assert_eq!(u.count(), 3);
    }
}
