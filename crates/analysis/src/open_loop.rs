//! Open-loop analysis of a network on its own: a sound description of
//! `f(X)` for an input box `X`, in a chosen [`Shape`], with the input box
//! partitioned uniformly or by the SG/GSG partitioners of
//! [`super::partition`].
//!
//! This is the network-level half of the tutorial's architecture
//! (partitioner + propagator + output shape). The closed loop uses it for the
//! control box of `sg_ibp_separate`; the open-loop problems of the language
//! (output reachable sets, robustness, robust action selection) are to be
//! stated on top of it.
//!
//! Soundness: every cell's offsets are CROWN (or IBP) bounds of `d·f(x)` over
//! the cell, rounded outward, intersected with the IBP box's support and with
//! the parent cell's offsets (a subset's bound); the union's offsets are the
//! largest over the cells, which cover the input box.

use nalgebra::DMatrix;

use super::crown::{Mode, Relaxation};
use super::partition::{refine, Bisector, Budget, Stop, Strategy};
use super::shape::{excess, extent_of_points, support_of_box, support_of_points, Shape};
use crate::sets::IBox;
use ravel_base::nn::Network;
use ravel_base::rng::Rng;

/// How the input box is split.
#[derive(Clone, Debug, PartialEq)]
pub enum Partitioner {
    /// A uniform grid with `k_i` cells along input `i` (all ones: none). The
    /// whole box is bounded first and every cell is intersected with it.
    Uniform(Vec<usize>),
    /// SG or GSG refinement by bisection, guided by the sampled outputs.
    Guided {
        /// Depth first (SG) or worst first (GSG).
        strategy: Strategy,
        /// When to stop.
        budget: Budget,
    },
}

/// A sound outer description `{y | D y ≤ offsets}` of `f(X)`.
#[derive(Clone, Debug)]
pub struct OutputSet {
    /// The directions `D`, one per row (see [`Shape::directions`]).
    pub directions: DMatrix<f64>,
    /// Certified upper bounds of `d·f(x)` over the whole input box.
    pub offsets: Vec<f64>,
    /// `max d·f(p)` over the sampled inputs (an under-approximation; `−∞`
    /// without samples).
    pub sampled: Vec<f64>,
    /// The final cells and their offsets.
    pub cells: Vec<(IBox, Vec<f64>)>,
    /// Cells bounded (including parents and the whole box).
    pub calls: usize,
    /// Why partitioning stopped.
    pub stop: Stop,
}

impl OutputSet {
    /// The bounding box, when the shape has one (every shape but lower bounds).
    pub fn bbox(&self) -> Option<IBox> {
        let m = self.directions.ncols();
        (self.offsets.len() >= 2 * m && self.directions.nrows() >= 2 * m && {
            (0..m).all(|i| self.directions[(i, i)] == 1.0 && self.directions[(m + i, i)] == -1.0)
        })
        .then(|| {
            IBox::new(
                self.offsets[m..2 * m].iter().map(|v| -v).collect(),
                self.offsets[..m].to_vec(),
            )
        })
    }

    /// The certified lower bound of every output component.
    pub fn lower_bounds(&self) -> Vec<f64> {
        let m = self.directions.ncols();
        (0..m)
            .map(|i| {
                (0..self.directions.nrows())
                    .filter(|&k| {
                        (0..m).all(|j| self.directions[(k, j)] == if i == j { -1.0 } else { 0.0 })
                    })
                    .map(|k| -self.offsets[k])
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .collect()
    }
}

/// The offsets of a union of cells: the largest of the cells' offsets per
/// direction (`−∞` without cells).
pub fn union_offsets<C>(cells: &[(C, Vec<f64>)], rows: usize) -> Vec<f64> {
    (0..rows)
        .map(|k| {
            cells
                .iter()
                .map(|(_, b)| b[k])
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .collect()
}

/// `n` input points of a box: its lowest and highest corners first, then
/// uniform points from a SplitMix64 stream seeded with `seed`.
pub fn sample_inputs(input: &IBox, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|k| match k {
            0 => input.lo.clone(),
            1 => input.hi.clone(),
            _ => (0..input.dim())
                .map(|i| rng.uniform(input.lo[i], input.hi[i]))
                .collect(),
        })
        .collect()
}

/// Certified offsets of `d·f(x)` over `cell` for every direction.
pub fn cell_offsets(net: &Network, cell: &IBox, mode: Mode, dirs: &DMatrix<f64>) -> Vec<f64> {
    let a = Relaxation::new(net, cell, mode);
    let out = a.boxes().last().cloned().unwrap_or_else(|| cell.clone());
    let mut b = support_of_box(dirs, &out.lo, &out.hi);
    if mode != Mode::Ibp {
        for (v, c) in b.iter_mut().zip(a.upper(dirs.clone()).concretize(cell)) {
            *v = v.min(c);
        }
    }
    b
}

/// Bound `f(input)` in `shape`. `inputs` are the sampled inputs that guide
/// the SG/GSG partitioners and shape a hull (see [`sample_inputs`]);
/// `elapsed` serves a time budget.
pub fn output_set(
    net: &Network,
    input: &IBox,
    mode: Mode,
    shape: &Shape,
    partitioner: &Partitioner,
    inputs: &[Vec<f64>],
    elapsed: &dyn Fn() -> f64,
) -> OutputSet {
    let outputs: Vec<Vec<f64>> = inputs.iter().map(|x| net.forward(x)).collect();
    let m = net.outputs();
    let directions = shape.directions(m, &outputs);
    let sampled = support_of_points(&directions, &outputs);
    let extent = extent_of_points(&directions, &outputs);
    let within = |b: &[f64], parent: Option<&Vec<f64>>| -> Vec<f64> {
        match parent {
            Some(p) => b.iter().zip(p).map(|(a, q)| a.min(*q)).collect(),
            None => b.to_vec(),
        }
    };
    let (cells, calls, stop): (Vec<(IBox, Vec<f64>)>, usize, Stop) = match partitioner {
        Partitioner::Uniform(grid) => {
            let root = cell_offsets(net, input, mode, &directions);
            let boxes = input.grid(grid);
            if boxes.len() <= 1 {
                (vec![(input.clone(), root)], 1, Stop::Grid)
            } else {
                let n = boxes.len() + 1;
                let cells = boxes
                    .into_iter()
                    .map(|c| {
                        let b = within(&cell_offsets(net, &c, mode, &directions), Some(&root));
                        (c, b)
                    })
                    .collect();
                (cells, n, Stop::Grid)
            }
        }
        Partitioner::Guided { strategy, budget } => {
            let r = refine(
                input,
                *strategy,
                budget,
                &mut |c, parent: Option<&Vec<f64>>| {
                    let b = within(&cell_offsets(net, c, mode, &directions), parent);
                    let s = excess(&b, &sampled, &extent);
                    (b, s)
                },
                elapsed,
                Bisector::Widest,
            );
            let cells = r.leaves.into_iter().map(|l| (l.cell, l.value)).collect();
            (cells, r.calls, r.stop)
        }
    };
    let offsets = union_offsets(&cells, directions.nrows());
    OutputSet {
        directions,
        offsets,
        sampled,
        cells,
        calls,
        stop,
    }
}
