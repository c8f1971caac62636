//! The diagnosis of an imperfect declared model: calibrate its linear
//! part, diagnose with the calibrated model, then refine every parameter
//! (linear ones and the effects found) together by multiple shooting.
//!
//! 0. **Declared first**: the diagnosis with the declared linear part
//!    trusted ([`super::diagnose`]); with low-level records
//!    (`--linear-record`) the calibration (step 1) comes first, and when
//!    the declared linear part leaves more than the noise floor and twice
//!    the calibrated model's error on them it cannot win: not run, the
//!    calibrated diagnosis is the only one. Without a linear record, when it
//!    explains the record up to the noise floor and names no stiffness or
//!    damping change, it is the result and nothing is calibrated; otherwise
//!    it is the alternative the calibrated diagnosis must beat on the record (the lower multiple-shooting error
//!    is reported, report.json `calibration.choice` gives both).
//! 1. **Calibrate** ([`crate::calibrate`]): springs and damping (and masses
//!    on request) by the linear model's output error on segments with free
//!    start states, on the low-level records when given (`--linear-record`),
//!    else on the record diagnosed. On a record with a nonlinear effect this
//!    calibration is biased towards the effect's equivalent linearization
//!    (a bumper stiffens the spring beside it and adds damping), but it
//!    removes the spread-out residual that a wrong damping leaves, so the
//!    location search and the trace see the localized effect.
//! 2. **Diagnose** ([`super::diagnose`]) with the calibrated model.
//! 3. **Refine**: the linear parameters and the effects' parameters are
//!    fitted together with the segment start states ([`super::joint`]) —
//!    the final refinement by simulation error of PNLSS (Paduart et al.,
//!    Automatica 46, 2010) and of Floren, Noël & Swevers (2025). The bias of
//!    step 1 goes back into the effect. The segments start from the states
//!    refined for the model ([`super::starts`]; from the reconstruction a
//!    segment may start on the wrong side of an impact, a basin the joint
//!    fit does not leave), and the refinement continues on segments of
//!    [`CalibratedSettings::long_segments`] consecutive ones over the whole
//!    record, where the damping of the lowest modes shows. Each stage is
//!    kept when it lowers the record's multiple-shooting error. A model
//!    with laws against ground on a free-free structure is refined and
//!    scored, on the record and the validation record, from the linear
//!    part's reconstruction corrected for the rigid-body wander fitted with
//!    its laws ([`super::ground::corrected`]), as the diagnosis scores it;
//!    each refined model from its own. A refined model above the noise
//!    with two nonlinear effects or more is refined again without each
//!    in turn, and one explaining the record as well without it is
//!    dropped (`refit_without`: a companion named beside an effect on a
//!    linear part the calibration biased).
//! 4. **Damping alone**: without a linear record, when neither the declared
//!    nor the calibrated linear part names any effect and the record is
//!    left above the noise, steps 2 and 3 are run again from the declared
//!    springs with the damping alone calibrated on the record; the lower
//!    multiple-shooting error is kept (a calibration that moves the
//!    springs can take a dominant effect's linearization into them).
//!
//! Stages that cannot usefully win are not run: once a diagnosis explains
//! the record up to the noise (multiple-shooting error at most 1.5 × its
//! noise level), the declared linear part is not refined as an
//! alternative; with the linear part calibrated on low-level records (not
//! biased by the effects), a diagnosis at the noise is neither refined nor
//! diagnosed again (rounds).
//!
//! The report lists the linear corrections (declared → final, with
//! standard errors from the refinement, significance and identifiability)
//! apart from the effects.

use super::fit::spread;
use super::report::pct;
use super::{effects, joint, prepare_located, DiagnoseSettings, Diagnosis, ErrorSet};
use crate::calibrate::{self, params, Calibration, CalibrationSettings, LinearParam};
use crate::error::Result;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::record::Record;
use crate::trace::{Candidate, EffectKind, RankedEffect};
use crate::update::{Parameter, Target};
use rayon::prelude::*;
use serde::Serialize;
use std::borrow::Cow;

/// Settings of the calibrated diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct CalibratedSettings {
    /// The linear calibration.
    pub calibration: CalibrationSettings,
    /// Skip the calibration and the refinement (the declared model is
    /// trusted, as by [`super::diagnose`]).
    pub off: bool,
    /// Segments of the joint refinement, spread over the record (default
    /// 40; the damping of the lowest modes needs more record than an
    /// effect's fit).
    pub refine_segments: usize,
    /// Most accepted steps of the joint refinement (default 40).
    pub refine_iterations: usize,
    /// Most passes of the joint refinement on the diagnosis's segments
    /// (default 4; 1: one): each pass after the first starts from the
    /// start states refined for the model the pass before reached, and
    /// runs while the pass before lowered the record's multiple-shooting
    /// error by more than the starts' `alternation_gain`.
    pub refine_passes: usize,
    /// After the joint refinement on the diagnosis's segments, refine
    /// again on segments of this many consecutive ones over the whole
    /// record (default 5: 0.5 s; 0 or 1: off), where the damping of the
    /// lowest modes shows; kept when it lowers the record's error.
    pub long_segments: usize,
    /// After the joint refinement, refine every parameter again by the
    /// open-loop simulation error over the whole record
    /// ([`super::open_loop`]; default false).
    pub open_loop: bool,
    /// Most accepted steps of the open-loop refinement (default 40).
    pub open_loop_iterations: usize,
    /// Rounds of diagnosis and refinement from the calibrated linear part
    /// (default 2): each round after the first, when the refinement before
    /// was kept, diagnoses again with the linear part that refinement gave
    /// (its location and trace no longer see the calibration's bias) and is
    /// kept when it lowers the record's error; with low-level records, not
    /// after a round at the noise (1.5 × its noise level).
    pub rounds: usize,
    /// Most rounds in all (default 4): a round after the `rounds`th is
    /// run while the round before at least halved the record's error and
    /// left it above the noise (a refinement started far from the record
    /// ends in a linear part still far from it, from which the next
    /// round's diagnosis fits the effects better).
    pub max_rounds: usize,
    /// After the joint refinement, when the linear part was calibrated on
    /// low-level records, the record measures fewer DOFs than the model
    /// has and the refined model with a contact or clearance is left
    /// above the noise (1.5 × its noise level), search each element's gap
    /// and stiffness on grids, every trial scored on start states refined
    /// for it ([`super::gap_search`]), and refine jointly again from the
    /// best (default true). Reason: on the row "clearance 2–3, modal
    /// 2.5 %, sensors 2, 3, 7" of `examples/imperfect_matrix.rs` (seed
    /// 15833) it took the record's error from 30.17 % to 5.62 % with a
    /// linear record; without one, on a linear part the record alone left
    /// wrong (k2 +58 %), from 47.30 % to 47.02 % at more than twice the
    /// row's time.
    pub gap_search: bool,
}

impl Default for CalibratedSettings {
    fn default() -> Self {
        CalibratedSettings {
            calibration: CalibrationSettings::default(),
            off: false,
            refine_segments: 40,
            refine_iterations: 40,
            refine_passes: 4,
            long_segments: 5,
            open_loop: false,
            open_loop_iterations: 40,
            rounds: 2,
            max_rounds: 4,
            gap_search: true,
        }
    }
}

/// One linear correction in the final model.
#[derive(Debug, Clone, Serialize)]
pub struct LinearCorrection {
    /// Name (`k5`, `zeta2`, `alpha`, ...).
    pub name: String,
    /// Unit ("" for a ratio).
    pub unit: String,
    /// Declared value.
    pub declared: f64,
    /// Value after the calibration alone.
    pub calibrated: f64,
    /// Value in the final model (after the joint refinement).
    pub value: f64,
    /// Relative change of the final value, value / declared − 1.
    pub change: f64,
    /// Standard error of the final value (measurement noise only), same
    /// unit; None when the refinement could not give one.
    pub std_error: Option<f64>,
    /// The change exceeds the significance rule (standard errors and
    /// minimum change of the calibration settings).
    pub significant: bool,
    /// The sensors used determine it (relative standard error below the
    /// settings' limit).
    pub identifiable: bool,
}

/// What the calibration and the refinement did.
#[derive(Debug, Clone, Serialize)]
pub struct CalibrationReport {
    /// The linear calibration.
    pub calibration: Calibration,
    /// The linear corrections of the final model.
    pub corrections: Vec<LinearCorrection>,
    /// The calibrated linear model's errors on the record.
    pub calibrated_errors: ErrorSet,
    /// Its errors on the validation record (None without one).
    pub calibrated_validation_errors: Option<ErrorSet>,
    /// Why the refinement was kept or not.
    pub refinement: String,
    /// Whether the diagnosis reported is the calibrated one (else the
    /// declared linear part explained the record better and is kept).
    pub used: bool,
    /// The two diagnoses' errors and the choice, in words.
    pub choice: String,
}

/// Diagnose `rec` against `declared`, its linear part calibrated first (on
/// `linear_records` when given) and refined with the effects found. A
/// model whose linear parameters are marked free (`[free]`,
/// [`Model::free`]) is calibrated with that freedom and without the
/// trusted alternative: its values are starting values only.
#[allow(clippy::too_many_arguments)]
pub fn diagnose_calibrated(
    declared: &Model,
    rec: &Record,
    validation: Option<&Record>,
    linear_records: &[Record],
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
    cal: &CalibratedSettings,
    progress: &dyn Fn(&str),
) -> Result<Diagnosis> {
    if cal.off {
        return super::diagnose(declared, rec, validation, sensors, settings, progress);
    }
    // a model whose linear values are marked free gives starting values
    // only: no plausible range around them
    let (spring_factor, damping_factor) = match declared.free {
        Some(_) => (f64::INFINITY, f64::INFINITY),
        None => (
            cal.calibration.spring_factor,
            cal.calibration.damping_factor,
        ),
    };
    let cal = &CalibratedSettings {
        calibration: CalibrationSettings {
            freedom: declared.free.unwrap_or(cal.calibration.freedom),
            spring_factor,
            damping_factor,
            ..cal.calibration.clone()
        },
        // the gap search only on a linear part calibrated on low-level
        // records ([`CalibratedSettings::gap_search`])
        gap_search: cal.gap_search && !linear_records.is_empty(),
        ..cal.clone()
    };
    // what the linear part is calibrated on: the low-level records, or
    // the record itself
    let on: Vec<&Record> = match linear_records.is_empty() {
        true => vec![rec],
        false => linear_records.iter().collect(),
    };
    let data = on
        .iter()
        .map(|r| calibrate::data_of(r, declared.ndof(), sensors, 0))
        .collect::<Result<Vec<_>>>()?;
    let calibrate_on = || -> Result<Calibration> {
        progress("calibrate the linear part");
        calibrate::calibrate(declared, &data, &cal.calibration)
    };
    // with low-level records the calibration comes first: when the
    // declared linear part does not explain them (declared_off), the
    // diagnosis that trusts it cannot win and is not run
    let early = match linear_records.is_empty() {
        true => None,
        false => Some(calibrate_on()?),
    };
    let off = early.as_ref().and_then(|c| declared_off(c, settings));
    // the declared model trusted, as the alternative the calibrated
    // diagnosis must beat on the record (none when its linear values are
    // only starting values, or off on the low-level records)
    let trusted = match (declared.free, &off) {
        (None, None) => Some(super::diagnose(
            declared, rec, validation, sensors, settings, progress,
        )?),
        _ => None,
    };
    // without a linear record, a declared model that explains the record
    // up to the noise floor with localized effects is not recalibrated on
    // it
    if let Some(t) = trusted.as_ref() {
        let explained = t
            .after
            .relative_error
            .is_some_and(|e| e <= t.noise_floor(settings));
        // a stiffness or damping change among its effects says the
        // declared linear part is wrong: calibrated all the same
        let linear_named = t
            .added
            .iter()
            .any(|e| e.candidate.kind.changes_linear_part());
        if linear_records.is_empty() && explained && !linear_named {
            return Ok(trusted.expect("checked above"));
        }
    }
    let calibration = match early {
        Some(c) => c,
        None => calibrate_on()?,
    };
    // a calibration that absorbs a localized effect keeps the declared
    // values: the diagnosis on them is the trusted one
    let d = match (&calibration.status, trusted.as_ref()) {
        (calibrate::CalibrationStatus::Absorbs { .. }, Some(t)) => t.clone(),
        _ => super::diagnose(
            &calibration.model,
            rec,
            validation,
            sensors,
            settings,
            progress,
        )?,
    };
    let (low_level, low_level_note) = match linear_records.is_empty() {
        true => (false, None),
        false => held(&calibration, &d, settings),
    };
    let ctx = Context {
        declared,
        low_level,
        low_level_note,
        data: &data,
        rec,
        validation,
        sensors,
        settings,
        cal,
        progress,
    };
    progress("refine the linear part with the effects");
    let first = ctx.refined(d, &calibration.model)?;
    let mut from_calibrated = ctx.more_rounds(first)?;
    if let Some(unheld) = calibration.unheld.as_ref() {
        if !ctx.at_noise(&from_calibrated.d) {
            from_calibrated = ctx.unheld_alternative(from_calibrated, unheld)?;
        }
    }
    // nothing named anywhere, far from the noise: the springs the
    // calibration moved may have absorbed the effect; the damping alone
    // calibrated is the other start
    let named = |d: &Diagnosis| !d.effects.is_empty();
    if linear_records.is_empty()
        && declared.free.is_none()
        && !ctx.at_noise(&from_calibrated.d)
        && !named(&from_calibrated.d)
        && !trusted.as_ref().is_some_and(named)
    {
        from_calibrated = ctx.damping_alternative(from_calibrated)?;
    }
    // a damper law chosen while the linear part was still off: the other
    // law tried on the refined linear part
    from_calibrated = ctx.damper_law_alternative(from_calibrated)?;
    // a free-free declared model left above the noise: a spring to ground
    // it lacks gives the rigid-body mode a frequency that the calibration
    // of springs and damping cannot
    from_calibrated = ctx.ground_spring_alternative(from_calibrated)?;
    // still above the noise without friction: the damping may have taken
    // the friction's share
    from_calibrated = ctx.friction_alternative(from_calibrated)?;
    let Some(trusted) = trusted else {
        // linear values marked free, or the declared ones off on the
        // low-level records: the calibrated diagnosis is the only one
        let why = off.unwrap_or_else(|| {
            "the model marks its linear parameters free: calibrated only".into()
        });
        let choice = format!(
            "{why} ({} on the record)",
            pct(from_calibrated.d.after.relative_error)
        );
        let report = ctx.report(&from_calibrated, calibration, (&choice, true));
        return ctx.finish(from_calibrated.d, report);
    };
    // the declared linear part refined with the effects it found: the
    // calibration on a record with an effect is biased by it, and a start
    // from the declared values may land nearer; not run when the
    // calibrated diagnosis already explains the record up to the noise
    let from_declared = if ctx.at_noise(&from_calibrated.d) {
        None
    } else {
        progress("refine the declared linear part with its effects");
        Some(ctx.refined(trusted.clone(), declared)?)
    };
    ctx.choose(trusted, from_calibrated, from_declared, calibration)
}

/// A diagnosis whose multiple-shooting error on the record is at most this
/// many times its noise level explains the record up to the noise: no
/// further round or alternative start is run (the acceptance of a
/// diagnosis at the noise is 1.5 × the measured level).
const AT_NOISE: f64 = 1.5;

/// At most this many springs to ground, in the order of
/// [`Context::ranked_ground_springs`], are refined fully with the effects
/// ([`Context::ground_spring_alternative`]): a full refinement costs
/// about as much as the diagnosis's rounds.
const GROUND_SPRING_TRIES: usize = 3;

/// The share of the refined damping's dissipation the friction on every
/// mass of [`Context::friction_alternative`] starts with (the damping
/// keeps the rest).
const FRICTION_SHARE: f64 = 0.5;

/// Whether the linear part calibrated on low-level records is trusted
/// as one not biased by the effects: when the calibration explains them
/// up to the noise (its output error at most [`AT_NOISE`] times the noise
/// level measured on the record diagnosed, `d`'s). Low-level records
/// with an effect of their own (friction everywhere: a stick–slip no
/// linear model reproduces) bias it as the record itself would; it is
/// then refined with the effects like a calibration on the record (the
/// note says so). When the low-level records are relatively noisier than
/// the record (absolute noise at a lower level), the rule errs towards
/// refining.
fn held(c: &Calibration, d: &Diagnosis, settings: &DiagnoseSettings) -> (bool, Option<String>) {
    let level = d.noise_level(settings);
    if c.error_after <= AT_NOISE * level {
        return (true, None);
    }
    let note = format!(
        "the linear part calibrated on the low-level records leaves {} on them (> {AT_NOISE} × the record's measured noise {}): not held, refined with the effects",
        pct(Some(c.error_after)),
        pct(Some(level))
    );
    (false, Some(note))
}

/// Why the declared linear part cannot win, when the calibration on the
/// low-level records says so: its output error there exceeds the noise
/// floor ([`DiagnoseSettings::noise_floor`]) and twice the calibrated
/// model's. None when it may.
fn declared_off(c: &Calibration, settings: &DiagnoseSettings) -> Option<String> {
    let floor = settings.noise_floor().max(2.0 * c.error_after);
    (c.error_before > floor).then(|| {
        format!(
            "the declared linear part leaves {} on the low-level records against {} calibrated: not diagnosed with it, calibrated only",
            pct(Some(c.error_before)),
            pct(Some(c.error_after))
        )
    })
}

/// What a diagnosis refined with its linear part gives.
struct RefinedPath {
    /// The diagnosis after the refinement, errors `before` of the declared
    /// model.
    d: Diagnosis,
    /// Errors of the linear model the diagnosis ran on.
    start_errors: ErrorSet,
    /// Its errors on the validation record (None without one).
    start_validation_errors: Option<ErrorSet>,
    /// The refinement's note.
    note: String,
    /// The refined parameters and their standard errors (empty when not
    /// kept).
    std: Vec<Estimated>,
    /// The refinement lowered the error and was kept.
    kept: bool,
}

/// The inputs of the calibrated diagnosis its steps share.
struct Context<'a> {
    declared: &'a Model,
    /// The linear part was calibrated on low-level records that it
    /// explains up to the noise ([`held`]: not biased by the effects on
    /// the record diagnosed).
    low_level: bool,
    /// Why a calibration on low-level records is not held ([`held`]).
    low_level_note: Option<String>,
    /// The calibration data of the records the linear part is calibrated
    /// on (the low-level records, or the record itself).
    data: &'a [calibrate::Data],
    rec: &'a Record,
    validation: Option<&'a Record>,
    sensors: Option<&'a [usize]>,
    settings: &'a DiagnoseSettings,
    cal: &'a CalibratedSettings,
    progress: &'a dyn Fn(&str),
}

impl Context<'_> {
    /// The rounds after the first ([`CalibratedSettings::rounds`]): each,
    /// while the refinement before was kept, diagnoses with the linear part
    /// it gave and refines; kept when it lowers the record's error.
    fn more_rounds(&self, mut best: RefinedPath) -> Result<RefinedPath> {
        // the error before the last round kept (None: the first)
        let mut previous: Option<f64> = None;
        for round in 1..self.cal.rounds.max(self.cal.max_rounds) {
            // beyond `rounds`, only while the round before halved the error
            let halved = match (best.d.after.relative_error, previous) {
                (Some(e), Some(p)) => e <= 0.5 * p,
                _ => false,
            };
            if round >= self.cal.rounds && (!halved || self.at_noise(&best.d)) {
                break;
            }
            // on a linear part calibrated on low-level records, another
            // diagnosis cannot usefully beat one at the noise (calibrated on
            // the record itself, the first round's noise and error still
            // carry the calibration's bias: bumper 5→6 of imperfect_matrix,
            // seed 4242, validation 1.34 % after one round, 0.99 % after two)
            if !best.kept || (self.low_level && self.at_noise(&best.d)) {
                break;
            }
            (self.progress)(&format!(
                "round {}: diagnose with the refined linear part",
                round + 1
            ));
            let linear = without_null_springs(best.d.model.linear_part());
            let d = super::diagnose(
                &linear,
                self.rec,
                self.validation,
                self.sensors,
                self.settings,
                self.progress,
            )?;
            let mut next = self.refined(d, &linear)?;
            next.note = format!("round {}: {}", round + 1, next.note);
            if !lower(next.d.after.relative_error, best.d.after.relative_error) {
                break;
            }
            previous = best.d.after.relative_error;
            best = next;
        }
        Ok(best)
    }

    /// The calibration held parameters out of their plausible range
    /// ([`calibrate::Held`]): the diagnosis from the calibration with every
    /// parameter free (`unheld`), refined and in rounds, is the
    /// alternative; the lower multiple-shooting error on the record is
    /// kept (the held start can leave a one-sided contact a spurious
    /// companion that the biased spring did not). Not run when the held
    /// path explains the record up to the noise.
    fn unheld_alternative(&self, held: RefinedPath, unheld: &Model) -> Result<RefinedPath> {
        (self.progress)("diagnose from the calibration without held parameters");
        self.better_of(
            held,
            unheld,
            [
                "with parameters held",
                "with none held",
                "held kept",
                "none held kept",
            ],
        )
    }

    /// The diagnosis from `start`, refined and in rounds, against
    /// `current`: the lower multiple-shooting error on the record is kept,
    /// the note gives both. `names`: how the note calls the calibration
    /// `current` came from and `start`, then each of them kept.
    fn better_of(
        &self,
        current: RefinedPath,
        start: &Model,
        [current_name, start_name, current_kept, start_kept]: [&str; 4],
    ) -> Result<RefinedPath> {
        let d = super::diagnose(
            start,
            self.rec,
            self.validation,
            self.sensors,
            self.settings,
            self.progress,
        )?;
        let first = self.refined(d, start)?;
        let mut other = self.more_rounds(first)?;
        let (e_current, e_other) = (current.d.after.relative_error, other.d.after.relative_error);
        let compared = format!(
            "multiple-shooting error on the record from the calibration {current_name} {}, {start_name} {}",
            pct(e_current),
            pct(e_other)
        );
        Ok(if lower(e_other, e_current) {
            other.note = format!("{}; {compared}: {start_kept}", other.note);
            other
        } else {
            RefinedPath {
                note: format!("{}; {compared}: {current_kept}", current.note),
                ..current
            }
        })
    }

    /// The diagnosis from the declared springs with the damping alone
    /// calibrated on the record, refined and in rounds, against `current`
    /// (the calibrated path); the lower multiple-shooting error on the
    /// record is kept. On a record an effect dominates, the calibration of
    /// every spring and the damping takes the effect's linearization into
    /// the springs beside it (the bumper 5→6 seen from sensors 1, 5, 6
    /// with twice the declared damping: k5 +41 %) and the diagnosis on it,
    /// like the one on the declared damping, names nothing; with the springs
    /// held the damping's correction unmasks the effect for the trace.
    fn damping_alternative(&self, current: RefinedPath) -> Result<RefinedPath> {
        (self.progress)("calibrate the damping alone");
        let cs = CalibrationSettings {
            freedom: calibrate::Freedom {
                springs: false,
                damping: true,
                masses: false,
            },
            ..self.cal.calibration.clone()
        };
        // (run without low-level records: `data` is the record's)
        let c = calibrate::calibrate(self.declared, self.data, &cs)?;
        if !c.status.usable() {
            return Ok(current);
        }
        self.better_of(
            current,
            &c.model,
            [
                "of springs and damping",
                "of the damping alone",
                "springs and damping kept",
                "the damping alone kept",
            ],
        )
    }

    /// A spring to ground added to `current`'s model when the declared
    /// model is free-free (no spring to ground, springs of a lumped model,
    /// not marked free) and `current` is left above the noise with no
    /// spring or law against ground: the linear part `current` reached is
    /// calibrated on the linear part's data (`data`) with a spring to
    /// ground at each DOF ([`calibrate::grounding::ground_springs`]); each,
    /// with the damping calibrated beside it, is added as an effect,
    /// ranked by a quick refinement ([`Self::ranked_ground_springs`]), and
    /// up to [`GROUND_SPRING_TRIES`] of them in that order have every
    /// parameter refined with the effects found ([`Self::refined`]) until
    /// one leaves the record at the noise; the lowest refined error is
    /// kept when it removes more than the screen's `companion_improvement`
    /// of the squared error above the squared noise level, as an effect
    /// fitted below the screen is ([`super::decide`]). The calibration of
    /// springs and damping cannot give the rigid-body mode the frequency
    /// the spring gives it, and the location along the linear part it
    /// leaves can miss the spring's DOF (a contact 2→3 with a spring of
    /// 1500 N/m at 8: the force located at pair 2–3 only, the springs
    /// beside 5–6 taking part of it in the refinement).
    fn ground_spring_alternative(&self, current: RefinedPath) -> Result<RefinedPath> {
        let d0 = &current.d;
        let applies = !self.declared.has_ground_spring()
            && self.declared.free.is_none()
            && !self.declared.calibrated_by_scales()
            && !d0.model.has_ground_spring()
            && super::ground::ground_laws(&d0.model).is_empty()
            && !self.at_noise(d0);
        if !applies {
            return Ok(current);
        }
        (self.progress)("calibrate a spring to ground at each DOF");
        let linear = d0.model.linear_part();
        let cs = &self.cal.calibration;
        let found = calibrate::grounding::ground_springs(&linear, self.data, cs)?;
        let mut best: Option<RefinedPath> = None;
        let mut tried = vec![];
        for (g, t) in self
            .ranked_ground_springs(d0, found)
            .into_iter()
            .take(GROUND_SPRING_TRIES)
        {
            let what = format!(
                "a spring to ground at {} calibrated ({:.4e} N/m; output error {} against {} without it)",
                g.dof,
                g.stiffness,
                pct(Some(g.error)),
                pct(Some(g.without)),
            );
            let (next, compared) = self.try_added(&current, t, &linear, &what)?;
            tried.push(compared);
            let done = next.as_ref().is_some_and(|n| self.at_noise(&n.d));
            if next.as_ref().is_some_and(|n| {
                best.as_ref()
                    .is_none_or(|b| lower(n.d.after.relative_error, b.d.after.relative_error))
            }) {
                best = next;
            }
            if done {
                break;
            }
        }
        let tried = tried.join("; ");
        Ok(match best {
            Some(mut next) => {
                next.note = format!("{}; {}; {tried}; the lowest kept", current.note, next.note);
                next
            }
            None if tried.is_empty() => current,
            None => RefinedPath {
                note: format!("{}; {tried}: none kept", current.note),
                ..current
            },
        })
    }

    /// The springs to ground calibrated on the linear part (`found`), each
    /// added to `d` ([`with_ground_spring`], that diagnosis scored), in
    /// the order of their multiple-shooting error on the record after one
    /// joint refinement of every parameter on the diagnosis's segments
    /// ([`quick_refined_error`]; one whose fit fails last). The linear
    /// part's output error puts the DOFs nearly level (the rigid-body mode
    /// on a soft spring has almost the same frequency wherever it is), and
    /// neither the diagnosed model's error with the spring added, its
    /// linear part refined without it, nor the quick refinement puts the
    /// right one first (seed 7543's contact 2→3 with 1500 N/m at 8: the
    /// output error ranks DOF 8 third of six, the diagnosed model's error
    /// and the quick refinement second, after DOF 6; refined fully, 8
    /// reaches the noise and 6 stops at 7.6 %).
    fn ranked_ground_springs(
        &self,
        d: &Diagnosis,
        found: Vec<calibrate::grounding::GroundSpring>,
    ) -> Vec<(calibrate::grounding::GroundSpring, Diagnosis)> {
        let mut scored: Vec<_> = found
            .into_par_iter()
            .map(|g| {
                let t = scored_as_is(with_ground_spring(d, &g));
                let quick = quick_refined_error(&t, self.cal, self.settings);
                (g, t, quick)
            })
            .collect();
        for (g, t, quick) in &scored {
            (self.progress)(&format!(
                "spring to ground at {}: {:.4e} N/m, output error {}, with the effects {}, after one joint refinement {}",
                g.dof,
                g.stiffness,
                pct(Some(g.error)),
                pct(t.after.relative_error),
                pct(*quick)
            ));
        }
        scored.sort_by(|a, b| {
            let e = |q: Option<f64>| q.unwrap_or(f64::INFINITY);
            e(a.2).total_cmp(&e(b.2))
        });
        scored.into_iter().map(|(g, t, _)| (g, t)).collect()
    }

    /// Friction on every mass added to `current`'s model when `current` is
    /// left above the noise without friction, in a lumped model of several
    /// DOFs (not from matrices, whose DOFs need not be masses' translations)
    /// that declares none: a damping refined on a record with
    /// friction takes the friction's dissipation (velocity-proportional for
    /// amplitude-independent: the validation record at another amplitude
    /// misses it), and beside the linear part's error the trace need not
    /// rank the friction (cubic 1–2 with 0.1 N of friction on every mass,
    /// imperfect matrix seed 49529: found the cubic only, 2.08 % on the
    /// record, 8.17 % on validation, the refined ratios +31 to +78 %).
    /// Started at [`FRICTION_SHARE`] of the level that dissipates, along
    /// the reconstructed states, what the refined damping does, with the
    /// damping scaled by the rest, every parameter refined with the effects
    /// ([`Self::refined`]); kept as the spring to ground is.
    fn friction_alternative(&self, current: RefinedPath) -> Result<RefinedPath> {
        let d0 = &current.d;
        let n = d0.model.physical_ndof();
        let applies = n > 1
            && self.declared.frictions.is_empty()
            && self.declared.relative_frictions.is_empty()
            && self.declared.free.is_none()
            && self.declared.matrices.is_none()
            && d0.model.frictions.is_empty()
            && d0.model.relative_frictions.is_empty()
            && !self.at_noise(d0);
        if !applies {
            return Ok(current);
        }
        let candidate = Candidate {
            vreg: self.settings.trace.friction_vreg,
            ..Candidate::new(EffectKind::Friction, (0..n).collect())
        };
        let states = &d0.prepared.recon.states;
        let Some((dissipated, total)) = super::fit::dissipation(&d0.model, &candidate, states)
        else {
            return Ok(current);
        };
        let level = FRICTION_SHARE * dissipated / total;
        let mut t = d0.clone();
        t.model.damping = t.model.damping.scaled(1.0 - FRICTION_SHARE);
        let t = scored_as_is(with_effect(t, candidate, vec![("level".into(), level)]));
        let what = format!(
            "friction on every mass from {level:.4e} N ({FRICTION_SHARE} of the level dissipating what the damping does), the damping scaled by {}",
            1.0 - FRICTION_SHARE
        );
        let linear = d0.model.linear_part();
        self.refined_with_added(current, t, &linear, &what)
    }

    /// The one damper the rounds named (quadratic or cubic in the relative
    /// velocity) replaced by the other law, from the coefficient that
    /// dissipates as much along the reconstructed states
    /// ([`super::laws::swap_at`]), every parameter refined
    /// with the effects; kept as the spring to ground is, when `current`
    /// is left above the noise. The rounds compare the two laws while the
    /// linear part is still off, and a viscous damping the declared model
    /// underestimates favours `ν|ν|`, the law nearer to linear: on a
    /// record of a cubic damper 6–7 beside a contact 3→2 with 4 % modal
    /// damping declared at 1 % (outside-the-matrix record p11 of
    /// docs/diagnose.md), the quadratic scored 18.10 % against the
    /// cubic's 18.29 % in the round and was kept, leaving 2.94 % at 0.3 %
    /// noise once the damping was refined. Not with the open-loop
    /// refinement, which tries both laws of every damper itself.
    fn damper_law_alternative(&self, current: RefinedPath) -> Result<RefinedPath> {
        let d0 = &current.d;
        let is_damper =
            |k: EffectKind| matches!(k, EffectKind::QuadraticDamping | EffectKind::CubicDamping);
        let dampers: Vec<usize> = (0..d0.added.len())
            .filter(|&i| is_damper(d0.added[i].candidate.kind))
            .collect();
        // (the open-loop refinement tries both laws itself, [`super::laws`])
        let skip = self.at_noise(d0) || self.cal.open_loop;
        let (&[i], false) = (dampers.as_slice(), skip) else {
            return Ok(current);
        };
        let Some(alt) = super::laws::swap_at(d0, i) else {
            return Ok(current);
        };
        let mut t = d0.clone();
        (t.model, t.added, t.effects) = (alt.model, alt.added, alt.effects);
        // the law tried last, as an effect just added is
        let a = t.added.remove(i);
        t.added.push(a);
        if i < t.effects.len() {
            let e = t.effects.remove(i);
            t.effects.push(e);
        }
        let linear = d0.model.linear_part();
        self.refined_with_added(current, scored_as_is(t), &linear, &alt.what)
    }

    /// `t`, `current`'s diagnosis with one effect added (`what`) and
    /// scored ([`scored_as_is`]), refined ([`Self::try_added`]); the refined path when it pays, else
    /// `current`; the note says which.
    fn refined_with_added(
        &self,
        current: RefinedPath,
        t: Diagnosis,
        linear: &Model,
        what: &str,
    ) -> Result<RefinedPath> {
        let (next, compared) = self.try_added(&current, t, linear, what)?;
        Ok(match next {
            Some(mut next) => {
                next.note = format!("{}; {}; {compared}: kept", current.note, next.note);
                next
            }
            None => RefinedPath {
                note: format!("{}; {compared}: not kept", current.note),
                ..current
            },
        })
    }

    /// `t`, `current`'s diagnosis with one effect added (`what`) and
    /// scored ([`scored_as_is`]), refined with every parameter
    /// ([`Self::refined`]): the refined
    /// path (its own note) when the effect is still named and removes more
    /// than the screen's `companion_improvement` of the squared error
    /// above the squared noise level (as an effect fitted below the screen
    /// must, [`super::decide`]), else None; with the errors compared.
    fn try_added(
        &self,
        current: &RefinedPath,
        t: Diagnosis,
        linear: &Model,
        what: &str,
    ) -> Result<(Option<RefinedPath>, String)> {
        let Some(kind) = t.added.last().map(|a| a.candidate.kind) else {
            return Ok((None, String::new()));
        };
        (self.progress)(&format!(
            "refine with {}",
            t.added.last().map_or("", |a| &a.label)
        ));
        let mut next = self.refined(t, linear)?;
        let d0 = &current.d;
        let (a, b) = (d0.after.relative_error, next.d.after.relative_error);
        let noise = d0.noise_level(self.settings);
        let need = self.settings.screen.companion_improvement;
        let named = next.d.added.iter().any(|e| e.candidate.kind == kind);
        let pays = named
            && matches!((a, b), (Some(a), Some(b)) if super::decide::removes(a, b, need, noise * noise));
        let compared = format!(
            "{what}, refined with the effects: multiple-shooting error on the record {} against {}",
            pct(b),
            pct(a)
        );
        if !pays {
            return Ok((None, compared));
        }
        next.start_errors = current.start_errors.clone();
        next.start_validation_errors = current.start_validation_errors.clone();
        Ok((Some(next), compared))
    }

    /// Whether `d` explains the record up to the noise: its
    /// multiple-shooting error at most [`AT_NOISE`] times the noise level it
    /// ran at ([`Diagnosis::noise_level`]).
    fn at_noise(&self, d: &Diagnosis) -> bool {
        let level = d.noise_level(self.settings);
        d.after
            .relative_error
            .is_some_and(|e| e <= AT_NOISE * level)
    }

    /// The diagnosis with the lowest multiple-shooting error on the record:
    /// the declared one as diagnosed, the calibrated one refined, or the
    /// declared one refined; with the calibration report.
    fn choose(
        &self,
        trusted: Diagnosis,
        from_calibrated: RefinedPath,
        from_declared: Option<RefinedPath>,
        calibration: Calibration,
    ) -> Result<Diagnosis> {
        let errs = [
            trusted.after.relative_error,
            from_calibrated.d.after.relative_error,
            from_declared
                .as_ref()
                .and_then(|p| p.d.after.relative_error),
        ];
        let (best, declared_used) = match from_declared {
            _ if lower(errs[1], errs[0]) && !lower(errs[2], errs[1]) => (from_calibrated, false),
            Some(p) if p.kept && lower(errs[2], errs[0]) => (p, true),
            _ => {
                let chosen = choice(&errs, "the declared model as diagnosed");
                let report = self.report(&from_calibrated, calibration, (&chosen, false));
                return self.finish(trusted, report);
            }
        };
        let chosen = choice(
            &errs,
            if declared_used {
                "the declared linear part refined with its effects"
            } else {
                "the calibrated linear part refined with its effects"
            },
        );
        let mut report = self.report(&best, calibration, (&chosen, true));
        if declared_used {
            report
                .corrections
                .iter_mut()
                .for_each(|c| c.calibrated = c.declared);
        }
        self.finish(best.d, report)
    }

    /// `d` reported with the calibration's `report`, its errors checked
    /// finite.
    fn finish(&self, mut d: Diagnosis, report: CalibrationReport) -> Result<Diagnosis> {
        super::finite_result(&d.model, &d.after, d.validation.as_ref())?;
        d.timings
            .insert("calibrate".into(), report.calibration.seconds);
        d.calibration = Some(report);
        Ok(d)
    }

    /// Refine `d` (diagnosed on the linear model `linear`): every linear
    /// parameter and the effects' together; `before` holds the declared
    /// model's errors.
    fn refined(&self, mut d: Diagnosis, linear: &Model) -> Result<RefinedPath> {
        (self.progress)("identify the validation record on the linear part");
        // the diagnosis's own when it ran on `linear` at these settings
        let done = d.validation_prepared.take();
        let vprep = match done.and_then(|v| v.take_for(linear, self.settings)) {
            Some(p) => Some(p),
            None => self
                .validation
                .map(|v| {
                    prepare_located(
                        linear,
                        v,
                        self.sensors,
                        self.settings,
                        d.prepared.located.as_ref(),
                    )
                })
                .transpose()?,
        };
        let sim0 = SimSettings {
            substeps: d.substeps.0,
            ..Default::default()
        };
        (self.progress)("the declared model's errors");
        let declared_errors = d.prepared.comparison.errors(self.declared, sim0).0;
        let declared_validation = vprep
            .as_ref()
            .map(|p| p.comparison.errors(self.declared, sim0).0);
        // a model with laws against ground is refined and scored from the
        // reconstruction corrected for the rigid-body wander
        // ([`super::ground`]), as the diagnosis scored it
        let bases = Bases {
            record: d.prepared.clone(),
            validation: vprep,
        };
        if let Cow::Owned(p) = own(&d.model, &bases.record) {
            d.prepared = p;
        }
        // on a linear part calibrated on low-level records, a diagnosis at
        // the noise leaves the refinement nothing to win
        let (mut note, mut std) = if self.low_level && self.at_noise(&d) {
            (
                format!(
                    "not refined: the diagnosis on the linear part calibrated on the low-level records explains the record up to the noise ({} ≤ {AT_NOISE} × {})",
                    pct(d.after.relative_error),
                    pct(Some(d.noise_level(self.settings)))
                ),
                vec![],
            )
        } else {
            let (n, std) = refine_once(&mut d, self.cal, self.settings, &bases, self.progress)?;
            match &self.low_level_note {
                Some(why) => (format!("{why}; {n}"), std),
                None => (n, std),
            }
        };
        if self.cal.open_loop {
            let vprep = bases.validation.as_ref().map(|v| own(&d.model, v));
            let (n, est) = self.open_loop(&mut d, vprep.as_ref().map(|p| &p.comparison))?;
            note = format!("{note}; {n}");
            std = est.unwrap_or(std);
        }
        if !self.at_noise(&d) {
            if let Some((n, est)) =
                refit_without(&mut d, self.cal, self.settings, &bases, self.progress)?
            {
                note = format!("{note}; {n}");
                std = est;
            }
        }
        update_effects(&mut d, &std, &self.cal.calibration);
        if let Some(n) = drop_negligible(&mut d, &bases, self.settings, self.progress) {
            note = format!("{note}; {n}");
        }
        let start_errors = std::mem::replace(&mut d.before, declared_errors);
        let mut start_validation_errors = None;
        if let (Some(v), Some(b)) = (d.validation.as_mut(), declared_validation) {
            start_validation_errors = Some(std::mem::replace(&mut v.before, b));
        }
        d.verdict = super::verdict(&d.effects);
        Ok(RefinedPath {
            d,
            start_errors,
            start_validation_errors,
            note,
            kept: !std.is_empty(),
            std,
        })
    }

    /// The open-loop refinement of `d` ([`super::open_loop`]), then each
    /// nonlinear damper in the other law ([`super::laws`]), the lower
    /// record error kept; the notes and, when one was kept, the
    /// parameters with their standard errors.
    fn open_loop(
        &self,
        d: &mut Diagnosis,
        vcmp: Option<&super::Comparison>,
    ) -> Result<(String, Option<Vec<Estimated>>)> {
        (self.progress)("refine every parameter by the open-loop error");
        let it = self.cal.open_loop_iterations;
        let cal = &self.cal.calibration;
        let t = std::time::Instant::now();
        let (mut note, mut std) = super::open_loop::refine(d, cal, self.settings, it, vcmp)?;
        super::state::add_time(&mut d.timings, "open_loop_refinement", t);
        let t = std::time::Instant::now();
        let refine = |t: &mut Diagnosis| super::open_loop::refine(t, cal, self.settings, it, vcmp);
        let (notes, est) = super::laws::keep_better_laws(d, &refine, self.progress)?;
        for n in notes {
            note = format!("{note}; {n}");
        }
        std = est.or(std);
        super::state::add_time(&mut d.timings, "damper_laws", t);
        Ok((note, std))
    }

    /// The calibration report of `p`; `chosen` says which diagnosis is
    /// reported, in words with the errors (`used`: one refined with its
    /// linear part).
    fn report(
        &self,
        p: &RefinedPath,
        calibration: Calibration,
        (chosen, used): (&str, bool),
    ) -> CalibrationReport {
        CalibrationReport {
            corrections: corrections(&calibration, &p.d.model, &p.std, &self.cal.calibration),
            calibration,
            calibrated_errors: p.start_errors.clone(),
            calibrated_validation_errors: p.start_validation_errors.clone(),
            refinement: p.note.clone(),
            used,
            choice: chosen.to_string(),
        }
    }
}

/// The choice in words: the record's errors of the declared, calibrated
/// and declared-refined diagnoses and which one (`chosen`) is reported.
fn choice(errs: &[Option<f64>; 3], chosen: &str) -> String {
    format!(
        "multiple-shooting error on the record after the diagnosis: {} with the declared linear part, {} with the calibrated one refined with its effects, {} with the declared one refined with its effects; {chosen} is reported",
        pct(errs[0]),
        pct(errs[1]),
        errs[2].map_or("not run (the calibrated one is at the noise)".into(), |e| pct(Some(e)))
    )
}

/// `d` with the spring to ground `g` added as an effect (at its
/// calibrated stiffness, the model's damping from `g`'s calibration, whose
/// lowest flexible mode is the former rigid-body mode).
fn with_ground_spring(d: &Diagnosis, g: &calibrate::grounding::GroundSpring) -> Diagnosis {
    let mut t = d.clone();
    t.model.damping = g.model.damping.clone();
    let candidate = Candidate::new(EffectKind::GroundSpring, vec![g.dof - 1]);
    with_effect(t, candidate, vec![("stiffness".into(), g.stiffness)])
}

/// `t` with its errors on the record and its predictions those of its
/// model as it stands (an effect just added, not yet refined).
fn scored_as_is(mut t: Diagnosis) -> Diagnosis {
    let (after, pred) = t.prepared.comparison.errors(&t.model, sim_of(&t));
    (t.after, t.predictions.1) = (after, pred);
    t
}

/// `t` with the effect `candidate` added to its model at `parameters` and
/// reported as found (scored later: no trace figures).
fn with_effect(
    mut t: Diagnosis,
    candidate: Candidate,
    parameters: Vec<(String, f64)>,
) -> Diagnosis {
    let ranked = RankedEffect {
        label: candidate.label(),
        candidate,
        parameters,
        std_errors: vec![],
        residual_explained: 0.0,
        force_explained: None,
        bic_change: 0.0,
        hidden: vec![],
    };
    let added = effects::add(&mut t.model, &ranked);
    let values = effects::values(&t.model, &added);
    t.effects.push(super::EffectReport {
        kind: ranked.candidate.kind,
        dofs: ranked.candidate.dofs.iter().map(|&d| d + 1).collect(),
        label: added.label.clone(),
        parameters: values.iter().cloned().collect(),
        std_errors: Default::default(),
        group_estimates: Default::default(),
        traced: values.into_iter().collect(),
        undetermined: vec![],
        unobservable: vec![],
        score: super::Score {
            residual_explained: 0.0,
            bic_change: 0.0,
            force_explained: None,
            error_before: t.after.relative_error,
            error_after: None,
        },
    });
    t.added.push(added);
    t
}

/// One joint refinement of `d`'s model; the note and, when kept, the
/// parameters with their standard errors.
fn refine_once(
    d: &mut Diagnosis,
    cal: &CalibratedSettings,
    settings: &DiagnoseSettings,
    bases: &Bases,
    progress: &dyn Fn(&str),
) -> Result<(String, Vec<Estimated>)> {
    Ok(match refine(d, &bases.record, cal, settings, progress)? {
        Refined::Kept(k) => {
            let Kept {
                model,
                prepared,
                after,
                pred,
                params,
                std,
                note,
            } = *k;
            d.model = model;
            if let Some(p) = prepared {
                d.prepared = p;
            }
            d.after = after;
            d.predictions.1 = pred;
            let sim = sim_of(d);
            progress("the refined model's errors on the validation record");
            rescore_validation(d, bases, settings, sim);
            (note, params.into_iter().zip(std).collect())
        }
        Refined::NotKept(note) => (note, vec![]),
    })
}

/// The linear part's reconstructions of the record and of the validation
/// record, from which each model's own is made ([`own`]).
struct Bases {
    record: super::prepare::Prepared,
    validation: Option<super::prepare::Prepared>,
}

/// The reconstruction `model` is simulated and scored from: for a model
/// with laws against ground in the absolute displacement and no spring to
/// ground, `base` corrected for the rigid-body wander fitted with its laws
/// ([`super::ground::corrected`], as the diagnosis scores it); else `base`.
/// The fitted model `d.model` scored again on the validation record, its
/// unobservable gaps against ground re-zeroed there
/// ([`super::validation::after_errors`]).
fn rescore_validation(
    d: &mut Diagnosis,
    bases: &Bases,
    settings: &DiagnoseSettings,
    sim: SimSettings,
) {
    if let (Some(b), Some(v)) = (bases.validation.as_ref(), d.validation.as_mut()) {
        let prep = own(&d.model, b);
        let q = &settings.fit.gap_quantiles;
        let (after, datum, _) = super::validation::after_errors(&d.model, &prep, q, sim);
        v.after = after;
        v.datum = datum;
    }
}

fn own<'a>(model: &Model, base: &'a super::prepare::Prepared) -> Cow<'a, super::prepare::Prepared> {
    owned(model, base).map_or(Cow::Borrowed(base), Cow::Owned)
}

/// [`own`] when it differs from `base`.
fn owned(model: &Model, base: &super::prepare::Prepared) -> Option<super::prepare::Prepared> {
    if model.has_ground_spring() {
        return None;
    }
    super::ground::corrected(model, base)
}

fn sim_of(d: &Diagnosis) -> SimSettings {
    SimSettings {
        substeps: d.substeps.1,
        ..Default::default()
    }
}

/// The free parameters of the refinement: the linear ones the calibration
/// opens and every nonlinear element's.
pub(super) fn refinement_parameters(
    model: &Model,
    added: &[super::effects::AddedEffect],
    cal: &CalibrationSettings,
) -> Result<Vec<Parameter>> {
    let mut out = vec![];
    for p in params::select(model, &cal.freedom) {
        let (lo, hi) = match p {
            LinearParam::Spring(_) => (-0.9, 10.0),
            LinearParam::Mass(_) | LinearParam::MassScale => (-0.5, 1.0),
            LinearParam::StiffnessScale => (-0.5, 1.0),
            _ => (-0.99, 20.0),
        };
        if p.get(model)? > 0.0 {
            out.push(Parameter::relative(model, p.target())?.with_relative_bounds(lo, hi));
        }
    }
    // the effects' own parameters with their bounds; a stiffness or
    // damping change is already a linear parameter
    for e in added {
        for p in effects::parameters(model, e)? {
            if !is_linear(model, p.target) && !out.iter().any(|q| q.target == p.target) {
                out.push(p);
            }
        }
    }
    Ok(out)
}

/// A refined parameter and its standard error.
pub(super) type Estimated = (Parameter, Option<f64>);

/// What the refinement gave.
enum Refined {
    /// Lower error: the model, its errors and predictions, the parameters
    /// and their standard errors.
    Kept(Box<Kept>),
    /// Not kept, and why.
    NotKept(String),
}

/// A kept refinement.
struct Kept {
    model: Model,
    /// The reconstruction the model is scored from when it differs from
    /// the diagnosis's ([`own`]).
    prepared: Option<super::prepare::Prepared>,
    after: ErrorSet,
    pred: Option<nalgebra::DMatrix<f64>>,
    params: Vec<Parameter>,
    std: Vec<Option<f64>>,
    note: String,
}

/// Refit every parameter of the diagnosed model together with the segment
/// start states; kept when it lowers the record's error. `d.prepared` is
/// the reconstruction `d.model` is scored from, `base` the linear part's
/// (they differ for a model with laws against ground: [`own`]).
fn refine(
    d: &Diagnosis,
    base: &super::prepare::Prepared,
    cs: &CalibratedSettings,
    settings: &DiagnoseSettings,
    progress: &dyn Fn(&str),
) -> Result<Refined> {
    let cal = &cs.calibration;
    let sim = sim_of(d);
    let cmp = &d.prepared.comparison;
    progress("joint refinement on the diagnosis's segments");
    let (problem, jf) = match first_joint_fit(d, cs, settings)? {
        Ok(f) => f,
        Err(e) => return Ok(Refined::NotKept(format!("not refined: {e}"))),
    };
    let refined = problem.model_at(&jf.x);
    progress("score the refined model");
    let prepared = owned(&refined, base);
    let own_cmp = prepared.as_ref().map_or(cmp, |p| &p.comparison);
    let (refined_starts, after, pred) = scored(own_cmp, &refined, sim);
    let mut note = format!(
        "{} parameters refined with the start states of {} segments ({}, {} steps, fit cost {:.3e} → {:.3e}): multiple-shooting error {} → {}",
        problem.parameters.len(),
        problem.segments.len(),
        jf.termination,
        jf.iterations,
        jf.cost.0,
        jf.cost.1,
        pct(d.after.relative_error),
        pct(after.relative_error)
    );
    note = format!(
        "{note} [weighted on the fitted segments: fit {:.2} %, scored {:.2} %]",
        100.0 * weighted(cmp, &jf.segments, Some(&jf.segment_costs), None),
        100.0 * weighted(cmp, &jf.segments, None, pred.as_ref())
    );
    let mut best = (problem, refined, jf.segments, after, pred, prepared);
    progress("joint refinement again from the start states refined for the refined model");
    let (refined_starts, n) = more_passes(d, base, &mut best, refined_starts, cs, settings)?;
    if let Some(n) = n {
        note = format!("{note}; {n}");
    }
    progress("joint refinement on long segments");
    if let Some((long, n)) = long_stage(d, base, &best, refined_starts, cs, settings)? {
        note = format!("{note}; {n}");
        if lower(long.3.relative_error, best.3.relative_error) {
            best = long;
        }
    }
    if let Some(n) = gap_searched(d, base, &mut best, cs, (settings, progress))? {
        note = format!("{note}; {n}");
    }
    let (problem, refined, segments, after, pred, prepared) = best;
    if !lower(after.relative_error, d.after.relative_error) {
        return Ok(Refined::NotKept(format!("{note}; not kept")));
    }
    // standard errors at the refined point, the residual level measured
    let level = after.relative_error.unwrap_or(settings.noise.level);
    progress("standard errors of the refinement");
    let (params, std) = std_errors_at(&problem, &refined, segments, &d.added, cal, level)?;
    Ok(Refined::Kept(Box::new(Kept {
        model: refined,
        prepared,
        after,
        pred,
        params,
        std,
        note: format!("{note}; kept"),
    })))
}

fn stall(settings: &DiagnoseSettings) -> joint::Stall {
    joint::Stall {
        steps: settings.starts.stall_steps,
        gain: settings.starts.stall_gain,
    }
}

/// A refinement's outcome: the problem it solved, the refined model, the
/// fitted segments, the record's errors and predictions, and the
/// reconstruction the model was scored from when it is its own ([`own`]).
type Stage = (
    crate::update::Problem,
    Model,
    Vec<crate::update::Segment>,
    ErrorSet,
    Option<nalgebra::DMatrix<f64>>,
    Option<super::prepare::Prepared>,
);

/// The joint refinement run again from `at`'s model, on the segments of
/// `starts` (the start states refined for it, [`super::starts`]), while a
/// pass lowers the record's multiple-shooting error by more than
/// [`super::settings::StartSettings::alternation_gain`] of itself, at most
/// [`CalibratedSettings::refine_passes`] passes in all. A joint fit moves
/// the start states only locally: started from states refined for the
/// diagnosed model, a segment whose refined model crosses an impact the
/// diagnosed one did not keeps its start in the wrong basin, and the fit
/// stalls there while start states refined afresh for the model it
/// reached explain those segments far better. `at` becomes the last pass
/// that lowered the error; the start states refined for it and the note
/// (None when no pass ran) are returned.
fn more_passes(
    d: &Diagnosis,
    base: &super::prepare::Prepared,
    at: &mut Stage,
    mut starts: Vec<crate::update::Segment>,
    cs: &CalibratedSettings,
    settings: &DiagnoseSettings,
) -> Result<(Vec<crate::update::Segment>, Option<String>)> {
    let gain = settings.starts.alternation_gain;
    let mut errors = vec![];
    for _ in 1..cs.refine_passes {
        let segments = spread(&starts, cs.refine_segments);
        let Ok((problem, jf)) = joint_fit(d, &at.1, segments, cs, settings)? else {
            break;
        };
        let refined = problem.model_at(&jf.x);
        let prepared = owned(&refined, base);
        let cmp = prepared
            .as_ref()
            .map_or(&d.prepared.comparison, |p| &p.comparison);
        let (next_starts, after, pred) = scored(cmp, &refined, sim_of(d));
        errors.push(pct(after.relative_error));
        let before = at.3.relative_error;
        if !lower(after.relative_error, before) {
            break;
        }
        let gained = match (after.relative_error, before) {
            (Some(a), Some(b)) => a < b * (1.0 - gain),
            _ => true,
        };
        *at = (problem, refined, jf.segments, after, pred, prepared);
        starts = next_starts;
        if !gained {
            break;
        }
    }
    let note = (!errors.is_empty()).then(|| {
        format!(
            "again from the start states refined for the refined model: multiple-shooting error {} (each pass kept while it lowers it)",
            errors.join(" → ")
        )
    });
    Ok((starts, note))
}

/// The refinement continued from `at` on long segments
/// ([`CalibratedSettings::long_segments`] consecutive segments of the
/// record's comparison each, over the whole record, from `starts`: the
/// start states refined for `at`'s model), where the damping of the lowest
/// modes shows; None when off. The note says what it did.
fn long_stage(
    d: &Diagnosis,
    base: &super::prepare::Prepared,
    at: &Stage,
    starts: Vec<crate::update::Segment>,
    cs: &CalibratedSettings,
    settings: &DiagnoseSettings,
) -> Result<Option<(Stage, String)>> {
    if cs.long_segments < 2 {
        return Ok(None);
    }
    let segments = merged(&starts, cs.long_segments);
    if segments.len() < 2 {
        return Ok(None);
    }
    let (problem, jf) = match joint_fit(d, &at.1, segments, cs, settings)? {
        Ok(f) => f,
        Err(e) => {
            return Ok(Some((
                at.clone(),
                format!("long segments: not refined: {e}"),
            )))
        }
    };
    let refined = problem.model_at(&jf.x);
    let prepared = owned(&refined, base);
    let cmp = prepared
        .as_ref()
        .map_or(&d.prepared.comparison, |p| &p.comparison);
    let (after, pred) = cmp.errors(&refined, sim_of(d));
    let note = format!(
        "then on {} segments of {} samples ({}, {} steps): multiple-shooting error {} [weighted: fit {:.2} %, scored {:.2} %]",
        problem.segments.len(),
        problem.segments[0].len,
        jf.termination,
        jf.iterations,
        pct(after.relative_error),
        100.0 * weighted(cmp, &jf.segments, Some(&jf.segment_costs), None),
        100.0 * weighted(cmp, &jf.segments, None, pred.as_ref())
    );
    Ok(Some((
        (problem, refined, jf.segments, after, pred, prepared),
        note,
    )))
}

/// The gap search ([`super::gap_search`]) from `at`'s model when
/// [`CalibratedSettings::gap_search`] and it applies, `at` left above the
/// noise; then the joint refinement again from the best point on the
/// start states refined for it ([`more_passes`]). `at` becomes the result
/// when its multiple-shooting error on the record is lower. None when the
/// search did not run.
fn gap_searched(
    d: &Diagnosis,
    base: &super::prepare::Prepared,
    at: &mut Stage,
    cs: &CalibratedSettings,
    (settings, progress): (&DiagnoseSettings, &dyn Fn(&str)),
) -> Result<Option<String>> {
    let cmp =
        at.5.as_ref()
            .map_or(&d.prepared.comparison, |p| &p.comparison);
    let level = d.noise_level(settings);
    let at_noise = at.3.relative_error.is_some_and(|e| e <= AT_NOISE * level);
    if !cs.gap_search || at_noise || !super::gap_search::applies(cmp, &at.1) {
        return Ok(None);
    }
    let sim = sim_of(d);
    progress("search the gaps and stiffnesses");
    let Some(s) = super::gap_search::search(cmp, &at.1, sim, AT_NOISE * level) else {
        return Ok(None);
    };
    let mut note = format!(
        "gap search over {} models: multiple-shooting error {} → {}",
        s.trials,
        pct(Some(s.error.1)),
        pct(Some(s.error.0))
    );
    if s.error.0 >= s.error.1 {
        return Ok(Some(format!("{note}: nothing lower")));
    }
    let prepared = owned(&s.model, base);
    let own_cmp = prepared
        .as_ref()
        .map_or(&d.prepared.comparison, |p| &p.comparison);
    let (starts, after, pred) = scored(own_cmp, &s.model, sim);
    let mut searched: Stage = (
        at.0.clone(),
        s.model,
        spread(&starts, cs.refine_segments),
        after,
        pred,
        prepared,
    );
    progress("joint refinement from the searched model");
    let (_, n) = more_passes(d, base, &mut searched, starts, cs, settings)?;
    if let Some(n) = n {
        note = format!("{note}; {n}");
    }
    if lower(searched.3.relative_error, at.3.relative_error) {
        *at = searched;
        note = format!("{note}: kept");
    } else {
        note = format!("{note}: not kept");
    }
    Ok(Some(note))
}

/// `d`'s multiple-shooting error on the record after one joint
/// refinement of every parameter on its segments ([`joint_fit`]), None
/// when the fit or the scoring fails.
fn quick_refined_error(
    d: &Diagnosis,
    cs: &CalibratedSettings,
    settings: &DiagnoseSettings,
) -> Option<f64> {
    let (problem, jf) = first_joint_fit(d, cs, settings).ok()?.ok()?;
    let refined = problem.model_at(&jf.x);
    scored(&d.prepared.comparison, &refined, sim_of(d))
        .1
        .relative_error
}

/// The first joint refinement of [`refine`]: `d`'s model with modal
/// ratios per mode, on `cs.refine_segments` of the segments whose start
/// states were refined for it ([`super::starts`]: from the reconstruction,
/// with continuity and growing horizons against a start on the wrong side
/// of an impact), spread over the record ([`joint_fit`]).
fn first_joint_fit(
    d: &Diagnosis,
    cs: &CalibratedSettings,
    settings: &DiagnoseSettings,
) -> Result<std::result::Result<(crate::update::Problem, joint::JointFit), joint::JointError>> {
    let model = params::per_mode(&d.model)?;
    let cmp = &d.prepared.comparison;
    let starts = starts_of(cmp, &cmp.shoot(&model, sim_of(d)));
    joint_fit(d, &model, spread(&starts, cs.refine_segments), cs, settings)
}

/// The joint refinement of `model`'s linear parameters and `d`'s effects
/// together with the start states of `segments`: the problem and its fit,
/// or why the fit failed.
fn joint_fit(
    d: &Diagnosis,
    model: &Model,
    segments: Vec<crate::update::Segment>,
    cs: &CalibratedSettings,
    settings: &DiagnoseSettings,
) -> Result<std::result::Result<(crate::update::Problem, joint::JointFit), joint::JointError>> {
    let mut problem = d.prepared.comparison.problem(model, segments, sim_of(d));
    problem.parameters = refinement_parameters(model, &d.added, &cs.calibration)?;
    let x0 = vec![0.0; problem.parameters.len()];
    let fit = crate::update::FitSettings {
        max_iterations: cs.refine_iterations,
        ..settings.fit_settings()
    };
    Ok(joint::fit(&problem, &x0, &fit, stall(settings)).map(|jf| (problem, jf)))
}

/// The record's errors and predictions of `model` from one multiple
/// shooting, with the segments whose start states it refined (the
/// reconstructed ones when it fails).
fn scored(
    cmp: &super::Comparison,
    model: &Model,
    sim: SimSettings,
) -> (
    Vec<crate::update::Segment>,
    ErrorSet,
    Option<nalgebra::DMatrix<f64>>,
) {
    let shot = cmp.shoot(model, sim);
    let starts = starts_of(cmp, &shot);
    let (errors, pred) = cmp.errors_of(model, sim, shot);
    (starts, errors, pred)
}

/// The segments whose start states `shot` refined; the reconstructed ones
/// when it failed.
fn starts_of(
    cmp: &super::Comparison,
    shot: &super::errors::ShotResult,
) -> Vec<crate::update::Segment> {
    shot.as_ref()
        .map_or_else(|_| cmp.segments.clone(), |(_, segs, _)| segs.clone())
}

/// Weighted relative error over `segs`: from the fit's segment costs when
/// given, else from the predictions `pred` (p × N).
fn weighted(
    cmp: &super::Comparison,
    segs: &[crate::update::Segment],
    costs: Option<&[f64]>,
    pred: Option<&nalgebra::DMatrix<f64>>,
) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (i, s) in segs.iter().enumerate() {
        for k in s.start..s.start + s.len {
            for (c, o) in cmp.observations.iter().enumerate() {
                let y = o.weight * o.data[k];
                den += y * y;
                if let Some(p) = pred {
                    let r = o.weight * (o.data[k] - p[(c, k)]);
                    num += r * r;
                }
            }
        }
        if let Some(c) = costs {
            num += c[i];
        }
    }
    crate::metrics::ratio(num, den)
}

/// Segments of `k` consecutive segments of `all` each, started from the
/// first one's start state (a last group of half or fewer is dropped).
fn merged(all: &[crate::update::Segment], k: usize) -> Vec<crate::update::Segment> {
    all.chunks(k)
        .filter(|c| c.len() == k || c.len() * 2 > k)
        .map(|c| {
            let last = &c[c.len() - 1];
            crate::update::Segment {
                len: last.start + last.len - c[0].start,
                ..c[0].clone()
            }
        })
        .collect()
}

/// True when an effect's target is a number the calibration corrects: a
/// spring of a lumped model (or of one written as matrices), or the modal
/// damping (moved by its ratios). A stiffness change between two points of
/// a model from matrices calibrated by scales is a localized effect.
fn is_linear(model: &Model, target: Target) -> bool {
    match target {
        Target::SpringStiffness(_) => !model.calibrated_by_scales(),
        Target::DampingRatio => true,
        _ => false,
    }
}

/// The effects' reported values from the final model and their standard
/// errors from the refinement; a stiffness or damping change is a linear
/// correction here ([`is_linear`]), reported with the corrections, not as
/// an effect.
fn update_effects(d: &mut Diagnosis, std: &[Estimated], s: &CalibrationSettings) {
    let mut keep: Vec<bool> = d
        .added
        .iter()
        .map(|e| {
            !(e.candidate.kind.changes_linear_part()
                && e.targets.iter().all(|t| is_linear(&d.model, *t)))
        })
        .collect();
    for (rep, e) in d.effects.iter_mut().zip(&d.added) {
        for ((name, v), t) in effects::values(&d.model, e).into_iter().zip(&e.targets) {
            rep.parameters.insert(name.clone(), v);
            if let Some((_, s)) = std.iter().find(|(p, _)| p.target == *t) {
                rep.std_errors.insert(name, *s);
            }
        }
    }
    // a local stiffness or damping change the refinement took back to
    // nothing (within the calibration's significance rule) is not an effect
    for ((k, rep), e) in keep.iter_mut().zip(&d.effects).zip(&d.added) {
        if e.candidate.kind.changes_linear_part() {
            *k &= rep.parameters.iter().any(|(name, v)| {
                let se = rep.std_errors.get(name).copied().flatten();
                v.abs() > s.min_change && se.is_none_or(|e| v.abs() > s.significance * e)
            });
        }
    }
    let pairs = std::mem::take(&mut d.effects)
        .into_iter()
        .zip(std::mem::take(&mut d.added))
        .zip(keep)
        .filter(|(_, k)| *k)
        .map(|(pair, _)| pair);
    (d.effects, d.added) = pairs.unzip();
}

/// A rise of the record's multiple-shooting error, as a fraction of it,
/// below which an effect switched off explains nothing the rest of the
/// model does not ([`drop_negligible`]).
const NEGLIGIBLE: f64 = 0.01;

/// Drop the nonlinear effects the final model does not need: each is
/// switched off in turn ([`effects::without`]: its stiffness, coefficient
/// or level to zero) and, when the record's multiple-shooting error rises
/// by less than [`NEGLIGIBLE`] of itself, it is no longer named (the model
/// keeps it switched off; the validation record is scored again). A
/// refinement can take an effect proposed beside the right one to nothing
/// (a clearance of 71 N/m beside a cubic spring) without the stop rules
/// seeing it. The note says what was dropped; None when nothing was.
fn drop_negligible(
    d: &mut Diagnosis,
    bases: &Bases,
    settings: &DiagnoseSettings,
    progress: &dyn Fn(&str),
) -> Option<String> {
    let sim = sim_of(d);
    let mut dropped = vec![];
    // every effect's screens on the model as it is, in parallel (the
    // screens are independent; one alone leaves a core idle in its
    // few-segment steps); after a drop, one at a time
    let mut ahead = d
        .after
        .relative_error
        .and_then(|_| screens_ahead(d, bases, sim));
    // the model's own screen error on its reconstruction, while it is
    // unchanged
    let mut with_screen: Option<Option<f64>> = None;
    for i in (0..d.added.len()).rev() {
        let e = &d.added[i];
        if e.candidate.kind.changes_linear_part() {
            continue;
        }
        let with = d.after.relative_error?;
        progress("score the model with an effect switched off");
        let s = match ahead.as_mut().and_then(|a| a[i].take()) {
            Some(s) => s,
            None => screened(d, e, bases, sim, &mut with_screen),
        };
        if needed(s.off_error, s.with_error) {
            continue;
        }
        let cmp = s
            .prepared
            .as_ref()
            .map_or(&d.prepared.comparison, |p| &p.comparison);
        let (after, pred) = cmp.errors(&s.off, sim);
        if !after
            .relative_error
            .is_some_and(|x| x <= with * (1.0 + NEGLIGIBLE))
        {
            continue;
        }
        dropped.push(format!(
            "{} dropped (switched off: {} against {})",
            e.label,
            pct(after.relative_error),
            pct(Some(with))
        ));
        d.model = s.off;
        // the screens computed ahead were on the model before the drop
        ahead = None;
        with_screen = None;
        if let Some(p) = s.prepared {
            d.prepared = p;
        }
        d.after = after;
        d.predictions.1 = pred;
        d.added.remove(i);
        d.effects.remove(i);
    }
    if dropped.is_empty() {
        return None;
    }
    rescore_validation(d, bases, settings, sim);
    Some(dropped.join("; "))
}

/// An effect switched off ([`effects::without`]) and the screens
/// ([`screen_error`]) of the model without it and with it, on the
/// reconstruction the model without it is scored from.
struct Screened {
    /// The model with the effect switched off.
    off: Model,
    /// Its own reconstruction when it differs from the diagnosis's
    /// ([`owned`]).
    prepared: Option<super::prepare::Prepared>,
    /// The screen error of the model with the effect.
    with_error: Option<f64>,
    /// The screen error of the model without it.
    off_error: Option<f64>,
}

/// [`Screened`] for the effect `e` of `d`, the two screens side by side;
/// `with_screen` caches the screen of `d`'s model on `d`'s own
/// reconstruction.
fn screened(
    d: &Diagnosis,
    e: &super::effects::AddedEffect,
    bases: &Bases,
    sim: SimSettings,
    with_screen: &mut Option<Option<f64>>,
) -> Screened {
    let off = effects::without(&d.model, e);
    let prepared = owned(&off, &bases.record);
    let cmp = prepared
        .as_ref()
        .map_or(&d.prepared.comparison, |p| &p.comparison);
    let (with_error, off_error) = match (&prepared, *with_screen) {
        (None, Some(w)) => (w, screen_error(cmp, &off, sim)),
        _ => rayon::join(
            || screen_error(cmp, &d.model, sim),
            || screen_error(cmp, &off, sim),
        ),
    };
    if prepared.is_none() {
        *with_screen = Some(with_error);
    }
    Screened {
        off,
        prepared,
        with_error,
        off_error,
    }
}

/// [`screened`] for every nonlinear effect of `d` (None for the others)
/// at once, in parallel, the screen of `d`'s model on its own
/// reconstruction computed once for those scored on it; None without a
/// nonlinear effect.
fn screens_ahead(d: &Diagnosis, bases: &Bases, sim: SimSettings) -> Option<Vec<Option<Screened>>> {
    use rayon::prelude::*;
    let offs: Vec<Option<(Model, Option<super::prepare::Prepared>)>> = d
        .added
        .par_iter()
        .map(|e| {
            (!e.candidate.kind.changes_linear_part()).then(|| {
                let off = effects::without(&d.model, e);
                let prepared = owned(&off, &bases.record);
                (off, prepared)
            })
        })
        .collect();
    let listed: Vec<_> = offs.iter().flatten().collect();
    if listed.is_empty() {
        return None;
    }
    let on_base = listed.iter().any(|(_, p)| p.is_none());
    let (base_with, each) = rayon::join(
        || on_base.then(|| screen_error(&d.prepared.comparison, &d.model, sim)),
        || {
            offs.par_iter()
                .map(|o| {
                    o.as_ref().map(|(off, prepared)| {
                        let cmp = prepared
                            .as_ref()
                            .map_or(&d.prepared.comparison, |p| &p.comparison);
                        let with = prepared.as_ref().map(|_| screen_error(cmp, &d.model, sim));
                        (screen_error(cmp, off, sim), with)
                    })
                })
                .collect::<Vec<_>>()
        },
    );
    Some(
        offs.into_iter()
            .zip(each)
            .map(|(o, s)| {
                let ((off, prepared), (off_error, with)) = (o?, s?);
                Some(Screened {
                    off,
                    prepared,
                    with_error: with.unwrap_or_else(|| base_with.flatten()),
                    off_error,
                })
            })
            .collect(),
    )
}

/// Every this many segments of the record, one is scored in the screen
/// of an effect switched off ([`needed`]).
const SCREEN_STRIDE: usize = 4;

/// The rise of the multiple-shooting error on the screen's segments, as a
/// fraction of the model's with the effect, above which the effect
/// switched off is needed without scoring every segment ([`needed`]);
/// 25 × [`NEGLIGIBLE`].
const SCREEN_RISE: f64 = 0.25;

/// The multiple-shooting error of `model` on every [`SCREEN_STRIDE`]-th
/// segment of `cmp` only, those segments' starts refined alone
/// ([`super::starts::refine`]): models screened this way are compared on
/// the same footing, neither with the continuity of neighbours the other
/// lacks. None with fewer than two such segments, without start-state
/// refinement, or when a prediction failed.
fn screen_error(cmp: &super::Comparison, model: &Model, sim: SimSettings) -> Option<f64> {
    let subset: Vec<_> = cmp
        .segments
        .iter()
        .skip(SCREEN_STRIDE / 2)
        .step_by(SCREEN_STRIDE)
        .cloned()
        .collect();
    if subset.len() < 2 || cmp.starts.iterations == 0 {
        return None;
    }
    let (segs, y, _) = super::starts::refine(cmp, model, sim, &subset, cmp.starts.iterations);
    // the prediction on the screen's samples only (NaN elsewhere)
    let mut a = nalgebra::DMatrix::from_element(y.nrows(), y.ncols(), f64::NAN);
    for s in &segs {
        let ys = y.columns(s.start, s.len);
        if ys.iter().any(|v| !v.is_finite()) {
            return None;
        }
        a.columns_mut(s.start, s.len).copy_from(&ys);
    }
    Some(cmp.total_error(&a))
}

/// Whether a model with an effect switched off, whose screen error
/// ([`screen_error`]) is `off`, is clearly worse than the model with it
/// (`with`): by more than [`SCREEN_RISE`]. False (score every segment)
/// when it is not, or when either error is missing.
fn needed(off: Option<f64>, with: Option<f64>) -> bool {
    matches!((off, with), (Some(o), Some(w)) if o > w * (1.0 + SCREEN_RISE))
}

/// Drop a spurious companion: with two nonlinear effects or more and the
/// record's error above the noise, each is switched off in turn
/// ([`effects::without`]) and the rest refined again without it
/// ([`refine_once`]: the linear part, the other effects and the start
/// states, from where the refinement with it ended); the lowest error so
/// reached replaces `d` when it is at most 1 + [`NEGLIGIBLE`] times the
/// error with the effect (fewer effects explaining the record as well). A
/// quadratic spring named before a contact on the same pair, on a linear
/// part the calibration biased, holds the refinement in a minimum the
/// contact alone leaves. The note and the refined parameters with their
/// standard errors; None when nothing was dropped.
fn refit_without(
    d: &mut Diagnosis,
    cal: &CalibratedSettings,
    settings: &DiagnoseSettings,
    bases: &Bases,
    progress: &dyn Fn(&str),
) -> Result<Option<(String, Vec<Estimated>)>> {
    let nonlinear: Vec<usize> = (0..d.added.len())
        .filter(|&i| !d.added[i].candidate.kind.changes_linear_part())
        .collect();
    let Some(with) = d.after.relative_error.filter(|_| nonlinear.len() >= 2) else {
        return Ok(None);
    };
    let mut best: Option<(Diagnosis, String, Vec<Estimated>)> = None;
    for &i in &nonlinear {
        let label = d.added[i].label.clone();
        progress(&format!("refine again without {label}"));
        let mut t = d.clone();
        t.model = effects::without(&d.model, &d.added[i]);
        t.prepared = owned(&t.model, &bases.record).unwrap_or_else(|| bases.record.clone());
        let (after, pred) = t.prepared.comparison.errors(&t.model, sim_of(&t));
        (t.after, t.predictions.1) = (after, pred);
        t.added.remove(i);
        t.effects.remove(i);
        let (n, est) = refine_once(&mut t, cal, settings, bases, progress)?;
        let e = t.after.relative_error;
        let better = best
            .as_ref()
            .is_none_or(|(b, _, _)| lower(e, b.after.relative_error));
        if !est.is_empty() && better && e.is_some_and(|e| e <= with * (1.0 + NEGLIGIBLE)) {
            let note = format!(
                "{label} dropped (the rest refined again without it: {} against {} with it; {n})",
                pct(e),
                pct(Some(with))
            );
            best = Some((t, note, est));
        }
    }
    Ok(best.map(|(t, note, est)| {
        *d = t;
        (note, est)
    }))
}

/// The linear corrections of the final model against the declared one
/// (named as the calibration named them).
fn corrections(
    calibration: &Calibration,
    model: &Model,
    std: &[Estimated],
    s: &CalibrationSettings,
) -> Vec<LinearCorrection> {
    // a spring to ground added as an effect gave the former rigid-body
    // mode a ratio of its own: the declared modes' ratios moved up by one
    let added = crate::model::added_mode(&calibration.model, model);
    calibration
        .corrections
        .iter()
        .map(|c| {
            let parameter = match (c.parameter, added) {
                (LinearParam::ModalRatio(r), Some(j)) if r >= j => LinearParam::ModalRatio(r + 1),
                (p, _) => p,
            };
            let value = parameter.get(model).unwrap_or(c.calibrated);
            let target = parameter.target();
            let se = std
                .iter()
                .find(|(p, _)| p.target == target)
                .and_then(|(_, s)| *s)
                .or_else(|| c.std_error.is_finite().then_some(c.std_error));
            let change = value / c.declared - 1.0;
            let rel = se.map(|s| s / value.abs().max(1e-300));
            LinearCorrection {
                name: c.name.clone(),
                unit: c.unit.clone(),
                declared: c.declared,
                calibrated: c.calibrated,
                value,
                change,
                std_error: se,
                significant: se.is_some_and(|e| (value - c.declared).abs() > s.significance * e)
                    && change.abs() > s.min_change,
                identifiable: rel.is_some_and(|r| r < s.max_relative_std),
            }
        })
        .collect()
}

/// The refinement's parameters re-opened at `refined` (with the fitted
/// `segments`) and their standard errors at residual level `level` (None
/// where the Jacobian cannot give one).
pub(super) fn std_errors_at(
    problem: &crate::update::Problem,
    refined: &Model,
    segments: Vec<crate::update::Segment>,
    added: &[effects::AddedEffect],
    cal: &CalibrationSettings,
    level: f64,
) -> Result<(Vec<Parameter>, Vec<Option<f64>>)> {
    let mut at = problem.clone();
    at.model = refined.clone();
    at.segments = segments;
    at.parameters = refinement_parameters(refined, added, cal)?;
    let std = joint::std_errors(&at, &vec![0.0; at.parameters.len()], level)
        .map(|v| v.into_iter().map(|s| s.is_finite().then_some(s)).collect())
        .unwrap_or_else(|| vec![None; at.parameters.len()]);
    Ok((at.parameters, std))
}

/// True when error `a` is lower than `b` (a failed error is never lower;
/// any error is lower than a failed one).
pub(super) fn lower(a: Option<f64>, b: Option<f64>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => a < b,
        (Some(_), None) => true,
        _ => false,
    }
}

/// `model` without its springs of zero stiffness (a spring to ground the
/// refinement took to its bound at 0 acts as no spring, and a model file
/// may not hold one).
fn without_null_springs(mut model: Model) -> Model {
    model.springs.retain(|s| s.stiffness > 0.0);
    model
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Contact;
    use crate::simulate::{simulate_record, RecordSpec};
    use crate::trace::{Candidate, EffectKind, RankedEffect};

    #[test]
    fn a_spring_refined_to_zero_leaves_a_valid_model() {
        let mut m = crate::model::Model::from_toml_str(
            "masses = [1.0, 1.0]\n[[spring]]\ndofs = [1, 2]\nstiffness = 5e4\n",
            "test",
        )
        .unwrap();
        m.springs.push(crate::model::Spring {
            dofs: vec![2],
            stiffness: 0.0,
            name: Some("ground2".into()),
        });
        assert!(m.validate("test").is_err());
        let kept = without_null_springs(m);
        assert_eq!(kept.springs.len(), 1);
        assert_eq!(kept.springs[0].stiffness, 5e4);
        assert!(kept.validate("test").is_ok());
    }

    /// A contact 3→2 on lanl8dof diagnosed, a quadratic 2–3 named beside
    /// it (as on a linear part the calibration biased): refined again
    /// without it, the record is explained as well, so it is dropped and
    /// the contact kept.
    #[test]
    fn a_companion_the_rest_explains_without_is_dropped() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let declared = Model::from_file(std::path::Path::new(p)).unwrap();
        let mut truth = declared.clone();
        truth.contacts.push(Contact {
            dofs: vec![3, 2],
            gap: 3e-4,
            stiffness: 2e6,
        });
        let spec = RecordSpec {
            samples: 2048,
            sensors: (1..=8).collect(),
            noise: 0.01,
            seed: 16,
            settings: SimSettings {
                substeps: 40,
                ..Default::default()
            },
            ..Default::default()
        };
        let rec = simulate_record(&truth, &spec).unwrap().0;
        let settings = DiagnoseSettings::default();
        let mut d =
            super::super::diagnose(&declared, &rec, None, None, &settings, &|_| {}).unwrap();
        assert_eq!(d.effects.len(), 1, "{}", d.verdict);
        assert_eq!(d.added[0].label, "contact 3→2");
        // the quadratic 2–3 of seed 77909's record without a linear record
        let q = Candidate::new(EffectKind::Quadratic, vec![1, 2]);
        let added = effects::add(&mut d.model, &RankedEffect::for_test(q, &[("k2", -6.4e5)]));
        let mut report = d.effects[0].clone();
        (report.kind, report.dofs, report.label) =
            (EffectKind::Quadratic, vec![2, 3], added.label.clone());
        d.added.push(added);
        d.effects.push(report);
        let with = d.prepared.comparison.errors(&d.model, sim_of(&d)).0;
        d.after = with.clone();
        let bases = Bases {
            record: d.prepared.clone(),
            validation: None,
        };
        let cal = CalibratedSettings::default();
        let dropped = refit_without(&mut d, &cal, &settings, &bases, &|_| {}).unwrap();
        let (note, est) = dropped.expect("the quadratic dropped");
        assert!(note.starts_with("quadratic 2–3 dropped"), "{note}");
        assert!(!est.is_empty());
        let labels: Vec<&str> = d.added.iter().map(|e| e.label.as_str()).collect();
        assert_eq!(labels, ["contact 3→2"]);
        let after = d.after.relative_error.unwrap();
        assert!(
            after < with.relative_error.unwrap(),
            "{after} {:?}",
            with.relative_error
        );
        assert!(after < 0.015, "{after}");
    }
}
