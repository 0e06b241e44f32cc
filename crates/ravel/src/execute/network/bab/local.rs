//! The derivative-free attack of the input-splitting search: a seeded
//! random local search for a violation, for the thin violating regions
//! that gradient steps miss (ACAS Xu 5_3 property 2, 1_9 property 7:
//! regions about 10⁻⁴ of the box wide, where the gradient at the sampled
//! and centre points leads elsewhere).
//!
//! One *stage* draws `samples` uniform points of a domain (a list of open
//! cells: half of the points in a cell chosen by volume, half in a cell
//! chosen by count, so both the open volume and the refined places, where
//! the bounds stay open longest, are sampled), keeps the `starts` most
//! violating ones, and from each runs a shrinking-box random search: draw
//! [`DRAWS`] points uniformly in the box of half-widths `r` around the best
//! point (projected into the input set), move to the best of them if it
//! improves the violation, else halve `r`; from [`RADIUS`] of the set's
//! widths down to [`FLOOR`] of its widest, at most [`STEPS`] steps. Every
//! point whose `f64` violation is non-negative is a candidate for
//! [`Ctx::confirmed`], the rule of every counterexample of a network spec;
//! nothing here is a bound.
//!
//! Deterministic: the points of a chunk of samples and of a start's walk
//! come from their own seeded [`Rng`] (the plan's seed, the stage, the
//! property, the chunk or start), the chunks and the starts run on the
//! threads in groups fixed by their count, and the first witness in start
//! order is kept (a later group starts only when no start of the earlier
//! ones found one), so the result does not depend on the thread count.

use super::{cell_margin, map_ordered, project, proved, violation, Ctx, Witness};
use ravel_analysis::sets::IBox;
use ravel_base::rng::Rng;

/// The points of a step of the walk, evaluated together.
pub(super) const DRAWS: usize = 64;

/// The walk's first half-width, relative to the input set's widths.
const RADIUS: f64 = 0.05;

/// The walk stops when its widest half-width is below this fraction of
/// the input set's widest side (float32 resolution, about).
const FLOOR: f64 = 1e-7;

/// The most steps of one walk.
const STEPS: usize = 160;

/// How far a sampled cell is widened on each side, relative to its width
/// (the part outside the input set is projected onto its boundary, where
/// violations of ACAS Xu's properties often lie).
const WIDEN: f64 = 0.25;

/// Samples drawn and evaluated per chunk (one seeded generator each).
const CHUNK: usize = 1024;

/// Starts walked per group (the groups run one after the other, the
/// starts of a group on the threads).
const GROUP: usize = 4;

/// What one stage searches: the property, where, and how much.
pub(super) struct Stage<'a> {
    /// The property.
    pub k: usize,
    /// The open cells to sample.
    pub cells: &'a [IBox],
    /// Uniform samples drawn.
    pub samples: usize,
    /// The best samples walked from.
    pub starts: usize,
    /// The stage's seed (mixed with each chunk's and start's index).
    pub seed: u64,
}

/// A seed for part `i` of a stage with seed `seed`.
fn part_seed(seed: u64, i: usize) -> u64 {
    let mut r = Rng::new(seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    r.next_u64()
}

/// The seed of stage `stage` for property `k` of a plan seeded `seed`.
pub(super) fn stage_seed(seed: u64, stage: usize, k: usize) -> u64 {
    part_seed(part_seed(seed ^ 0x10CA_15EA_4C40_0000, stage), k)
}

impl Ctx<'_> {
    /// The `f64` violation of property `k` at each point (positive:
    /// violated), the points evaluated as one batch.
    pub(super) fn violations(&self, k: usize, pts: &[Vec<f64>]) -> Vec<f64> {
        let net = &self.plan.net;
        let (c, n, m) = (pts.len(), net.inputs, net.outputs());
        if c == 0 {
            return Vec::new();
        }
        let mut x = vec![0.0; n * c];
        for (s, p) in pts.iter().enumerate() {
            for (i, v) in p.iter().enumerate().take(n) {
                x[i * c + s] = *v;
            }
        }
        let y = net.forward_batch(&x, c);
        let kind = &self.props()[k].kind;
        let label = self.labels[k];
        let mut ys = vec![0.0; m];
        (0..c)
            .map(|s| {
                for (j, v) in ys.iter_mut().enumerate() {
                    *v = y[j * c + s];
                }
                violation(kind, label, &ys)
            })
            .collect()
    }

    /// The cells of `open` (each with its property-row bounds) on which
    /// property `k` is not proved.
    pub(super) fn open_for<'b>(
        &self,
        k: usize,
        open: impl Iterator<Item = (&'b IBox, &'b [f64])>,
    ) -> Vec<IBox> {
        let kind = &self.props()[k].kind;
        open.filter(|(_, b)| !proved(kind, cell_margin(kind, b, &self.ranges[k]).0))
            .map(|(c, _)| c.clone())
            .collect()
    }

    /// One stage of the local search (see the module documentation): a
    /// confirmed counterexample of property `k`, or `None`; the first
    /// real-arithmetic-only violation met is kept in `real_only`. Stops
    /// between groups of starts when `late()`.
    pub(super) fn local_search(
        &self,
        st: &Stage,
        late: &(dyn Fn() -> bool + Sync),
        real_only: &mut Option<Vec<f64>>,
    ) -> Option<Witness> {
        if st.cells.is_empty() || st.samples == 0 || st.starts == 0 {
            return None;
        }
        let root = self.region.bbox();
        let n = root.dim();
        let width: Vec<f64> = (0..n).map(|i| root.hi[i] - root.lo[i]).collect();
        // each cell's volume relative to the set's, for the choice by volume
        let mut cum = Vec::with_capacity(st.cells.len());
        let mut total = 0.0;
        for c in st.cells {
            let v: f64 = (0..n)
                .map(|i| {
                    if width[i] > 0.0 {
                        (c.hi[i] - c.lo[i]) / width[i]
                    } else {
                        1.0
                    }
                })
                .product();
            total += if v.is_finite() && v > 0.0 { v } else { 0.0 };
            cum.push(total);
        }
        let by_volume = total > 0.0 && total.is_finite();
        // the samples, chunk by chunk: each chunk's best `starts`
        let chunks: Vec<usize> = (0..st.samples.div_ceil(CHUNK)).collect();
        let best = map_ordered(&chunks, self.ctl.threads, &|&ch: &usize| {
            if late() {
                return Vec::new();
            }
            let mut rng = Rng::new(part_seed(st.seed, ch));
            let count = CHUNK.min(st.samples - ch * CHUNK);
            let pts: Vec<Vec<f64>> = (0..count)
                .filter_map(|s| {
                    let at = if by_volume && s % 2 == 0 {
                        let u = rng.unit() * total;
                        cum.partition_point(|&c| c <= u).min(st.cells.len() - 1)
                    } else {
                        rng.below(st.cells.len())
                    };
                    // the cell widened by [`WIDEN`] on every side, then
                    // projected into the set: a cell on the set's boundary
                    // gives points on its faces, edges and corners too
                    let c = &st.cells[at];
                    let x = (0..n)
                        .map(|i| {
                            let w = WIDEN * (c.hi[i] - c.lo[i]);
                            rng.uniform(c.lo[i] - w, c.hi[i] + w)
                        })
                        .collect();
                    project(self.region, x)
                })
                .collect();
            let vs = self.violations(st.k, &pts);
            let mut ranked: Vec<(f64, Vec<f64>)> = vs.into_iter().zip(pts).collect();
            ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
            ranked.truncate(st.starts);
            ranked
        });
        // the best over the chunks (ties: the earlier chunk and sample)
        let mut ranked: Vec<(f64, Vec<f64>)> = best.into_iter().flatten().collect();
        ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
        ranked.truncate(st.starts);
        let starts: Vec<(usize, (f64, Vec<f64>))> = ranked.into_iter().enumerate().collect();
        for group in starts.chunks(GROUP) {
            if late() {
                return None;
            }
            let found = map_ordered(group, self.ctl.threads, &|(s, (v, x)): &(
                usize,
                (f64, Vec<f64>),
            )| {
                let mut real = None;
                let seed = part_seed(st.seed ^ 0x5741_4C4B, *s);
                let w = self.walk(st.k, x.clone(), *v, seed, &width, &mut real);
                (w, real)
            });
            let mut hit = None;
            for (w, real) in found {
                if real_only.is_none() {
                    *real_only = real;
                }
                if hit.is_none() {
                    hit = w;
                }
            }
            if hit.is_some() {
                return hit;
            }
        }
        None
    }

    /// The shrinking-box random search for property `k` from `x` (of
    /// violation `v`), with the generator seeded `seed`; `width` the input
    /// set's widths.
    fn walk(
        &self,
        k: usize,
        mut x: Vec<f64>,
        mut v: f64,
        seed: u64,
        width: &[f64],
        real_only: &mut Option<Vec<f64>>,
    ) -> Option<Witness> {
        if v >= 0.0 {
            if let Some(w) = self.confirmed(k, &x, real_only) {
                return Some(w);
            }
        }
        let mut rng = Rng::new(seed);
        let mut r: Vec<f64> = width.iter().map(|w| RADIUS * w).collect();
        let floor = FLOOR * width.iter().fold(0.0f64, |a, w| a.max(*w));
        for _ in 0..STEPS {
            if r.iter().fold(0.0f64, |a, v| a.max(*v)) <= floor {
                break;
            }
            let pts: Vec<Vec<f64>> = (0..DRAWS)
                .filter_map(|_| {
                    let y = x
                        .iter()
                        .zip(&r)
                        .map(|(xi, ri)| xi + ri * (2.0 * rng.unit() - 1.0))
                        .collect();
                    project(self.region, y)
                })
                .collect();
            let vs = self.violations(k, &pts);
            let mut at = None;
            for (s, &w) in vs.iter().enumerate() {
                if w > at.map_or(v, |(_, b)| b) {
                    at = Some((s, w));
                }
            }
            match at {
                Some((s, w)) => {
                    x.clone_from(&pts[s]);
                    v = w;
                    if v >= 0.0 {
                        if let Some(w) = self.confirmed(k, &x, real_only) {
                            return Some(w);
                        }
                    }
                }
                None => r.iter_mut().for_each(|ri| *ri *= 0.5),
            }
        }
        None
    }
}
