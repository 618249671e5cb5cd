//! Connectivity: keeps the largest 4-connected free component of a
//! generated map (scanline flood fill, labelling in place).

use super::{FREE, OCCUPIED};

/// Temporary label of the component being kept (connectivity pass only).
const LABEL_KEEP: u8 = 252;
/// Temporary label of other components (connectivity pass only).
const LABEL_OTHER: u8 = 253;

/// 4-connected scanline flood fill of the `from`-valued region containing
/// (sx, sy), relabelled `to`; returns the number of cells relabelled.
fn flood(px: &mut [u8], w: usize, h: usize, sx: usize, sy: usize, from: u8, to: u8) -> u64 {
    if from == to || px[sy * w + sx] != from {
        return 0;
    }
    let mut n = 0u64;
    let mut stack: Vec<(u32, u32)> = vec![(sx as u32, sy as u32)];
    while let Some((x, y)) = stack.pop() {
        let (x, y) = (x as usize, y as usize);
        let row = y * w;
        if px[row + x] != from {
            continue;
        }
        let mut l = x;
        while l > 0 && px[row + l - 1] == from {
            l -= 1;
        }
        let mut r = x;
        while r + 1 < w && px[row + r + 1] == from {
            r += 1;
        }
        px[row + l..=row + r].fill(to);
        n += (r - l + 1) as u64;
        for ny in [y.wrapping_sub(1), y + 1] {
            if ny >= h {
                continue;
            }
            let nrow = ny * w;
            let mut x = l;
            while x <= r {
                if px[nrow + x] == from {
                    stack.push((x as u32, ny as u32));
                    while x <= r && px[nrow + x] == from {
                        x += 1;
                    }
                } else {
                    x += 1;
                }
            }
        }
    }
    n
}

/// Keeps the largest 4-connected free component (trying the component at
/// `hint` first: if it holds most free cells no full labelling is needed);
/// every other free cell becomes occupied. Returns how many were removed.
pub(super) fn keep_largest(px: &mut [u8], w: usize, h: usize, hint: Option<(usize, usize)>) -> u64 {
    let total = px.iter().filter(|&&p| p == FREE).count() as u64;
    if total == 0 {
        return 0;
    }
    let mut kept = 0u64;
    let mut kept_at = None;
    if let Some((x, y)) = hint {
        if x < w && y < h && px[y * w + x] == FREE {
            kept = flood(px, w, h, x, y, FREE, LABEL_KEEP);
            kept_at = Some((x, y));
        }
    }
    if kept * 2 <= total {
        let mut rest = total - kept;
        let mut best: Option<(usize, u64)> = None;
        let mut i = 0;
        while i < px.len() && rest > 0 {
            if px[i] == FREE {
                let n = flood(px, w, h, i % w, i / w, FREE, LABEL_OTHER);
                rest -= n;
                if best.is_none_or(|b| n > b.1) {
                    best = Some((i, n));
                }
            }
            i += 1;
        }
        if let Some((bi, bn)) = best {
            if bn > kept {
                if let Some((x, y)) = kept_at {
                    flood(px, w, h, x, y, LABEL_KEEP, LABEL_OTHER);
                }
                flood(px, w, h, bi % w, bi / w, LABEL_OTHER, LABEL_KEEP);
                kept = bn;
            }
        }
    }
    for p in px.iter_mut() {
        *p = match *p {
            LABEL_KEEP => FREE,
            FREE | LABEL_OTHER => OCCUPIED,
            v => v,
        };
    }
    total - kept
}
