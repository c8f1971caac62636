//! The F-16 ground vibration test (Noël & Schoukens 2017) closed end to
//! end: a linear modal model identified from the low-level record
//! ([`crate::correlate::modelfit`]), the close-the-loop diagnosis with the
//! linear part calibrated on a high-level record, and the open-loop
//! simulation error per channel over the steady-state periods, before and
//! after, on the record and on a validation record (`docs/f16.md`).
//!
//! The records are the benchmark's full-grid multisine files read as they
//! are: `Force` at the driving point, `Acceleration` rows 1–3 at the
//! driving point (`exc`), on the wing (`wing`) and on the payload
//! (`payload`) next to the interface, `Fs` (uint16). Nine periods of 8192
//! samples; the first is the transient ([`Settings::warm_up`]).

use crate::correlate::modelfit::{identify_model, ModelFit, ModelFitSettings};
use crate::correlate::{FitSettings, FrfSettings, Window};
use crate::diagnose::calibrated::{diagnose_calibrated, CalibratedSettings};
use crate::diagnose::{interface, DiagnoseSettings, EffectReport};
use crate::error::{Result, TacitError};
use crate::integrate::{Integrator, SimSettings};
use crate::model::{modal, Model};
use crate::record::{self, MatChannel, MatMapping, MatRate, Quantity, Record, WarmUp};
use serde::Serialize;
use std::path::Path;

/// The points, in the order of the `Acceleration` rows.
pub const POINTS: [&str; 3] = ["exc", "wing", "payload"];

/// Settings of the F-16 case.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    /// Samples of one period of the multisine.
    pub period: usize,
    /// Samples left out at the start of every record (the transient first
    /// period).
    pub warm_up: usize,
    /// Band of the modal model, Hz (the excited band).
    pub band_hz: (f64, f64),
    /// Curve-fit orders.
    pub orders: (usize, usize),
    /// Sub-steps per sample of the open-loop simulations.
    pub substeps: usize,
    /// How the linear part is calibrated on the record diagnosed.
    pub calibration: Calibration,
    /// The interface candidate ([`interface::offer`]) fitted on the linear
    /// and the estimation record and ranked with the Level-1 model and the
    /// diagnosed model on them (None: the diagnosed model is the model
    /// after).
    pub interface: Option<interface::OfferSettings>,
    /// More estimation records for the interface candidate's fit and
    /// ranking (beside the linear and the estimation record).
    pub also_estimate: Vec<std::path::PathBuf>,
    /// The diagnosis.
    #[serde(skip)]
    pub diagnose: DiagnoseSettings,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            period: 8192,
            warm_up: 8192,
            band_hz: (2.0, 15.0),
            orders: (10, 100),
            substeps: 10,
            calibration: Calibration::Reidentify,
            interface: Some(Default::default()),
            also_estimate: vec![],
            diagnose: DiagnoseSettings {
                // the lifted smoother stops on this model ("the
                // initial-state system is not positive definite"); the
                // full-horizon smoother reconstructs its states
                states: crate::diagnose::StatesSource::Reconstructed,
                ..Default::default()
            },
        }
    }
}

/// How the linear part is calibrated on the record diagnosed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Calibration {
    /// The modal model identified again, the same way, on the record's
    /// steady-state periods (its modes at the record's level); the
    /// diagnosis then trusts it.
    Reidentify,
    /// The diagnosis's own calibration of springs and modal damping
    /// ([`crate::diagnose::calibrated`]) on the Level-1 model.
    Diagnosis,
}

/// The mapping of a benchmark file: force and the three accelerations
/// at named points, the rate from `Fs`.
pub fn mapping() -> MatMapping {
    let mut channels = vec![MatChannel {
        point: Some(POINTS[0].into()),
        ..MatChannel::at_dof("Force", Quantity::Force, 0)
    }];
    for (r, p) in POINTS.iter().enumerate() {
        channels.push(MatChannel {
            variable: "Acceleration".into(),
            signal: Some(r + 1),
            quantity: Quantity::Accel,
            dof: 0,
            point: Some((*p).into()),
        });
    }
    MatMapping {
        channels,
        fs: MatRate::Variable("Fs".into()),
        remove_mean: false,
    }
}

/// Read a benchmark file as it is.
pub fn read(path: &Path) -> Result<Record> {
    record::read_mat(path, &mapping())
}

/// The modal model identified from the low-level record (its
/// steady-state periods, whole-period segments, no window).
pub fn linear_model(rec: &Record, s: &Settings) -> Result<(ModelFit, String)> {
    let steady = rec.without_warm_up(WarmUp::Samples(s.warm_up))?;
    let settings = ModelFitSettings {
        frf: FrfSettings {
            segment: s.period,
            overlap: 0.0,
            window: Window::Rectangular,
        },
        fit: FitSettings {
            band_hz: s.band_hz,
            orders: s.orders,
            ..Default::default()
        },
        residuals: true,
    };
    let fit = identify_model(std::slice::from_ref(&steady), &settings)?;
    let text = modal::to_toml_string(
        "f16-linear",
        &format!(
            "F-16 GVT (Noël & Schoukens 2017), modal model identified from {}",
            rec.source.display()
        ),
        &fit.section,
    );
    Ok((fit, text))
}

/// Open-loop simulation of `model` from rest under the record's force;
/// the RMS error per output channel (m/s²) over the samples after
/// `warm_up`, in the order of the record's outputs. The record's channels
/// are resolved to the model's DOFs ([`Model::resolve_channels`]).
pub fn rms_per_channel(
    model: &Model,
    rec: &Record,
    warm_up: usize,
    substeps: usize,
) -> Result<Vec<f64>> {
    let e = simulate_errors(model, rec, warm_up, substeps)?;
    Ok(e.iter().map(|c| crate::signal::rms_of(c)).collect())
}

/// Open-loop simulation of `model` from rest under the record's force:
/// per output channel, simulated minus measured acceleration (m/s²) at
/// the samples after `warm_up` ([`interface::open_loop_errors`]).
pub fn simulate_errors(
    model: &Model,
    rec: &Record,
    warm_up: usize,
    substeps: usize,
) -> Result<Vec<Vec<f64>>> {
    interface::open_loop_errors(model, rec, warm_up, substeps)
}

/// The frequency bands (Hz) of [`crate::signal::band_rms`] on this case: below the
/// excited band, the rigid-body modes, wing bending, wing torsion, the
/// modes above, and above the excited band.
pub const BANDS_HZ: [(f64, f64); 6] = [
    (0.0, 2.0),
    (2.0, 4.5),
    (4.5, 6.2),
    (6.2, 8.5),
    (8.5, 15.0),
    (15.0, f64::INFINITY),
];

/// Per-channel RMS errors, m/s², before, with the linear part calibrated,
/// and after.
#[derive(Debug, Clone, Serialize)]
pub struct BeforeAfter {
    /// The record.
    pub record: String,
    /// Channel names, in the order of the errors.
    pub channels: Vec<String>,
    /// RMS of the measured channels over the steady-state periods, m/s².
    pub rms_measured: Vec<f64>,
    /// The linear (low-level) model.
    pub before: Errors,
    /// The linear model calibrated on the record diagnosed, without effects.
    pub calibrated: Errors,
    /// The model after ([`F16Result::after_model`]).
    pub after: Errors,
}

/// An effect of the model after.
#[derive(Debug, Clone, Serialize)]
pub struct FoundEffect {
    /// What it is.
    pub label: String,
    /// The points it joins (`ground` for a point to ground).
    pub points: Vec<String>,
    /// With an effect on the interface coordinate: the measured relative
    /// motion it follows most in the simulation of the estimation record
    /// (pair, correlation of the velocities; [`interface::Restoring::follows`]).
    pub couples_most: Option<(String, f64)>,
    /// Parameters, SI.
    pub parameters: Vec<(String, f64)>,
}

impl FoundEffect {
    /// The interface effect of `f` (an [`interface::Fitted`] on the
    /// coordinate).
    fn interface(f: &interface::Fitted, couples: Option<&(String, f64)>) -> FoundEffect {
        let mut label = match f.elements {
            1 => "jenkins (stick–slip friction) on the interface coordinate".to_string(),
            n => format!("iwan ({n} jenkins elements) on the interface coordinate"),
        };
        let mut parameters = vec![
            ("stiffness".to_string(), f.stiffness),
            ("slip_force".to_string(), f.slip_force),
            ("spread".to_string(), f.spread),
        ];
        if let Some(e) = &f.softening {
            label += " with an elastic softening (saturating spring)";
            parameters.push(("softening_stiffness".into(), f.softening_stiffness));
            parameters.push(("softening_force".into(), e.force));
        }
        for (hz, d) in &f.participations {
            parameters.push((format!("participation_{hz:.2}_hz"), *d));
        }
        FoundEffect {
            label,
            points: f.points.to_vec(),
            couples_most: couples.cloned(),
            parameters,
        }
    }

    /// The Jenkins element between the pair.
    fn interface_pair(f: &interface::Fitted) -> FoundEffect {
        FoundEffect {
            label: "jenkins (stick–slip friction) between two points".into(),
            points: f.points.to_vec(),
            couples_most: None,
            parameters: vec![
                ("stiffness".into(), f.stiffness),
                ("slip_force".into(), f.slip_force),
            ],
        }
    }

    /// A diagnosed effect of `model`.
    fn diagnosed(e: &EffectReport, model: &Model) -> FoundEffect {
        let mut points: Vec<String> = e.dofs.iter().map(|&k| model.dof_name(k)).collect();
        if points.len() == 1 {
            points.push("ground".into());
        }
        FoundEffect {
            label: e.label.clone(),
            points,
            couples_most: None,
            parameters: e.parameters.clone().into_iter().collect(),
        }
    }
}

/// Errors of one model on one record.
#[derive(Debug, Clone, Serialize)]
pub struct Errors {
    /// Open-loop simulation RMS error per channel over the steady-state
    /// periods, m/s².
    pub rms_per_channel: Vec<f64>,
}

/// What came out.
#[derive(Debug, Clone, Serialize)]
pub struct F16Result {
    /// The linear model (modes, fit errors, notes).
    pub linear: ModelFit,
    /// On the diagnosed record.
    pub estimation: BeforeAfter,
    /// On the validation record.
    pub validation: BeforeAfter,
    /// The model after: the name of the model ranked first on the
    /// estimation records ([`interface::Offer::ranking`]), or the
    /// diagnosed model without the interface candidate.
    pub after_model: String,
    /// The effects of the model after, with the points each joins.
    pub effects_found: Vec<FoundEffect>,
    /// The interface candidate: its stages, where it couples, every model
    /// ranked on the estimation records.
    pub interface: Option<interface::Offer>,
    /// The diagnosis's verdict.
    pub verdict: String,
    /// Effects found (kind, points, parameters).
    pub effects: Vec<EffectReport>,
    /// Best candidates of the first trace round (label, share of the
    /// residual removed), with the points each joins.
    pub ranking: Vec<(String, f64, Vec<String>)>,
    /// The points the effects join, by label.
    pub effect_points: Vec<Vec<String>>,
    /// The noise measured on the diagnosed record (None when not
    /// measured).
    pub noise: Option<crate::diagnose::noise::NoiseEstimate>,
    /// Linear corrections of the calibration (name, declared, final).
    pub linear_corrections: Vec<(String, f64, f64)>,
    /// The modes re-identified on the record diagnosed
    /// ([`Calibration::Reidentify`]).
    pub calibrated_modes: Vec<crate::model::modal::ModalMode>,
    /// Seconds: identification, diagnosis, interface candidate, scoring.
    pub seconds: (f64, f64, f64, f64),
    /// Settings.
    pub settings: Settings,
}

fn before_after(rec: &Record, models: [&Model; 3], s: &Settings) -> Result<BeforeAfter> {
    let [before, calibrated, after] = models;
    Ok(BeforeAfter {
        record: rec.source.display().to_string(),
        channels: rec.outputs.iter().map(|c| c.name()).collect(),
        rms_measured: rec
            .outputs
            .iter()
            .map(|c| crate::signal::rms_of(&c.data[s.warm_up..]))
            .collect(),
        before: Errors {
            rms_per_channel: rms_per_channel(before, rec, s.warm_up, s.substeps)?,
        },
        calibrated: Errors {
            rms_per_channel: rms_per_channel(calibrated, rec, s.warm_up, s.substeps)?,
        },
        after: Errors {
            rms_per_channel: rms_per_channel(after, rec, s.warm_up, s.substeps)?,
        },
    })
}

/// Name of the Level-1 model in the ranking.
pub const LEVEL1: &str = "level-1 model";
/// Name of the diagnosed model (the linear part calibrated on the
/// estimation record, with the effects the diagnosis found) in the ranking.
pub const DIAGNOSED: &str = "diagnosed model";

/// What [`run`] returns.
pub struct Outputs {
    /// The result (report.json).
    pub result: F16Result,
    /// The model after ([`F16Result::after_model`]).
    pub after: Model,
    /// The text of the Level-1 modal model file.
    pub linear_text: String,
    /// Every model ranked, by name (the Level-1 model, the diagnosed model,
    /// the interface models).
    pub models: Vec<(String, Model)>,
    /// With an interface model after: its restoring force in the
    /// simulation of the estimation record (the last period).
    pub restoring: Option<interface::Restoring>,
}

/// The whole case: identify on `linear`, diagnose `estimate` (without
/// its warm-up), offer the interface candidate ([`Settings::interface`]),
/// rank the models on `linear` and `estimate` and score the first
/// (the model after) with the Level-1 and the calibrated model on
/// `estimate` and `validate`.
pub fn run(
    linear: &Path,
    estimate: &Path,
    validate: &Path,
    s: &Settings,
    progress: &dyn Fn(&str),
) -> Result<Outputs> {
    let t0 = std::time::Instant::now();
    let (fit, text) = linear_model(&read(linear)?, s)?;
    let model = modal::from_toml_str(&text, "f16-linear")?;
    let load = |p: &Path| -> Result<Record> {
        let mut r = read(p)?;
        model.resolve_channels(&mut r)?;
        Ok(r)
    };
    let (r1, est, val) = (load(linear)?, load(estimate)?, load(validate)?);
    let t1 = t0.elapsed().as_secs_f64();
    let (d, linear_cal, calibrated_modes) = diagnose_step(&model, &est, &val, s, progress)?;
    let t2 = t0.elapsed().as_secs_f64();
    let pair = interface::trace_pair(&d).unwrap_or([2, 3]);
    let alternatives = vec![
        (LEVEL1.to_string(), model.clone()),
        (DIAGNOSED.to_string(), d.model.clone()),
    ];
    let (offer, models) = match &s.interface {
        Some(o) => {
            let o = offer_settings(o, pair, s);
            let more = s
                .also_estimate
                .iter()
                .map(|p| load(p))
                .collect::<Result<Vec<_>>>()?;
            let mut recs = vec![&r1, &est];
            recs.extend(more.iter());
            let (f, m) = interface::offer(&fit.section, &recs, alternatives, &o, progress)?;
            (Some(f), m)
        }
        None => (None, alternatives),
    };
    let after_model = offer.as_ref().map_or(DIAGNOSED, |o| o.chosen()).to_string();
    let after = by_name(&models, &after_model)?.clone();
    let t3 = t0.elapsed().as_secs_f64();
    let estimation = before_after(&est, [&model, &linear_cal, &after], s)?;
    let validation = before_after(&val, [&model, &linear_cal, &after], s)?;
    let restoring = match after.points.iter().any(|p| p == interface::INTERFACE) {
        true => Some(interface::restoring(
            &after, &est, pair, s.substeps, s.period,
        )?),
        false => None,
    };
    let t4 = t0.elapsed().as_secs_f64();
    let follows = restoring.as_ref().and_then(|r| r.follows.first());
    let effects_found = effects_of(&after_model, &after, &d, offer.as_ref(), follows);
    let result = F16Result {
        linear: fit,
        estimation,
        validation,
        after_model,
        effects_found,
        interface: offer,
        verdict: d.verdict.clone(),
        effects: d.effects.clone(),
        effect_points: effect_points(&d),
        ranking: trace_ranking(&d),
        noise: d.noise.clone(),
        linear_corrections: corrections(&d),
        calibrated_modes,
        seconds: (t1, t2 - t1, t3 - t2, t4 - t3),
        settings: s.clone(),
    };
    Ok(Outputs {
        result,
        after,
        linear_text: text,
        models,
        restoring,
    })
}

/// The interface candidate's settings for this case: the pair the trace
/// located, the case's sub-steps and warm-up.
fn offer_settings(
    o: &interface::OfferSettings,
    pair: [usize; 2],
    s: &Settings,
) -> interface::OfferSettings {
    let mut o = o.clone();
    o.spec.pair = pair;
    o.spec.substeps = s.substeps;
    o.spec.warm_up = s.warm_up;
    o
}

/// The model named `name` in `models`.
fn by_name<'a>(models: &'a [(String, Model)], name: &str) -> Result<&'a Model> {
    models
        .iter()
        .find(|m| m.0 == name)
        .map(|m| &m.1)
        .ok_or_else(|| TacitError::Numerical(format!("no model named {name} was ranked")))
}

/// The effects of the model after: the interface's, or the diagnosis's.
fn effects_of(
    name: &str,
    after: &Model,
    d: &crate::diagnose::Diagnosis,
    offer: Option<&interface::Offer>,
    follows: Option<&(String, f64)>,
) -> Vec<FoundEffect> {
    match offer {
        Some(o) if [interface::JENKINS, interface::IWAN, interface::SOFTENED].contains(&name) => {
            let f = o.fitted(name).unwrap_or(&o.jenkins);
            vec![FoundEffect::interface(f, follows)]
        }
        Some(o) if name == interface::PAIR => vec![FoundEffect::interface_pair(&o.pair)],
        _ if name == DIAGNOSED => d
            .effects
            .iter()
            .map(|e| FoundEffect::diagnosed(e, after))
            .collect(),
        _ => vec![],
    }
}

/// The diagnosis of the estimation record with the linear part calibrated
/// ([`Settings::calibration`]): the diagnosis, the calibrated linear model
/// and the re-identified modes.
fn diagnose_step(
    model: &Model,
    est: &Record,
    val: &Record,
    s: &Settings,
    progress: &dyn Fn(&str),
) -> Result<(crate::diagnose::Diagnosis, Model, Vec<modal::ModalMode>)> {
    let est_ss = est.without_warm_up(WarmUp::Samples(s.warm_up))?;
    let val_ss = val.without_warm_up(WarmUp::Samples(s.warm_up))?;
    let (declared, calibrated_modes, off) = match s.calibration {
        Calibration::Reidentify => {
            let (fit7, text7) = linear_model(est, s)?;
            let m = modal::from_toml_str(&text7, "f16-calibrated")?;
            (m, fit7.section.modes, true)
        }
        Calibration::Diagnosis => (model.clone(), vec![], false),
    };
    let cal = CalibratedSettings {
        off,
        ..Default::default()
    };
    let d = diagnose_calibrated(
        &declared,
        &est_ss,
        Some(&val_ss),
        &[],
        None,
        &s.diagnose,
        &cal,
        progress,
    )?;
    let linear_cal = match s.calibration {
        Calibration::Reidentify => declared,
        Calibration::Diagnosis => d.model.linear_part(),
    };
    Ok((d, linear_cal, calibrated_modes))
}

/// The points each effect of the diagnosis joins.
fn effect_points(d: &crate::diagnose::Diagnosis) -> Vec<Vec<String>> {
    d.effects
        .iter()
        .map(|e| e.dofs.iter().map(|&k| d.model.dof_name(k)).collect())
        .collect()
}

/// The first trace round's ranking: label, share, points.
fn trace_ranking(d: &crate::diagnose::Diagnosis) -> Vec<(String, f64, Vec<String>)> {
    d.ranking
        .iter()
        .map(|r| {
            let pts = r
                .candidate
                .dofs
                .iter()
                .map(|&k| d.model.dof_name(k + 1))
                .collect();
            (r.label.clone(), r.residual_explained, pts)
        })
        .collect()
}

/// The calibration's linear corrections (name, declared, final).
fn corrections(d: &crate::diagnose::Diagnosis) -> Vec<(String, f64, f64)> {
    d.calibration
        .as_ref()
        .map(|c| {
            c.corrections
                .iter()
                .map(|x| (x.name.clone(), x.declared, x.value))
                .collect()
        })
        .unwrap_or_default()
}

impl F16Result {
    /// The per-channel table for people.
    pub fn summary(&self) -> String {
        let mut s = format!("verdict: {}\n", self.verdict);
        if let Some(n) = &self.noise {
            s += &format!("noise: {}\n", n.summary());
        }
        for (e, pts) in self.effects.iter().zip(&self.effect_points) {
            s += &format!(
                "diagnosis: effect {} between {}\n",
                e.label,
                pts.join(" and ")
            );
        }
        if let Some(o) = &self.interface {
            s += "models ranked on the estimation records:\n";
            s += &o.summary();
        }
        s += &format!("model after: {}\n", self.after_model);
        for e in &self.effects_found {
            let c = e.couples_most.as_ref().map_or(String::new(), |(p, c)| {
                format!(" (follows most the motion {p}: correlation {c:+.3})")
            });
            s += &format!("effect {} between {}{c}\n", e.label, e.points.join(" and "));
        }
        for (what, ba) in [
            ("record", &self.estimation),
            ("validation", &self.validation),
        ] {
            s += &format!("{what} {}\n", ba.record);
            for (c, ch) in ba.channels.iter().enumerate() {
                s += &format!(
                    "  {ch:<14} measured RMS {:.3}  before {:.3}  calibrated {:.3}  after {:.3} m/s^2\n",
                    ba.rms_measured[c],
                    ba.before.rms_per_channel[c],
                    ba.calibrated.rms_per_channel[c],
                    ba.after.rms_per_channel[c]
                );
            }
        }
        s += &format!(
            "seconds: identification {:.1}, diagnosis {:.1}, interface {:.1}, scoring {:.1}\n",
            self.seconds.0, self.seconds.1, self.seconds.2, self.seconds.3
        );
        s
    }
}

/// What the interface fit ([`interface_fit`]) does with the linear part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LinearPart {
    /// Held at the low-level model: only the effect's coefficients are
    /// fitted, so the model reduces to the low-level model at low
    /// amplitude.
    Held,
    /// Fitted with the effect: the coupling spring between the two
    /// points and the damping ratios of the modes nearest the given
    /// frequencies.
    Free,
}

/// The damper of the interface model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Damper {
    /// `c_2 ν|ν|`: its equivalent damping grows as the amplitude.
    Quadratic,
    /// `c_3 ν³`: its equivalent damping grows as the amplitude squared, as
    /// the cubic spring's stiffness, so both fade together at low level.
    Cubic,
}

/// What [`interface_fit`] fits.
#[derive(Debug, Clone, PartialEq)]
pub struct InterfaceSpec {
    /// The two points, DOFs from 1.
    pub pair: [usize; 2],
    /// Start values: the cubic spring's k3 (N/m³) and the quadratic
    /// damper's c2 (N s²/m²); a cubic damper starts from
    /// `c2 / ν_rms` (`ν_rms` the RMS relative velocity of the pair in the
    /// model's simulation of the record).
    pub starts: (f64, f64),
    /// The damper's law.
    pub damper: Damper,
    /// The linear part held or fitted.
    pub linear: LinearPart,
    /// With [`LinearPart::Free`]: the modal damping ratios of the modes
    /// nearest these frequencies (Hz) are fitted too.
    pub ratios_near_hz: Vec<f64>,
}

/// The Level-1 model with a softening-or-stiffening cubic spring and a
/// damper ([`Damper`]) between the two points of `spec`, their
/// coefficients fitted by open-loop output error on the whole record from
/// rest. With [`LinearPart::Free`] the coupling spring between the two
/// points (when the model has one) and the modal damping ratios of
/// `spec.ratios_near_hz` are fitted with them. Returns the whole fit: the
/// model in `.model`, with how the fit ended and its iterations.
pub fn interface_fit(
    model: &Model,
    rec: &Record,
    spec: &InterfaceSpec,
    substeps: usize,
) -> Result<crate::update::FitResult> {
    use crate::model::{Cubic, CubicDamper, QuadraticDamper};
    use crate::update::{
        self, optimize::FitSettings, param::Parameter, param::Target, problem::Problem,
    };
    let (pair, starts, linear) = (spec.pair, spec.starts, spec.linear);
    let mut m = model.clone();
    m.cubics.push(Cubic {
        dofs: pair.to_vec(),
        k3: starts.0,
    });
    // the held linear part needs more of the effects to reach the record;
    // k3 free in sign and size on either side of its start (a start of
    // either sign)
    let (k3_up, c_up) = match linear {
        LinearPart::Held => (20.0, 200.0),
        LinearPart::Free => (5.0, 20.0),
    };
    let damper = match spec.damper {
        Damper::Quadratic => {
            m.quadratic_dampers.push(QuadraticDamper {
                dofs: pair.to_vec(),
                c2: starts.1.max(1.0),
            });
            Target::DamperC2(m.quadratic_dampers.len() - 1)
        }
        Damper::Cubic => {
            let nu = relative_velocity_rms(model, rec, pair, substeps)?;
            m.cubic_dampers.push(CubicDamper {
                dofs: pair.to_vec(),
                c3: (starts.1 / nu).max(1.0),
            });
            Target::DamperC3(m.cubic_dampers.len() - 1)
        }
    };
    let mut params = vec![
        Parameter::relative(&m, Target::CubicK3(m.cubics.len() - 1))?
            .with_relative_bounds(-k3_up, k3_up),
        Parameter::relative(&m, damper)?.with_relative_bounds(-0.999, c_up),
    ];
    let spring = if linear == LinearPart::Free {
        m.springs.iter().position(|s| {
            s.dofs.len() == 2 && s.dofs.contains(&pair[0]) && s.dofs.contains(&pair[1])
        })
    } else {
        None
    };
    if let Some(i) = spring {
        params.push(
            Parameter::relative(&m, Target::SpringStiffness(i))?.with_relative_bounds(-0.9, 1.0),
        );
    }
    let modes = crate::modal::solve(&m.mass_matrix(), &m.stiffness_matrix())?;
    let flex: Vec<f64> = (0..modes.freq_hz.len())
        .filter(|&r| !modes.rigid[r])
        .map(|r| modes.freq_hz[r])
        .collect();
    let ratios = if linear == LinearPart::Free {
        &spec.ratios_near_hz[..]
    } else {
        &[]
    };
    for f in ratios {
        let r = (0..flex.len())
            .min_by(|&a, &b| (flex[a] - f).abs().total_cmp(&(flex[b] - f).abs()))
            .ok_or_else(|| TacitError::Numerical("the model has no flexible mode".into()))?;
        params
            .push(Parameter::relative(&m, Target::ModalRatio(r))?.with_relative_bounds(-0.9, 10.0));
    }
    let n = m.ndof();
    let mut p = Problem::from_record(
        &m,
        rec,
        &[Quantity::Accel],
        None,
        params,
        vec![0.0; n],
        vec![0.0; n],
    )?;
    p.sim.substeps = substeps;
    update::fit(&p, &FitSettings::default())
}

/// RMS of the relative velocity between the two DOFs of `pair` (from 1)
/// in the open-loop simulation of `model` under the record's force, m/s.
fn relative_velocity_rms(
    model: &Model,
    rec: &Record,
    pair: [usize; 2],
    substeps: usize,
) -> Result<f64> {
    let nd = model.ndof();
    let force = crate::signal::force_matrix(rec, nd);
    let sim = SimSettings {
        substeps,
        ..Default::default()
    };
    let run =
        Integrator::new(model, rec.fs, sim)?.run(force.as_view(), &vec![0.0; nd], &vec![0.0; nd]);
    let (i, j) = (pair[0] - 1, pair[1] - 1);
    let rel: Vec<f64> = (0..run.v.ncols())
        .map(|k| run.v[(i, k)] - run.v[(j, k)])
        .collect();
    let nu = crate::signal::rms_of(&rel);
    if !(run.completed() && nu > 0.0 && nu.is_finite()) {
        return Err(TacitError::Numerical(format!(
            "the relative velocity of DOFs {} and {} in the simulation of {} is {nu} m/s RMS: no start for a cubic damper",
            pair[0],
            pair[1],
            rec.source.display()
        )));
    }
    Ok(nu)
}

/// The interface fit ([`interface_fit`]) scored on several records.
#[derive(Debug, Clone, Serialize)]
pub struct InterfaceFit {
    /// The linear part held at the Level-1 model or fitted with the effect.
    pub linear: LinearPart,
    /// The damper's law.
    pub damper: Damper,
    /// Cubic spring between `wing` and `payload`, N/m³.
    pub k3: f64,
    /// Quadratic damper between them, N s²/m² (0 with a cubic damper).
    pub c2: f64,
    /// Cubic damper between them, N s³/m³ (0 with a quadratic damper).
    pub c3: f64,
    /// The coupling spring `wing`–`payload`: Level-1 value and fitted, N/m.
    pub coupling: Option<(f64, f64)>,
    /// Per record: file, the Level-1 model's and the interface model's
    /// open-loop RMS error per channel (m/s², steady-state periods).
    pub errors: Vec<(String, Vec<f64>, Vec<f64>)>,
    /// How the output-error fit ended (converged, iteration limit,
    /// stalled with its reason).
    pub termination: crate::update::Termination,
    /// Accepted iterations of the fit.
    pub iterations: usize,
    /// The fitted parameters: start, value, bounds and whether a bound
    /// holds them.
    pub parameters: Vec<crate::update::FittedParameter>,
    /// Seconds of the fit.
    pub seconds: f64,
}

/// Fit the interface model on `estimate` (with [`LinearPart::Free`] the
/// wing bending and torsion damping and the coupling spring freed with it)
/// and score it with the Level-1 model on `records`.
pub fn interface_study(
    linear: &Path,
    estimate: &Path,
    records: &[&Path],
    (part, damper): (LinearPart, Damper),
    s: &Settings,
) -> Result<(InterfaceFit, Model)> {
    let lin = read(linear)?;
    let (_, text) = linear_model(&lin, s)?;
    let l1 = modal::from_toml_str(&text, "f16-linear")?;
    let mut est = read(estimate)?;
    l1.resolve_channels(&mut est)?;
    let t = std::time::Instant::now();
    let spec = InterfaceSpec {
        pair: [2, 3],
        starts: (-3.0e12, 1.5e5),
        damper,
        linear: part,
        ratios_near_hz: vec![5.2, 7.3],
    };
    let fitted = interface_fit(&l1, &est, &spec, s.substeps)?;
    let m = fitted.model;
    let seconds = t.elapsed().as_secs_f64();
    let mut errors = vec![];
    for p in records {
        let mut r = read(p)?;
        l1.resolve_channels(&mut r)?;
        errors.push((
            p.display().to_string(),
            rms_per_channel(&l1, &r, s.warm_up, s.substeps)?,
            rms_per_channel(&m, &r, s.warm_up, s.substeps)?,
        ));
    }
    let coupling = |mm: &Model| {
        mm.springs
            .iter()
            .find(|sp| sp.dofs == [2, 3])
            .map(|sp| sp.stiffness)
    };
    let fit = InterfaceFit {
        linear: part,
        damper,
        k3: m.cubics.last().map_or(0.0, |c| c.k3),
        c2: m.quadratic_dampers.last().map_or(0.0, |d| d.c2),
        c3: m.cubic_dampers.last().map_or(0.0, |d| d.c3),
        coupling: coupling(&l1).zip(coupling(&m)),
        errors,
        termination: fitted.termination,
        iterations: fitted.iterations,
        parameters: fitted.parameters,
        seconds,
    };
    Ok((fit, m))
}

/// One model scored on one record.
#[derive(Debug, Clone, Serialize)]
pub struct Scored {
    /// The model's name.
    pub model: String,
    /// The record.
    pub record: String,
    /// Open-loop RMS error per channel over the steady-state periods, m/s².
    pub rms_per_channel: Vec<f64>,
    /// The same per frequency band of [`BANDS_HZ`]: `[channel][band]`.
    pub rms_per_band: Vec<Vec<f64>>,
}

/// Score every model on every record (open loop from rest, RMS per channel
/// and per band over the samples after `warm_up`).
pub fn score(
    models: &[(&str, &Model)],
    records: &[&Record],
    warm_up: usize,
    substeps: usize,
) -> Result<Vec<Scored>> {
    let mut out = vec![];
    for rec in records {
        for (name, m) in models {
            let e = simulate_errors(m, rec, warm_up, substeps)?;
            out.push(Scored {
                model: name.to_string(),
                record: rec.source.display().to_string(),
                rms_per_channel: e.iter().map(|c| crate::signal::rms_of(c)).collect(),
                rms_per_band: crate::signal::band_rms(&e, rec.fs, &BANDS_HZ),
            });
        }
    }
    Ok(out)
}
