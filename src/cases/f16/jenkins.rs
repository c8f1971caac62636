//! The F-16 interface as stick–slip friction: a Jenkins element (a spring
//! in series with a Coulomb slider, [`crate::model::Jenkins`]) between the
//! wing and payload points that takes over part `k_J` of the Level-1
//! model's coupling spring between them. While the slider sticks the model
//! *is* the Level-1 model (the coupling is `k_J` through the Jenkins element
//! plus the rest of the spring; the damping matrix is held at the Level-1
//! model's); once the interface force exceeds the slip force `F_s` the
//! coupling softens by `k_J` and the slider dissipates (`docs/f16.md`).
//!
//! Or the element acts on the interface as a coordinate of its own
//! ([`Direction::Coordinate`], [`coordinate_model`]): an unmeasured point
//! of the modal model whose displacement in each in-band mode (the
//! interface's participation in that mode) is fitted, so that the slip
//! softens and damps each mode by as much as the test shows rather than in
//! proportion to the relative displacement of two measured points.
//!
//! The fit is by open-loop output error over the steady-state periods of
//! one or more records (Levenberg–Marquardt on the logarithms of the
//! parameters). The Jenkins element's slip state has no derivative
//! recursion in the integrator, so the Jacobian is taken by centered
//! finite differences of the simulation (step [`FitSpec::fd_step`] in the
//! logarithm), one simulation per perturbed parameter and side.

use super::{simulate_errors, POINTS};
use crate::error::{Result, TacitError};
use crate::model::{modal, Jenkins, Model};
use crate::record::Record;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rayon::prelude::*;
use serde::Serialize;
use std::f64::consts::PI;
use std::sync::Arc;

/// A linear-part parameter fitted with the interface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ModeParam {
    /// The natural frequency of the (non-residual) mode nearest this
    /// frequency, Hz.
    Frequency(f64),
    /// The damping ratio of the mode nearest this frequency, Hz.
    Damping(f64),
}

/// Where the Jenkins element acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Between the two points of [`FitSpec::pair`], taking `k_J` out of
    /// their coupling spring ([`model_with`]); fitted: `k_J` and `F_s`.
    Points,
    /// From the interface coordinate to ground ([`coordinate_model`]): an
    /// unmeasured point whose modal displacements (the interface's
    /// participation in each non-residual mode) are fitted with `F_s`,
    /// starting from the relative displacement of [`FitSpec::pair`] in
    /// those modes.
    Coordinate,
}

/// What [`fit`] fits.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitSpec {
    /// Where the Jenkins element acts.
    pub direction: Direction,
    /// The two points the Jenkins element joins (DOFs from 1); with
    /// [`Direction::Coordinate`], the pair whose relative displacement
    /// the interface coordinate starts from and whose coupling sets `k_J`.
    pub pair: [usize; 2],
    /// Start of the share of the coupling spring taken by the Jenkins
    /// element, `k_J / k_coupling` (in (0, 1]).
    pub share: f64,
    /// Start of the slip force, N (with several elements, the largest).
    pub slip_force: f64,
    /// Jenkins elements in parallel (1: one Jenkins element; `n > 1`: an
    /// Iwan model, `n` elements of stiffness `k_J / n` each and slip forces
    /// `F_s i / n`, `i = 1..n`, a uniform density of slip forces up to
    /// `F_s`: the interface slips gradually, microslip before macroslip).
    pub elements: usize,
    /// Linear parameters fitted with the interface (empty: the Level-1
    /// linear part held).
    pub modes: Vec<ModeParam>,
    /// Factor on the frequency of the residual mode above the band, its
    /// shape scaled by the same factor so that its flexibility at the
    /// points (shape² / ω²) is unchanged (1: as identified).
    pub upper_residual_factor: f64,
    /// Damping ratio of the residual mode above the band (None: as
    /// identified). The residual mode stands for a quasi-static
    /// flexibility; its own resonance is not a mode of the structure.
    pub upper_residual_damping: Option<f64>,
    /// Step of the centered differences in the logarithm of a parameter.
    pub fd_step: f64,
    /// Limit on the simulations of the fit.
    pub max_simulations: usize,
    /// Sub-steps per sample of the simulations.
    pub substeps: usize,
    /// Samples not scored at the start of every record.
    pub warm_up: usize,
}

impl FitSpec {
    /// Check the settings.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(TacitError::Setting(format!("F-16 Jenkins fit: {m}")));
        if !(self.share > 0.0 && self.share <= 1.0) {
            return bad(format!("share {} must be in (0, 1]", self.share));
        }
        if !(self.slip_force > 0.0 && self.slip_force.is_finite()) {
            return bad(format!("slip force {} must be > 0", self.slip_force));
        }
        if !(self.upper_residual_factor >= 1.0 && self.upper_residual_factor.is_finite()) {
            return bad(format!(
                "upper residual factor {} must be >= 1",
                self.upper_residual_factor
            ));
        }
        if !(self.fd_step > 0.0 && self.fd_step < 0.1) {
            return bad(format!("fd_step {} must be in (0, 0.1)", self.fd_step));
        }
        if self.substeps == 0 || self.max_simulations == 0 || self.elements == 0 {
            return bad("substeps, elements and max_simulations must be > 0".into());
        }
        Ok(())
    }
}

/// The model with the Jenkins element: `base`'s modal section with the
/// linear parameters `x_modes` applied (factors on the frequency or the
/// damping ratio of the chosen modes), the damping matrix of that linear
/// model held, and the Jenkins element `(k_J, F_s)` taking `k_J` out of
/// the coupling spring of `pair`.
pub fn model_with(
    base: &modal::ModalSection,
    spec: &FitSpec,
    factors: &[f64],
    k_j_share: f64,
    slip_force: f64,
) -> Result<Model> {
    let section = linear_section(base, spec, factors)?;
    let mut m = held_model(&section)?;
    let pair = spec.pair;
    let s = coupling_index(&m, pair)?;
    let k_c = m.springs[s].stiffness;
    let k_j = k_j_share * k_c;
    m.springs[s].stiffness = k_c - k_j;
    push_jenkins(&mut m, spec, pair.to_vec(), k_j, slip_force);
    Ok(m)
}

/// `n` Jenkins elements of stiffness `k_j / n` and slip forces
/// `F_s i / n` on `dofs` (one: a single Jenkins element).
fn push_jenkins(m: &mut Model, spec: &FitSpec, dofs: Vec<usize>, k_j: f64, slip_force: f64) {
    let n = spec.elements.max(1);
    for i in 1..=n {
        m.jenkins.push(Jenkins {
            dofs: dofs.clone(),
            stiffness: k_j / n as f64,
            slip_force: slip_force * i as f64 / n as f64,
        });
    }
}

/// `base` with the residual mode above the band and the factors of
/// `spec.modes` applied.
fn linear_section(
    base: &modal::ModalSection,
    spec: &FitSpec,
    factors: &[f64],
) -> Result<modal::ModalSection> {
    let mut section = base.clone();
    let top = section
        .modes
        .iter()
        .map(|m| m.frequency_hz)
        .fold(0.0, f64::max);
    for m in section.modes.iter_mut() {
        if m.residual && m.frequency_hz == top {
            m.frequency_hz *= spec.upper_residual_factor;
            m.shape
                .iter_mut()
                .for_each(|v| *v *= spec.upper_residual_factor);
            if let Some(z) = spec.upper_residual_damping {
                m.damping = z;
            }
        }
    }
    for (p, &f) in spec.modes.iter().zip(factors) {
        let (hz, freq) = match *p {
            ModeParam::Frequency(hz) => (hz, true),
            ModeParam::Damping(hz) => (hz, false),
        };
        let r = nearest_mode(&section, hz)?;
        if freq {
            section.modes[r].frequency_hz *= f;
        } else {
            section.modes[r].damping *= f;
        }
    }
    Ok(section)
}

/// The dense model of `section` with its modal damping matrix held as a
/// matrix (so that splitting a stiffness does not change it).
fn held_model(section: &modal::ModalSection) -> Result<Model> {
    let text = modal::to_toml_string("f16-jenkins", "F-16 GVT, Jenkins interface", section);
    let mut m = modal::from_toml_str(&text, "f16-jenkins")?;
    let c = m.damping_matrix()?;
    let mut lin = m
        .matrices
        .as_deref()
        .cloned()
        .ok_or_else(|| TacitError::Numerical("the modal model has no matrices".into()))?;
    lin.c = Some(c);
    m.matrices = Some(Arc::new(lin));
    m.damping = crate::model::Damping::None;
    Ok(m)
}

/// Index in `m.springs` of the coupling spring between the two points.
fn coupling_index(m: &Model, pair: [usize; 2]) -> Result<usize> {
    m.springs
        .iter()
        .position(|s| s.dofs.len() == 2 && s.dofs.contains(&pair[0]) && s.dofs.contains(&pair[1]))
        .ok_or_else(|| {
            TacitError::Numerical(format!(
                "the model has no coupling spring between {} and {}",
                m.dof_name(pair[0]),
                m.dof_name(pair[1])
            ))
        })
}

/// Label of the unmeasured point that is the interface's slip coordinate
/// ([`Direction::Coordinate`]).
pub const INTERFACE: &str = "interface";

/// The Level-1 coupling spring between the points of `spec.pair` (N/m)
/// times `spec.share`: the stuck stiffness `k_J` of the Jenkins element on
/// the interface coordinate.
pub fn coordinate_stiffness(base: &modal::ModalSection, spec: &FitSpec) -> Result<f64> {
    let m = held_model(base)?;
    Ok(spec.share * m.springs[coupling_index(&m, spec.pair)?].stiffness)
}

/// The interface's participation `δ_r` in each non-residual mode of `base`
/// (in the section's order) when the interface coordinate is the relative
/// displacement of `spec.pair` restricted to those modes:
/// `δ_r = √k_J (φ_a,r − φ_b,r) / ω_r`.
pub fn pair_participations(base: &modal::ModalSection, spec: &FitSpec) -> Result<Vec<f64>> {
    let k_j = coordinate_stiffness(base, spec)?;
    let [a, b] = spec.pair.map(|d| d - 1);
    Ok(base
        .modes
        .iter()
        .filter(|m| !m.residual)
        .map(|m| k_j.sqrt() * (m.shape[a] - m.shape[b]) / (2.0 * PI * m.frequency_hz))
        .collect())
}

/// The model with the interface as a coordinate of its own: `base` (with
/// `factors`, [`linear_section`]) gains the unmeasured point
/// [`INTERFACE`] whose displacement in mode `r` is
/// `g_r = δ_r ω_r / √k_J` for the non-residual modes (`deltas`, in the
/// section's order) and 0 for the residual modes; a Jenkins element
/// `(k_J, F_s)` acts from it to ground, and `k_J` is taken out of the
/// linear stiffness of that coordinate, so that stuck the model is the
/// linear model and fully slipped the stiffness of the modes loses
/// `k_J g gᵀ` (mode `r` alone: `ω_r² (1 − δ_r²)`). `k_J` is
/// [`coordinate_stiffness`]; it only sets the coordinate's scale.
pub fn coordinate_model(
    base: &modal::ModalSection,
    spec: &FitSpec,
    factors: &[f64],
    deltas: &[f64],
    slip_force: f64,
) -> Result<Model> {
    let k_j = coordinate_stiffness(base, spec)?;
    let mut section = linear_section(base, spec, factors)?;
    let free = section.modes.iter().filter(|m| !m.residual).count();
    if deltas.len() != free {
        return Err(TacitError::Setting(format!(
            "F-16 interface coordinate: {} participations for {free} modes",
            deltas.len()
        )));
    }
    section.points.push(INTERFACE.into());
    let mut d = deltas.iter();
    for m in section.modes.iter_mut() {
        let g = match m.residual {
            true => 0.0,
            false => d.next().copied().unwrap_or(0.0) * 2.0 * PI * m.frequency_hz / k_j.sqrt(),
        };
        m.shape.push(g);
    }
    if !section.dofs.is_empty() {
        let next = section.dofs.iter().max().copied().unwrap_or(0) + 1;
        section.dofs.push(next);
    }
    let mut m = held_model(&section)?;
    let s = m.points.len();
    let mut lin = m
        .matrices
        .as_deref()
        .cloned()
        .ok_or_else(|| TacitError::Numerical("the modal model has no matrices".into()))?;
    lin.k_rest[(s - 1, s - 1)] -= k_j;
    m.matrices = Some(Arc::new(lin));
    push_jenkins(&mut m, spec, vec![s], k_j, slip_force);
    Ok(m)
}

/// Index of the non-residual mode nearest `hz`.
fn nearest_mode(section: &modal::ModalSection, hz: f64) -> Result<usize> {
    (0..section.modes.len())
        .filter(|&r| !section.modes[r].residual)
        .min_by(|&a, &b| {
            let d = |r: usize| (section.modes[r].frequency_hz - hz).abs();
            d(a).total_cmp(&d(b))
        })
        .ok_or_else(|| TacitError::Numerical("the modal model has no mode".into()))
}

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
    /// Natural frequencies with every slider slipping (the Jenkins
    /// springs removed), Hz.
    pub slipped_hz: Vec<f64>,
    /// The coupling spring of the Level-1 model, N/m.
    pub coupling: f64,
    /// Stuck stiffness of the Jenkins element(s), N/m (their sum).
    pub stiffness: f64,
    /// Slip force, N (the largest).
    pub slip_force: f64,
    /// Relative displacement at which the (last) slider slips, m.
    pub slip_displacement: f64,
    /// Jenkins elements in parallel.
    pub elements: usize,
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

impl Problem<'_> {
    /// `x = [ln factors..., ln share, ln F_s]` ([`Direction::Points`]) or
    /// `[ln factors..., δ..., ln F_s]` ([`Direction::Coordinate`]; `δ`
    /// scaled into `|δ| ≤ 0.95`, so that the slipped model stays stable).
    fn model(&self, x: &[f64]) -> Result<Model> {
        let nm = self.spec.modes.len();
        let f: Vec<f64> = x[..nm].iter().map(|v| v.exp()).collect();
        let fs = x[x.len() - 1].exp();
        match self.spec.direction {
            Direction::Points => model_with(self.base, self.spec, &f, x[nm].exp().min(1.0), fs),
            Direction::Coordinate => {
                let d = &x[nm..x.len() - 1];
                let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt();
                let scale = if norm > 0.95 { 0.95 / norm } else { 1.0 };
                let d: Vec<f64> = d.iter().map(|v| v * scale).collect();
                coordinate_model(self.base, self.spec, &f, &d, fs)
            }
        }
    }

    fn residual(&self, x: &[f64]) -> Result<DVector<f64>> {
        self.simulations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let m = self.model(x)?;
        let mut out = vec![];
        for (rec, w) in self.records.iter().zip(&self.weights) {
            let e = simulate_errors(&m, rec, self.spec.warm_up, self.spec.substeps)?;
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
        Direction::Coordinate => x0.extend(pair_participations(base, spec)?),
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

/// The fitted interface's parameters and modes (`x` as [`Problem::model`]
/// takes it); the fit's record, cost and counts are left empty.
fn describe(
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
    let name = |d: usize| POINTS.get(d - 1).map_or(d.to_string(), |s| s.to_string());
    let (points, coupling, participations) = match spec.direction {
        Direction::Points => {
            let s = &model.springs[coupling_index(model, spec.pair)?];
            (spec.pair.map(name), s.stiffness + k_j, vec![])
        }
        Direction::Coordinate => {
            let nm = spec.modes.len();
            let hz = base.modes.iter().filter(|m| !m.residual);
            let p = hz
                .zip(&x[nm..x.len() - 1])
                .map(|(m, &d)| (m.frequency_hz, d));
            let pts = [INTERFACE.to_string(), "ground".to_string()];
            (pts, k_j / spec.share, p.collect())
        }
    };
    let mut stuck = model.stiffness_matrix();
    for e in &model.jenkins {
        let ends = (e.dofs[0] - 1, e.dofs.get(1).map(|d| d - 1));
        crate::model::add_spring(&mut stuck, ends, e.stiffness);
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
        slip_displacement: j.slip_force / k_j,
        elements: model.jenkins.len(),
        modes: spec
            .modes
            .iter()
            .zip(x)
            .map(|(m, v)| (*m, v.exp()))
            .collect(),
        ..Default::default()
    })
}

/// The Jenkins interface fitted and scored ([`study`]).
#[derive(Debug, Clone, Serialize)]
pub struct Study {
    /// The fit's settings.
    pub spec: FitSpec,
    /// The fitted interface.
    pub fitted: Fitted,
    /// With [`Direction::Coordinate`]: the Jenkins element between the
    /// points of the pair, fitted first (its `k_J` and `F_s` start the
    /// interface coordinate's fit).
    pub pair: Option<Fitted>,
    /// The Level-1 model, the modal model re-identified on the estimation
    /// record (linear, for reference), the pair's Jenkins model (with
    /// [`Direction::Coordinate`]) and the fitted model on every record:
    /// RMS per channel and per band ([`super::BANDS_HZ`]).
    pub scores: Vec<super::Scored>,
}

/// Fit the Jenkins interface ([`fit`]) on the linear (Level-1) record and
/// the estimation record together, with the Level-1 modal model, and score
/// it with the Level-1 model and the estimation record's re-identified
/// modal model on `records`. With [`Direction::Coordinate`] the element
/// between the points of the pair is fitted first and starts the
/// interface coordinate's fit. Returns the study and the Jenkins model.
pub fn study(
    linear: &std::path::Path,
    estimate: &std::path::Path,
    records: &[&std::path::Path],
    spec: &FitSpec,
    s: &super::Settings,
) -> Result<(Study, Model)> {
    let lin = super::read(linear)?;
    let (fit1, text1) = super::linear_model(&lin, s)?;
    let l1 = modal::from_toml_str(&text1, "f16-linear")?;
    let load = |p: &std::path::Path| -> Result<Record> {
        let mut r = super::read(p)?;
        l1.resolve_channels(&mut r)?;
        Ok(r)
    };
    let (r1, est) = (load(linear)?, load(estimate)?);
    let pair_spec = FitSpec {
        direction: Direction::Points,
        max_simulations: spec.max_simulations.min(60),
        ..spec.clone()
    };
    let (pair_fit, pair_model) = fit(&fit1.section, &[&r1, &est], &pair_spec)?;
    let (fitted, model, pair) = match spec.direction {
        Direction::Points => (pair_fit, pair_model.clone(), None),
        Direction::Coordinate => {
            let from_pair = FitSpec {
                share: pair_fit.stiffness / pair_fit.coupling,
                slip_force: pair_fit.slip_force,
                ..spec.clone()
            };
            let (f, m) = fit(&fit1.section, &[&r1, &est], &from_pair)?;
            (f, m, Some(pair_fit))
        }
    };
    let (_, text7) = super::linear_model(&est, s)?;
    let l7 = modal::from_toml_str(&text7, "f16-calibrated")?;
    let recs = records
        .iter()
        .map(|p| load(p))
        .collect::<Result<Vec<_>>>()?;
    let refs: Vec<&Record> = recs.iter().collect();
    let mut models = vec![
        ("level-1 model", &l1),
        ("re-identified at the estimation level", &l7),
    ];
    if pair.is_some() {
        models.push(("jenkins between the pair", &pair_model));
    }
    models.push(("jenkins interface", &model));
    let scores = super::score(&models, &refs, s.warm_up, s.substeps)?;
    let st = Study {
        spec: spec.clone(),
        fitted,
        pair,
        scores,
    };
    Ok((st, model))
}

impl Default for FitSpec {
    fn default() -> Self {
        FitSpec {
            direction: Direction::Points,
            pair: [2, 3],
            share: 0.5,
            slip_force: 50.0,
            elements: 1,
            upper_residual_factor: 1.0,
            upper_residual_damping: Some(0.3),
            modes: vec![],
            fd_step: 1e-3,
            max_simulations: 60,
            substeps: 10,
            warm_up: 8192,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section() -> modal::ModalSection {
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
        t["modal"].clone().try_into().unwrap()
    }

    #[test]
    fn stuck_jenkins_model_has_the_linear_models_matrices() {
        let s = section();
        let spec = FitSpec {
            direction: Direction::Points,
            pair: [2, 3],
            share: 0.5,
            slip_force: 1.0,
            elements: 1,
            upper_residual_factor: 1.0,
            upper_residual_damping: None,
            modes: vec![],
            fd_step: 1e-3,
            max_simulations: 10,
            substeps: 4,
            warm_up: 0,
        };
        let text = modal::to_toml_string("x", "x", &s);
        let lin = modal::from_toml_str(&text, "x").unwrap();
        let m = model_with(&s, &spec, &[], 0.5, 1.0).unwrap();
        // the coupling spring split: linear rest + stuck Jenkins = L1's
        let mut k = m.stiffness_matrix();
        let j = &m.jenkins[0];
        crate::model::add_spring(&mut k, (1, Some(2)), j.stiffness);
        let k1 = lin.stiffness_matrix();
        assert!((k - &k1).abs().max() < 1e-9 * k1.abs().max());
        let c = m.damping_matrix().unwrap();
        let c1 = lin.damping_matrix().unwrap();
        assert!((c - &c1).abs().max() < 1e-9 * c1.abs().max());
        assert!(j.stiffness > 0.0);
    }

    #[test]
    fn interface_coordinate_softens_only_the_modes_it_strains() {
        let mut s = section();
        s.modes.push(modal::ModalMode {
            frequency_hz: 30.0,
            damping: 0.05,
            shape: vec![0.2, 0.1, -0.3],
            residual: true,
        });
        // a pair the linear model couples by a spring
        let d = &held_model(&s).unwrap().springs[0].dofs;
        let spec = FitSpec {
            direction: Direction::Coordinate,
            pair: [d[0], d[1]],
            upper_residual_damping: None,
            ..Default::default()
        };
        // the 7-Hz mode alone: fully slipped it keeps 1 − δ² of its ω²
        let m = coordinate_model(&s, &spec, &[], &[0.0, 0.0, 0.6], 1.0).unwrap();
        assert_eq!(m.points, ["exc", "wing", "payload", INTERFACE]);
        assert_eq!(m.jenkins[0].dofs, [4]);
        let f = describe(&m, &s, &spec, &[0.0, 0.0, 0.6, 0.0]).unwrap();
        let want = [3.0, 5.0, 7.0, 30.0];
        for (got, w) in f.stuck_hz.iter().zip(want) {
            assert!((got - w).abs() < 1e-7 * w, "stuck {:?}", f.stuck_hz);
        }
        let slipped = [3.0, 5.0, 7.0 * 0.8, 30.0];
        let mut got = f.slipped_hz.clone();
        got.sort_by(f64::total_cmp);
        for (g, w) in got.iter().zip(slipped) {
            assert!((g - w).abs() < 1e-7 * w, "slipped {:?}", f.slipped_hz);
        }
        // the stuck model's damping is modal with the section's ratios
        let mut k = m.stiffness_matrix();
        crate::model::add_spring(&mut k, (3, None), m.jenkins[0].stiffness);
        let modes = crate::modal::solve(&m.mass_matrix(), &k).unwrap();
        let c = m.damping_matrix().unwrap();
        let mc = modes.shapes.transpose() * c * &modes.shapes;
        for (r, z) in [0.02, 0.01, 0.01, 0.05].iter().enumerate() {
            let w = modes.omega[r];
            assert!(
                (mc[(r, r)] - 2.0 * z * w).abs() < 1e-7 * w,
                "mode {r}: {}",
                mc[(r, r)]
            );
        }
        // participations of the pair's relative displacement: all modes
        let d = pair_participations(&s, &spec).unwrap();
        assert_eq!(d.len(), 3);
        assert!(d.iter().all(|v| v.abs() > 0.0));
    }
}
