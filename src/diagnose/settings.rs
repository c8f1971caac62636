//! Settings of the diagnosis: every threshold in one tree.
//!
//! [`DiagnoseSettings`] holds one group per stage. Each field says what it
//! means, its unit, its default, the values [`DiagnoseSettings::validate`]
//! accepts, and why it has its default. The noise-related thresholds are
//! multiples of one noise level ([`NoiseSettings::level`], replaced by the
//! level measured on the record unless [`NoiseSettings::measure`] is off). The
//! whole tree is written into report.json and read back by
//! `tacit diagnose --settings FILE` (TOML or JSON), so a run can be
//! replayed.

use super::lifted::LiftedSettings;
use crate::error::{Result, TacitError};
use crate::horizon::{self, settings::HorizonSettings};
pub use crate::identify::locate::LocateSettings;
use crate::trace::TraceSettings;
use crate::update::optimize::{FitSettings, JacobianMethod};
use serde::{Deserialize, Serialize};

/// Settings of the diagnosis (module docs). Every field has a default; a
/// settings file may give any subset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiagnoseSettings {
    /// Where the states come from (default: the lifted smoother).
    pub states: StatesSource,
    /// The measurement noise.
    pub noise: NoiseSettings,
    /// Segments of the multiple-shooting error.
    pub segments: SegmentSettings,
    /// Sub-steps of the simulations.
    pub substeps: SubstepSettings,
    /// The force-location search.
    pub locate: LocateSettings,
    /// The lifted smoother.
    pub lifted: LiftedGroup,
    /// The full-horizon smoother ([`StatesSource::Reconstructed`] only).
    pub horizon: HorizonSettings,
    /// The trace of the residual to candidate effects.
    pub trace: TraceGroup,
    /// Which candidate is fitted, and which is kept.
    pub screen: ScreenSettings,
    /// The fit of the added effects.
    pub fit: FitGroup,
    /// The segment start states.
    pub starts: StartSettings,
    /// Samples at the start of every record that the open-loop error
    /// simulates but does not score (`simulation_error`,
    /// `rms_per_channel`; default 0, every sample scored; a value beyond
    /// a record leaves its last sample scored). Reason: a benchmark's
    /// test records allow their first samples for the state's
    /// initialisation (the Silverbox: 50).
    pub unscored: usize,
}

/// Source of the states the trace and the segments use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StatesSource {
    /// Reconstructed by the sub-sample ("lifted") smoother
    /// ([`super::lifted::reconstruct`]): the unknown force piecewise
    /// constant on sub-intervals of each sample, so impacts between samples
    /// are seen.
    #[default]
    Lifted,
    /// Reconstructed by the full-horizon smoother ([`crate::horizon`]), the
    /// unknown force linear between samples.
    Reconstructed,
    /// The truth stored with a simulated record (for validation of the
    /// later steps only; an error on a record without truth).
    Truth,
}

/// The measurement noise: measured from the record ([`super::noise`]), or
/// assumed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoiseSettings {
    /// Noise standard deviation of every channel as a fraction of its RMS
    /// (default 0.01; > 0 and < 1): the level assumed when `measure` is
    /// off, and the starting guess of the measurement. Weighs the lifted
    /// smoother's data, sets the fit's standard errors and the noise cost
    /// a fit is judged against. Reason: accelerometers of a shaker test
    /// read about 1 %.
    pub level: f64,
    /// Measure each channel's noise from the residual of the located-force
    /// reconstruction and use the measured level in place of `level`
    /// (default true). Reason: real records carry 0.1–5 % noise; a floor
    /// assumed at 1 % hides small effects in quiet records and calls noise
    /// an effect in noisy ones.
    pub measure: bool,
    /// The force directions are searched again with the measured level
    /// when it differs from `level` by more than this factor (default 1.5,
    /// above 1). Reason: the search stops when the residual reaches 1.5 × the
    /// noise, so a level off by more than that changes how many directions
    /// it takes.
    pub relocate_factor: f64,
    /// Frequency bands the residual's spectrum is split into for the
    /// measurement (default 16; 4 to 256). The level is the lower quartile
    /// over the bands (corrected for white noise's own quartile), so model
    /// error confined to fewer than three bands in four (at the modes) does
    /// not raise it. Reason: 16 bands of a 4096-sample record hold 128
    /// lines each, a 12 % scatter per band.
    pub bands: usize,
    /// Multiple-shooting relative error at or below `floor_multiple ×`
    /// the noise level is taken as noise and integration error: no effect
    /// is sought (default 2.5; > 0). Reason: the exact model of a record
    /// scores 1.1–1.4 × its noise level, so 2.5 leaves room without hiding
    /// a missing effect.
    pub floor_multiple: f64,
    /// The loop's stop: no further effect is sought once the
    /// multiple-shooting error is at or below `stop_multiple ×` the level
    /// measured on the record, when that is below the noise floor
    /// (default 1.2; ≥ 1). Reason: the measured level knows the noise the
    /// assumed one only bounds; a record whose exact model scores 1.3 × its
    /// measured noise was left at 2.1 % by the floor of 2.5 %, its 0.1 N
    /// friction on every mass taken for noise; and at 1.5 × (where a
    /// diagnosis is accepted) a stop of mass 8 with 0.2 N of friction on
    /// every mass stopped at 1.31 × the measured 1.29 % after the stop, its
    /// validation at 1.50 ×, where at 1.2 × the friction is found (0.2005
    /// N) and both errors end at 0.98 %. An effect must still pay to be
    /// kept below it.
    pub stop_multiple: f64,
}

impl Default for NoiseSettings {
    fn default() -> Self {
        NoiseSettings {
            level: 0.01,
            measure: true,
            relocate_factor: 1.5,
            bands: 16,
            floor_multiple: 2.5,
            stop_multiple: 1.2,
        }
    }
}

impl NoiseSettings {
    /// The noise floor of the multiple-shooting error, `floor_multiple ×
    /// level`.
    pub fn floor(&self) -> f64 {
        self.floor_multiple * self.level
    }
}

/// Segments of the multiple-shooting error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentSettings {
    /// Segment length, s (default 0.1; > 0, at least 4 samples are used,
    /// and the record must hold two segments). Reason: a few periods of
    /// the lowest mode, short enough that a start-state error does not grow
    /// past the effect sought.
    pub seconds: f64,
    /// Segments used by the fit, evenly spread over the record (default
    /// 20; ≥ 1). Reason: enough impacts for a contact's gap and stiffness
    /// at a tenth of the cost of every segment.
    pub fit_segments: usize,
    /// Samples over which the identified force must be quiet where a
    /// segment boundary is placed (default 4; ≥ 1). Reason: a start
    /// state estimated just after an impact carries the impulse's error.
    pub quiet_window: usize,
}

impl Default for SegmentSettings {
    fn default() -> Self {
        SegmentSettings {
            seconds: 0.1,
            fit_segments: 20,
            quiet_window: 4,
        }
    }
}

/// Sub-steps per sample of the simulations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SubstepSettings {
    /// Sub-steps of the identification and the trace's linear model
    /// (default 10; ≥ 1). Reason: the sampled map of a linear model is
    /// exact at 10.
    pub base: usize,
    /// Fewest sub-steps of a scored or fitted model (default 40; ≥ 1).
    /// Reason: at 10 the Newmark period error of the highest modes was
    /// left for an effect to fit; a linear model (and a contact model
    /// while its contacts are open) is stepped a whole sample at a time,
    /// so it costs nothing there.
    pub min: usize,
    /// Target `ω h` of the stiffest element (default 0.15 rad; > 0).
    /// Reason: a period error of about `(ω h)²/12`, 0.2 %, below the noise.
    pub omega_h: f64,
    /// Most sub-steps (default 80; ≥ `min`). Reason: bounds the cost of a
    /// very stiff trial contact.
    pub max: usize,
    /// Noise level (a fraction of the channel RMS) the three values above
    /// are set for (default 0.01; in (0, 1]). On a record whose noise
    /// level ν is below it, with `r = min(noise_reference / ν, 4)`, the
    /// loop runs at `omega_h / r`, `min · r^½` and `max · r^½`: Newmark's
    /// error falls as h², a contact's engagement inside a sub-step as h
    /// (docs/diagnose.md, *Integration error and noise*); `r` stops at 4,
    /// where the cost has grown fourfold and a noise-free record would
    /// ask for no end of sub-steps. Reason: at 0.3 % noise the true model
    /// scored at 40–49 sub-steps against records integrated at 400 left
    /// 1.1–1.55 × the noise, at 160 sub-steps 0.93–0.94 ×.
    pub noise_reference: f64,
}

/// Largest ratio of [`SubstepSettings::noise_reference`] to a record's
/// noise that [`SubstepSettings::at_noise`] acts on.
const MAX_NOISE_RATIO: f64 = 4.0;

impl SubstepSettings {
    /// The settings for a record whose noise level is `level` (see
    /// [`SubstepSettings::noise_reference`]); unchanged at or above it.
    pub fn at_noise(&self, level: f64) -> SubstepSettings {
        let ratio = (self.noise_reference / level).min(MAX_NOISE_RATIO);
        if !(ratio > 1.0) {
            return *self;
        }
        let scaled = |n: usize| (n as f64 * ratio.sqrt()).round() as usize;
        SubstepSettings {
            omega_h: self.omega_h / ratio,
            min: scaled(self.min),
            max: scaled(self.max),
            ..*self
        }
    }
}

impl Default for SubstepSettings {
    fn default() -> Self {
        SubstepSettings {
            base: 10,
            min: 40,
            omega_h: 0.15,
            max: 80,
            noise_reference: 0.01,
        }
    }
}

/// The lifted smoother ([`LiftedSettings`] without its noise level, which
/// is [`NoiseSettings::level`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LiftedGroup {
    /// Sub-intervals per sample on which the unknown force is constant
    /// (default 8; 1..=64). Reason: an impact between samples is placed to
    /// an eighth of a sample.
    pub resolution: usize,
    /// Weight of the force prior, 1/N² relative to the data weight
    /// (default 1e-2; > 0). Reason: 1e-4 to 1e-1 gave the same states
    /// within a few per cent on the LANL contact records.
    pub lambda: f64,
    /// Prior standard deviations of the initial displacements (m) and
    /// velocities (m/s) (default (1, 10); finite, > 0). Reason: weak, yet
    /// states the data do not see stay determined.
    pub x0_std: (f64, f64),
    /// Reweighting passes that make the force prior sparse (default 4;
    /// 0..=50). Reason: a contact force has a mean that a quadratic prior
    /// removes.
    pub reweight_passes: usize,
    /// ε of the reweighting relative to the force RMS (default 1e-3;
    /// (0, 1]). Reason: bounds the weights by 1/ε.
    pub reweight_floor: f64,
    /// Least weighted residual RMS (1 = the noise level) of the
    /// reconstruction along located directions: below it `lambda` is
    /// raised by factors of √10, kept when no weight up to 1e4 times
    /// reaches it (default 0.5; [0, 1), 0 keeps `lambda`).
    /// Reason: a closer fit absorbs more than three quarters of the noise
    /// with the force; at 32 361 DOFs of the membrane of docs/formats.md
    /// `lambda` = 1e-2 left 0.18 and lost the stop.
    pub min_residual: f64,
}

impl Default for LiftedGroup {
    fn default() -> Self {
        let l = LiftedSettings::default();
        LiftedGroup {
            resolution: l.resolution,
            lambda: l.lambda,
            x0_std: l.x0_std,
            reweight_passes: l.reweight_passes,
            reweight_floor: l.reweight_floor,
            min_residual: l.min_residual,
        }
    }
}

/// The trace ([`TraceSettings`]; one effect is selected per round).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TraceGroup {
    /// Smallest fraction of the remaining residual energy an effect must
    /// remove to be selected (default 0.05; [0, 1)). Reason: noise and
    /// integration error select nothing.
    pub min_gain: f64,
    /// Friction regularisation velocity, m/s (default 1e-3; > 0). Reason:
    /// well below the velocities of the test.
    pub friction_vreg: f64,
    /// Points of the coarse gap scan of a contact (default 24; ≥ 2).
    /// Reason: resolves the gap to a few per cent of the displacement range.
    pub gap_grid: usize,
}

impl Default for TraceGroup {
    fn default() -> Self {
        let t = TraceSettings::default();
        TraceGroup {
            min_gain: t.min_gain,
            friction_vreg: t.friction_vreg,
            gap_grid: t.gap_grid,
        }
    }
}

/// Which candidate is fitted, and which is kept.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScreenSettings {
    /// Most effects added (default 3; ≥ 0). Reason: a model that needs
    /// more is better rebuilt than patched.
    pub max_effects: usize,
    /// Share of the squared multiple-shooting error a fitted effect must
    /// remove, or it is withdrawn (default 0.05; [0, 1)). Reason: the
    /// trace's threshold.
    pub min_improvement: f64,
    /// The same for a candidate below the trace's screen, as a share of
    /// the squared error above the noise measured on the record (default
    /// 0.5; [0, 1)). Reason: it must explain half of what remains.
    pub companion_improvement: f64,
    /// A candidate below the screen predicted to remove less than this
    /// share of the fit cost is not fitted (default 0.2; [0, 1]). Reason:
    /// a smaller gain is within what the linearization misjudges.
    pub companion_screen: f64,
    /// ...unless the error is above `far_from_noise ×` the noise floor
    /// (default 4; > 0)...
    pub far_from_noise: f64,
    /// ...when this screen applies (default 0.05; [0, 1]). Reason: a model
    /// that far from the record is worth a fit for a smaller predicted
    /// gain (the linearization at a contact's fit underrated a spring
    /// beside it: 18.9 % predicted, 25 % → 1.2 % fitted).
    pub companion_screen_far: f64,
    /// While the multiple-shooting error is above this multiple of the
    /// noise measured on the record, a dissipative law with the model's
    /// damping free beside it is fitted whatever the joint
    /// linearization predicts (default 2; ≥ 1). Reason: linearized at zero
    /// strength a friction's derivative is a viscous force the freed
    /// damping takes up; what a finite level adds (the masses sticking) it
    /// does not see (0.3 N on every mass beside a bumper: predicted 2.5 %
    /// of the fit cost, fitted the error falls from 3.3 % to 2.5 %, and to
    /// 0.99 % refined).
    pub dissipative_far: f64,
    /// Multiples of the joint linearization's parameter step that start
    /// the fit of a candidate taken in below the screen (default [1, 2,
    /// 3]; finite). Reason: the linearized step falls short along the
    /// valley where a companion trades against the effect found.
    pub gn_strides: Vec<f64>,
    /// Smallest relative stiffness change that is also fitted as the
    /// cubic spring on its pair (default 0.5; > 0). Reason: a large
    /// change is how a stiffening spring shows up linearized.
    pub alternative_change: f64,
    /// ...when the error it leaves is above this multiple of the noise
    /// floor (default 4; > 0). Reason: near the noise the linear change
    /// is as good.
    pub alternative_floor: f64,
}

impl Default for ScreenSettings {
    fn default() -> Self {
        ScreenSettings {
            max_effects: 3,
            min_improvement: 0.05,
            companion_improvement: 0.5,
            companion_screen: 0.2,
            far_from_noise: 4.0,
            companion_screen_far: 0.05,
            dissipative_far: 2.0,
            gn_strides: vec![1.0, 2.0, 3.0],
            alternative_change: 0.5,
            alternative_floor: 4.0,
        }
    }
}

/// The fit of the added effects.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FitGroup {
    /// Levenberg–Marquardt iteration limit of the fit and of the joint fit
    /// of parameters and start states (default 30; ≥ 1). Reason: the joint
    /// fit converges in under 20 on the test matrix.
    pub max_iterations: usize,
    /// Converged when a step changes every scaled parameter by less than
    /// `x_tol (1 + |x|)` (default 1e-5; > 0). Reason: far below the
    /// parameters' standard errors.
    pub x_tol: f64,
    /// Converged when an accepted step lowers the cost by less than this
    /// fraction (default 1e-7; > 0).
    pub f_tol: f64,
    /// Jacobian of the race of starts (default the integrator's forward
    /// sensitivities; the joint fit always uses them).
    pub jacobian: JacobianMethod,
    /// Initial Levenberg–Marquardt damping relative to `diag(JᵀJ)`
    /// (default 1e-3; > 0).
    pub lm_lambda: f64,
    /// Iterations each start of the race gets before the best goes on
    /// (default 6; ≥ 1). Reason: enough to rank the basins.
    pub race_iterations: usize,
    /// Race starts carried on at most (default 2; ≥ 1).
    pub polish_starts: usize,
    /// A carried-on fit ending below this multiple of the noise cost is
    /// not tried from another start (default 10; > 0).
    pub noise_margin: f64,
    /// Multiples of a cubic spring's traced `k3` that start the fit too
    /// (default [0.6, 1.6]; > 0). Reason: the segment error has local
    /// minima in `k3`.
    pub cubic_brackets: Vec<f64>,
    /// Contact stiffnesses of the scan, as multiples of the stiffest
    /// spring at the pair (default [10, 40]; > 0). Reason: a bumper is
    /// one to two orders stiffer than the springs it stops.
    pub contact_stiffnesses: Vec<f64>,
    /// Quantiles of the reconstructed relative displacement tried as the
    /// contact's gap (default [0.8, 0.88, 0.93, 0.96, 0.98, 0.99, 0.995];
    /// in [0, 1]). Reason: the cost is rough in the gap, and a contact
    /// closes in the top fifth of the motion.
    pub gap_quantiles: Vec<f64>,
    /// The contact gap's upper bound, as a multiple of the largest
    /// reconstructed relative displacement (default 1.2; ≥ 1). Reason:
    /// beyond it the contact never closes.
    pub gap_upper: f64,
    /// A friction level's upper bound beside freed damping (the damping's
    /// nuisance parameters, or a damping change found before), at least
    /// this multiple of the level that dissipates along the reconstructed
    /// states what the model's damping does (default 2; ≥ 1). Reason: a
    /// damping calibrated on a record with friction has taken the
    /// friction's share, so the trace rates the friction at a tenth of its
    /// level and a bound at 11 × the traced level can exclude the truth;
    /// freed, the damping gives that share back, at most all it dissipates.
    pub friction_upper: f64,
    /// The fit runs on the start states fitted for the model without the
    /// new effect when the trial at its start scores lower on them than on
    /// the reconstructed ones by at least this factor, per sample covered
    /// (default 8; ≥ 1). Reason: with a cubic spring kept, the
    /// reconstruction from the linear model leaves its error in the start
    /// states (10 and 43 × the fitted ones' cost on two records of a cubic
    /// with friction on every mass), and a race on them drives the
    /// friction to a bound; beside a contact (1.14 and 4.7 ×) the start
    /// states fitted without the friction hold part of it and the race
    /// there ends low (0.195 N for 0.3 N).
    pub fitted_states_gain: f64,
    /// Between this factor and `fitted_states_gain` the fit runs on both
    /// sets of start states, and the one whose polished fit ends lower
    /// (on start states refined jointly with the parameters, the same
    /// segments) is kept (default 2; ≥ 1, ≤ `fitted_states_gain`; equal
    /// to it: never both). Reason: the ratios measured beside a contact
    /// (1.14, 2.33, 4.7) and beside a cubic (10.3, 43) leave no factor
    /// with a margin on both sides; in between, the polished cost decides
    /// rather than the cost at the start. Each fit in the band costs two
    /// races and two polishes.
    pub fitted_states_both: f64,
    /// Clearance stiffnesses of the scan, as multiples of the stiffest
    /// spring at the pair (default [3, 5.5, 10, 18, 30]; > 0). Reason: a
    /// clearance's stiffness is of the order of the spring it works
    /// beside, not a penalty one to two orders stiffer; the error's valley
    /// in (gap, stiffness) is narrow, so the multiples are less than 2×
    /// apart.
    pub clearance_stiffnesses: Vec<f64>,
    /// Quantiles of the reconstructed relative displacement's magnitude
    /// tried as a clearance's gap (default [0.2, 0.35, 0.5, 0.6, 0.7,
    /// 0.8, 0.9]; in [0, 1]). Reason: a clearance engages on either side
    /// whenever `|δ|` passes the gap, so its gap may lie anywhere in the
    /// motion, not only in its top fifth.
    pub clearance_gap_quantiles: Vec<f64>,
    /// Score each (gap, stiffness) of a clearance's scan on segment start
    /// states refined for that model, and race the starts on those of the
    /// best (default true). Reason: on the states reconstructed with the
    /// linear model every clearance scored alike, the true one included.
    pub clearance_refined_scan: bool,
    /// Where a parameter traced at zero (which cannot be scaled
    /// relatively) starts instead.
    pub zero_starts: ZeroStarts,
}

/// Starts of parameters traced at zero: a contact traced to switch on at
/// zero gap or with zero stiffness, a friction level or a spring of zero.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ZeroStarts {
    /// A contact's gap, as a fraction of the largest reconstructed
    /// relative displacement (default 0.05; > 0). Reason: just inside the
    /// motion, so the contact closes.
    pub gap: f64,
    /// A contact's stiffness, as a multiple of the stiffest spring at the
    /// pair (default 10; > 0). Reason: the lower end of a bumper's range.
    pub contact_stiffness: f64,
    /// A friction level, as a fraction of the largest applied force
    /// (default 1e-3; > 0). Reason: small, yet it scales.
    pub friction: f64,
    /// A spring's stiffness, as a fraction of the stiffest spring at its
    /// DOFs (default 1e-3; > 0). Reason: small, yet it scales.
    pub spring: f64,
}

impl Default for ZeroStarts {
    fn default() -> Self {
        ZeroStarts {
            gap: 0.05,
            contact_stiffness: 10.0,
            friction: 1e-3,
            spring: 1e-3,
        }
    }
}

impl Default for FitGroup {
    fn default() -> Self {
        FitGroup {
            max_iterations: 30,
            x_tol: 1e-5,
            f_tol: 1e-7,
            jacobian: FitSettings::default().jacobian,
            lm_lambda: FitSettings::default().lm_lambda,
            race_iterations: 6,
            polish_starts: 2,
            noise_margin: 10.0,
            cubic_brackets: vec![0.6, 1.6],
            contact_stiffnesses: vec![10.0, 40.0],
            gap_quantiles: vec![0.8, 0.88, 0.93, 0.96, 0.98, 0.99, 0.995],
            gap_upper: 1.2,
            friction_upper: 2.0,
            fitted_states_gain: 8.0,
            fitted_states_both: 2.0,
            clearance_stiffnesses: vec![3.0, 5.5, 10.0, 18.0, 30.0],
            clearance_gap_quantiles: vec![0.2, 0.35, 0.5, 0.6, 0.7, 0.8, 0.9],
            clearance_refined_scan: true,
            zero_starts: ZeroStarts::default(),
        }
    }
}

/// The segment start states ([`super::starts`], [`super::joint`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StartSettings {
    /// Gauss–Newton iterations refining each segment's start state for the
    /// model scored (default 3; 0 = the reconstructed states; a linear
    /// model takes one). Reason: from a few sensors the reconstructed
    /// start state's error dominates an exact model's segment error.
    pub iterations: usize,
    /// Most alternations of start-state refinement and joint fit after an
    /// effect's race (default 12). Reason: they stop earlier, once the cost
    /// falls by less than `alternation_gain`.
    pub alternations: usize,
    /// Relative cost decrease below which the alternations stop (default
    /// 0.01; [0, 1)).
    pub alternation_gain: f64,
    /// A segment whose cost exceeds this multiple of the median is taken to
    /// be started in a wrong basin (default 8; > 1). Reason: an impact on
    /// the wrong side of a gap costs an order of magnitude.
    pub outlier: f64,
    /// A segment whose step lowered its cost by less than this fraction
    /// takes no further step (default 1e-3; [0, 1)).
    pub settled: f64,
    /// Run-in passes over outlying segments (default 2).
    pub run_in_passes: usize,
    /// Passes of segment splits after the rescues (default 3; 0 = none):
    /// a segment far above the lowest costs is cut in two, each half with
    /// its own start ([`super::starts`], split). Reason: a clearance
    /// between masses of lanl8dof engaged above the Nyquist frequency left
    /// the exact model at 63 % over 0.1 s segments, 1.47 % after two
    /// passes, 1.01 % after three (1 % noise), 1.00 % after five. The
    /// third pass costs time where the second keeps splits (the
    /// background-friction tests: 547 s against 296 s with two).
    pub split_passes: usize,
    /// A split is kept when its halves cost at most this fraction of the
    /// segment (default 0.5; (0, 1]). Reason: a model that lacks the
    /// effect gains about a tenth from a split, the exact model orders of
    /// magnitude.
    pub split_gain: f64,
    /// Accepted joint-fit steps in a row each lowering the cost by less
    /// than `stall_gain` after which the joint fit stops (default 3; ≥ 1).
    /// Reason: a run of them is the cost's roughness (contact switches
    /// within the segments), not progress.
    pub stall_steps: usize,
    /// See `stall_steps` (default 1e-3; [0, 1)).
    pub stall_gain: f64,
    /// A second race start carried on is given up once its cost exceeds
    /// this multiple of the first's (default 2; ≥ 1). Reason: it will not
    /// catch up, and each alternation costs a joint fit.
    pub give_up: f64,
    /// Gauss–Newton iterations of the start states on which a withdrawal
    /// of a candidate below the screen is confirmed ([`super::decide`];
    /// default 10; 0 = not confirmed, else ≥ `iterations`). Reason: with
    /// `iterations` from the reconstructed states a nonlinear model's
    /// segments are not converged: a cubic spring 1–2 (3e12 N/m³) with
    /// 0.1 N of friction on every mass fitted beside it scored 1.67 %
    /// against 1.90 % without the friction at 3 iterations, 1.33 % against
    /// 1.72 % at 10, the fit's own start states giving 1.27 % on its
    /// segments (docs/diagnose.md, the loop's step 4).
    pub confirm_iterations: usize,
}

impl Default for StartSettings {
    fn default() -> Self {
        StartSettings {
            iterations: 3,
            alternations: 12,
            alternation_gain: 0.01,
            outlier: 8.0,
            settled: 1e-3,
            run_in_passes: 2,
            split_passes: 3,
            split_gain: 0.5,
            stall_steps: 3,
            stall_gain: 1e-3,
            give_up: 2.0,
            confirm_iterations: 10,
        }
    }
}

impl Default for DiagnoseSettings {
    fn default() -> Self {
        DiagnoseSettings {
            states: StatesSource::Lifted,
            noise: NoiseSettings::default(),
            segments: SegmentSettings::default(),
            substeps: SubstepSettings::default(),
            locate: LocateSettings::default(),
            lifted: LiftedGroup::default(),
            horizon: HorizonSettings {
                selection: horizon::settings::WeightSelection::Gcv,
                ..HorizonSettings::default()
            },
            trace: TraceGroup::default(),
            screen: ScreenSettings::default(),
            fit: FitGroup::default(),
            starts: StartSettings::default(),
            unscored: 0,
        }
    }
}

/// A rule of [`DiagnoseSettings::validate`]: Err names the field, its
/// value and the rule.
fn rule(ok: bool, field: &str, value: impl std::fmt::Debug, rule: &str) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(TacitError::Setting(format!(
            "diagnose settings: {field} = {value:?}: {rule}"
        )))
    }
}

/// `x` in `(0, ∞)`, finite.
fn positive(x: f64) -> bool {
    x > 0.0 && x.is_finite()
}

/// `x` in `[0, 1)`.
fn fraction(x: f64) -> bool {
    (0.0..1.0).contains(&x)
}

impl DiagnoseSettings {
    /// The multiple-shooting relative error taken as noise and integration
    /// error ([`NoiseSettings::floor`]).
    pub fn noise_floor(&self) -> f64 {
        self.noise.floor()
    }

    /// The optimizer settings of the fit (Levenberg–Marquardt; the noise
    /// level of the standard errors is [`NoiseSettings::level`]).
    pub fn fit_settings(&self) -> FitSettings {
        FitSettings {
            max_iterations: self.fit.max_iterations,
            x_tol: self.fit.x_tol,
            f_tol: self.fit.f_tol,
            jacobian: self.fit.jacobian,
            lm_lambda: self.fit.lm_lambda,
            noise_level: self.noise.level,
            ..FitSettings::default()
        }
    }

    /// The lifted smoother's settings (its noise level is
    /// [`NoiseSettings::level`]).
    pub fn lifted_settings(&self) -> LiftedSettings {
        LiftedSettings {
            resolution: self.lifted.resolution,
            lambda: self.lifted.lambda,
            noise_fraction: self.noise.level,
            x0_std: self.lifted.x0_std,
            reweight_passes: self.lifted.reweight_passes,
            reweight_floor: self.lifted.reweight_floor,
            min_residual: self.lifted.min_residual,
        }
    }

    /// The trace's settings for one round (one effect selected).
    pub fn trace_settings(&self) -> TraceSettings {
        TraceSettings {
            min_gain: self.trace.min_gain,
            max_effects: 1,
            friction_vreg: self.trace.friction_vreg,
            gap_grid: self.trace.gap_grid,
        }
    }

    /// Check every rule; the error names the field, its value and the rule.
    pub fn validate(&self) -> Result<()> {
        self.validate_basics()?;
        self.validate_lifted()?;
        self.horizon.validate().map_err(|e| match e {
            TacitError::Setting(m) => TacitError::Setting(format!("diagnose settings: {m}")),
            e => e,
        })?;
        let t = &self.trace;
        rule(
            fraction(t.min_gain),
            "trace.min_gain",
            t.min_gain,
            "must be in [0, 1)",
        )?;
        rule(
            positive(t.friction_vreg),
            "trace.friction_vreg",
            t.friction_vreg,
            "must be > 0",
        )?;
        rule(t.gap_grid >= 2, "trace.gap_grid", t.gap_grid, "must be ≥ 2")?;
        self.validate_screen()?;
        self.validate_fit()?;
        let st = &self.starts;
        rule(
            fraction(st.alternation_gain),
            "starts.alternation_gain",
            st.alternation_gain,
            "must be in [0, 1)",
        )?;
        rule(
            st.outlier > 1.0 && st.outlier.is_finite(),
            "starts.outlier",
            st.outlier,
            "must be > 1",
        )?;
        rule(
            st.split_gain > 0.0 && st.split_gain <= 1.0,
            "starts.split_gain",
            st.split_gain,
            "must be in (0, 1]",
        )?;
        rule(
            fraction(st.settled),
            "starts.settled",
            st.settled,
            "must be in [0, 1)",
        )?;
        rule(
            st.stall_steps >= 1,
            "starts.stall_steps",
            st.stall_steps,
            "must be ≥ 1",
        )?;
        rule(
            fraction(st.stall_gain),
            "starts.stall_gain",
            st.stall_gain,
            "must be in [0, 1)",
        )?;
        let c = st.confirm_iterations;
        rule(
            c == 0 || c >= st.iterations,
            "starts.confirm_iterations",
            c,
            "must be 0 or ≥ starts.iterations",
        )?;
        let g = st.give_up;
        rule(
            g >= 1.0 && g.is_finite(),
            "starts.give_up",
            g,
            "must be ≥ 1",
        )
    }

    fn validate_basics(&self) -> Result<()> {
        let n = &self.noise;
        rule(
            n.level > 0.0 && n.level < 1.0,
            "noise.level",
            n.level,
            "must be in (0, 1)",
        )?;
        rule(
            n.relocate_factor > 1.0 && n.relocate_factor.is_finite(),
            "noise.relocate_factor",
            n.relocate_factor,
            "must be > 1",
        )?;
        rule(
            (4..=256).contains(&n.bands),
            "noise.bands",
            n.bands,
            "must be in 4..=256",
        )?;
        rule(
            positive(n.floor_multiple),
            "noise.floor_multiple",
            n.floor_multiple,
            "must be > 0",
        )?;
        rule(
            n.stop_multiple >= 1.0 && n.stop_multiple.is_finite(),
            "noise.stop_multiple",
            n.stop_multiple,
            "must be ≥ 1",
        )?;
        let g = &self.segments;
        rule(
            positive(g.seconds),
            "segments.seconds",
            g.seconds,
            "must be > 0",
        )?;
        rule(
            g.fit_segments >= 1,
            "segments.fit_segments",
            g.fit_segments,
            "must be ≥ 1",
        )?;
        rule(
            g.quiet_window >= 1,
            "segments.quiet_window",
            g.quiet_window,
            "must be ≥ 1",
        )?;
        let s = &self.substeps;
        rule(s.base >= 1, "substeps.base", s.base, "must be ≥ 1")?;
        rule(s.min >= 1, "substeps.min", s.min, "must be ≥ 1")?;
        rule(
            positive(s.omega_h),
            "substeps.omega_h",
            s.omega_h,
            "must be > 0",
        )?;
        rule(
            s.max >= s.min,
            "substeps.max",
            s.max,
            "must be ≥ substeps.min",
        )?;
        rule(
            s.noise_reference > 0.0 && s.noise_reference <= 1.0,
            "substeps.noise_reference",
            s.noise_reference,
            "must be in (0, 1]",
        )?;
        let l = &self.locate;
        rule(
            (0.0..1.0).contains(&l.ratio),
            "locate.ratio",
            l.ratio,
            "must be in [0, 1) (0: off)",
        )?;
        rule(
            positive(l.noise_stop),
            "locate.noise_stop",
            l.noise_stop,
            "must be > 0",
        )
    }

    fn validate_lifted(&self) -> Result<()> {
        let l = &self.lifted;
        rule(
            (1..=64).contains(&l.resolution),
            "lifted.resolution",
            l.resolution,
            "must be in 1..=64",
        )?;
        rule(positive(l.lambda), "lifted.lambda", l.lambda, "must be > 0")?;
        let x0 = l.x0_std;
        rule(
            positive(x0.0) && positive(x0.1),
            "lifted.x0_std",
            x0,
            "both must be > 0 and finite",
        )?;
        rule(
            l.reweight_passes <= 50,
            "lifted.reweight_passes",
            l.reweight_passes,
            "must be in 0..=50",
        )?;
        rule(
            l.reweight_floor > 0.0 && l.reweight_floor <= 1.0,
            "lifted.reweight_floor",
            l.reweight_floor,
            "must be in (0, 1]",
        )?;
        rule(
            (0.0..1.0).contains(&l.min_residual),
            "lifted.min_residual",
            l.min_residual,
            "must be in [0, 1)",
        )
    }

    fn validate_screen(&self) -> Result<()> {
        let s = &self.screen;
        rule(
            fraction(s.min_improvement),
            "screen.min_improvement",
            s.min_improvement,
            "must be in [0, 1)",
        )?;
        rule(
            fraction(s.companion_improvement),
            "screen.companion_improvement",
            s.companion_improvement,
            "must be in [0, 1)",
        )?;
        rule(
            (0.0..=1.0).contains(&s.companion_screen),
            "screen.companion_screen",
            s.companion_screen,
            "must be in [0, 1]",
        )?;
        rule(
            positive(s.far_from_noise),
            "screen.far_from_noise",
            s.far_from_noise,
            "must be > 0",
        )?;
        rule(
            (0.0..=1.0).contains(&s.companion_screen_far),
            "screen.companion_screen_far",
            s.companion_screen_far,
            "must be in [0, 1]",
        )?;
        rule(
            s.dissipative_far >= 1.0 && s.dissipative_far.is_finite(),
            "screen.dissipative_far",
            s.dissipative_far,
            "must be finite and >= 1",
        )?;
        rule(
            s.gn_strides.iter().all(|f| f.is_finite()),
            "screen.gn_strides",
            &s.gn_strides,
            "must be finite",
        )?;
        rule(
            positive(s.alternative_change),
            "screen.alternative_change",
            s.alternative_change,
            "must be > 0",
        )?;
        rule(
            positive(s.alternative_floor),
            "screen.alternative_floor",
            s.alternative_floor,
            "must be > 0",
        )
    }

    fn validate_fit(&self) -> Result<()> {
        let f = &self.fit;
        rule(
            f.max_iterations >= 1,
            "fit.max_iterations",
            f.max_iterations,
            "must be ≥ 1",
        )?;
        rule(positive(f.x_tol), "fit.x_tol", f.x_tol, "must be > 0")?;
        rule(positive(f.f_tol), "fit.f_tol", f.f_tol, "must be > 0")?;
        rule(
            positive(f.lm_lambda),
            "fit.lm_lambda",
            f.lm_lambda,
            "must be > 0",
        )?;
        rule(
            f.race_iterations >= 1,
            "fit.race_iterations",
            f.race_iterations,
            "must be ≥ 1",
        )?;
        rule(
            f.polish_starts >= 1,
            "fit.polish_starts",
            f.polish_starts,
            "must be ≥ 1",
        )?;
        rule(
            positive(f.noise_margin),
            "fit.noise_margin",
            f.noise_margin,
            "must be > 0",
        )?;
        let all_pos = |v: &[f64]| !v.is_empty() && v.iter().all(|&x| positive(x));
        rule(
            all_pos(&f.cubic_brackets),
            "fit.cubic_brackets",
            &f.cubic_brackets,
            "must be > 0, at least one",
        )?;
        rule(
            all_pos(&f.contact_stiffnesses),
            "fit.contact_stiffnesses",
            &f.contact_stiffnesses,
            "must be > 0, at least one",
        )?;
        rule(
            all_pos(&f.clearance_stiffnesses),
            "fit.clearance_stiffnesses",
            &f.clearance_stiffnesses,
            "must be > 0, at least one",
        )?;
        let quantiles = |v: &[f64]| !v.is_empty() && v.iter().all(|q| (0.0..=1.0).contains(q));
        rule(
            quantiles(&f.gap_quantiles),
            "fit.gap_quantiles",
            &f.gap_quantiles,
            "must be in [0, 1], at least one",
        )?;
        rule(
            quantiles(&f.clearance_gap_quantiles),
            "fit.clearance_gap_quantiles",
            &f.clearance_gap_quantiles,
            "must be in [0, 1], at least one",
        )?;
        rule(
            f.gap_upper >= 1.0 && f.gap_upper.is_finite(),
            "fit.gap_upper",
            f.gap_upper,
            "must be ≥ 1",
        )?;
        rule(
            f.friction_upper >= 1.0 && f.friction_upper.is_finite(),
            "fit.friction_upper",
            f.friction_upper,
            "must be ≥ 1",
        )?;
        rule(
            f.fitted_states_gain >= 1.0 && f.fitted_states_gain.is_finite(),
            "fit.fitted_states_gain",
            f.fitted_states_gain,
            "must be ≥ 1",
        )?;
        rule(
            f.fitted_states_both >= 1.0 && f.fitted_states_both <= f.fitted_states_gain,
            "fit.fitted_states_both",
            f.fitted_states_both,
            "must be ≥ 1 and ≤ fit.fitted_states_gain",
        )?;
        let z = &f.zero_starts;
        rule(positive(z.gap), "fit.zero_starts.gap", z.gap, "must be > 0")?;
        let k = z.contact_stiffness;
        rule(
            positive(k),
            "fit.zero_starts.contact_stiffness",
            k,
            "must be > 0",
        )?;
        rule(
            positive(z.friction),
            "fit.zero_starts.friction",
            z.friction,
            "must be > 0",
        )?;
        rule(
            positive(z.spring),
            "fit.zero_starts.spring",
            z.spring,
            "must be > 0",
        )
    }

    /// Read settings from a file: TOML (`.toml`), or JSON — a settings
    /// object, or a diagnosis report.json whose `settings` it replays.
    /// Missing fields take their defaults; unknown fields are errors. The
    /// result is validated.
    pub fn from_file(path: &std::path::Path) -> Result<DiagnoseSettings> {
        let text = std::fs::read_to_string(path).map_err(|e| TacitError::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
        let bad = |msg: String| TacitError::Setting(format!("{}: {msg}", path.display()));
        let s: DiagnoseSettings = if path.extension().is_some_and(|e| e == "json") {
            let v: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
            let v = match v.get("settings") {
                Some(s) if v.get("verdict").is_some() => s.clone(),
                _ => v,
            };
            serde_json::from_value(v).map_err(|e| bad(e.to_string()))?
        } else {
            toml::from_str(&text).map_err(|e| bad(e.to_string()))?
        };
        s.validate().map_err(|e| match e {
            TacitError::Setting(m) => bad(m),
            e => e,
        })?;
        Ok(s)
    }

    /// The settings as TOML (what [`DiagnoseSettings::from_file`] reads).
    pub fn to_toml_string(&self) -> Result<String> {
        toml::to_string(self)
            .map_err(|e| TacitError::Setting(format!("diagnose settings as TOML: {e}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sub_steps_follow_a_noise_below_the_reference_up_to_four_times() {
        let s = SubstepSettings::default();
        for level in [0.01, 0.03, 0.5] {
            assert_eq!(s.at_noise(level), s, "at {level}");
        }
        let quarter = s.at_noise(0.0025);
        assert!((quarter.omega_h - 0.0375).abs() < 1e-15);
        assert_eq!((quarter.min, quarter.max, quarter.base), (80, 160, 10));
        assert_eq!(s.at_noise(1e-5), quarter, "the ratio stops at 4");
        let near = s.at_noise(0.00999);
        assert_eq!((near.min, near.max), (40, 80), "no jump just below 1 %");
        let low = s.at_noise(0.003);
        assert_eq!((low.min, low.max), (73, 146));
    }

    /// The defaults pass, and the noise floor derived from the noise level
    /// is the 0.025 used before it was derived, to the bit.
    #[test]
    fn the_defaults_are_valid_and_the_floor_is_two_and_a_half_percent() {
        let s = DiagnoseSettings::default();
        s.validate().unwrap();
        assert_eq!(s.noise_floor(), 0.025);
        assert_eq!(s.fit_settings().noise_level, 0.01);
        assert_eq!(s.lifted_settings().noise_fraction, 0.01);
        assert_eq!(s.lifted_settings(), LiftedSettings::default());
    }

    /// Each invalid value is refused with a message naming its field.
    #[test]
    fn validate_names_the_field_of_each_invalid_value() {
        type Breaker = fn(&mut DiagnoseSettings);
        let cases: &[(&str, Breaker)] = &[
            ("noise.level", |s| s.noise.level = 0.0),
            ("noise.level", |s| s.noise.level = f64::NAN),
            ("noise.floor_multiple", |s| s.noise.floor_multiple = -1.0),
            ("noise.stop_multiple", |s| s.noise.stop_multiple = 0.9),
            ("noise.relocate_factor", |s| s.noise.relocate_factor = 1.0),
            ("noise.bands", |s| s.noise.bands = 3),
            ("segments.seconds", |s| s.segments.seconds = 0.0),
            ("segments.fit_segments", |s| s.segments.fit_segments = 0),
            ("segments.quiet_window", |s| s.segments.quiet_window = 0),
            ("substeps.base", |s| s.substeps.base = 0),
            ("substeps.min", |s| s.substeps.min = 0),
            ("substeps.omega_h", |s| s.substeps.omega_h = 0.0),
            ("substeps.max", |s| s.substeps.max = 39),
            ("substeps.noise_reference", |s| {
                s.substeps.noise_reference = 0.0
            }),
            ("locate.ratio", |s| s.locate.ratio = 1.0),
            ("locate.noise_stop", |s| s.locate.noise_stop = 0.0),
            ("lifted.resolution", |s| s.lifted.resolution = 0),
            ("lifted.lambda", |s| s.lifted.lambda = 0.0),
            ("lifted.x0_std", |s| s.lifted.x0_std = (1.0, f64::INFINITY)),
            ("lifted.reweight_passes", |s| s.lifted.reweight_passes = 51),
            ("lifted.reweight_floor", |s| s.lifted.reweight_floor = 0.0),
            ("lifted.min_residual", |s| s.lifted.min_residual = 1.0),
            ("lifted.min_residual", |s| s.lifted.min_residual = f64::NAN),
            ("trace.min_gain", |s| s.trace.min_gain = 1.0),
            ("trace.friction_vreg", |s| s.trace.friction_vreg = 0.0),
            ("trace.gap_grid", |s| s.trace.gap_grid = 1),
            ("screen.min_improvement", |s| {
                s.screen.min_improvement = -0.1
            }),
            ("screen.companion_improvement", |s| {
                s.screen.companion_improvement = 1.0
            }),
            ("screen.companion_screen", |s| {
                s.screen.companion_screen = 1.5
            }),
            ("screen.far_from_noise", |s| s.screen.far_from_noise = 0.0),
            ("screen.companion_screen_far", |s| {
                s.screen.companion_screen_far = -1.0
            }),
            ("screen.dissipative_far", |s| s.screen.dissipative_far = 0.5),
            ("screen.gn_strides", |s| {
                s.screen.gn_strides = vec![f64::NAN]
            }),
            ("screen.alternative_change", |s| {
                s.screen.alternative_change = 0.0
            }),
            ("screen.alternative_floor", |s| {
                s.screen.alternative_floor = 0.0
            }),
            ("fit.max_iterations", |s| s.fit.max_iterations = 0),
            ("fit.x_tol", |s| s.fit.x_tol = 0.0),
            ("fit.f_tol", |s| s.fit.f_tol = -1.0),
            ("fit.lm_lambda", |s| s.fit.lm_lambda = 0.0),
            ("fit.race_iterations", |s| s.fit.race_iterations = 0),
            ("fit.polish_starts", |s| s.fit.polish_starts = 0),
            ("fit.noise_margin", |s| s.fit.noise_margin = 0.0),
            ("fit.cubic_brackets", |s| s.fit.cubic_brackets = vec![]),
            ("fit.contact_stiffnesses", |s| {
                s.fit.contact_stiffnesses = vec![10.0, 0.0]
            }),
            ("fit.gap_quantiles", |s| s.fit.gap_quantiles = vec![1.2]),
            ("fit.clearance_gap_quantiles", |s| {
                s.fit.clearance_gap_quantiles = vec![]
            }),
            ("fit.clearance_stiffnesses", |s| {
                s.fit.clearance_stiffnesses = vec![-1.0]
            }),
            ("fit.gap_upper", |s| s.fit.gap_upper = 0.9),
            ("fit.friction_upper", |s| s.fit.friction_upper = f64::NAN),
            ("fit.fitted_states_gain", |s| s.fit.fitted_states_gain = 0.5),
            ("fit.fitted_states_both", |s| s.fit.fitted_states_both = 9.0),
            ("starts.alternation_gain", |s| {
                s.starts.alternation_gain = 1.0
            }),
            ("starts.outlier", |s| s.starts.outlier = 1.0),
            ("starts.settled", |s| s.starts.settled = -0.5),
            ("starts.split_gain", |s| s.starts.split_gain = 0.0),
            ("starts.stall_steps", |s| s.starts.stall_steps = 0),
            ("starts.stall_gain", |s| s.starts.stall_gain = 2.0),
            ("starts.give_up", |s| s.starts.give_up = 0.5),
            ("starts.confirm_iterations", |s| {
                s.starts.confirm_iterations = 2
            }),
            ("fit.zero_starts.gap", |s| s.fit.zero_starts.gap = 0.0),
            ("fit.zero_starts.contact_stiffness", |s| {
                s.fit.zero_starts.contact_stiffness = -1.0
            }),
            ("fit.zero_starts.friction", |s| {
                s.fit.zero_starts.friction = 0.0
            }),
            ("fit.zero_starts.spring", |s| {
                s.fit.zero_starts.spring = f64::NAN
            }),
            ("horizon: lambda", |s| s.horizon.lambda = 0.0),
        ];
        for (field, brk) in cases {
            let mut s = DiagnoseSettings::default();
            brk(&mut s);
            let e = s.validate().expect_err(field).to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
    }

    /// Written as TOML and read back, non-default settings come back
    /// equal; a report.json's settings are read the same way; a partial
    /// file takes the defaults for the rest.
    #[test]
    fn settings_files_round_trip() {
        let mut s = DiagnoseSettings::default();
        s.noise.level = 0.02;
        s.segments.fit_segments = 7;
        s.states = StatesSource::Reconstructed;
        s.fit.gap_quantiles = vec![0.9, 0.95];
        s.fit.jacobian = JacobianMethod::CentralDifference;
        s.lifted.x0_std = (0.5, 3.0);
        let dir = tempfile::tempdir().unwrap();
        let toml_path = dir.path().join("s.toml");
        std::fs::write(&toml_path, s.to_toml_string().unwrap()).unwrap();
        assert_eq!(DiagnoseSettings::from_file(&toml_path).unwrap(), s);
        let report = serde_json::json!({ "verdict": "found", "settings": s });
        let json_path = dir.path().join("report.json");
        std::fs::write(&json_path, report.to_string()).unwrap();
        assert_eq!(DiagnoseSettings::from_file(&json_path).unwrap(), s);
        std::fs::write(&toml_path, "[screen]\nmax_effects = 1\n").unwrap();
        let partial = DiagnoseSettings::from_file(&toml_path).unwrap();
        let mut want = DiagnoseSettings::default();
        want.screen.max_effects = 1;
        assert_eq!(partial, want);
        std::fs::write(&toml_path, "[screen]\nmax_efects = 1\n").unwrap();
        let e = DiagnoseSettings::from_file(&toml_path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("max_efects") && e.contains("s.toml"), "{e}");
    }
}
