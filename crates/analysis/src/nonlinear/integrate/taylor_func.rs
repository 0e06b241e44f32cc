//! The recurrences of the elementary functions and integer powers (see
//! [`super::taylor`] for the formulas).

use super::flow::FlowError;
use super::interval::DomainError;
use super::taylor::{cauchy, divide, weighted, Coeff, Engine};
use ravel_base::expr::Func;

/// Binary powering of `a^m` as products of auxiliary series: slot 0 is
/// `a`, operation `i` makes slot `i + 1` as the product of two earlier
/// slots; returns the operations and the slot of the result (`m ≥ 1`).
fn power_plan(m: u32) -> (Vec<(usize, usize)>, usize) {
    let mut ops = Vec::new();
    let (mut base, mut result, mut e) = (0usize, None::<usize>, m);
    while e > 0 {
        if e & 1 == 1 {
            result = Some(match result {
                None => base,
                Some(r) => {
                    ops.push((r, base));
                    ops.len()
                }
            });
        }
        e >>= 1;
        if e > 0 {
            ops.push((base, base));
            base = ops.len();
        }
    }
    (ops, result.unwrap_or(0))
}

impl<T: Coeff> Engine<'_, T> {
    /// Coefficient `k` of `aᵖ` (node `id`).
    pub(super) fn powi(&mut self, id: usize, a: u32, p: i32, k: usize) -> Result<T, FlowError> {
        let m = p.unsigned_abs();
        if m == 0 {
            return if k == 0 { self.lift(1.0) } else { self.zero() };
        }
        let zero = self.zero()?;
        let (ops, result) = power_plan(m);
        let ak = self.coef(a, k)?;
        self.aux_mut(id, 0)?.push(ak);
        for (i, &(x, y)) in ops.iter().enumerate() {
            let v = cauchy(self.aux(id, x)?, self.aux(id, y)?, k, (0, k), &zero)?;
            self.aux_mut(id, i + 1)?.push(v);
        }
        let pk = self
            .aux(id, result)?
            .get(k)
            .cloned()
            .ok_or(FlowError::Malformed)?;
        if p > 0 {
            return Ok(pk);
        }
        // 1 / aᵐ: the reciprocal of the power's series
        let one_k = if k == 0 {
            self.lift(1.0)?
        } else {
            zero.clone()
        };
        let q = self.series(id as u32)?;
        divide(&one_k, self.aux(id, result)?, q, k, &zero)
    }

    /// Coefficient `k` of `f(a)` (node `id`).
    pub(super) fn func(&mut self, id: usize, f: Func, a: u32, k: usize) -> Result<T, FlowError> {
        let zero = self.zero()?;
        let a0 = self.coef(a, 0)?;
        if k == 0 && !matches!(f, Func::Sin | Func::Cos | Func::Tan | Func::Tanh) {
            if f == Func::Abs && self.smooth {
                return self.abs(a, 0);
            }
            return Ok(a0.apply(f)?);
        }
        let kf = k as f64;
        let sa = self.series(a)?;
        let own = self.series(id as u32)?;
        Ok(match f {
            Func::Exp => weighted(sa, own, k, k, &zero)?.div_scalar(kf)?,
            Func::Log => {
                let s = weighted(own, sa, k, k - 1, &zero)?.div_scalar(kf)?;
                self.coef(a, k)?.sub(&s)?.div(&a0)?
            }
            Func::Sqrt => {
                let s = cauchy(own, own, k, (1, k - 1), &zero)?;
                let s0 = own.first().ok_or(FlowError::Malformed)?.scale(2.0)?;
                self.coef(a, k)?.sub(&s)?.div(&s0)?
            }
            Func::Sin | Func::Cos => return self.sin_cos(id, f == Func::Sin, a, k),
            Func::Tan | Func::Tanh => return self.tan_tanh(id, f == Func::Tan, a, k),
            Func::Abs => return self.abs(a, k),
        })
    }

    /// `sign(a₀)·a_k`, or [`DomainError::AbsKink`].
    fn abs(&self, a: u32, k: usize) -> Result<T, FlowError> {
        let r = self.coef(a, 0)?.range();
        let ak = self.coef(a, k)?;
        if r.lo > 0.0 {
            Ok(ak)
        } else if r.hi < 0.0 {
            Ok(ak.neg())
        } else if r.is_finite() {
            Err(DomainError::AbsKink.into())
        } else {
            Err(DomainError::NotFinite.into())
        }
    }

    /// `sin a` (or `cos a`) with its companion in auxiliary slot 0.
    fn sin_cos(&mut self, id: usize, sine: bool, a: u32, k: usize) -> Result<T, FlowError> {
        let (own, other) = if k == 0 {
            let a0 = self.coef(a, 0)?;
            let (s, c) = (a0.apply(Func::Sin)?, a0.apply(Func::Cos)?);
            if sine {
                (s, c)
            } else {
                (c, s)
            }
        } else {
            let zero = self.zero()?;
            let sa = self.series(a)?;
            let (own, other) = (self.series(id as u32)?, self.aux(id, 0)?);
            // s' = c·a', c' = −s·a'
            let from_other = weighted(sa, other, k, k, &zero)?.div_scalar(k as f64)?;
            let from_own = weighted(sa, own, k, k, &zero)?.div_scalar(k as f64)?;
            if sine {
                (from_other, from_own.neg())
            } else {
                (from_other.neg(), from_own)
            }
        };
        self.aux_mut(id, 0)?.push(other);
        Ok(own)
    }

    /// `tan a` (`t' = (1 + t²)a'`) or `tanh a` (`t' = (1 − t²)a'`), with
    /// `w = 1 ± t²` in auxiliary slot 0.
    fn tan_tanh(&mut self, id: usize, tan: bool, a: u32, k: usize) -> Result<T, FlowError> {
        let zero = self.zero()?;
        let sign = if tan { 1.0 } else { -1.0 };
        let (t, sq) = if k == 0 {
            let t0 = self
                .coef(a, 0)?
                .apply(if tan { Func::Tan } else { Func::Tanh })?;
            let sq = t0.mul(&t0)?;
            (t0, sq)
        } else {
            let sa = self.series(a)?;
            let w = self.aux(id, 0)?;
            let tk = weighted(sa, w, k, k, &zero)?.div_scalar(k as f64)?;
            let own = self.series(id as u32)?;
            let t0 = own.first().ok_or(FlowError::Malformed)?;
            // (t²)_k = Σ_{1≤j<k} t_j t_{k−j} + 2·t₀·t_k
            let inner = cauchy(own, own, k, (1, k - 1), &zero)?;
            let sq = inner.add(&t0.mul(&tk)?.scale(2.0)?)?;
            (tk, sq)
        };
        let w_k = if k == 0 {
            self.lift(1.0)?.add(&sq.scale(sign)?)?
        } else {
            sq.scale(sign)?
        };
        self.aux_mut(id, 0)?.push(w_k);
        Ok(t)
    }
}
