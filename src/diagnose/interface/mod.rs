//! The interface as a coordinate of its own: a candidate effect for a
//! modal model (a model file with a `[modal]` section, as `tacit modal`
//! writes it) whose nonlinearity sits in a joint no sensor measures.
//!
//! The measured points give the element between two of them a direction in
//! the modal coordinates fixed by their shapes, `φ_a − φ_b`; a joint next
//! to them need not take part in the modes in that proportion. Here the
//! modal model gains an unmeasured point, [`INTERFACE`], whose displacement
//! in each non-residual mode (the interface's participation `δ_r` in that
//! mode) is a parameter, and a Jenkins element (a spring `k_J` in series
//! with a Coulomb slider `F_s`; Iwan 1966) or an Iwan model (several in
//! parallel, a density of slip forces) acts from that point to ground with
//! `k_J` taken out of the coordinate's linear stiffness: stuck, the model
//! *is* the identified linear model; fully slipped, mode `r` alone keeps
//! `1 − δ_r²` of its ω² and the modes couple through the one joint
//! ([`build::coordinate_model`]).
//!
//! [`offer`] fits it in three stages, each by open-loop output error over
//! the steady-state samples of the estimation records (every record
//! weighted by 1 / its RMS response; [`fit::fit`]):
//!
//! 1. a Jenkins element between the two points of [`OfferSettings::pair`]
//!    taking a share of their coupling spring: its `k_J` sets the
//!    coordinate's scale and, with its `F_s`, starts the next stage;
//! 2. the Jenkins element on the interface coordinate: the participations
//!    (started from the pair's relative displacement) and `F_s`;
//! 3. with [`OfferSettings::iwan`] elements, an Iwan model on the same
//!    coordinate, started from stage 2, the exponent of its slip-force
//!    density fitted too;
//! 4. with [`OfferSettings::softening`], an elastic softening beside the
//!    slider ([`Softening`]: a saturating spring on the same coordinate,
//!    stiffness `k_e` lost once its force reaches `F_e`), started from
//!    stage 3 (or 2) with the participations held: `k_e`, `F_e`, the
//!    slider's slip force and density fitted. A friction law alone ties
//!    the softening to the dissipation (both come from the same slipping
//!    elements); this stage lets the interface soften before it
//!    dissipates.
//!
//! Every interface model and the linear alternatives the caller gives (the
//! declared model, the diagnosed model, a model identified at another
//! level) are then ranked by the same weighted open-loop error on the
//! estimation records, never on a validation record; [`Offer::coupling`]
//! says where the interface couples most: the cosine between the fitted
//! participations and those of the relative displacement of every pair of
//! measured points (and of every point to ground).

pub mod build;
pub mod fit;
mod restoring;

pub use build::{
    coordinate_model, coordinate_stiffness, model_with, pair_participations, Direction, FitSpec,
    ModeParam, Softening, INTERFACE,
};
pub use fit::{fit, Fitted};
pub use restoring::{restoring, restoring_figure, Restoring};

use crate::error::{Result, TacitError};
use crate::integrate::{Integrator, SimSettings};
use crate::model::{modal, Model};
use crate::record::{Quantity, Record};
use serde::Serialize;

/// Open-loop simulation of `model` from rest under the record's force:
/// per output channel (accelerations), simulated minus measured (m/s²) at
/// the samples after `warm_up`. The record's channels must be resolved to
/// the model's DOFs ([`Model::resolve_channels`]).
pub fn open_loop_errors(
    model: &Model,
    rec: &Record,
    warm_up: usize,
    substeps: usize,
) -> Result<Vec<Vec<f64>>> {
    let run = simulate(model, rec, substeps)?;
    let n = rec.len();
    let mut out = Vec::with_capacity(rec.outputs.len());
    for c in &rec.outputs {
        if c.quantity != Quantity::Accel {
            return Err(TacitError::record(
                rec.source.clone(),
                format!("channel {} is not an acceleration", c.name()),
            ));
        }
        let d = c.dof - 1;
        out.push((warm_up..n).map(|k| run.a[(d, k)] - c.data[k]).collect());
    }
    Ok(out)
}

/// The open-loop simulation of `model` from rest under the record's force,
/// or an error naming the record and why it stopped.
fn simulate(
    model: &Model,
    rec: &Record,
    substeps: usize,
) -> Result<crate::integrate::newmark::Simulation> {
    let nd = model.ndof();
    let force = crate::signal::force_matrix(rec, nd);
    let sim = SimSettings {
        substeps,
        ..Default::default()
    };
    let run =
        Integrator::new(model, rec.fs, sim)?.run(force.as_view(), &vec![0.0; nd], &vec![0.0; nd]);
    if !run.completed() || run.len() < rec.len() {
        return Err(TacitError::Numerical(format!(
            "open-loop simulation of {} stopped: {}",
            rec.source.display(),
            crate::simulate::describe_status(&run.status)
        )));
    }
    Ok(run)
}

/// Settings of [`offer`].
#[derive(Debug, Clone, Serialize)]
pub struct OfferSettings {
    /// The coordinate fit's settings: the pair (DOFs from 1) whose relative
    /// displacement starts the participations and whose coupling spring
    /// sets `k_J` (`share` of it), the start of the slip force, the
    /// residual mode's damping, the limit on simulations, sub-steps and
    /// warm-up. `direction`, `elements` and `participations` are set by
    /// each stage.
    pub spec: FitSpec,
    /// Limit on the simulations of stage 1 (the element between the pair).
    pub pair_simulations: usize,
    /// Elements of the Iwan model of stage 3 (None or 1: no stage 3).
    pub iwan: Option<usize>,
    /// Stage 4: the start of the elastic softening's share `k_e / k_J`
    /// (its bound starts at the smallest slip force of the stage it
    /// starts from); None: no stage 4.
    pub softening: Option<f64>,
}

impl Default for OfferSettings {
    fn default() -> Self {
        OfferSettings {
            spec: FitSpec {
                direction: Direction::Coordinate,
                max_simulations: 150,
                ..Default::default()
            },
            pair_simulations: 60,
            iwan: None,
            softening: None,
        }
    }
}

impl OfferSettings {
    /// Check the settings.
    pub fn validate(&self) -> Result<()> {
        self.spec.validate()?;
        if self.pair_simulations == 0 {
            return Err(TacitError::Setting(
                "interface: pair_simulations must be > 0".into(),
            ));
        }
        if self.iwan == Some(0) {
            return Err(TacitError::Setting(
                "interface: an Iwan model needs at least one element".into(),
            ));
        }
        if let Some(e) = self.softening {
            if !(e > 0.0 && e.is_finite()) {
                return Err(TacitError::Setting(format!(
                    "interface: the softening's share {e} must be > 0"
                )));
            }
        }
        Ok(())
    }
}

/// One model ranked by its open-loop error on the estimation records.
#[derive(Debug, Clone, Serialize)]
pub struct Ranked {
    /// The model's name.
    pub name: String,
    /// Where its effect acts: `interface–ground`, `wing–payload`, or
    /// `linear` for a model without effect.
    pub acts: String,
    /// RMS of the weighted open-loop error over every estimation record's
    /// steady-state samples (each record weighted by 1 / its RMS response).
    pub cost: f64,
    /// Per estimation record: the open-loop RMS error per channel, m/s².
    pub rms_per_channel: Vec<Vec<f64>>,
}

/// What [`offer`] found.
#[derive(Debug, Clone, Serialize)]
pub struct Offer {
    /// The estimation records.
    pub records: Vec<String>,
    /// Stage 1: the Jenkins element between the pair.
    pub pair: Fitted,
    /// Stage 2: the Jenkins element on the interface coordinate.
    pub jenkins: Fitted,
    /// Stage 3: the Iwan model on the interface coordinate.
    pub iwan: Option<Fitted>,
    /// Stage 4: the slider with an elastic softening on the coordinate.
    pub softened: Option<Fitted>,
    /// Where the interface couples: per pair of measured points
    /// (`a–b`) and per point to ground (`a–ground`), the cosine between
    /// the fitted participations of the chosen interface model and those
    /// of that relative displacement, largest magnitude first.
    pub coupling: Vec<(String, f64)>,
    /// Every model, best (lowest cost) first.
    pub ranking: Vec<Ranked>,
}

impl Offer {
    /// The name of the model ranked first.
    pub fn chosen(&self) -> &str {
        self.ranking.first().map_or("", |r| r.name.as_str())
    }

    /// The best interface model on the coordinate (its fit).
    pub fn best_interface(&self) -> &Fitted {
        [JENKINS, IWAN, SOFTENED]
            .into_iter()
            .filter_map(|name| Some((self.rank_of(name), self.fitted(name)?)))
            .min_by_key(|(rank, _)| *rank)
            .map_or(&self.jenkins, |(_, f)| f)
    }

    /// The fit of the interface model named `name` in [`Offer::ranking`]
    /// (None for a model that is not an interface model).
    pub fn fitted(&self, name: &str) -> Option<&Fitted> {
        match name {
            PAIR => Some(&self.pair),
            JENKINS => Some(&self.jenkins),
            IWAN => self.iwan.as_ref(),
            SOFTENED => self.softened.as_ref(),
            _ => None,
        }
    }

    fn rank_of(&self, name: &str) -> usize {
        self.ranking
            .iter()
            .position(|r| r.name == name)
            .unwrap_or(usize::MAX)
    }

    /// Lines for people: the ranking and where the interface couples.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        for r in &self.ranking {
            s += &format!(
                "  {:<44} {:<22} cost {:.4}  rms {:.3?} m/s^2\n",
                r.name, r.acts, r.cost, r.rms_per_channel
            );
        }
        let f = self.best_interface();
        for (hz, d) in &f.participations {
            s += &format!("  interface participation of the {hz:.2}-Hz mode: {d:+.4}\n");
        }
        let c: Vec<String> = self
            .coupling
            .iter()
            .map(|(w, c)| format!("{w} {c:+.3}"))
            .collect();
        s += &format!("  couples most with: {}\n", c.join(", "));
        s
    }
}

/// Name of stage 1's model in [`Offer::ranking`].
pub const PAIR: &str = "jenkins between the pair";
/// Name of stage 2's model in [`Offer::ranking`].
pub const JENKINS: &str = "jenkins on the interface coordinate";
/// Name of stage 3's model in [`Offer::ranking`].
pub const IWAN: &str = "iwan on the interface coordinate";
/// Name of stage 4's model in [`Offer::ranking`].
pub const SOFTENED: &str = "slider and elastic softening on the interface coordinate";

/// Fit the interface ([module docs](self)) of the modal model `section` on
/// the estimation `records` (resolved to the model's points), and rank it
/// against the `alternatives` (name, model) by the weighted open-loop
/// error on those records. Returns what was found and every model by name
/// (the alternatives first, then the stages').
pub fn offer(
    section: &modal::ModalSection,
    records: &[&Record],
    alternatives: Vec<(String, Model)>,
    s: &OfferSettings,
    progress: &dyn Fn(&str),
) -> Result<(Offer, Vec<(String, Model)>)> {
    s.validate()?;
    if records.is_empty() {
        return Err(TacitError::Setting(
            "interface: no estimation record".into(),
        ));
    }
    progress("interface: the element between the pair");
    let pair_spec = FitSpec {
        direction: Direction::Points,
        elements: 1,
        participations: None,
        max_simulations: s.pair_simulations,
        ..s.spec.clone()
    };
    let (pair, pair_model) = fit(section, records, &pair_spec)?;
    progress("interface: the Jenkins element on the interface coordinate");
    let coord = FitSpec {
        direction: Direction::Coordinate,
        elements: 1,
        share: pair.stiffness / pair.coupling,
        slip_force: pair.slip_force,
        participations: None,
        ..s.spec.clone()
    };
    let (jenkins, jenkins_model) = fit(section, records, &coord)?;
    let mut models = alternatives;
    models.push((PAIR.into(), pair_model));
    models.push((JENKINS.into(), jenkins_model));
    let (iwan, last) = match s.iwan {
        Some(n) if n > 1 => {
            progress("interface: the Iwan model on the interface coordinate");
            let spec = iwan_spec(&coord, &jenkins, n);
            let (f, m) = fit(section, records, &spec)?;
            models.push((IWAN.into(), m));
            (Some(f), spec)
        }
        _ => (None, coord.clone()),
    };
    let softened = match s.softening {
        Some(share) => {
            progress("interface: the slider and an elastic softening on the coordinate");
            let from = iwan.as_ref().unwrap_or(&jenkins);
            let (f, m) = fit(section, records, &softening_spec(&last, from, share))?;
            models.push((SOFTENED.into(), m));
            Some(f)
        }
        None => None,
    };
    progress("interface: ranking on the estimation records");
    let ranking = rank(&models, records, &s.spec, [&pair, &jenkins])?;
    let mut o = Offer {
        records: records
            .iter()
            .map(|r| r.source.display().to_string())
            .collect(),
        pair,
        jenkins,
        iwan,
        softened,
        coupling: vec![],
        ranking,
    };
    o.coupling = coupling(section, &o.best_interface().participations);
    Ok((o, models))
}

/// Stage 3's settings: `n` elements on the coordinate, started from the
/// Jenkins element's participations and with the same total slip force
/// (`Σ F_s (i/n)^p` = the single element's), the density's exponent
/// fitted from 1.
fn iwan_spec(coord: &FitSpec, jenkins: &Fitted, n: usize) -> FitSpec {
    let sum: f64 = (1..=n).map(|i| i as f64 / n as f64).sum();
    FitSpec {
        elements: n,
        spread: 1.0,
        fit_spread: true,
        slip_force: jenkins.slip_force / sum,
        participations: Some(jenkins.participations.iter().map(|p| p.1).collect()),
        ..coord.clone()
    }
}

/// Stage 4's settings: the slider of `from` (fitted with `spec`) with its
/// participations held, and a saturating spring of `share · k_J` whose
/// bound starts at the slider's smallest slip force.
fn softening_spec(spec: &FitSpec, from: &Fitted, share: f64) -> FitSpec {
    let n = spec.elements.max(1);
    FitSpec {
        spread: from.spread,
        slip_force: from.slip_force,
        participations: Some(from.participations.iter().map(|p| p.1).collect()),
        hold_participations: true,
        softening: Some(Softening {
            share,
            force: build::element_slip_force(1, n, from.spread, from.slip_force),
        }),
        ..spec.clone()
    }
}

/// Every model scored on every record, best first ([`Ranked`]).
fn rank(
    models: &[(String, Model)],
    records: &[&Record],
    spec: &FitSpec,
    [pair, coord]: [&Fitted; 2],
) -> Result<Vec<Ranked>> {
    let mut out = vec![];
    for (name, m) in models {
        let mut sq = 0.0;
        let mut count = 0usize;
        let mut per = vec![];
        for rec in records {
            let e = open_loop_errors(m, rec, spec.warm_up, spec.substeps)?;
            let w = 1.0 / measured_rms(rec, spec.warm_up);
            sq += e.iter().flatten().map(|v| (v * w).powi(2)).sum::<f64>();
            count += e.iter().map(|c| c.len()).sum::<usize>();
            per.push(e.iter().map(|c| crate::signal::rms_of(c)).collect());
        }
        let acts = match name.as_str() {
            PAIR => pair.points.join("–"),
            JENKINS | IWAN | SOFTENED => coord.points.join("–"),
            _ => describe_effects(m),
        };
        out.push(Ranked {
            name: name.clone(),
            acts,
            cost: (sq / count.max(1) as f64).sqrt(),
            rms_per_channel: per,
        });
    }
    out.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    Ok(out)
}

/// The RMS of the record's outputs over the samples after `warm_up`.
fn measured_rms(rec: &Record, warm_up: usize) -> f64 {
    let ss: f64 = rec
        .outputs
        .iter()
        .map(|c| crate::signal::rms_of(&c.data[warm_up.min(c.data.len())..]).powi(2))
        .sum();
    (ss / rec.outputs.len().max(1) as f64).sqrt()
}

/// `linear` for a model without nonlinear element, else the points its
/// elements join.
fn describe_effects(m: &Model) -> String {
    let els = crate::model::elements::compile(m);
    if els.is_empty() {
        return "linear".into();
    }
    let mut pts: Vec<String> = els
        .iter()
        .map(|e| {
            let (i, j) = e.ends();
            let a = m.dof_name(i + 1);
            j.map_or(format!("{a}–ground"), |j| {
                format!("{a}–{}", m.dof_name(j + 1))
            })
        })
        .collect();
    pts.dedup();
    pts.join(", ")
}

/// The pair of points (DOFs from 1) of the best candidate between two
/// points in the diagnosis's first trace round: where the trace locates
/// the effect; the interface's first stage acts there.
pub fn trace_pair(d: &crate::diagnose::Diagnosis) -> Option<[usize; 2]> {
    d.ranking
        .iter()
        .find(|r| r.candidate.dofs.len() == 2)
        .map(|r| [r.candidate.dofs[0] + 1, r.candidate.dofs[1] + 1])
}

/// The pair of points (DOFs from 1) joined by the model's stiffest
/// coupling spring.
pub fn coupled_pair(model: &Model) -> Option<[usize; 2]> {
    model
        .springs
        .iter()
        .filter(|s| s.dofs.len() == 2)
        .max_by(|a, b| a.stiffness.total_cmp(&b.stiffness))
        .map(|s| [s.dofs[0], s.dofs[1]])
}

/// The cosine between the participations `delta` (per non-residual mode)
/// and those of each pair of measured points and each point to ground,
/// largest magnitude first.
pub fn coupling(section: &modal::ModalSection, delta: &[(f64, f64)]) -> Vec<(String, f64)> {
    let modes: Vec<&modal::ModalMode> = section.modes.iter().filter(|m| !m.residual).collect();
    let d: Vec<f64> = delta.iter().map(|p| p.1).collect();
    let p = section.points.len();
    let mut out = vec![];
    let dir = |f: &dyn Fn(&modal::ModalMode) -> f64| -> Vec<f64> {
        modes.iter().map(|m| f(m) / m.frequency_hz).collect()
    };
    for a in 0..p {
        for b in a + 1..p {
            let v = dir(&|m| m.shape[a] - m.shape[b]);
            let name = format!("{}–{}", section.points[a], section.points[b]);
            out.push((name, cosine(&d, &v)));
        }
        let v = dir(&|m| m.shape[a]);
        out.push((format!("{}–ground", section.points[a]), cosine(&d, &v)));
    }
    out.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
    out
}

fn cosine(a: &[f64], b: &[f64]) -> f64 {
    let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let n = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let den = n(a) * n(b);
    if den > 0.0 {
        dot / den
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coupling_points_to_the_pair_whose_relative_motion_the_participations_follow() {
        let text = r#"
[modal]
points = ["exc", "wing", "payload"]
driving_point = "exc"
[[modal.mode]]
frequency_hz = 3.0
damping = 0.02
shape = [0.4, 0.3, 0.25]
[[modal.mode]]
frequency_hz = 5.0
damping = 0.01
shape = [0.3, -0.1, -0.3]
[[modal.mode]]
frequency_hz = 7.0
damping = 0.01
shape = [0.1, -0.4, 0.4]
"#;
        let t: toml::Table = text.parse().unwrap();
        let s: modal::ModalSection = t["modal"].clone().try_into().unwrap();
        // participations proportional to (φ_wing − φ_payload) / f
        let d: Vec<(f64, f64)> = s
            .modes
            .iter()
            .map(|m| {
                (
                    m.frequency_hz,
                    2.0 * (m.shape[1] - m.shape[2]) / m.frequency_hz,
                )
            })
            .collect();
        let c = coupling(&s, &d);
        assert_eq!(c[0].0, "wing–payload");
        approx::assert_relative_eq!(c[0].1, 1.0, epsilon = 1e-12);
        assert!(c[1].1.abs() < 0.99, "{c:?}");
        assert_eq!(c.len(), 6);
    }
}
