//! Whether a finite union of closed boxes covers a box.
//!
//! The target is split by the first cell that overlaps it: the part inside
//! the cell is covered, and what is left is at most `2n` closed slabs, each
//! narrower than the piece it came from along one axis. A slab taken as
//! closed asks for slightly more than the open remainder, which loses
//! nothing: a finite union of closed boxes is closed, so it covers the
//! remainder exactly when it covers its closure.

use super::bounds::Bx;

/// Work limit: coordinates compared (pieces × cells scanned × dimension)
/// before the answer is "undecided" — a few seconds at most.
pub const MAX_WORK: usize = 2_000_000_000;

/// `Ok` when `cells` cover every point of `target` except in pieces that
/// `misses` shows to lie outside the set of interest; otherwise
/// `Err(Some(point))` with a point of `target` in no cell, or `Err(None)`
/// when the work limit ran out.
pub fn covers(
    cells: &[Bx],
    target: &Bx,
    misses: &dyn Fn(&Bx) -> bool,
) -> Result<(), Option<Vec<f64>>> {
    covers_within(cells, target, misses, MAX_WORK)
}

/// [`covers`] with the work limit `max_work` instead of [`MAX_WORK`].
pub fn covers_within(
    cells: &[Bx],
    target: &Bx,
    misses: &dyn Fn(&Bx) -> bool,
    max_work: usize,
) -> Result<(), Option<Vec<f64>>> {
    let n = target.lo.len();
    let mut stack = vec![target.clone()];
    let mut work = 0usize;
    while let Some(piece) = stack.pop() {
        // the scan below looks at up to every cell, every coordinate
        work = work.saturating_add(cells.len().max(1).saturating_mul(n.max(1)));
        if work > max_work {
            return Err(None);
        }
        // a cell overlapping the piece: with positive length along every
        // axis the piece is wide in, containing it along the others
        // (a cell of another dimension overlaps nothing)
        let cell = cells.iter().find(|c| {
            c.lo.len() == n
                && c.hi.len() == n
                && (c.lo.iter().zip(&c.hi))
                    .zip(piece.lo.iter().zip(&piece.hi))
                    .all(|((c_lo, c_hi), (p_lo, p_hi))| {
                        if p_lo < p_hi {
                            c_lo < p_hi && c_hi > p_lo
                        } else {
                            c_lo <= p_lo && p_lo <= c_hi
                        }
                    })
        });
        let Some(c) = cell else {
            if misses(&piece) {
                continue;
            }
            let mid = piece
                .lo
                .iter()
                .zip(&piece.hi)
                .map(|(l, h)| l + (h - l) / 2.0)
                .collect();
            return Err(Some(mid));
        };
        let mut rest = piece.clone();
        for (d, (&c_lo, &c_hi)) in c.lo.iter().zip(&c.hi).enumerate() {
            if rest.lo.get(d).is_some_and(|&r| c_lo > r) {
                let mut slab = rest.clone();
                set(&mut slab.hi, d, c_lo);
                stack.push(slab);
                set(&mut rest.lo, d, c_lo);
            }
            if rest.hi.get(d).is_some_and(|&r| c_hi < r) {
                let mut slab = rest.clone();
                set(&mut slab.lo, d, c_hi);
                stack.push(slab);
                set(&mut rest.hi, d, c_hi);
            }
        }
    }
    Ok(())
}

/// Set entry `d` of a box's ends `v` to `x` (`d` is an axis of the box).
fn set(v: &mut [f64], d: usize, x: f64) {
    if let Some(e) = v.get_mut(d) {
        *e = x;
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn b(lo: &[f64], hi: &[f64]) -> Bx {
        Bx {
            lo: lo.to_vec(),
            hi: hi.to_vec(),
        }
    }

    #[test]
    fn a_grid_covers_and_a_grid_with_a_hole_does_not() {
        let mut cells = Vec::new();
        for i in 0..4 {
            for j in 0..3 {
                let (x, y) = (i as f64 * 0.25, j as f64 / 3.0);
                cells.push(b(&[x, y], &[x + 0.25, (j + 1) as f64 / 3.0]));
            }
        }
        let target = b(&[0.0, 0.0], &[1.0, 1.0]);
        assert_eq!(covers(&cells, &target, &|_| false), Ok(()));
        let hole = cells.remove(5);
        let Err(Some(p)) = covers(&cells, &target, &|_| false) else {
            panic!("a missing cell must be found");
        };
        assert!(hole.contains(&p));
        // a gap of one ulp between two cells is found too
        let split = 0.5f64;
        let gap = vec![b(&[0.0], &[split]), b(&[split.next_up().next_up()], &[1.0])];
        assert!(covers(&gap, &b(&[0.0], &[1.0]), &|_| false).is_err());
        let touching = vec![b(&[0.0], &[split]), b(&[split], &[1.0])];
        assert_eq!(covers(&touching, &b(&[0.0], &[1.0]), &|_| false), Ok(()));
    }

    #[test]
    fn degenerate_targets_and_overlapping_cells() {
        let cells = vec![b(&[-1.0, 0.0], &[0.5, 2.0]), b(&[0.0, -1.0], &[2.0, 1.0])];
        assert_eq!(
            covers(&cells, &b(&[0.0, 0.5], &[1.0, 0.5]), &|_| false),
            Ok(())
        );
        assert!(covers(&cells, &b(&[0.0, 1.5], &[1.0, 1.5]), &|_| false).is_err());
    }
}
