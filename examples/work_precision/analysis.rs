//! Reading the curves: fitted orders and the cost to reach an error.

use crate::run::{Measured, Method, SweepPoint};

/// A least-squares fit log₁₀(error) = p·log₁₀(dt) + c.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    /// The fitted slope p (the observed order).
    pub slope: f64,
    /// Number of points used.
    pub points: usize,
    /// Smallest dt used.
    pub dt_min: f64,
    /// Largest dt used.
    pub dt_max: f64,
    /// Largest distance of a used point from the fitted line, in decades.
    pub max_residual: f64,
    /// Slopes between consecutive used points, from the largest dt to the
    /// smallest (a trend shows a pre-asymptotic regime).
    pub local: Vec<f64>,
}

/// Which points enter the order fit: the `max_points` smallest time steps
/// among those with a finite error in `[lo, hi]`, at least 10× the
/// run's own solver error (if it has a Newton iteration) and at least 10×
/// its accumulated round-off `steps · roundoff`, where `lo` keeps
/// clear of the reference's own error, the solver error of the
/// accumulated Newton tolerance, `hi` leaves out unstable large steps, and
/// taking the smallest steps stays in the asymptotic regime.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitWindow {
    /// Lower error limit.
    pub lo: f64,
    /// Upper error limit.
    pub hi: f64,
    /// At most this many points (the smallest dt).
    pub max_points: usize,
    /// Round-off per step, ε·max(1, ‖q_ref‖∞): a run of n steps has an
    /// error floor of about n times this (linear accumulation, the
    /// worst case).
    pub roundoff: f64,
}

impl FitWindow {
    /// `true` if the measured error of a run of `steps` steps is clear
    /// (by 10×) of the reference's error, the run's solver error and its
    /// accumulated round-off, and below `hi`.
    pub fn admits(&self, m: &Measured, steps: usize) -> bool {
        m.error.is_finite() && m.error <= self.hi && self.above_floor(m, steps)
    }

    /// `true` if a measured error is clear of the reference's error, the
    /// solver's error and round-off (large errors included): a filled
    /// marker in the plots.
    pub fn above_floor(&self, m: &Measured, steps: usize) -> bool {
        m.error >= self.lo
            && m.error >= 10.0 * steps as f64 * self.roundoff
            && m.solver_error.is_none_or(|s| m.error >= 10.0 * s)
    }
}

/// Fits the observed order over the points of one curve selected by
/// `window`; `None` with fewer than 3 such points.
pub fn fit_order(points: &[SweepPoint], window: FitWindow) -> Option<Fit> {
    // (dt, log10 dt, log10 error), smallest dt first
    let mut used: Vec<(f64, f64, f64)> = points
        .iter()
        .filter_map(|p| {
            let m = p.outcome.as_ref().ok()?;
            (window.admits(m, p.steps) && p.dt > 0.0).then(|| (p.dt, p.dt.log10(), m.error.log10()))
        })
        .collect();
    used.sort_by(|a, b| a.0.total_cmp(&b.0));
    used.truncate(window.max_points);
    if used.len() < 3 {
        return None;
    }
    let n = used.len() as f64;
    let mx = used.iter().map(|p| p.1).sum::<f64>() / n;
    let my = used.iter().map(|p| p.2).sum::<f64>() / n;
    let sxx: f64 = used.iter().map(|p| (p.1 - mx).powi(2)).sum();
    let sxy: f64 = used.iter().map(|p| (p.1 - mx) * (p.2 - my)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let slope = sxy / sxx;
    let max_residual = used
        .iter()
        .map(|p| (p.2 - (my + slope * (p.1 - mx))).abs())
        .fold(0.0, f64::max);
    let local = used
        .windows(2)
        .rev()
        .map(|w| (w[1].2 - w[0].2) / (w[1].1 - w[0].1))
        .collect();
    Some(Fit {
        slope,
        points: used.len(),
        dt_min: used[0].0,
        dt_max: used[used.len() - 1].0,
        max_residual,
        local,
    })
}

/// The cost at which a curve reaches an error target.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reach {
    /// Interpolated (log-log, between the two measured points around the
    /// crossing) cost in s per simulated s.
    Interpolated(f64),
    /// Already below the target at the cheapest usable point: at most this cost.
    AtMost(f64),
    /// Never (stays) below the target: the best error and its cost.
    NotReached {
        /// Smallest error measured.
        best_error: f64,
        /// Its cost (s/s).
        cost: f64,
    },
    /// No finished run at all.
    NoData,
}

/// Cost to reach `target` along one curve (points in order of decreasing
/// dt): the crossing after which every smaller dt also stays at or below
/// `target` — a curve that dips below and comes back up (or fails) at
/// smaller dt has not reached it at the dip.
pub fn cost_to_reach(points: &[SweepPoint], target: f64) -> Reach {
    let below = |p: &SweepPoint| {
        p.outcome
            .as_ref()
            .is_ok_and(|m| m.error.is_finite() && m.error <= target)
    };
    let best = points
        .iter()
        .filter_map(|p| p.outcome.as_ref().ok())
        .filter(|m| m.error.is_finite())
        .min_by(|a, b| a.error.total_cmp(&b.error));
    let Some(best) = best else {
        return Reach::NoData;
    };
    // first index from which all points are below the target
    let mut first = points.len();
    for i in (0..points.len()).rev() {
        if below(&points[i]) {
            first = i;
        } else {
            break;
        }
    }
    if first == points.len() {
        return Reach::NotReached {
            best_error: best.error,
            cost: best.cost,
        };
    }
    let Ok(at) = &points[first].outcome else {
        return Reach::NoData;
    };
    if first == 0 {
        return Reach::AtMost(at.cost);
    }
    match &points[first - 1].outcome {
        Ok(prev) if prev.error.is_finite() && prev.error > target => {
            let t = (target.log10() - prev.error.log10()) / (at.error.log10() - prev.error.log10());
            let lc = prev.cost.log10() + t * (at.cost.log10() - prev.cost.log10());
            Reach::Interpolated(10f64.powf(lc))
        }
        // the previous point failed: the crossing is somewhere before `at`
        _ => Reach::AtMost(at.cost),
    }
}

/// All points of one method, in order of decreasing dt.
pub fn curve(points: &[SweepPoint], method: Method) -> Vec<SweepPoint> {
    let mut c: Vec<SweepPoint> = points
        .iter()
        .filter(|p| p.method == method)
        .cloned()
        .collect();
    c.sort_by(|a, b| b.dt.total_cmp(&a.dt));
    c
}

/// Three significant digits in scientific notation (`1.23e-4`).
pub fn sci(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2e}")
    } else {
        format!("{v}")
    }
}

/// A cost in s per simulated s as milliseconds per simulated second, three
/// significant digits.
pub fn ms(cost: f64) -> String {
    let v = cost * 1e3;
    if !v.is_finite() {
        return format!("{v}");
    }
    if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 10.0 {
        format!("{v:.1}")
    } else if v >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// A [`Reach`] as a table cell (costs in ms per simulated second).
pub fn reach_cell(r: &Reach) -> String {
    match r {
        Reach::Interpolated(c) => ms(*c),
        Reach::AtMost(c) => format!("≤ {}", ms(*c)),
        Reach::NotReached { best_error, cost } => {
            format!("— (best {} at {})", sci(*best_error), ms(*cost))
        }
        Reach::NoData => "—".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::Failure;

    fn point(dt: f64, error: Option<f64>, cost: f64) -> SweepPoint {
        SweepPoint {
            method: Method::Rk4,
            dt,
            steps: 1,
            outcome: match error {
                Some(error) => Ok(Measured {
                    error,
                    constraint_violation: 0.0,
                    solver_error: None,
                    cost,
                    cost_min: cost,
                    cost_max: cost,
                    reps: 1,
                }),
                None => Err(Failure {
                    diverged: true,
                    message: String::new(),
                }),
            },
        }
    }

    #[test]
    fn fit_recovers_a_power_law() {
        let pts: Vec<_> = [0.1, 0.05, 0.02, 0.01]
            .iter()
            .map(|&dt: &f64| point(dt, Some(3.0 * dt.powi(2)), 1.0 / dt))
            .collect();
        let all = FitWindow {
            lo: 0.0,
            hi: 1.0,
            max_points: 10,
            roundoff: 0.0,
        };
        let f = fit_order(&pts, all).unwrap();
        assert!((f.slope - 2.0).abs() < 1e-12);
        assert_eq!(f.points, 4);
        assert_eq!(f.local.len(), 3);
        assert!(f.local.iter().all(|s| (s - 2.0).abs() < 1e-12));
        let three = fit_order(
            &pts,
            FitWindow {
                max_points: 3,
                ..all
            },
        )
        .unwrap();
        assert_eq!((three.points, three.dt_max), (3, 0.05));
    }

    #[test]
    fn fit_leaves_out_solver_and_roundoff_floors() {
        // a fourth-order curve whose two smallest steps sit on a solver
        // floor (error ≈ solver error) and a round-off floor
        let mut pts: Vec<_> = [0.04, 0.02, 0.01, 0.005, 0.0025, 0.00125]
            .iter()
            .map(|&dt: &f64| point(dt, Some(10.0 * dt.powi(4)), 1.0 / dt))
            .collect();
        if let Ok(m) = &mut pts[4].outcome {
            m.error = 3e-9;
            m.solver_error = Some(2.9e-9);
        }
        pts[5].steps = 1_000_000;
        if let Ok(m) = &mut pts[5].outcome {
            m.error = 1e-10; // < 10 · 10⁶ · 2.2e-16
        }
        let window = FitWindow {
            lo: 1e-13,
            hi: 1.0,
            max_points: 10,
            roundoff: f64::EPSILON,
        };
        let f = fit_order(&pts, window).unwrap();
        assert_eq!((f.points, f.dt_min), (4, 0.005));
        assert!((f.slope - 4.0).abs() < 1e-9, "{}", f.slope);
        // without the floors the two points spoil the fit
        let mut bare = pts.clone();
        for p in &mut bare {
            if let Ok(m) = &mut p.outcome {
                m.solver_error = None;
            }
        }
        let spoiled = fit_order(
            &bare,
            FitWindow {
                roundoff: 0.0,
                ..window
            },
        )
        .unwrap();
        assert!((spoiled.slope - 4.0).abs() > 0.3, "{}", spoiled.slope);
    }

    #[test]
    fn reach_interpolates_and_needs_the_tail_below() {
        let pts = vec![
            point(0.1, Some(1e-1), 1.0),
            point(0.01, Some(1e-3), 10.0),
            point(0.001, Some(1e-5), 100.0),
        ];
        match cost_to_reach(&pts, 1e-4) {
            Reach::Interpolated(c) => assert!((c - 10f64.powf(1.5)).abs() < 1e-9),
            r => panic!("{r:?}"),
        }
        assert_eq!(cost_to_reach(&pts, 1.0), Reach::AtMost(1.0));
        let dip = vec![
            point(0.1, None, 1.0),
            point(0.01, Some(1e-6), 10.0),
            point(0.001, Some(1e-2), 100.0),
        ];
        assert_eq!(
            cost_to_reach(&dip, 1e-3),
            Reach::NotReached {
                best_error: 1e-6,
                cost: 10.0
            }
        );
    }
}
