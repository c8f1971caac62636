//! Simulated modal tests of a model, and identification of their modes:
//! the test data of the paper's §2–4 built from the LANL 8-DOF testbed.
//!
//! The Los Alamos test plan (docs/theory.md, facts T1–T2): random force at mass 1,
//! accelerometers on all 8 masses, records of 8 s and 4096 samples at
//! 512 Hz, five records per configuration; the masses slide on a rod, so
//! there is Coulomb friction. [`ModalTest::like_the_paper`] simulates that
//! (0.3 N of friction at every mass, 1 % noise on every accelerometer);
//! [`ModalTest::linear`] is the same test without friction or noise.

use super::fit::{identify, FitResult, FitSettings};
use super::frf::{h1_records, Frf, FrfSettings};
use super::testmodes::TestModes;
use crate::error::{Result, TacitError};
use crate::integrate::SimSettings;
use crate::model::{Friction, Model};
use crate::record::{Quantity, Record};
use crate::simulate::{simulate_record, InputSpec, RecordSpec};
use serde::Serialize;

/// A copy of `model` with the spring labelled `label` (e.g. "k5") scaled
/// by `1 + change` (the paper's damage: `change = −0.14`).
pub fn with_spring_change(model: &Model, label: &str, change: f64) -> Result<Model> {
    if !(change.is_finite() && change > -1.0) {
        return Err(TacitError::Setting(format!(
            "stiffness change {change} of {label}: must be > −1"
        )));
    }
    let mut m = model.clone();
    let i = (0..m.springs.len())
        .find(|&i| m.springs[i].label(i) == label)
        .ok_or_else(|| {
            let names: Vec<String> = (0..model.springs.len())
                .map(|i| model.springs[i].label(i))
                .collect();
            TacitError::model(
                &model.name,
                format!("no spring labelled {label} (springs: {})", names.join(", ")),
            )
        })?;
    m.springs[i].stiffness *= 1.0 + change;
    m.name = format!("{}-{}{:+.0}pct", model.name, label, 100.0 * change);
    m.description = format!(
        "{} with {label} changed by {:+.1} %",
        model.description,
        100.0 * change
    );
    Ok(m)
}

/// A simulated modal test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModalTest {
    /// Records (averaged together; default 5).
    pub records: usize,
    /// Samples per record (default 4096).
    pub samples: usize,
    /// Sample rate, Hz (default 512).
    pub fs: f64,
    /// DOF of the shaker (default 1).
    pub input_dof: usize,
    /// Band of the random force, Hz (default 5–200).
    pub band_hz: (f64, f64),
    /// RMS of the random force, N (default 20).
    pub rms: f64,
    /// Accelerometer DOFs (default 1–8).
    pub sensors: Vec<usize>,
    /// Noise on every accelerometer, fraction of its RMS (default 0).
    pub noise: f64,
    /// Coulomb friction level at every mass, N (0 = none; default 0).
    pub friction: f64,
    /// Regularisation velocity of the friction law, m/s (default 1e-3).
    pub friction_velocity: f64,
    /// Seed of record 1; record r uses `seed + r − 1` (default 11).
    pub seed: u64,
    /// Integrator sub-steps per sample (default 10).
    pub substeps: usize,
    /// Stiffness of a spring from the input DOF to ground, N/m, standing
    /// for the shaker's suspension, which the model does not have (0 =
    /// none; default 0).
    pub shaker_stiffness: f64,
}

impl ModalTest {
    /// The LANL test plan on a linear structure, noise-free.
    pub fn linear() -> Self {
        ModalTest {
            records: 5,
            samples: 4096,
            fs: 512.0,
            input_dof: 1,
            band_hz: (5.0, 200.0),
            rms: 20.0,
            sensors: (1..=8).collect(),
            noise: 0.0,
            friction: 0.0,
            friction_velocity: 1e-3,
            seed: 11,
            substeps: 10,
            shaker_stiffness: 0.0,
        }
    }

    /// The LANL test plan with the masses sliding on the rod (0.3 N of
    /// Coulomb friction each) and 1 % accelerometer noise.
    pub fn like_the_paper() -> Self {
        ModalTest {
            noise: 0.01,
            friction: 0.3,
            ..Self::linear()
        }
    }

    /// The tested structure: `model` with the friction elements (and the
    /// shaker suspension) added.
    pub fn structure(&self, model: &Model) -> Model {
        let mut m = model.clone();
        if self.shaker_stiffness > 0.0 {
            m.springs.push(crate::model::Spring {
                dofs: vec![self.input_dof],
                stiffness: self.shaker_stiffness,
                name: Some("shaker".into()),
            });
        }
        if self.friction > 0.0 {
            for d in 1..=m.ndof() {
                m.frictions.push(Friction {
                    dof: d,
                    level: self.friction,
                    velocity: self.friction_velocity,
                });
            }
        }
        m
    }

    /// Simulate the records (record r with seed `seed + r − 1`).
    pub fn simulate(&self, model: &Model) -> Result<Vec<Record>> {
        if self.records < 1 {
            return Err(TacitError::Setting("a modal test needs >= 1 record".into()));
        }
        let structure = self.structure(model);
        structure.validate(&structure.name)?;
        (0..self.records)
            .map(|r| {
                let spec = RecordSpec {
                    fs: self.fs,
                    samples: self.samples,
                    input_dof: self.input_dof,
                    input: InputSpec::Random {
                        band: self.band_hz,
                        rms: self.rms,
                    },
                    sensors: self.sensors.clone(),
                    kinds: vec![Quantity::Accel],
                    noise: self.noise,
                    seed: self.seed + r as u64,
                    settings: SimSettings {
                        substeps: self.substeps,
                        ..SimSettings::default()
                    },
                    u0: vec![],
                    v0: vec![],
                };
                simulate_record(&structure, &spec).map(|(rec, _)| rec)
            })
            .collect()
    }
}

/// FRFs and the modes identified from them.
#[derive(Debug, Clone, Serialize)]
pub struct Identification {
    /// The H1 FRFs (accelerance).
    pub frf: Frf,
    /// The curve fit.
    pub fit: FitResult,
}

/// Simulate `test` on `model` and identify its modes with the default FRF
/// and fit settings at the test's sensors; keep the first `count` modes.
pub fn identified_modes(
    model: &Model,
    test: &ModalTest,
    name: &str,
    count: usize,
) -> Result<(TestModes, Identification)> {
    let recs = test.simulate(model)?;
    let id = identify_records(
        &recs,
        Some(test.input_dof),
        &test.sensors,
        &FrfSettings::default(),
        &FitSettings::default(),
    )?;
    let t = id.fit.test_modes(name, model.ndof())?.first(count);
    Ok((t, id))
}

/// H1 over the records, then the curve fit (accelerations at `sensors`).
pub fn identify_records(
    records: &[Record],
    input_dof: Option<usize>,
    sensors: &[usize],
    frf: &FrfSettings,
    fit: &FitSettings,
) -> Result<Identification> {
    let frf = h1_records(records, input_dof, sensors, Quantity::Accel, frf)?;
    let fit = identify(&frf, fit)?;
    Ok(Identification { frf, fit })
}
