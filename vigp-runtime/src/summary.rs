//! A rollout summary: energy error, constraint violation and time per step,
//! the numbers the examples print.

use crate::integrator::Integrator;
use crate::mechanism::{Mechanism, State};
use crate::newton::StepError;
use core::fmt;

/// What a rollout did to energy and constraints, and what it cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RolloutSummary {
    /// Steps taken.
    pub steps: usize,
    /// Energy of the initial state (J).
    pub initial_energy: f64,
    /// max_k |E_k − E_0| (J).
    pub max_energy_error: f64,
    /// E_last − E_0 (J): negative when damping dissipates energy.
    pub final_energy_change: f64,
    /// max_k |g(q_k)| over the rollout (0 for a tree).
    pub max_constraint_violation: f64,
    /// Wall-clock time per step in µs (median of 5 equal batches), including
    /// the energy and constraint evaluations of the summary itself.
    pub micros_per_step: f64,
}

impl fmt::Display for RolloutSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} steps | E0 = {:.6} J | max |ΔE| = {:.3e} J | E_end − E0 = {:.3e} J | max |g| = {:.2e} | {:.3} µs/step",
            self.steps,
            self.initial_energy,
            self.max_energy_error,
            self.final_energy_change,
            self.max_constraint_violation,
            self.micros_per_step
        )
    }
}

/// Roll `integrator` out for `steps` steps from `z0` on `model` and summarise.
/// Energies are the integrator's own ([`Integrator::state_energy`]: the
/// midpoint VI evaluates at the interval's midpoint, which is what makes its
/// energy error second order), else `model.energy`.
/// Timing: the rollout is split into 5 batches timed separately; the median
/// batch time per step is reported (robust to a noisy shared machine).
#[cfg(feature = "std")]
pub fn summarize<I, M, const N: usize, const C: usize>(
    integrator: &I,
    model: &M,
    z0: &State<N>,
    steps: usize,
) -> Result<RolloutSummary, StepError>
where
    I: Integrator<State = State<N>, Error = StepError>,
    M: Mechanism<N, C>,
{
    let energy = |z: &State<N>| {
        integrator
            .state_energy(z)
            .unwrap_or_else(|| model.energy(z))
    };
    let e0 = energy(z0);
    let mut z = *z0;
    let (mut max_de, mut max_g) = (0.0f64, model.constraint_violation(z0));
    let batches = 5;
    let per = steps.div_ceil(batches).max(1);
    let mut times = Vec::with_capacity(batches);
    let mut done = 0;
    while done < steps {
        let n = per.min(steps - done);
        let start = std::time::Instant::now();
        for k in 0..n {
            z = integrator.step(&z).map_err(|e| e.at_step(done + k))?;
            max_de = max_de.max((energy(&z) - e0).abs());
            max_g = max_g.max(model.constraint_violation(&z));
        }
        times.push(start.elapsed().as_secs_f64() * 1e6 / n as f64);
        done += n;
    }
    times.sort_by(f64::total_cmp);
    Ok(RolloutSummary {
        steps,
        initial_energy: e0,
        max_energy_error: max_de,
        final_energy_change: energy(&z) - e0,
        max_constraint_violation: max_g,
        micros_per_step: times.get(times.len() / 2).copied().unwrap_or(0.0),
    })
}
