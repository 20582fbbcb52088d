//! Training options and the training report.

use serde::{Deserialize, Serialize};

use crate::error::GpError;
use crate::kernel::{Hyperparameters, check_positive};
use crate::mean::PriorMean;

/// Box bounds on the hyperparameters, in *normalised* units (i.e. after
/// input standardisation and output scaling, when those are on).
///
/// Keep them wide. In particular the noise lower bound must allow the tiny
/// noise of near-deterministic data (σ = 1e-3 observation noise
/// gives σ_n² ≈ 1e-7 after normalisation); ill-conditioning is handled by
/// jitter, not by a noise floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// (lower, upper) for every length scale ℓ_j.
    pub length_scale: (f64, f64),
    /// (lower, upper) for the signal variance σ_f².
    pub signal_variance: (f64, f64),
    /// (lower, upper) for the noise variance σ_n².
    pub noise_variance: (f64, f64),
}

impl Default for Bounds {
    /// ℓ ∈ [1e-3, 1e3], σ_f² ∈ [1e-4, 1e4], σ_n² ∈ [1e-10, 10].
    fn default() -> Self {
        Self {
            length_scale: (1e-3, 1e3),
            signal_variance: (1e-4, 1e4),
            noise_variance: (1e-10, 1e1),
        }
    }
}

impl Bounds {
    /// Same bounds for every hyperparameter (scikit-learn style, e.g. (1e-5, 1e5)).
    pub fn uniform(lower: f64, upper: f64) -> Self {
        Self {
            length_scale: (lower, upper),
            signal_variance: (lower, upper),
            noise_variance: (lower, upper),
        }
    }

    pub(crate) fn validate(&self) -> Result<(), GpError> {
        for (what, (lo, hi)) in [
            ("length scale bound", self.length_scale),
            ("signal variance bound", self.signal_variance),
            ("noise variance bound", self.noise_variance),
        ] {
            check_positive(what, lo)?;
            check_positive(what, hi)?;
            if lo > hi {
                return Err(GpError::InvalidHyperparameter { what, value: lo });
            }
        }
        Ok(())
    }

    /// Lower and upper bounds on θ = (ln ℓ, ln σ_f², ln σ_n²).
    pub(crate) fn log_box(&self, d: usize) -> (Vec<f64>, Vec<f64>) {
        let mut lo = vec![self.length_scale.0.ln(); d];
        let mut hi = vec![self.length_scale.1.ln(); d];
        lo.push(self.signal_variance.0.ln());
        hi.push(self.signal_variance.1.ln());
        lo.push(self.noise_variance.0.ln());
        hi.push(self.noise_variance.1.ln());
        (lo, hi)
    }
}

/// Which GP a [`Gp`](super::Gp) is: the exact posterior, or the sparse
/// variational approximation (SGPR).
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Method {
    /// The exact GP: O(N³) per likelihood evaluation, O(N²) memory per output.
    #[default]
    Exact,
    /// Titsias' (2009) variational sparse GP (SGPR, the collapsed "VFE"
    /// bound) with M inducing points shared by all outputs: O(N·M²) per
    /// evaluation, O(N·M) memory. Hyperparameters maximise the evidence
    /// lower bound; the inducing points stay where [`SparseOptions`] puts
    /// them unless [`SparseOptions::optimise_inducing`] asks for a joint
    /// refinement of both. Caveat: K_uu carries a relative
    /// jitter 1e-10·σ_f², which enters the bound's trace term as
    /// ≈ N·1e-10·σ_f²/(2σ_n²); with nearly noise-free data and σ_n² at
    /// [`Bounds::default`]'s 1e-10 that term dominates even at M = N. The
    /// noise variance of a sparse GP is therefore kept at or above
    /// [`SparseOptions::min_noise_variance`] (default
    /// [`SPARSE_MIN_NOISE_VARIANCE`]); for an exact fit of noise-free data
    /// use the exact GP (`docs/gp.md`, "Nearly noise-free data").
    Sparse(SparseOptions),
}

/// Settings of the sparse GP ([`Method::Sparse`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SparseOptions {
    /// Number M of inducing points (at most N; M = N gives the exact
    /// posterior mean up to the jitter).
    pub inducing: usize,
    /// Where the inducing points come from.
    pub init: InducingInit,
    /// Floor of the noise variance σ_n² (the GP's working units, like
    /// [`Bounds`]): training uses max([`Bounds::noise_variance`]`.0`, this)
    /// as σ_n²'s lower bound (capped at its upper bound). 0 keeps
    /// [`TrainOptions::bounds`] as they are. Must be finite and ≥ 0.
    pub min_noise_variance: f64,
    /// After the hyperparameter starts (at fixed inducing points), refine
    /// the inducing points Z and every output's hyperparameters jointly:
    /// one bounded L-BFGS run on the sum of the outputs' bounds (Z is
    /// shared), from the winning hyperparameters and the initial Z, with
    /// the analytic gradient in Z. The bound can only rise (the run keeps
    /// its best point); [`TrainReport::inducing`] records before and after.
    /// Each inducing coordinate is kept within the training inputs' range
    /// widened by that range on either side (or wider, to include given
    /// initial points that lie outside).
    ///
    /// Cost: one evaluation is p bound evaluations (one per output, in
    /// parallel over outputs) plus 2·M·N·d flops each for the gradient in
    /// Z, and the run has M·d + p·(d + 2) variables, so it typically takes
    /// more iterations than a hyperparameter start (up to
    /// [`TrainOptions::max_iters`]). Default `false`, because of that cost
    /// (GPflow's `SGPR` trains Z by default). Where M ≪ N the gain can be
    /// large: N = 10⁴, d = 4, M = 64, bound 12 340 → 21 492 in 4.3 s
    /// instead of 0.5 s (`docs/gp.md`, "Sparse GP (SGPR)").
    pub optimise_inducing: bool,
}

/// The default [`SparseOptions::min_noise_variance`]: 1e-6, in units of
/// the normalised output (variance ≈ 1).
///
/// Why: the bound's trace term carries ≈ N·ε·σ_f²/(2σ_n²) from K_uu's
/// relative jitter ε = 1e-10, which at the exact GP's floor σ_n² = 1e-10
/// is ≈ N·σ_f²/2 and pushes σ_f² down until the model underfits. At
/// σ_n² = 1e-6 it is ≈ N·σ_f²·5e-5, about one nat per 2·10⁴ samples at
/// σ_f² ≈ 1. Measured on a noise-free 20 000-step cart-pole log (M = 128,
/// 1 + 1 starts, 20-step position MSE on held-out runs; the nominal model
/// 1.0e-4): minimal coordinates 1.3e-6 at the old floor 1e-10, 4.5e-8 at
/// 1e-6; maximal coordinates 6.9e-5 and 2.4e-6 (`docs/gp.md`). The price:
/// on perfectly clean simulated data whose residual the floorless fit
/// resolves, errors far below any sensor noise rise (a noise-free pendulum
/// sweep, N = 8192: 1.5e-17 → 1.1e-14); set 0 there.
pub const SPARSE_MIN_NOISE_VARIANCE: f64 = 1e-6;

impl SparseOptions {
    /// M inducing points chosen by k-means++ (seeded by `TrainOptions::seed`),
    /// noise floor [`SPARSE_MIN_NOISE_VARIANCE`], not optimised.
    pub fn kmeans(inducing: usize) -> Self {
        Self {
            inducing,
            init: InducingInit::KMeansPlusPlus { lloyd_iters: 0 },
            min_noise_variance: SPARSE_MIN_NOISE_VARIANCE,
            optimise_inducing: false,
        }
    }
}

/// How the inducing points of a sparse GP are chosen, in the units of the
/// (standardised, when `normalise_inputs` is on) inputs.
#[derive(Clone, Debug, PartialEq)]
pub enum InducingInit {
    /// k-means++ seeding (Arthur & Vassilvitskii 2007) on the training
    /// inputs, then `lloyd_iters` Lloyd iterations (0: the seeds themselves,
    /// which are training inputs).
    KMeansPlusPlus {
        /// Lloyd (k-means) iterations after the seeding.
        lloyd_iters: usize,
    },
    /// The first M training inputs (e.g. data already in random order).
    First,
    /// Given points, row-major M × d, in original input units.
    Given(Vec<f64>),
}

/// How to train a [`Gp`](super::Gp).
///
/// Defaults: the exact GP, constant prior mean, inputs and outputs
/// normalised, 5 random restarts besides the initial point, seed 0,
/// [`Bounds::default`], L-BFGS memory 10 (scipy's), no warm start.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Prior mean m(x); the GPs model y − m(x).
    pub mean: PriorMean,
    /// Standardise each input dimension (mean 0, standard deviation 1).
    pub normalise_inputs: bool,
    /// Divide each output's residual y − m(x) by its root mean square.
    pub normalise_outputs: bool,
    /// Starting hyperparameters (normalised units) of the first optimiser
    /// run; `None` means ℓ = 1, σ_f² = 1, σ_n² = 0.01 (clamped into the bounds).
    pub initial: Option<Hyperparameters>,
    /// Number of extra starts drawn log-uniformly inside the bounds
    /// (scikit-learn's `n_restarts_optimizer`): 1 + restarts runs per output
    /// (at most [`MAX_RESTARTS`]).
    pub restarts: usize,
    /// Seed of the restart points. Same seed and data → bit-identical model,
    /// whatever the thread count or scheduling.
    pub seed: u64,
    /// Hyperparameter bounds (normalised units).
    pub bounds: Bounds,
    /// Maximum L-BFGS iterations per start.
    pub max_iters: usize,
    /// Stop when the relative decrease of −LML in one iteration is below this.
    pub ftol: f64,
    /// Stop when the infinity norm of the projected gradient of −LML (w.r.t.
    /// log hyperparameters) is below this.
    pub pgtol: f64,
    /// Curvature pairs the L-BFGS-B optimiser keeps (scipy's `maxcor`,
    /// default 10 as in scipy and scikit-learn; 1 to [`MAX_MEMORY`]).
    ///
    /// With d + 2 hyperparameters, a memory of at least d + 2 keeps one
    /// curvature pair per hyperparameter, which paid on many inputs (on
    /// few it can also lengthen the path): in the paper's evaluation (d = 2 to 24, the
    /// maximal-coordinate models the largest) a memory of 30 needed 30 %
    /// fewer likelihood evaluations on all 512 samples than 10, to the same
    /// stopping test (see `docs/gp.md`, "Optimiser memory"). Where the
    /// likelihood has several optima the one reached can differ, either
    /// way; the extra cost per iteration is O((d + 2)²·memory), negligible
    /// against one O(N³) evaluation (with more than 64 variables, a sparse
    /// GP's inducing-point refinement, O(memory³) per iteration).
    pub memory: usize,
    /// Exact or sparse GP.
    pub method: Method,
    /// Warm start: hyperparameters in **original** units, one per output
    /// (e.g. [`Gp::warm_start`](super::Gp::warm_start) of a model trained on
    /// fewer samples, or the previous run of a sweep). They replace
    /// `initial` as start 0 of each output (converted to the new
    /// normalisation and clamped into the bounds); the random restarts are
    /// unchanged, so `restarts: 0` refines the previous optimum only
    /// (unless an output ends on the white-noise plateau, see
    /// [`Gp::train`](super::Gp::train)).
    pub warm_start: Option<Vec<Hyperparameters>>,
    /// Whether the starts of an exact GP run first on a subset of the
    /// samples ([`Screening`]; default [`Screening::Auto`]).
    pub screening: Screening,
    /// Optima found on a subset of these samples, to refine on all of
    /// them **instead of** running the starts: one list per output, in
    /// original units, e.g. [`OutputReport::optima`] of a model trained on
    /// the first N/2 samples of a nested sweep. That earlier training then
    /// plays the part of [`Screening`]'s subset runs, which are not
    /// repeated. Exact GP only; not with `warm_start`.
    ///
    /// Each candidate is one optimiser run on all samples from that point
    /// (converted to this model's normalisation, clamped into the bounds),
    /// numbered by its index in the list. An output without candidates, or
    /// whose best refined fit is not preferred over white noise (see
    /// [`Gp::train`](super::Gp::train)), runs the initial point and the
    /// random restarts on all samples instead, as a screened output that
    /// falls back. The report's [`OutputReport::screening`] says which
    /// (`subset` 0, `refined` the candidates' indices).
    ///
    /// Only as good as the candidates: an optimum that no start found on
    /// the subset is not looked for (`docs/gp.md`, "Screening the starts",
    /// measures how often a subset misses the full data's best optimum).
    pub candidates: Option<Vec<Vec<Hyperparameters>>>,
    /// The optimiser's curvature at each of `candidates` (same shape: one
    /// list per output, one entry per candidate), e.g.
    /// [`OutputReport::optima_curvature`] of the same earlier training.
    /// Each candidate's refinement then starts from a quasi-Newton model
    /// of the likelihood instead of scipy's steepest-descent first step,
    /// with every y scaled by N / [`Curvature::samples`] (the likelihood's
    /// curvature grows with the sample count), as the refinements of
    /// [`Screening`] start from their subset run's pairs. `None`: every
    /// refinement starts with an empty memory. Needs `candidates`.
    pub candidate_curvature: Option<Vec<Vec<Curvature>>>,
}

/// The L-BFGS model at an optimum: the curvature pairs of the run that
/// reached it, to seed a refinement of that optimum on more samples
/// ([`TrainOptions::candidate_curvature`]).
///
/// The pairs are in the coordinates of [`Hyperparameters::to_log`]
/// (log ℓ₁, …, log ℓ_d, log σ_f², log σ_n²) of the negative log marginal
/// likelihood (of a sparse GP: of its negative bound). Steps and gradient differences there do not depend on the
/// normalisation (a change of units shifts every coordinate by a constant
/// and the likelihood by a constant), so the pairs carry over to a
/// training whose normaliser differs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Curvature {
    /// Samples of the training the pairs come from (N there).
    pub samples: usize,
    /// The pairs (s, y), oldest first: s a step, y the change of the
    /// gradient along it, both of length d + 2.
    pub pairs: Vec<(Vec<f64>, Vec<f64>)>,
}

/// How the starts of an exact GP's training meet the data.
///
/// One likelihood evaluation costs ≈ N³ flops (Cholesky and inverse), so
/// a start on m samples costs (m/N)³ of one on all N. With screening every
/// start (the initial point or warm start, the random restarts, the
/// white-noise plateau's retries and rescue starts) runs first on a seeded
/// random subset of m samples, in the full data's normalised units; the
/// distinct optima found there (equal LML to 1e-6 relative, or equal
/// log-hyperparameters to 1e-2; plateau optima dropped when another is
/// fitted) are then refined on all N samples from where they ended, and
/// the best refined fit wins. An output whose best refined fit is still
/// not preferred over white noise runs its starts again on all samples
/// without screening. [`OutputReport::screening`] records the subset's
/// work.
///
/// Caveat: this is a heuristic. An optimum of the full data whose basin
/// no subset optimum lies in is missed; the refinement of every distinct
/// subset optimum (not only the best) makes that rare on a few inputs. On
/// the benchmark problems of `docs/gp.md` and the unseen data sets of
/// `scripts/gp_screening_check.py` (d ≤ 8) the screened fit reaches the
/// unscreened best LML to 1e-6 relative (see there). On many inputs it
/// does not: of the paper evaluation's 45 outputs at N = 512 (d = 2 to
/// 24), 12 ended lower screened (up to 16 nats, 8.5e-3 relative) and 6
/// higher, and a 20-input set lost 19.5 nats (docs/gp.md, "Screening
/// the starts"). [`Screening::Off`] is scikit-learn's procedure; use it
/// where the last nats of a many-input fit matter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Screening {
    /// Exact GP, no warm start and N ≥ [`SCREEN_FROM`]: a subset of
    /// [`Screening::auto_size`]`(N)` samples; otherwise off.
    #[default]
    Auto,
    /// Every start runs on all N samples (scikit-learn's procedure).
    Off,
    /// Screen on a subset of this many samples (exact GP only; at least 2;
    /// N or more means no screening).
    Subset(usize),
}

/// The smallest N that [`Screening::Auto`] screens: below it one
/// evaluation takes about a millisecond and the subset would be too small
/// to show the full data's optima.
pub const SCREEN_FROM: usize = 512;

impl Screening {
    /// The subset size of [`Screening::Auto`] at N samples: N/4, at least
    /// 256 (so N/2 at N = 512) and at most 1024.
    pub fn auto_size(n: usize) -> usize {
        (n / 4).clamp(256, 1024)
    }

    /// The subset size to screen on for N samples, or `None` for no
    /// screening. `sparse`: the GP is sparse; `warm`: a warm start is given
    /// (both turn `Auto` off).
    pub(crate) fn subset(self, n: usize, sparse: bool, warm: bool) -> Option<usize> {
        let m = match self {
            Screening::Off => return None,
            Screening::Auto if sparse || warm || n < SCREEN_FROM => return None,
            Screening::Auto => Self::auto_size(n),
            Screening::Subset(m) => m,
        };
        (m < n).then_some(m)
    }
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            mean: PriorMean::Constant,
            normalise_inputs: true,
            normalise_outputs: true,
            initial: None,
            restarts: 5,
            seed: 0,
            bounds: Bounds::default(),
            max_iters: 500,
            ftol: 2.220446049250313e-9,
            pgtol: 1e-5,
            memory: 10,
            method: Method::Exact,
            warm_start: None,
            screening: Screening::Auto,
            candidates: None,
            candidate_curvature: None,
        }
    }
}

/// The largest L-BFGS memory [`TrainOptions::memory`] accepts (1000
/// curvature pairs; beyond the number of hyperparameters more pairs only
/// add history, and each costs two vectors of their length).
pub const MAX_MEMORY: usize = 1000;

/// The most random restarts [`TrainOptions::restarts`] accepts (10⁵):
/// each is a full optimiser run, so more is a typo, not a search (and
/// `usize::MAX` would overflow the start count).
pub const MAX_RESTARTS: usize = 100_000;

impl TrainOptions {
    /// `ftol` and `pgtol` must be finite and ≥ 0 (a NaN would never stop a
    /// run by its test, a negative one never either); `restarts` at most
    /// [`MAX_RESTARTS`]; `memory` from 1 to [`MAX_MEMORY`].
    pub(crate) fn validate_settings(&self) -> Result<(), GpError> {
        if self.restarts > MAX_RESTARTS {
            return Err(GpError::InvalidOptions(
                "restarts must be <= MAX_RESTARTS (100000)",
            ));
        }
        if !(1..=MAX_MEMORY).contains(&self.memory) {
            return Err(GpError::InvalidOptions(
                "memory (L-BFGS curvature pairs) must be from 1 to MAX_MEMORY (1000)",
            ));
        }
        if !(self.ftol.is_finite() && self.ftol >= 0.0) {
            return Err(GpError::InvalidOptions("ftol must be finite and >= 0"));
        }
        if !(self.pgtol.is_finite() && self.pgtol >= 0.0) {
            return Err(GpError::InvalidOptions("pgtol must be finite and >= 0"));
        }
        if let Screening::Subset(m) = self.screening {
            if m < 2 {
                return Err(GpError::InvalidOptions(
                    "Screening::Subset needs at least 2 samples",
                ));
            }
            if matches!(self.method, Method::Sparse(_)) {
                return Err(GpError::InvalidOptions(
                    "Screening::Subset applies to the exact GP only",
                ));
            }
        }
        if self.candidates.is_some() {
            if matches!(self.method, Method::Sparse(_)) {
                return Err(GpError::InvalidOptions(
                    "candidates apply to the exact GP only",
                ));
            }
            if self.warm_start.is_some() {
                return Err(GpError::InvalidOptions(
                    "give candidates or a warm start, not both",
                ));
            }
        }
        if self.candidate_curvature.is_some() && self.candidates.is_none() {
            return Err(GpError::InvalidOptions(
                "candidate_curvature needs candidates",
            ));
        }
        if let Method::Sparse(so) = &self.method
            && !(so.min_noise_variance.is_finite() && so.min_noise_variance >= 0.0)
        {
            return Err(GpError::InvalidOptions(
                "SparseOptions::min_noise_variance must be finite and >= 0",
            ));
        }
        Ok(())
    }

    /// The box the optimiser searches, on θ = (ln ℓ, ln σ_f², ln σ_n²):
    /// [`Bounds::log_box`] with a sparse GP's noise floor
    /// ([`SparseOptions::min_noise_variance`]) raising σ_n²'s lower bound
    /// (never above its upper bound).
    pub(crate) fn log_box(&self, d: usize) -> (Vec<f64>, Vec<f64>) {
        let (mut lo, hi) = self.bounds.log_box(d);
        if let Method::Sparse(so) = &self.method
            && so.min_noise_variance > 0.0
        {
            lo[d + 1] = lo[d + 1].max(so.min_noise_variance.ln()).min(hi[d + 1]);
        }
        (lo, hi)
    }
}

/// What happened during training, per output.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    /// One entry per output.
    pub outputs: Vec<OutputReport>,
    /// The joint refinement of a sparse GP's inducing points
    /// ([`SparseOptions::optimise_inducing`]); `None` when it did not run.
    #[serde(default)]
    pub inducing: Option<InducingReport>,
}

/// What the joint refinement of inducing points and hyperparameters did
/// ([`SparseOptions::optimise_inducing`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InducingReport {
    /// Sum over outputs of the bound at the winning hyperparameters and the
    /// initial inducing points (normalised units).
    pub bound_before: f64,
    /// The same sum after the refinement (never below `bound_before`).
    pub bound_after: f64,
    /// L-BFGS iterations of the refinement.
    pub iterations: usize,
    /// Evaluations of the summed bound and its gradient (each is one
    /// evaluation per output).
    pub evaluations: usize,
    /// Whether the refinement met a convergence test (not the iteration cap).
    pub converged: bool,
}

/// Training details of one output's GP.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputReport {
    /// Best log marginal likelihood (normalised units), over all starts;
    /// for a sparse GP the evidence lower bound at the winning start (after
    /// [`SparseOptions::optimise_inducing`]'s refinement, the final bound).
    pub log_marginal_likelihood: f64,
    /// Index of the winning start (0 = the initial point, then the random
    /// restarts, then any extra starts from other outputs' optima that
    /// [`Gp::train`](super::Gp::train) gives an output left on the
    /// white-noise plateau).
    pub best_start: usize,
    /// Final LML of every start (`NaN` for a start that failed):
    /// 1 + restarts entries, plus the extra starts if any.
    pub start_lmls: Vec<f64>,
    /// Total L-BFGS iterations over all starts.
    pub iterations: usize,
    /// Total likelihood evaluations over all starts.
    pub evaluations: usize,
    /// Likelihood evaluations of every start (0 for a start that failed).
    #[serde(default)]
    pub start_evaluations: Vec<usize>,
    /// Whether the winning start met a convergence test (not the iteration cap).
    pub converged: bool,
    /// Absolute jitter (normalised units) on the diagonal of the final Gram matrix.
    pub jitter: f64,
    /// The screening of the starts on a subset ([`Screening`]), `None`
    /// when they ran on all samples. With screening, `start_lmls`,
    /// `start_evaluations`, `evaluations` and `iterations` count the runs
    /// on all samples only: a start whose subset optimum was not refined
    /// (a duplicate, or a plateau optimum beside a fitted one) has `NaN`
    /// and 0 there.
    #[serde(default)]
    pub screening: Option<ScreeningReport>,
    /// The distinct optima of the runs on all samples, best first, in
    /// original units (equal LML to 1e-6 relative, or equal
    /// log-hyperparameters to 1e-2, count once; optima not preferred over
    /// white noise are left out when a fitted one exists). The first is
    /// the winning start's (the model's, unless a sparse GP's inducing
    /// points were refined after it). [`TrainOptions::candidates`] of a
    /// training on more samples takes them.
    #[serde(default)]
    pub optima: Vec<Hyperparameters>,
    /// The optimiser's curvature at each of `optima` (same order): the
    /// curvature pairs held at the end of the run that reached it (of a
    /// sparse GP's bound for a sparse GP). [`TrainOptions::candidate_curvature`]
    /// of an exact training on more samples takes them.
    #[serde(default)]
    pub optima_curvature: Vec<Curvature>,
}

/// What the screening of one output's starts did ([`Screening`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScreeningReport {
    /// Samples in the subset (m); 0 when the optima refined were
    /// [`TrainOptions::candidates`] (no subset run: `start_lmls` and
    /// `start_evaluations` are empty, `evaluations` 0).
    pub subset: usize,
    /// Final LML on the subset of every start (`NaN` for a failed start),
    /// numbered as [`OutputReport::start_lmls`].
    pub start_lmls: Vec<f64>,
    /// Evaluations on the subset, per start.
    pub start_evaluations: Vec<usize>,
    /// Evaluations on the subset in all (each ≈ (m/N)³ of one on all N).
    pub evaluations: usize,
    /// Starts whose subset optimum was refined on all samples.
    pub refined: Vec<usize>,
    /// The refined fit was not preferred over white noise, so the starts
    /// ran again on all samples without screening.
    pub fell_back: bool,
}
