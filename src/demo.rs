//! The task of the CARRL demonstration (`ravel-carrl-demo`): keeping a lane
//! with discrete accelerations, and its optimal action values.
//!
//! State `(x, v)`: lateral position and velocity. Actions: accelerate by
//! `−2`, `0` or `+2`. One step of `DT = 0.1`: `x⁺ = x + DT·v`,
//! `v⁺ = clamp(v + DT·a, ±V_MAX)`. Reward `1 − min(x², 1)` per step; leaving
//! `|x| ≤ CRASH` ends the episode with `CRASH_REWARD`. The optimal action
//! values (discount `GAMMA`) come from value iteration on a grid with
//! bilinear interpolation; `ravel-models` fits a Q-network to them.

/// The time step.
pub const DT: f64 = 0.1;
/// The accelerations of the three actions.
pub const ACTIONS: [f64; 3] = [-2.0, 0.0, 2.0];
/// The discount of the action values.
pub const GAMMA: f64 = 0.95;
/// Leaving `|x| ≤ CRASH` ends an episode.
pub const CRASH: f64 = 1.5;
/// The reward of a crash.
pub const CRASH_REWARD: f64 = -5.0;
/// The speed limit.
pub const V_MAX: f64 = 2.5;

/// One step: the next state, the reward, and whether the episode ended.
pub fn step(s: [f64; 2], a: usize) -> ([f64; 2], f64, bool) {
    let x = s[0] + DT * s[1];
    let v = (s[1] + DT * ACTIONS[a]).clamp(-V_MAX, V_MAX);
    if x.abs() > CRASH {
        return ([x, v], CRASH_REWARD, true);
    }
    ([x, v], 1.0 - (x * x).min(1.0), false)
}

/// Optimal action values on a grid, by value iteration.
pub struct Values {
    xs: Vec<f64>,
    vs: Vec<f64>,
    /// `value[i * vs.len() + j]` at `(xs[i], vs[j])`.
    value: Vec<f64>,
}

impl Values {
    /// Value iteration on `nx × nv` grid points over `|x| ≤ CRASH`, `|v| ≤ V_MAX`.
    pub fn solve(nx: usize, nv: usize, sweeps: usize) -> Values {
        let grid = |n: usize, m: f64| -> Vec<f64> {
            (0..n)
                .map(|k| -m + 2.0 * m * k as f64 / (n - 1) as f64)
                .collect()
        };
        let mut v = Values {
            xs: grid(nx, CRASH),
            vs: grid(nv, V_MAX),
            value: vec![0.0; nx * nv],
        };
        for _ in 0..sweeps {
            let next: Vec<f64> = (0..nx * nv)
                .map(|k| {
                    let s = [v.xs[k / nv], v.vs[k % nv]];
                    (0..ACTIONS.len())
                        .map(|a| v.q(s, a))
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect();
            v.value = next;
        }
        v
    }

    /// The optimal value of state `s` (bilinear interpolation; clamped to the grid).
    pub fn value(&self, s: [f64; 2]) -> f64 {
        let locate = |g: &[f64], t: f64| -> (usize, f64) {
            let n = g.len();
            let u = ((t - g[0]) / (g[n - 1] - g[0]) * (n - 1) as f64).clamp(0.0, (n - 1) as f64);
            let i = (u.floor() as usize).min(n - 2);
            (i, u - i as f64)
        };
        let (i, fx) = locate(&self.xs, s[0]);
        let (j, fv) = locate(&self.vs, s[1]);
        let nv = self.vs.len();
        let at = |a: usize, b: usize| self.value[a * nv + b];
        (1.0 - fx) * ((1.0 - fv) * at(i, j) + fv * at(i, j + 1))
            + fx * ((1.0 - fv) * at(i + 1, j) + fv * at(i + 1, j + 1))
    }

    /// The optimal value of action `a` in state `s`.
    pub fn q(&self, s: [f64; 2], a: usize) -> f64 {
        let (n, r, done) = step(s, a);
        if done {
            r
        } else {
            r + GAMMA * self.value(n)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steering_back_to_the_lane_is_better_than_away() {
        let v = Values::solve(33, 27, 150);
        // drifting right near the edge: braking (−2) beats accelerating (+2)
        let s = [0.8, 0.5];
        assert!(v.q(s, 0) > v.q(s, 2));
        assert!(step([1.49, 1.0], 2).2, "leaving the lane ends the episode");
    }
}
