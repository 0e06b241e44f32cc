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
        let cell = cells.iter().find(|c| {
            (0..n).all(|d| {
                if piece.lo[d] < piece.hi[d] {
                    c.lo[d] < piece.hi[d] && c.hi[d] > piece.lo[d]
                } else {
                    c.lo[d] <= piece.lo[d] && piece.lo[d] <= c.hi[d]
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
        for d in 0..n {
            if c.lo[d] > rest.lo[d] {
                let mut slab = rest.clone();
                slab.hi[d] = c.lo[d];
                stack.push(slab);
                rest.lo[d] = c.lo[d];
            }
            if c.hi[d] < rest.hi[d] {
                let mut slab = rest.clone();
                slab.lo[d] = c.hi[d];
                stack.push(slab);
                rest.hi[d] = c.hi[d];
            }
        }
    }
    Ok(())
}

#[cfg(test)]
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
