//! The interface fitted by open-loop output error over the steady-state
//! samples of one or more records: Levenberg–Marquardt on the logarithms
//! of the slip force, the Jenkins share, the density's exponent and the
//! elastic softening's share and bound (the participations linear).
//! The Jenkins element's slip state has no derivative recursion in the
//! integrator, so the Jacobian is taken by centered finite differences of
//! the simulation (step [`FitSpec::fd_step`] in the logarithm), one
//! simulation per perturbed parameter and side, in parallel.

use super::build::*;
use super::open_loop_errors;
use crate::error::{Result, TacitError};
use crate::model::{modal, Model};
use crate::record::Record;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rayon::prelude::*;
use serde::Serialize;

/// The fitted interface.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Fitted {
    /// Points joined (the interface coordinate and `ground` with
    /// [`Direction::Coordinate`]).
    pub points: [String; 2],
    /// With [`Direction::Coordinate`]: per non-residual mode, its
    /// frequency (Hz) and the interface's participation `δ_r` (fully
    /// slipped, that mode alone would keep `1 − δ_r²` of its ω²).
    pub participations: Vec<(f64, f64)>,
    /// Natural frequencies of the model stuck (the linear model), Hz.
    pub stuck_hz: Vec<f64>,
    /// Natural frequencies with every slider slipping and the softening
    /// saturated (the Jenkins and saturating springs removed), Hz.
    pub slipped_hz: Vec<f64>,
    /// The coupling spring of the identified model between the points of
    /// [`FitSpec::pair`], N/m.
    pub coupling: f64,
    /// Stuck stiffness of the Jenkins element(s), N/m (their sum).
    pub stiffness: f64,
    /// Slip force, N (the largest).
    pub slip_force: f64,
    /// Relative displacement at which the last slider slips from rest, m.
    pub slip_displacement: f64,
    /// Jenkins elements in parallel.
    pub elements: usize,
    /// The exponent of the slip-force density ([`FitSpec::spread`]).
    pub spread: f64,
    /// The elastic softening beside the slider ([`FitSpec::softening`]).
    pub softening: Option<Softening>,
    /// Its stiffness `k_e`, N/m (0 without).
    pub softening_stiffness: f64,
    /// The linear parameters fitted with it: (parameter, factor).
    pub modes: Vec<(ModeParam, f64)>,
    /// Records fitted on.
    pub records: Vec<String>,
    /// RMS of the weighted residual at the start and at the end.
    pub cost: (f64, f64),
    /// How the Levenberg–Marquardt search ended.
    pub termination: String,
    /// Simulations run.
    pub simulations: usize,
    /// Seconds.
    pub seconds: f64,
}

struct Problem<'a> {
    base: &'a modal::ModalSection,
    spec: &'a FitSpec,
    records: &'a [&'a Record],
    /// Per record: 1 / RMS of its measured outputs (steady state), so that
    /// every record weighs alike.
    weights: Vec<f64>,
    x: DVector<f64>,
    r: Option<DVector<f64>>,
    failure: std::sync::Mutex<Option<String>>,
    simulations: std::sync::atomic::AtomicUsize,
}

/// The parameters of [`Problem::model`] unpacked.
pub(super) struct Parts {
    /// Factors on the linear parameters of [`FitSpec::modes`].
    pub factors: Vec<f64>,
    /// The share of the coupling ([`Direction::Points`]) or the
    /// participations, scaled so that the model fully slipped (and
    /// saturated) stays stable: `|δ|² (1 + share_e) ≤ 0.95²`
    /// ([`Direction::Coordinate`]).
    pub middle: Vec<f64>,
    /// The elastic softening ([`FitSpec::softening`]).
    pub softening: Option<Softening>,
    /// The exponent of the slip-force density.
    pub spread: f64,
    /// The (largest) slip force, N.
    pub slip_force: f64,
}

/// `x = [ln factors..., ln share | δ..., (ln share_e, ln F_e), (ln p), ln F_s]`
/// ([`Direction::Points`] | [`Direction::Coordinate`], the `δ` absent when
/// [`FitSpec::hold_participations`]; `ln share_e, ln F_e` with
/// [`FitSpec::softening`]; `ln p` with [`FitSpec::fit_spread`] and several
/// elements).
pub(super) fn unpack(spec: &FitSpec, x: &[f64]) -> Parts {
    let nm = spec.modes.len();
    let n = x.len();
    let with_p = fits_spread(spec) as usize;
    let with_e = 2 * spec.softening.is_some() as usize;
    let end = n - 1 - with_p - with_e;
    let softening = spec.softening.map(|_| Softening {
        share: x[end].exp(),
        force: x[end + 1].exp(),
    });
    let middle = match spec.direction {
        Direction::Points => vec![x[nm].exp().min(1.0)],
        Direction::Coordinate => {
            let d = match (&spec.participations, spec.hold_participations) {
                (Some(p), true) => p.as_slice(),
                _ => &x[nm..end],
            };
            let grow = 1.0 + softening.map_or(0.0, |e| e.share);
            let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt() * grow.sqrt();
            let scale = if norm > 0.95 { 0.95 / norm } else { 1.0 };
            d.iter().map(|v| v * scale).collect()
        }
    };
    Parts {
        factors: x[..nm].iter().map(|v| v.exp()).collect(),
        middle,
        softening,
        spread: if with_p == 1 {
            x[n - 2].exp()
        } else {
            spec.spread
        },
        slip_force: x[n - 1].exp(),
    }
}

/// True when the exponent of the slip-force density is fitted.
pub(super) fn fits_spread(spec: &FitSpec) -> bool {
    spec.fit_spread && spec.elements > 1
}

/// The model at the parameters `x` ([`unpack`]).
pub(super) fn model_at(base: &modal::ModalSection, spec: &FitSpec, x: &[f64]) -> Result<Model> {
    let p = unpack(spec, x);
    let spec = FitSpec {
        spread: p.spread,
        softening: p.softening,
        ..spec.clone()
    };
    match spec.direction {
        Direction::Points => model_with(base, &spec, &p.factors, p.middle[0], p.slip_force),
        Direction::Coordinate => coordinate_model(base, &spec, &p.factors, &p.middle, p.slip_force),
    }
}

impl Problem<'_> {
    fn model(&self, x: &[f64]) -> Result<Model> {
        model_at(self.base, self.spec, x)
    }

    fn residual(&self, x: &[f64]) -> Result<DVector<f64>> {
        self.simulations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let m = self.model(x)?;
        let mut out = vec![];
        for (rec, w) in self.records.iter().zip(&self.weights) {
            let e = open_loop_errors(&m, rec, self.spec.warm_up, self.spec.substeps)?;
            out.extend(e.iter().flatten().map(|v| v * w));
        }
        Ok(DVector::from_vec(out))
    }

    fn note(&self, e: TacitError) {
        let mut f = self.failure.lock().unwrap_or_else(|p| p.into_inner());
        f.get_or_insert_with(|| e.to_string());
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
        let limit = self.spec.max_simulations;
        if self.simulations.load(std::sync::atomic::Ordering::Relaxed) >= limit {
            self.r = None;
            return;
        }
        self.r = match self.residual(x.as_slice()) {
            Ok(r) => Some(r),
            Err(e) => {
                self.note(e);
                None
            }
        };
    }
    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        self.r.clone()
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let h = self.spec.fd_step;
        let n = self.x.len();
        let cols: Vec<Option<DVector<f64>>> = (0..n)
            .into_par_iter()
            .map(|c| {
                let side = |s: f64| {
                    let mut x = self.x.clone();
                    x[c] += s * h;
                    self.residual(x.as_slice()).map_err(|e| self.note(e)).ok()
                };
                Some((side(1.0)? - side(-1.0)?) / (2.0 * h))
            })
            .collect();
        let cols: Option<Vec<DVector<f64>>> = cols.into_iter().collect();
        Some(DMatrix::from_columns(&cols?))
    }
}

/// Fit the Jenkins interface (and the linear parameters of `spec.modes`)
/// to `records` by open-loop output error; `base` is the Level-1 modal
/// section. Returns the fit and the model.
pub fn fit(
    base: &modal::ModalSection,
    records: &[&Record],
    spec: &FitSpec,
) -> Result<(Fitted, Model)> {
    spec.validate()?;
    let t = std::time::Instant::now();
    let weights = records
        .iter()
        .map(|r| {
            let ss: f64 = r
                .outputs
                .iter()
                .map(|c| crate::signal::rms_of(&c.data[spec.warm_up..]).powi(2))
                .sum();
            1.0 / (ss / r.outputs.len() as f64).sqrt()
        })
        .collect();
    let nm = spec.modes.len();
    let mut x0 = vec![0.0; nm];
    match spec.direction {
        Direction::Points => x0.push(spec.share.ln()),
        Direction::Coordinate if spec.hold_participations => {}
        Direction::Coordinate => match &spec.participations {
            Some(d) => x0.extend(d),
            None => x0.extend(pair_participations(base, spec)?),
        },
    }
    if let Some(e) = &spec.softening {
        x0.extend([e.share.ln(), e.force.ln()]);
    }
    if fits_spread(spec) {
        x0.push(spec.spread.ln());
    }
    x0.push(spec.slip_force.ln());
    let mut p = Problem {
        base,
        spec,
        records,
        weights,
        x: DVector::from_vec(x0.clone()),
        r: None,
        failure: Default::default(),
        simulations: Default::default(),
    };
    let r0 = p.residual(&x0)?;
    let n_res = r0.len() as f64;
    let cost0 = (r0.norm_squared() / n_res).sqrt();
    p.r = Some(r0);
    let (p, report) = LevenbergMarquardt::new()
        .with_tol(1e-6)
        .with_patience(spec.max_simulations / (2 * x0.len() + 1) + 1)
        .minimize(p);
    let x = p.x.as_slice().to_vec();
    let model = p.model(&x)?;
    let cost1 = (2.0 * report.objective_function / n_res).sqrt();
    let failure = p.failure.lock().map(|f| f.clone()).unwrap_or(None);
    let termination = match failure {
        Some(f) if !report.termination.was_successful() => {
            format!("{:?} ({f})", report.termination)
        }
        _ => format!("{:?}", report.termination),
    };
    let mut fitted = describe(&model, base, spec, &x)?;
    fitted.records = records
        .iter()
        .map(|r| r.source.display().to_string())
        .collect();
    fitted.cost = (cost0, cost1);
    fitted.termination = termination;
    fitted.simulations = p.simulations.into_inner();
    fitted.seconds = t.elapsed().as_secs_f64();
    Ok((fitted, model))
}

/// The fitted interface's parameters and modes (`x` as [`unpack`]
/// takes it); the fit's record, cost and counts are left empty.
pub(super) fn describe(
    model: &Model,
    base: &modal::ModalSection,
    spec: &FitSpec,
    x: &[f64],
) -> Result<Fitted> {
    let j = model
        .jenkins
        .last()
        .ok_or_else(|| TacitError::Numerical("no Jenkins element in the fitted model".into()))?;
    let k_j: f64 = model.jenkins.iter().map(|j| j.stiffness).sum();
    let name = |d: usize| model.dof_name(d);
    let parts = unpack(spec, x);
    let (points, coupling, participations) = match spec.direction {
        Direction::Points => {
            let s = &model.springs[coupling_index(model, spec.pair)?];
            (spec.pair.map(name), s.stiffness + k_j, vec![])
        }
        Direction::Coordinate => {
            let hz = base.modes.iter().filter(|m| !m.residual);
            let p = hz.zip(&parts.middle).map(|(m, &d)| (m.frequency_hz, d));
            let pts = [INTERFACE.to_string(), "ground".to_string()];
            (pts, k_j / spec.share, p.collect())
        }
    };
    let mut stuck = model.stiffness_matrix();
    let ends = |d: &[usize]| (d[0] - 1, d.get(1).map(|d| d - 1));
    for e in &model.jenkins {
        crate::model::add_spring(&mut stuck, ends(&e.dofs), e.stiffness);
    }
    for e in &model.saturating {
        crate::model::add_spring(&mut stuck, ends(&e.dofs), e.stiffness);
    }
    let mass = model.mass_matrix();
    Ok(Fitted {
        points,
        participations,
        stuck_hz: crate::modal::solve(&mass, &stuck)?.freq_hz,
        slipped_hz: crate::modal::solve(&mass, &model.stiffness_matrix())?.freq_hz,
        coupling,
        stiffness: k_j,
        slip_force: j.slip_force,
        slip_displacement: j.slip_force / j.stiffness,
        elements: model.jenkins.len(),
        spread: parts.spread,
        softening: parts.softening,
        softening_stiffness: model.saturating.iter().map(|e| e.stiffness).sum(),
        modes: spec
            .modes
            .iter()
            .zip(x)
            .map(|(m, v)| (*m, v.exp()))
            .collect(),
        ..Default::default()
    })
}
