//! The `time` declaration of a system block (`time discrete`, or `time
//! continuous dt …`) and the zero-order hold that discretises a
//! continuous-time plant.

use nalgebra::{DMatrix, DVector};

use super::Ctx;
use ravel_analysis::closed_loop::{ModelError, Plant};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{did_you_mean, Code, Diagnostic};

impl Ctx {
    /// `time continuous dt …` / `time discrete`: `Some(dt)` for continuous time.
    pub(super) fn time_decl(
        &mut self,
        kind: &Spanned<String>,
        dt: &Option<Spanned<f64>>,
        span: Span,
    ) -> Result<Option<f64>, ()> {
        match (kind.node.as_str(), dt) {
            ("discrete", None) => Ok(None),
            ("discrete", Some(d)) => {
                self.err(
                    Diagnostic::new(
                        Code::TimeStep,
                        d.span,
                        "`dt` applies only to continuous time",
                    )
                    .label("a time step for a discrete-time plant")
                    .hint("write `time continuous dt …` to discretise A, B, c, or drop `dt`"),
                );
                Err(())
            }
            ("continuous", None) => {
                self.err(
                    Diagnostic::new(Code::TimeStep, span, "a continuous-time plant needs a time step")
                        .label("no `dt`")
                        .hint("write `time continuous dt 0.1`: the controller acts every dt seconds (zero-order hold)"),
                );
                Err(())
            }
            ("continuous", Some(d)) => {
                let x = self.finite(d);
                if x > 0.0 && x.is_finite() {
                    Ok(Some(x))
                } else {
                    self.err(
                        Diagnostic::new(
                            Code::TimeStep,
                            d.span,
                            format!(
                                "the time step must be positive, not {}",
                                ravel_syntax::diag::compact(d.node)
                            ),
                        )
                        .label("dt ≤ 0")
                        .hint("the controller's sampling period in seconds, e.g. `dt 0.1`"),
                    );
                    Err(())
                }
            }
            (other, _) => {
                let mut d = Diagnostic::new(
                    Code::UnknownName,
                    kind.span,
                    format!("unknown time kind `{other}`"),
                )
                .label("not a kind of time");
                d = match did_you_mean(other, ["continuous", "discrete"]) {
                    Some(s) => d.hint(format!("did you mean `{s}`?")),
                    None => d.hint("write `time continuous dt …` or `time discrete`"),
                };
                self.err(d);
                Err(())
            }
        }
    }
}

/// Exact zero-order-hold discretisation of `ẋ = A x + B u + c` over `dt`:
/// `exp([[A, B, c], [0, 0, 0]]·dt) = [[A_d, B_d, c_d], [0, I, 0…]]`, so
/// `A_d = e^{A dt}` and `B_d`, `c_d` are the input integrals `∫₀^dt e^{Aτ} dτ · (B, c)`.
/// The exponential is enclosed rigorously ([`ravel_analysis::expm`]), including the
/// rounding of `big·dt`; the enclosure's radius becomes the plant's
/// [`ModelError`], which every propagator adds to its bounds.
/// `None` when the exponential cannot be enclosed (overflow).
pub fn zero_order_hold(plant: &Plant, dt: f64) -> Option<Plant> {
    let n = plant.a.nrows();
    let m = plant.b.ncols();
    let k = n + m + 1;
    let mut big = DMatrix::<f64>::zeros(k, k);
    big.view_mut((0, 0), (n, n)).copy_from(&plant.a);
    big.view_mut((0, n), (n, m)).copy_from(&plant.b);
    big.view_mut((0, n + m), (n, 1)).copy_from(&plant.c);
    let scaled = &big * dt;
    let (e, mut err) = ravel_analysis::expm::expm_enclosure(&scaled)?;
    err += ravel_analysis::expm::rounding_bound(&scaled);
    if e.iter().chain(err.iter()).any(|v| !v.is_finite()) {
        return None;
    }
    Some(Plant {
        a: e.view((0, 0), (n, n)).into_owned(),
        b: e.view((0, n), (n, m)).into_owned(),
        c: DVector::from_iterator(n, e.view((0, n + m), (n, 1)).iter().copied()),
        obs: plant.obs.clone(),
        w: plant.w.clone(),
        v: plant.v.clone(),
        err: Some(ModelError {
            a: err.view((0, 0), (n, n)).into_owned(),
            b: err.view((0, n), (n, m)).into_owned(),
            c: DVector::from_iterator(n, err.view((0, n + m), (n, 1)).iter().copied()),
        }),
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use ravel_analysis::sets::IBox;

    #[test]
    fn zero_order_hold_of_a_double_integrator() {
        // ẋ = [[0, 1], [0, 0]] x + [0, 1] u: A_d = [[1, dt], [0, 1]], B_d = [dt²/2, dt]
        let p = Plant {
            a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]),
            b: DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            c: DVector::from_column_slice(&[0.0, -2.0]),
            obs: DMatrix::identity(2, 2),
            w: IBox::new(vec![0.0; 2], vec![0.0; 2]),
            v: IBox::new(vec![0.0; 2], vec![0.0; 2]),
            err: None,
        };
        let d = zero_order_hold(&p, 0.5).expect("finite");
        let e = d
            .err
            .as_ref()
            .expect("a discretised plant carries its error");
        // exact values inside the enclosure, whose radius is a few ulps of the entries
        let within = |x: f64, want: f64, r: f64| (x - want).abs() <= r && r < 1e-13;
        assert!(within(d.a[(0, 1)], 0.5, e.a[(0, 1)]) && within(d.a[(0, 0)], 1.0, e.a[(0, 0)]));
        assert!(within(d.a[(1, 0)], 0.0, e.a[(1, 0)]) && within(d.a[(1, 1)], 1.0, e.a[(1, 1)]));
        assert!(within(d.b[(0, 0)], 0.125, e.b[(0, 0)]) && within(d.b[(1, 0)], 0.5, e.b[(1, 0)]));
        assert!(within(d.c[0], -0.25, e.c[0]) && within(d.c[1], -1.0, e.c[1]));
    }

    /// A stiff oscillator `ẋ0 = x1, ẋ1 = −ω² x0 + β u`: the closed form
    /// `A_d = [[cos ωT, sin ωT / ω], [−ω sin ωT, cos ωT]]`,
    /// `B_d = β [(1 − cos ωT)/ω², sin ωT / ω]` lies in the enclosure, whose
    /// radius stays near the rounding of the entries (it was ±618 for
    /// `ω = 2π`, `T = 1`, when the rounding of `A·T` was bounded through
    /// `e^{‖A T‖∞}`).
    #[test]
    fn zero_order_hold_of_a_stiff_oscillator() {
        for (w, dt) in [
            (std::f64::consts::TAU, 1.0),
            (6.0, 0.9),
            (20.0, 0.3),
            (1.5, 2.0),
        ] {
            let beta = 0.25;
            let p = Plant {
                a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, 0.0]),
                b: DMatrix::from_row_slice(2, 1, &[0.0, beta]),
                c: DVector::from_column_slice(&[0.0, 0.0]),
                obs: DMatrix::identity(2, 2),
                w: IBox::new(vec![0.0; 2], vec![0.0; 2]),
                v: IBox::new(vec![0.0; 2], vec![0.0; 2]),
                err: None,
            };
            let d = zero_order_hold(&p, dt).expect("finite");
            let e = d.err.as_ref().expect("an error bound");
            let (c, s) = ((w * dt).cos(), (w * dt).sin());
            let want_a = [c, -w * s, s / w, c]; // column-major
            let want_b = [beta * (1.0 - c) / (w * w), beta * s / w];
            // the closed form in f64: cos and sin of the rounded ωT, the
            // error of that argument times ω in the largest entry
            let slack = 8.0 * f64::EPSILON * (1.0 + w).powi(2) * (1.0 + dt);
            for (i, want) in want_a.iter().enumerate() {
                assert!((d.a[i] - want).abs() <= e.a[i] + slack, "ω {w}, A {i}");
                assert!(e.a[i] < 1e-9, "ω {w}, T {dt}: A {i} ± {}", e.a[i]);
            }
            for (i, want) in want_b.iter().enumerate() {
                assert!((d.b[i] - want).abs() <= e.b[i] + slack, "ω {w}, B {i}");
                assert!(e.b[i] < 1e-9, "ω {w}, T {dt}: B {i} ± {}", e.b[i]);
            }
        }
    }
}
