//! Expressions of a nonlinear plant: a flat tape of nodes in topological
//! order, over one vector of variables.
//!
//! A [`VectorField`] is what a spec's `der x[i] = …` (continuous time) or
//! `next x[i] = …` (discrete time) lines become after checking: one output
//! node per state component, over the variables `[x (n), u (m), w (p)]` —
//! the states, then the controls, then the disturbances, in that order.
//!
//! This module is plain data and `f64` evaluation only. The validated
//! arithmetic (intervals, Taylor models) lives with the analysis, and the
//! certificate checker brings its own; both read the same tape.
//!
//! A literal means its `f64` value: the plant analysed is the one whose
//! constants are the doubles the spec's decimals round to (as for linear
//! plants), and `pi` is the double nearest π.

/// The index of a node in its [`Tape`].
pub type Id = u32;

/// An elementary function of one argument.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Func {
    /// `sin`
    Sin,
    /// `cos`
    Cos,
    /// `tan`
    Tan,
    /// `exp`
    Exp,
    /// `log` (natural)
    Log,
    /// `sqrt`
    Sqrt,
    /// `tanh`
    Tanh,
    /// `abs`
    Abs,
}

impl Func {
    /// Every function, in the order of the documentation.
    pub const ALL: [Func; 8] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Exp,
        Func::Log,
        Func::Sqrt,
        Func::Tanh,
        Func::Abs,
    ];

    /// The spec-language name.
    pub fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Exp => "exp",
            Func::Log => "log",
            Func::Sqrt => "sqrt",
            Func::Tanh => "tanh",
            Func::Abs => "abs",
        }
    }

    /// The function with this spec-language name.
    pub fn from_name(name: &str) -> Option<Func> {
        Func::ALL.into_iter().find(|f| f.name() == name)
    }

    /// The function at a point, in `f64` (the platform's `libm`).
    pub fn apply(self, a: f64) -> f64 {
        match self {
            Func::Sin => a.sin(),
            Func::Cos => a.cos(),
            Func::Tan => a.tan(),
            Func::Exp => a.exp(),
            Func::Log => a.ln(),
            Func::Sqrt => a.sqrt(),
            Func::Tanh => a.tanh(),
            Func::Abs => a.abs(),
        }
    }
}

/// One node of a tape. Operands are ids of earlier nodes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Node {
    /// A constant.
    Const(f64),
    /// Variable `i` of the tape's variable vector.
    Var(u32),
    /// `−a`
    Neg(Id),
    /// `a + b`
    Add(Id, Id),
    /// `a − b`
    Sub(Id, Id),
    /// `a · b`
    Mul(Id, Id),
    /// `a / b`
    Div(Id, Id),
    /// `aⁿ` for an integer `n` (negative: `1 / a⁻ⁿ`).
    Powi(Id, i32),
    /// `f(a)`
    Func(Func, Id),
}

/// Nodes in topological order: every operand id is smaller than the id of
/// the node that uses it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tape {
    /// The nodes.
    pub nodes: Vec<Node>,
}

impl Tape {
    /// An empty tape.
    pub fn new() -> Tape {
        Tape::default()
    }

    /// Append a node and return its id. Operands must be earlier nodes
    /// (checked in debug builds; the builders in `check` guarantee it).
    pub fn push(&mut self, node: Node) -> Id {
        debug_assert!(operands(&node)
            .iter()
            .all(|&o| (o as usize) < self.nodes.len()));
        let id = self.nodes.len() as Id;
        self.nodes.push(node);
        id
    }

    /// Whether every operand refers to an earlier node and every variable
    /// index is below `vars` (what a tape read from outside must satisfy
    /// before it is evaluated).
    pub fn is_well_formed(&self, vars: usize) -> bool {
        self.nodes.iter().enumerate().all(|(i, n)| {
            operands(n).iter().all(|&o| (o as usize) < i)
                && match n {
                    Node::Var(v) => (*v as usize) < vars,
                    _ => true,
                }
        })
    }

    /// Every node's value at `vars`, in `f64` (no rounding control: for
    /// simulation, never for a bound). `values` is resized to the tape.
    pub fn eval_into(&self, vars: &[f64], values: &mut Vec<f64>) {
        values.clear();
        for node in &self.nodes {
            let v = match *node {
                Node::Const(c) => c,
                Node::Var(i) => vars.get(i as usize).copied().unwrap_or(f64::NAN),
                Node::Neg(a) => -at(values, a),
                Node::Add(a, b) => at(values, a) + at(values, b),
                Node::Sub(a, b) => at(values, a) - at(values, b),
                Node::Mul(a, b) => at(values, a) * at(values, b),
                Node::Div(a, b) => at(values, a) / at(values, b),
                Node::Powi(a, n) => at(values, a).powi(n),
                Node::Func(f, a) => f.apply(at(values, a)),
            };
            values.push(v);
        }
    }
}

/// The operands of a node.
pub fn operands(node: &Node) -> Vec<Id> {
    match *node {
        Node::Const(_) | Node::Var(_) => Vec::new(),
        Node::Neg(a) | Node::Powi(a, _) | Node::Func(_, a) => vec![a],
        Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) | Node::Div(a, b) => vec![a, b],
    }
}

fn at(values: &[f64], id: Id) -> f64 {
    values.get(id as usize).copied().unwrap_or(f64::NAN)
}

/// How time passes in a nonlinear plant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Time {
    /// `ẋ = f(x, u, w)`, the control held constant over each control period
    /// (a zero-order hold), and so is the disturbance.
    Continuous {
        /// The control period in seconds.
        period: f64,
    },
    /// `x⁺ = f(x, u, w)`, one application per step.
    Discrete,
}

/// A plant's right-hand side: `outputs[i]` is `ẋ_i` (continuous time) or
/// `x⁺_i` (discrete time) as a node of `tape`, over the variables
/// `[x (states), u (controls), w (disturbances)]`.
#[derive(Clone, Debug, PartialEq)]
pub struct VectorField {
    /// The nodes.
    pub tape: Tape,
    /// One node per state component.
    pub outputs: Vec<Id>,
    /// `n`: the state dimension (`outputs.len()`).
    pub states: usize,
    /// `m`: the control dimension.
    pub controls: usize,
    /// `p`: the disturbance dimension.
    pub disturbances: usize,
    /// Continuous or discrete time.
    pub time: Time,
}

impl VectorField {
    /// `n + m + p`: the length of the variable vector.
    pub fn vars(&self) -> usize {
        self.states + self.controls + self.disturbances
    }

    /// The right-hand side at `(x, u, w)` in `f64` (simulation only).
    pub fn eval(&self, x: &[f64], u: &[f64], w: &[f64], values: &mut Vec<f64>) -> Vec<f64> {
        let vars: Vec<f64> = x.iter().chain(u).chain(w).copied().collect();
        self.tape.eval_into(&vars, values);
        self.outputs.iter().map(|&o| at(values, o)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `ẋ0 = x1`, `ẋ1 = u0 · x1² − x0` (ReachNN's B1), evaluated at a point.
    #[test]
    fn a_tape_evaluates_in_order() {
        let mut t = Tape::new();
        let x0 = t.push(Node::Var(0));
        let x1 = t.push(Node::Var(1));
        let u = t.push(Node::Var(2));
        let sq = t.push(Node::Powi(x1, 2));
        let p = t.push(Node::Mul(u, sq));
        let d1 = t.push(Node::Sub(p, x0));
        let f = VectorField {
            tape: t,
            outputs: vec![x1, d1],
            states: 2,
            controls: 1,
            disturbances: 0,
            time: Time::Continuous { period: 0.2 },
        };
        assert!(f.tape.is_well_formed(3));
        assert!(!f.tape.is_well_formed(2));
        let mut scratch = Vec::new();
        assert_eq!(
            f.eval(&[1.0, 2.0], &[0.5], &[], &mut scratch),
            vec![2.0, 1.0]
        );
    }

    #[test]
    fn function_names_round_trip() {
        for f in Func::ALL {
            assert_eq!(Func::from_name(f.name()), Some(f));
        }
        assert_eq!(Func::from_name("sinh"), None);
    }
}
