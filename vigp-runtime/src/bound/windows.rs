//! Held-out windows with the inputs their steps were taken under: the one
//! calibration set ([`CalibrationOf`]) of the planar
//! ([`Calibration`](super::Calibration)) and the spatial
//! (`crate::spatial::bound::SpatialCalibration`) bounds — validation, the
//! inputs' layout, the cutting of trajectories and the accessors.

use super::BoundError;
use nalgebra::SVector;

/// The seal of [`CalibrationWindow`]: each window type implements it
/// beside its definition (the planar, spatial and robot bounds'), so
/// this module names none of them.
pub(crate) mod sealed {
    pub trait Sealed {}
}

/// A held-out window of a calibration set: a start and the K true states
/// after it ([`super::Window`] of coordinates, or the spatial bound's
/// window of configurations, or a robot's window of joint positions).
/// Sealed: the bounds know these three.
pub trait CalibrationWindow: sealed::Sealed + Sized {
    /// One sample of a logged trajectory: positions (`SVector<f64, N>`)
    /// or configurations.
    type Sample;
    /// The window of `horizon` steps from sample `s` of `samples`, its
    /// start velocity from samples s and s + 1 (the data's convention).
    fn cut(samples: &[Self::Sample], s: usize, horizon: usize, dt: f64) -> Self;
    /// K: the true states after the start.
    fn steps(&self) -> usize;
    /// No NaN or ±∞ in the start or the true states.
    fn is_finite(&self) -> bool;
    /// What else makes the (finite) window unusable, if anything.
    fn defect(&self) -> Option<&'static str> {
        None
    }
}

/// Windows of equal length K ≥ 2 with time step `dt`, and their inputs.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Windows<W> {
    pub dt: f64,
    pub windows: Vec<W>,
    /// Inputs per window (K·U values each: step k's input at k·U), empty
    /// without inputs.
    pub inputs: Vec<Vec<f64>>,
    /// Per window the input held before its start, over the interval of
    /// the start's velocity (U values each; empty without inputs): the
    /// previous input of the first step.
    pub previous: Vec<Vec<f64>>,
    /// U (0: the windows carry no inputs).
    pub input_count: usize,
    /// The run (trajectory) each window was cut from: windows of one run
    /// are not independent of each other (each window its own run unless
    /// cut by [`Windows::cut`]).
    pub runs: Vec<usize>,
}

impl<W: CalibrationWindow> Windows<W> {
    /// Errors: `dt` not finite and positive, a window with fewer than 2
    /// steps, windows of different lengths, a NaN/∞ anywhere, or what the
    /// window's [`CalibrationWindow::defect`] names.
    pub fn new(dt: f64, windows: Vec<W>) -> Result<Self, BoundError> {
        if vigp_core::step::check_time_step(dt).is_err() {
            return Err(BoundError::InvalidSetting {
                what: "calibration dt (must be finite and > 0, with dt² a normal number)",
                value: dt,
            });
        }
        let k = windows.first().map_or(2, W::steps);
        for (index, w) in windows.iter().enumerate() {
            if w.steps() < 2 {
                return Err(BoundError::Calibration {
                    index,
                    reason: "a window needs at least 2 true states after its start",
                });
            }
            if w.steps() != k {
                return Err(BoundError::Calibration {
                    index,
                    reason: "windows of different lengths",
                });
            }
            if !w.is_finite() {
                return Err(BoundError::Calibration {
                    index,
                    reason: "NaN or infinity in the window",
                });
            }
            if let Some(reason) = w.defect() {
                return Err(BoundError::Calibration { index, reason });
            }
        }
        Ok(Self {
            dt,
            runs: (0..windows.len()).collect(),
            windows,
            inputs: Vec::new(),
            previous: Vec::new(),
            input_count: 0,
        })
    }

    /// The windows with `inputs[i]`, window i's K inputs, each window's
    /// previous input taken as its first (held across the start; see
    /// [`Windows::with_previous`]). Errors: `U = 0`;
    /// not one sequence per window; a window's input count other than its
    /// K; a NaN or ∞ input.
    pub fn with_inputs<const U: usize>(
        mut self,
        inputs: Vec<Vec<SVector<f64, U>>>,
    ) -> Result<Self, BoundError> {
        if U == 0 {
            return Err(BoundError::InvalidSetting {
                what: "number of inputs of forced calibration windows (must be >= 1)",
                value: 0.0,
            });
        }
        if inputs.len() != self.windows.len() {
            return Err(BoundError::WrongLength {
                what: "calibration inputs (one sequence per window)",
                expected: self.windows.len(),
                got: inputs.len(),
            });
        }
        for (index, (w, us)) in self.windows.iter().zip(&inputs).enumerate() {
            if us.len() != w.steps() {
                return Err(BoundError::Calibration {
                    index,
                    reason: "a window needs one input per step",
                });
            }
            if !us.iter().flatten().all(|x| x.is_finite()) {
                return Err(BoundError::Calibration {
                    index,
                    reason: "NaN or infinity in the window's inputs",
                });
            }
        }
        self.inputs = inputs
            .iter()
            .map(|us| us.iter().flat_map(|u| u.iter().copied()).collect())
            .collect();
        self.previous = inputs
            .iter()
            .map(|us| {
                us.first()
                    .map_or(Vec::new(), |u| u.iter().copied().collect())
            })
            .collect();
        self.input_count = U;
        Ok(self)
    }

    /// The windows with `previous[i]` as window i's previous input (the
    /// one that produced its start's velocity), after
    /// [`Windows::with_inputs`]. Errors: not one per window; a NaN or ∞.
    pub fn with_previous<const U: usize>(
        mut self,
        previous: Vec<SVector<f64, U>>,
    ) -> Result<Self, BoundError> {
        if previous.len() != self.windows.len() {
            return Err(BoundError::WrongLength {
                what: "previous inputs of calibration windows (one per window)",
                expected: self.windows.len(),
                got: previous.len(),
            });
        }
        if let Some(index) = previous
            .iter()
            .position(|u| !u.iter().all(|x| x.is_finite()))
        {
            return Err(BoundError::Calibration {
                index,
                reason: "NaN or infinity in the window's previous input",
            });
        }
        self.previous = previous
            .iter()
            .map(|u| u.iter().copied().collect())
            .collect();
        Ok(self)
    }

    /// Window `index`'s previous input (the input held over its start's
    /// velocity interval; None as [`Windows::window_inputs`]).
    pub fn window_previous_input<const U: usize>(&self, index: usize) -> Option<SVector<f64, U>> {
        if U != self.input_count || U == 0 {
            return None;
        }
        Some(SVector::from_column_slice(self.previous.get(index)?))
    }

    /// Window `index`'s inputs as `U`-vectors, one per step (None when `U`
    /// is not the windows' input count, is 0, or the index is out of
    /// range).
    pub fn window_inputs<const U: usize>(&self, index: usize) -> Option<Vec<SVector<f64, U>>> {
        if U != self.input_count || U == 0 {
            return None;
        }
        let flat = self.inputs.get(index)?;
        Some(
            flat.chunks_exact(U)
                .map(SVector::from_column_slice)
                .collect(),
        )
    }

    /// Window `index`'s previous input (U values; empty without inputs or
    /// out of range).
    pub fn previous_input(&self, index: usize) -> &[f64] {
        self.previous.get(index).map_or(&[], Vec::as_slice)
    }

    /// Window `index`'s first input (U values; empty without inputs or
    /// out of range).
    pub fn first_input(&self, index: usize) -> &[f64] {
        self.inputs
            .get(index)
            .map_or(&[], |flat| &flat[..self.input_count])
    }

    /// K (0 without windows).
    pub fn horizon(&self) -> usize {
        self.windows.first().map_or(0, W::steps)
    }

    /// Windows of `horizon` steps cut from trajectories of `lengths`
    /// samples at every `stride`-th sample, `window(r, s)` the one of
    /// trajectory r from sample s; each remembers its run. Errors: those of
    /// [`window_starts`] and [`Windows::new`].
    pub fn cut(
        lengths: &[usize],
        dt: f64,
        horizon: usize,
        stride: usize,
        window: impl Fn(usize, usize) -> W,
    ) -> Result<Self, BoundError> {
        let starts = window_starts(lengths, horizon, stride)?;
        Self::from_starts(&starts, dt, window)
    }

    /// [`Windows::cut`] with the inputs logged with every sample
    /// ([`logged_inputs`]).
    pub fn cut_forced<I: AsRef<[SVector<f64, U>]>, const U: usize>(
        lengths: &[usize],
        inputs: &[I],
        dt: f64,
        horizon: usize,
        stride: usize,
        window: impl Fn(usize, usize) -> W,
    ) -> Result<Self, BoundError> {
        let starts = window_starts(lengths, horizon, stride)?;
        let window_inputs = logged_inputs(lengths, inputs, &starts, horizon)?;
        // the input logged with the start's sample produced its velocity
        let previous = starts.iter().map(|&(r, s)| inputs[r].as_ref()[s]).collect();
        Self::from_starts(&starts, dt, window)?
            .with_inputs(window_inputs)?
            .with_previous(previous)
    }

    /// The windows `window(r, s)` at `starts` (run r, sample s), each
    /// remembering its run.
    pub(crate) fn from_starts(
        starts: &[(usize, usize)],
        dt: f64,
        window: impl Fn(usize, usize) -> W,
    ) -> Result<Self, BoundError> {
        let windows = starts.iter().map(|&(r, s)| window(r, s)).collect();
        let mut set = Self::new(dt, windows)?;
        set.runs = starts.iter().map(|&(r, _)| r).collect();
        Ok(set)
    }
}

/// (trajectory, first sample) of every window of `horizon` steps that
/// starts at a `stride`-th sample of trajectories of `lengths` samples.
/// Errors: `horizon` < 2, `stride` = 0, no window at all.
pub(crate) fn window_starts(
    lengths: &[usize],
    horizon: usize,
    stride: usize,
) -> Result<Vec<(usize, usize)>, BoundError> {
    if horizon < 2 {
        return Err(BoundError::InvalidSetting {
            what: "calibration horizon (must be >= 2)",
            value: horizon as f64,
        });
    }
    if stride == 0 {
        return Err(BoundError::InvalidSetting {
            what: "calibration stride (must be >= 1)",
            value: 0.0,
        });
    }
    let mut starts = Vec::new();
    for (r, &len) in lengths.iter().enumerate() {
        let mut s = 0;
        while s + horizon < len {
            starts.push((r, s));
            s += stride;
        }
    }
    if starts.is_empty() {
        return Err(BoundError::Empty(
            "calibration trajectories (none is longer than the horizon)",
        ));
    }
    Ok(starts)
}

/// Each window's inputs from inputs logged with every sample and held from
/// it (the data files' convention): the step from the window's state at
/// sample s + k is driven by sample s + k + 1's input. Errors: not one
/// input sequence per trajectory, or not one input per sample.
fn logged_inputs<I: AsRef<[SVector<f64, U>]>, const U: usize>(
    lengths: &[usize],
    inputs: &[I],
    starts: &[(usize, usize)],
    horizon: usize,
) -> Result<Vec<Vec<SVector<f64, U>>>, BoundError> {
    if inputs.len() != lengths.len() {
        return Err(BoundError::WrongLength {
            what: "calibration inputs (one sequence per trajectory)",
            expected: lengths.len(),
            got: inputs.len(),
        });
    }
    for (index, (&len, u)) in lengths.iter().zip(inputs).enumerate() {
        if u.as_ref().len() != len {
            return Err(BoundError::Calibration {
                index,
                reason: "a trajectory needs one input per sample",
            });
        }
    }
    Ok(starts
        .iter()
        .map(|&(r, s)| inputs[r].as_ref()[s + 1..=s + horizon].to_vec())
        .collect())
}

/// Sample counts of trajectories.
fn lengths<T: AsRef<[E]>, E>(trajectories: &[T]) -> Vec<usize> {
    trajectories.iter().map(|t| t.as_ref().len()).collect()
}

/// Held-out calibration windows of equal length K with their time step,
/// their runs and (for a model trained under inputs) the inputs of their
/// steps: the set a conformal bound is calibrated on. The planar bound
/// reads [`Calibration`](super::Calibration) (windows of coordinates), the
/// spatial one `SpatialCalibration` (windows of configurations); both are
/// this type.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationOf<W> {
    pub(crate) set: Windows<W>,
}

impl<W: CalibrationWindow> CalibrationOf<W> {
    /// Windows with time step `dt`. Errors ([`BoundError`]): `dt` not
    /// finite and positive, a window with fewer than 2 true states after
    /// its start, windows of different lengths, a NaN/∞ anywhere, or (a
    /// spatial window) a quaternion, start or true orientation, not of
    /// unit norm to 1e-9 ([`BoundError::Calibration`], naming the window).
    /// Without windows, calibrating a bound is
    /// [`BoundError::TooFewCalibration`].
    pub fn new(dt: f64, windows: Vec<W>) -> Result<Self, BoundError> {
        Ok(Self {
            set: Windows::new(dt, windows)?,
        })
    }

    /// Windows of `horizon` steps from trajectories sampled every `dt`
    /// (positions, or configurations; the form training data has): a
    /// window starts at every `stride`-th sample that leaves room for its
    /// horizon, its start velocity from its first two samples. Errors:
    /// `horizon` < 2, `stride` = 0, no window at all, or what
    /// [`CalibrationOf::new`] rejects.
    pub fn from_trajectories<T: AsRef<[W::Sample]>>(
        trajectories: &[T],
        dt: f64,
        horizon: usize,
        stride: usize,
    ) -> Result<Self, BoundError> {
        Ok(Self {
            set: Windows::cut(&lengths(trajectories), dt, horizon, stride, |r, s| {
                W::cut(trajectories[r].as_ref(), s, horizon, dt)
            })?,
        })
    }

    /// [`CalibrationOf::from_trajectories`] for an actuated mechanism:
    /// `inputs[r][i]` is the input logged with sample i of trajectory r
    /// and held from t_i to t_{i+1} (the data files' convention), so the
    /// step from a window's state at sample s + k (whose velocity spans
    /// [t_{s+k}, t_{s+k+1}]) to the next one is driven by sample
    /// s + k + 1's input, after sample s + k's (sample s's for the first
    /// step: each window's previous input). Errors: those of
    /// `from_trajectories` and [`CalibrationOf::new_forced`]; a trajectory
    /// whose inputs are not one per sample.
    pub fn from_trajectories_forced<T, I, const U: usize>(
        trajectories: &[T],
        inputs: &[I],
        dt: f64,
        horizon: usize,
        stride: usize,
    ) -> Result<Self, BoundError>
    where
        T: AsRef<[W::Sample]>,
        I: AsRef<[SVector<f64, U>]>,
    {
        Ok(Self {
            set: Windows::cut_forced(
                &lengths(trajectories),
                inputs,
                dt,
                horizon,
                stride,
                |r, s| W::cut(trajectories[r].as_ref(), s, horizon, dt),
            )?,
        })
    }

    /// Windows of an actuated mechanism with time step `dt`: `inputs[i]`
    /// holds window i's K inputs, step k (from the start's k-th successor
    /// towards true state k + 1) taken under `inputs[i][k]` held over the
    /// step. Each window's previous input (the one that produced its
    /// start's velocity, which a forced learned step takes: see
    /// `crate::learned`, "Under inputs") is taken as its first, held
    /// across the start; [`CalibrationOf::with_previous_inputs`] sets it.
    /// Errors: those of [`CalibrationOf::new`]; `U = 0`; a window's input
    /// count other than its K; a NaN or ∞ input.
    pub fn new_forced<const U: usize>(
        dt: f64,
        windows: Vec<W>,
        inputs: Vec<Vec<SVector<f64, U>>>,
    ) -> Result<Self, BoundError> {
        Ok(Self {
            set: Windows::new(dt, windows)?.with_inputs(inputs)?,
        })
    }

    /// These forced windows with `previous[i]` as window i's previous
    /// input (held over the interval of its start's velocity). Errors: not
    /// one per window, a NaN or ∞, or windows without inputs of this count
    /// ([`BoundError::Mismatch`]).
    pub fn with_previous_inputs<const U: usize>(
        self,
        previous: Vec<SVector<f64, U>>,
    ) -> Result<Self, BoundError> {
        if U == 0 || self.set.input_count != U {
            return Err(BoundError::Mismatch(
                "previous inputs for windows without inputs of that count",
            ));
        }
        Ok(Self {
            set: self.set.with_previous(previous)?,
        })
    }

    /// Window `index`'s previous input (None without `U` inputs or out of
    /// range).
    pub fn window_previous_input<const U: usize>(&self, index: usize) -> Option<SVector<f64, U>> {
        self.set.window_previous_input(index)
    }

    /// The windows.
    pub fn windows(&self) -> &[W] {
        &self.set.windows
    }

    /// The run each window was cut from (cut from trajectories: the
    /// trajectory's index; windows given directly: each its own).
    pub fn window_runs(&self) -> &[usize] {
        &self.set.runs
    }

    /// Number of inputs per step the windows carry (0: unforced windows).
    pub fn input_count(&self) -> usize {
        self.set.input_count
    }

    /// Window `index`'s inputs as `U`-vectors, one per step (None when
    /// `U` is not [`CalibrationOf::input_count`] or the index is out of
    /// range).
    pub fn window_inputs<const U: usize>(&self, index: usize) -> Option<Vec<SVector<f64, U>>> {
        self.set.window_inputs(index)
    }

    /// Number of windows n.
    pub fn len(&self) -> usize {
        self.set.windows.len()
    }

    /// `true` without windows.
    pub fn is_empty(&self) -> bool {
        self.set.windows.is_empty()
    }

    /// Window length K (0 without windows).
    pub fn horizon(&self) -> usize {
        self.set.horizon()
    }

    /// The time step of the windows.
    pub fn dt(&self) -> f64 {
        self.set.dt
    }
}
