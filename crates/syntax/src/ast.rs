//! The abstract syntax tree of a spec file. Every node keeps its source span.

use std::fmt;

/// A byte range in the source text.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Span {
    /// First byte.
    pub start: usize,
    /// One past the last byte.
    pub end: usize,
}

impl Span {
    /// A span from byte offsets.
    pub fn new(start: usize, end: usize) -> Span {
        Span { start, end }
    }
}

impl fmt::Debug for Span {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}..{}", self.start, self.end)
    }
}

/// A value with the span it was written at.
#[derive(Clone, PartialEq)]
pub struct Spanned<T> {
    /// The value.
    pub node: T,
    /// Where it was written.
    pub span: Span,
}

impl<T: fmt::Debug> fmt::Debug for Spanned<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if f.alternate() {
            write!(f, "{:#?} @{:?}", self.node, self.span)
        } else {
            write!(f, "{:?} @{:?}", self.node, self.span)
        }
    }
}

/// A parsed spec file: its items in source order.
#[derive(Clone, Debug, PartialEq)]
pub struct Spec {
    /// The top-level items.
    pub items: Vec<Item>,
}

/// A top-level item.
#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    /// `system NAME { … }`
    System(System),
    /// `controller "path"`
    Controller(Spanned<String>),
    /// `initial NAME = set`
    Initial(SetDef),
    /// `goal NAME = set`
    Goal(SetDef),
    /// `avoid NAME = set [at …]`
    Avoid(AvoidDef),
    /// `horizon N`
    Horizon(Spanned<u64>),
    /// `analysis { … }`
    Analysis(Analysis),
    /// `network NAME { input x[n] output y[m] }`
    Network(NetworkDecl),
    /// `model "path"`
    Model(Spanned<String>),
    /// `input NAME = set`
    Input(SetDef),
    /// `require NAME = set`
    Require(SetDef),
    /// `robust NAME [label K]`
    Robust(RobustDef),
    /// `radius NAME for PROPERTY (budget…)`
    Radius(RadiusDef),
    /// `select NAME { … }`
    Select(SelectDef),
}

/// `select NAME { epsilon …  norm …  observations … }`
#[derive(Clone, Debug, PartialEq)]
pub struct SelectDef {
    /// Its name.
    pub name: Spanned<String>,
    /// Its statements in order.
    pub stmts: Vec<Spanned<SelectStmt>>,
    /// The whole block.
    pub span: Span,
}

/// A statement of a select block.
#[derive(Clone, Debug, PartialEq)]
pub enum SelectStmt {
    /// `epsilon r` or `epsilon [r, …]`
    Epsilon(Spanned<Value>),
    /// `norm p`
    Norm(Spanned<String>),
    /// `observations [[…], …]`
    Inline(Spanned<Value>),
    /// `observations "file.csv"`
    File(Spanned<String>),
}

/// `network NAME { … }`
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkDecl {
    /// The network's name.
    pub name: Spanned<String>,
    /// `input x[n]`: name and dimension (absent if not written).
    pub input: Vec<(Spanned<String>, Spanned<u64>)>,
    /// `output y[m]`: name and dimension.
    pub output: Vec<(Spanned<String>, Spanned<u64>)>,
    /// The whole block.
    pub span: Span,
}

/// `robust NAME [label K]`
#[derive(Clone, Debug, PartialEq)]
pub struct RobustDef {
    /// The property's name.
    pub name: Spanned<String>,
    /// The label, if given (else the centre's).
    pub label: Option<Spanned<u64>>,
    /// The whole item.
    pub span: Span,
}

/// `radius NAME for PROPERTY (max s, tolerance t)`
#[derive(Clone, Debug, PartialEq)]
pub struct RadiusDef {
    /// The search's name.
    pub name: Spanned<String>,
    /// The property whose radius is searched.
    pub property: Spanned<String>,
    /// `(name, value)` budget items.
    pub budget: Vec<(Spanned<String>, Spanned<f64>)>,
    /// The whole item.
    pub span: Span,
}

/// `system NAME { … }`
#[derive(Clone, Debug, PartialEq)]
pub struct System {
    /// The system's name.
    pub name: Spanned<String>,
    /// Its statements in order.
    pub stmts: Vec<SystemStmt>,
    /// The whole block.
    pub span: Span,
}

/// A statement of a system block.
#[derive(Clone, Debug, PartialEq)]
pub enum SystemStmt {
    /// `state x[n]`
    State {
        /// The state vector's name.
        name: Spanned<String>,
        /// Its dimension.
        dim: Spanned<u64>,
        /// The whole statement.
        span: Span,
    },
    /// `control u[m]`
    Control {
        /// The control vector's name.
        name: Spanned<String>,
        /// Its dimension.
        dim: Spanned<u64>,
        /// The whole statement.
        span: Span,
    },
    /// `NAME in box(…)`
    Bound {
        /// The bounded quantity (`w`, `v` or the control).
        name: Spanned<String>,
        /// The box.
        set: Spanned<BoxSet>,
        /// The whole statement.
        span: Span,
    },
    /// `NAME = value`
    Assign {
        /// The parameter (`A`, `B`, `c` or `C`).
        name: Spanned<String>,
        /// The value.
        value: Spanned<Value>,
        /// The whole statement.
        span: Span,
    },
    /// `time continuous dt 0.1` / `time discrete`
    Time {
        /// `continuous` or `discrete`.
        kind: Spanned<String>,
        /// The time step, if given.
        dt: Option<Spanned<f64>>,
        /// The whole statement.
        span: Span,
    },
    /// `const NAME = expr`
    Const {
        /// The constant's name.
        name: Spanned<String>,
        /// Its value.
        value: Spanned<Expr>,
        /// The whole statement.
        span: Span,
    },
    /// `der x[i] = expr` (continuous time) or `next x[i] = expr` (discrete time)
    Equation {
        /// `der` or `next`.
        kind: Spanned<EquationKind>,
        /// The state component it defines.
        target: Component,
        /// The right-hand side.
        expr: Spanned<Expr>,
        /// The whole statement.
        span: Span,
    },
    /// `observe [e, …]`: the controller's inputs
    Observe {
        /// One expression per network input.
        exprs: Vec<Spanned<Expr>>,
        /// The whole statement.
        span: Span,
    },
    /// `actuate [e, …]`: the control from the network's outputs
    Actuate {
        /// One expression per control component.
        exprs: Vec<Spanned<Expr>>,
        /// The whole statement.
        span: Span,
    },
}

/// Which kind of equation defines a state component.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EquationKind {
    /// `der x[i] = …`: the derivative (continuous time).
    Der,
    /// `next x[i] = …`: the value one step later (discrete time).
    Next,
}

/// A binary operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinOp {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
}

/// An expression of a nonlinear plant, a constant, `observe` or `actuate`.
/// Every sub-expression carries its span; operators of one precedence level
/// are kept as one chain, so a long sum is a flat list, not a deep tree.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    /// A number as written (without sign: `-` is an operator).
    Number(f64),
    /// A name: a constant or `pi`.
    Name(String),
    /// `x[i]`: a component of a vector.
    Component(Component),
    /// `-a`
    Neg(Box<Spanned<Expr>>),
    /// `a op b op c …`: operators of one precedence level (`+ -` or `* /`),
    /// applied left to right.
    Chain {
        /// The first operand.
        first: Box<Spanned<Expr>>,
        /// Each operator with its right operand, in order.
        rest: Vec<(BinOp, Spanned<Expr>)>,
    },
    /// `a ^ b`
    Pow {
        /// The base.
        base: Box<Spanned<Expr>>,
        /// The exponent (an integer once folded).
        exp: Box<Spanned<Expr>>,
    },
    /// `f(a, …)`
    Call {
        /// The function's name.
        func: Spanned<String>,
        /// The arguments.
        args: Vec<Spanned<Expr>>,
    },
}

/// A literal value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `[[…], …]`, rows in order.
    Matrix(Vec<Spanned<Vec<Spanned<f64>>>>),
    /// `[…]`
    Vector(Vec<Spanned<f64>>),
    /// `eye(n)`
    Eye(Spanned<u64>),
    /// `zeros(n)` or `zeros(n, m)`
    Zeros(Spanned<u64>, Option<Spanned<u64>>),
    /// a bare number
    Scalar(f64),
    /// `per_step(v0, v1, …)`: one value per step
    PerStep(Vec<Spanned<Value>>),
}

/// A named set definition.
#[derive(Clone, PartialEq)]
pub struct SetDef {
    /// The set's name.
    pub name: Spanned<String>,
    /// The set.
    pub set: Spanned<SetExpr>,
    /// The whole item.
    pub span: Span,
    /// A goal's time clause (`at time T`, `always during […]`,
    /// `eventually during […]`); absent: at the horizon (and always for
    /// other sets).
    pub when: Option<Spanned<GoalWhen>>,
}

// Written out so that a set without a time clause prints as it did before
// the clause existed (the parse snapshots of every spec stay the same).
impl fmt::Debug for SetDef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut d = f.debug_struct("SetDef");
        d.field("name", &self.name)
            .field("set", &self.set)
            .field("span", &self.span);
        if let Some(w) = &self.when {
            d.field("when", w);
        }
        d.finish()
    }
}

/// When a goal applies, in seconds of the plant's time.
#[derive(Clone, Debug, PartialEq)]
pub enum GoalWhen {
    /// `at time T`: at the sampling instant `T`.
    AtTime(Spanned<f64>),
    /// `always during [t0, t1]`: at every instant of the window.
    Always(Window),
    /// `eventually during [t0, t1]`: at some instant of the window.
    Eventually(Window),
}

/// `during [t0, t1]`: a window of time in seconds, both ends included.
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// The first time.
    pub t0: Spanned<f64>,
    /// The last time.
    pub t1: Spanned<f64>,
    /// The whole `during [t0, t1]`.
    pub span: Span,
}

/// An avoid-set definition.
#[derive(Clone, PartialEq)]
pub struct AvoidDef {
    /// The set's name.
    pub name: Spanned<String>,
    /// The set (possibly a union).
    pub set: Spanned<SetExpr>,
    /// The steps at which it applies (inclusive); all steps if absent.
    pub steps: Option<Spanned<(u64, u64)>>,
    /// The whole item.
    pub span: Span,
    /// `during [t0, t1]`: the window of time in seconds instead of steps.
    pub during: Option<Window>,
}

// Written out so that an avoid set without `during` prints as before.
impl fmt::Debug for AvoidDef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut d = f.debug_struct("AvoidDef");
        d.field("name", &self.name)
            .field("set", &self.set)
            .field("steps", &self.steps)
            .field("span", &self.span);
        if let Some(w) = &self.during {
            d.field("during", w);
        }
        d.finish()
    }
}

/// A union of basic sets (one member for a plain set).
#[derive(Clone, Debug, PartialEq)]
pub struct SetExpr {
    /// The members of the union.
    pub members: Vec<Spanned<SetAtom>>,
}

/// A basic set.
#[derive(Clone, Debug, PartialEq)]
pub enum SetAtom {
    /// `box(…)`
    Box(BoxSet),
    /// `{ … }`
    Polytope(Vec<Constraint>),
    /// `ball(center […], radius …, norm p)`
    Ball(BallSet),
    /// `{ … }` with at least one inequality between expressions (a set
    /// whose rows are all linear in the written form is a `Polytope`).
    Inequalities(Vec<SetRow>),
}

/// One inequality of a set `{ … }`.
#[derive(Clone, Debug, PartialEq)]
pub enum SetRow {
    /// `Σ coef·x[i] (<= | >=) rhs`
    Linear(Constraint),
    /// `expr (<= | >=) expr`
    General(Inequality),
}

/// `lhs (<= | >=) rhs` between two expressions.
#[derive(Clone, Debug, PartialEq)]
pub struct Inequality {
    /// The left-hand side.
    pub lhs: Spanned<Expr>,
    /// The comparison.
    pub cmp: Cmp,
    /// The right-hand side.
    pub rhs: Spanned<Expr>,
    /// The whole inequality.
    pub span: Span,
}

/// An ℓp ball as written.
#[derive(Clone, Debug, PartialEq)]
pub struct BallSet {
    /// The centre.
    pub center: Spanned<Vec<Spanned<f64>>>,
    /// The radius: a number or one per dimension.
    pub radius: Spanned<Value>,
    /// `1`, `2` or `inf` (absent: 2).
    pub norm: Option<Spanned<String>>,
}

/// A box, by component or positionally.
#[derive(Clone, Debug, PartialEq)]
pub enum BoxSet {
    /// `box(x[0] in [a, b], …)`
    Named(Vec<(Component, Interval)>),
    /// `box([a, b], …)`
    Positional(Vec<Interval>),
}

/// `[lo, hi]`
#[derive(Clone, Debug, PartialEq)]
pub struct Interval {
    /// Lower end.
    pub lo: Spanned<f64>,
    /// Upper end.
    pub hi: Spanned<f64>,
    /// The whole interval.
    pub span: Span,
}

/// `x[i]`
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// The vector's name.
    pub name: Spanned<String>,
    /// The index.
    pub index: Spanned<u64>,
    /// The whole component.
    pub span: Span,
}

/// `Σ coef·x[i] (<= | >=) rhs`
#[derive(Clone, Debug, PartialEq)]
pub struct Constraint {
    /// Terms with signed coefficients.
    pub terms: Vec<(f64, Component)>,
    /// The comparison.
    pub cmp: Cmp,
    /// The right-hand side.
    pub rhs: Spanned<f64>,
    /// The whole constraint.
    pub span: Span,
}

/// A comparison operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cmp {
    /// `<=`
    Le,
    /// `>=`
    Ge,
}

/// `analysis { … }`
#[derive(Clone, Debug, PartialEq)]
pub struct Analysis {
    /// Its statements.
    pub stmts: Vec<Spanned<AnalysisStmt>>,
    /// The whole block.
    pub span: Span,
}

/// A statement of the analysis block.
#[derive(Clone, Debug, PartialEq)]
pub enum AnalysisStmt {
    /// `propagator NAME`
    Propagator(Spanned<String>),
    /// `partitioner none` / `partitioner NAME`
    Partitioner(Spanned<String>),
    /// `partitioner uniform [k, …]`
    Uniform(Vec<Spanned<u64>>),
    /// `boundary NAME`
    Boundary(Spanned<String>),
    /// `boundary polytope K` (a count) or `boundary polytope [[…], …]`
    BoundaryPolytope(Spanned<Value>),
    /// `partitioner sg|gsg|property (budget…)`
    Guided {
        /// The guide's name.
        guide: Spanned<String>,
        /// `(name, value)` budget items.
        budget: Vec<(Spanned<String>, Spanned<f64>)>,
    },
    /// `shape NAME` (network specs)
    Shape(Spanned<String>),
    /// `shape polytope K` or `shape polytope [[…], …]` (network specs)
    ShapePolytope(Spanned<Value>),
    /// `samples N`
    Samples(Spanned<u64>),
    /// `seed N`
    Seed(Spanned<u64>),
    /// `optimise_slopes N`
    OptimiseSlopes(Spanned<u64>),
}
