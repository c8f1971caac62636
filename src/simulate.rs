//! Simulated records: run a model under an input and sample the measured
//! channels, with noise, keeping the truth (every DOF's u, v, a and
//! internal force, and the model) beside them.

use crate::error::{Result, TacitError};
use crate::integrate::{Integrator, SimSettings, SimStatus, Simulation};
use crate::model::Model;
use crate::record::{Channel, Quantity, Record, Truth};
use crate::signal;
use nalgebra::DMatrix;

/// The input force.
#[derive(Debug, Clone, PartialEq)]
pub enum InputSpec {
    /// Band-limited Gaussian random force ([`signal::random_band`]).
    Random {
        /// Band, Hz.
        band: (f64, f64),
        /// RMS, N.
        rms: f64,
    },
    /// Linear sine sweep.
    Sweep {
        /// Start frequency, Hz.
        f0: f64,
        /// End frequency, Hz.
        f1: f64,
        /// Amplitude, N.
        amplitude: f64,
    },
    /// Half-sine impulse.
    Impulse {
        /// Peak, N.
        amplitude: f64,
        /// Duration in samples.
        width: usize,
    },
    /// Given force history at the input DOF.
    Given(Vec<f64>),
    /// No force (free response from the initial state).
    None,
}

/// What to simulate and what to record.
#[derive(Debug, Clone)]
pub struct RecordSpec {
    /// Sample rate, Hz.
    pub fs: f64,
    /// Number of samples.
    pub samples: usize,
    /// DOF (from 1) where the input force acts.
    pub input_dof: usize,
    /// The input.
    pub input: InputSpec,
    /// Sensor DOFs (from 1).
    pub sensors: Vec<usize>,
    /// Quantities measured at every sensor.
    pub kinds: Vec<Quantity>,
    /// Noise standard deviation as a fraction of each channel's RMS.
    pub noise: f64,
    /// Seed of the input and the noise.
    pub seed: u64,
    /// Integrator settings.
    pub settings: SimSettings,
    /// Initial displacement (zeros when empty).
    pub u0: Vec<f64>,
    /// Initial velocity (zeros when empty).
    pub v0: Vec<f64>,
}

impl Default for RecordSpec {
    fn default() -> Self {
        RecordSpec {
            fs: 512.0,
            samples: 4096,
            input_dof: 1,
            input: InputSpec::Random {
                band: (5.0, 200.0),
                rms: 20.0,
            },
            sensors: vec![],
            kinds: vec![Quantity::Accel],
            noise: 0.0,
            seed: 7,
            settings: SimSettings::default(),
            u0: vec![],
            v0: vec![],
        }
    }
}

/// Build the input force history of a spec.
pub fn input_history(spec: &RecordSpec) -> Result<Vec<f64>> {
    let n = spec.samples;
    match &spec.input {
        InputSpec::Random { band, rms } => signal::random_band(n, spec.fs, *band, *rms, spec.seed),
        InputSpec::Sweep { f0, f1, amplitude } => {
            signal::sine_sweep(n, spec.fs, *f0, *f1, *amplitude)
        }
        InputSpec::Impulse { amplitude, width } => signal::impulse(n, *amplitude, *width),
        InputSpec::Given(x) => {
            if x.len() < n {
                return Err(TacitError::Setting(format!(
                    "the given input has {} samples, {} requested",
                    x.len(),
                    n
                )));
            }
            Ok(x[..n].to_vec())
        }
        InputSpec::None => Ok(vec![0.0; n]),
    }
}

/// Sub-steps at which a record of `model` at `fs` Hz stands for the
/// continuous structure: ω h ≤ [`CONTINUOUS_OMEGA_H`] for the stiffest
/// spring, contact or clearance (`k Σ 1/m`) and, given the displacements
/// `u` (DOF × sample) of a first run, for a cubic or quadratic spring's
/// tangent at its largest stroke; at least [`CONTINUOUS_MIN`], at most
/// [`crate::integrate::newmark::MAX_SUBSTEPS`].
pub fn continuous_substeps(model: &Model, fs: f64, u: Option<&DMatrix<f64>>) -> usize {
    continuous_need(model, fs, u).min(crate::integrate::newmark::MAX_SUBSTEPS)
}

/// [`continuous_substeps`] without its upper bound: what the stiffest
/// element asks for.
pub fn continuous_need(model: &Model, fs: f64, u: Option<&DMatrix<f64>>) -> usize {
    crate::diagnose::auto_substeps(model, fs, CONTINUOUS_MIN, CONTINUOUS_OMEGA_H, usize::MAX, u)
}

/// Target ω h of [`continuous_substeps`]: a period error `(ω h)²/12` of
/// 3e-5.
pub const CONTINUOUS_OMEGA_H: f64 = 0.02;

/// Fewest sub-steps of [`continuous_substeps`]: 0.05 % of integration
/// error on the LANL testbed's linear model at 512 Hz, against 4.8 % at
/// 10 (docs/diagnose.md, *Integration error and noise*).
pub const CONTINUOUS_MIN: usize = 100;

/// [`simulate_record`] at [`continuous_substeps`] (`spec.settings.substeps`
/// ignored): a first run at the sub-steps of the springs, contacts and
/// clearances, a second one when a cubic or quadratic spring's tangent at
/// the strokes of the first asks for more.
pub fn simulate_continuous(model: &Model, spec: &RecordSpec) -> Result<(Record, Simulation)> {
    let mut spec = spec.clone();
    spec.settings.substeps = continuous_substeps(model, spec.fs, None);
    let (rec, sim) = simulate_record(model, &spec)?;
    let more = continuous_substeps(model, spec.fs, Some(&sim.u));
    if more <= spec.settings.substeps {
        return Ok((rec, sim));
    }
    spec.settings.substeps = more;
    simulate_record(model, &spec)
}

/// Simulate and sample a record. The simulation is returned too: when it
/// did not complete (`sim.status`), the record is not built and the error
/// says when and why.
pub fn simulate_record(model: &Model, spec: &RecordSpec) -> Result<(Record, Simulation)> {
    let n = model.ndof();
    if spec.samples < 2 {
        return Err(TacitError::Setting(
            "a record needs at least 2 samples".into(),
        ));
    }
    for &d in spec.sensors.iter().chain(std::iter::once(&spec.input_dof)) {
        if d < 1 || d > n {
            return Err(TacitError::Setting(format!(
                "DOF {d} is outside the model (1..={n})"
            )));
        }
    }
    if !(spec.noise >= 0.0 && spec.noise.is_finite()) {
        return Err(TacitError::Setting(format!(
            "noise {} must be >= 0",
            spec.noise
        )));
    }
    let fin = input_history(spec)?;
    let mut force = DMatrix::zeros(n, spec.samples);
    for (k, v) in fin.iter().enumerate() {
        force[(spec.input_dof - 1, k)] = *v;
    }
    let integ = Integrator::new(model, spec.fs, spec.settings)?;
    let zeros = vec![0.0; n];
    let u0 = if spec.u0.is_empty() { &zeros } else { &spec.u0 };
    let v0 = if spec.v0.is_empty() { &zeros } else { &spec.v0 };
    if u0.len() != n || v0.len() != n {
        return Err(TacitError::Setting(format!(
            "initial state has {} / {} values, the model {n} DOFs",
            u0.len(),
            v0.len()
        )));
    }
    let sim = integ.run(force.as_view(), u0, v0);
    check_run(model, &integ, force.as_view(), &sim)?;
    let mut g = signal::rng(spec.seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut outputs = Vec::new();
    for &kind in &spec.kinds {
        let src = match kind {
            Quantity::Disp => &sim.u,
            Quantity::Vel => &sim.v,
            Quantity::Accel => &sim.a,
            Quantity::Force => {
                return Err(TacitError::Setting("a sensor cannot measure force".into()))
            }
        };
        for &d in &spec.sensors {
            let mut data: Vec<f64> = src.row(d - 1).iter().copied().collect();
            signal::add_noise(&mut data, spec.noise, &mut g);
            outputs.push(Channel::new(kind, d, data));
        }
    }
    let rows = |m: &DMatrix<f64>| -> Vec<Vec<f64>> {
        (0..n).map(|i| m.row(i).iter().copied().collect()).collect()
    };
    let rec = Record {
        t0: 0.0,
        fs: spec.fs,
        inputs: vec![Channel::new(Quantity::Force, spec.input_dof, fin)],
        outputs,
        truth: Some(Truth {
            u: rows(&sim.u),
            v: rows(&sim.v),
            a: rows(&sim.a),
            fint: rows(&sim.fint),
            model_toml: model.to_toml_string(),
        }),
        source: Default::default(),
    };
    Ok((rec, sim))
}

/// An error with the facts when `sim` stopped early or diverged (its
/// energy above what the force can put in: [`Integrator::divergence`]).
pub fn check_run(
    model: &Model,
    integ: &Integrator,
    force: nalgebra::DMatrixView<'_, f64>,
    sim: &Simulation,
) -> Result<()> {
    if !sim.completed() {
        let step = match sim.status {
            SimStatus::NonFinite { .. } => format!("; {}", integ.describe_step()),
            _ => String::new(),
        };
        return Err(TacitError::Numerical(format!(
            "simulation of {} stopped: {}{step}",
            model.name,
            describe_status(&sim.status)
        )));
    }
    match integ.divergence(force, sim) {
        None => Ok(()),
        Some(d) => Err(TacitError::Numerical(format!(
            "simulation of {} diverged from sample {} (t = {:.6} s) on: its energy is {:.3e} times what the force can put in (DOF {} at {:.3e} m/s^2); {}",
            model.name,
            d.sample,
            d.sample as f64 * integ.substep() * integ.settings().substeps as f64,
            d.growth.powi(2),
            d.dof,
            d.accel,
            integ.describe_step()
        ))),
    }
}

/// How a simulation ended, in words with its facts.
pub fn describe_status(status: &SimStatus) -> String {
    match status {
        SimStatus::Completed => "completed".into(),
        SimStatus::NewtonFailed {
            time,
            sample,
            iterations,
            residual,
        } => format!(
            "the Newton iterations did not converge at t = {time:.6} s (after sample {sample}; {iterations} iterations, residual {residual:.3e} N); more sub-steps may resolve the element"
        ),
        SimStatus::NonFinite { time, sample } => format!(
            "the state became non-finite at t = {time:.6} s (after sample {sample}): the model or the step is unstable"
        ),
    }
}
