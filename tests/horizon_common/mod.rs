//! Shared set-up of the horizon tests: the lanl8dof testbed (full order),
//! linear records made with the exact sampled model.
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use rand_distr::{Distribution, StandardNormal};
use tacit::horizon::{HorizonData, HorizonSettings};
use tacit::linear::SampledModel;
use tacit::model::Model;
use tacit::record::Quantity;

pub const FS: f64 = 512.0;

pub fn lanl8dof(name: &str) -> Model {
    let p = format!("{}/data/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    Model::from_file(std::path::Path::new(&p)).unwrap()
}

pub fn sampled() -> SampledModel {
    SampledModel::from_model(&lanl8dof("lanl8dof"), FS, 10).unwrap()
}

/// Accelerations at DOFs 1, 5, 6.
pub fn channels() -> Vec<(Quantity, usize)> {
    vec![
        (Quantity::Accel, 0),
        (Quantity::Accel, 4),
        (Quantity::Accel, 5),
    ]
}

/// A linear record: known random force at DOF 1 (20 N RMS), unknown
/// forces `w` through `bu`, initial state `x0`, white Gaussian noise of
/// `noise_std` per channel (absolute). Returns (known force, measured,
/// true states).
pub fn linear_record(
    sm: &SampledModel,
    len: usize,
    bu: &DMatrix<f64>,
    w: &DMatrix<f64>,
    x0: &DVector<f64>,
    noise_std: &[f64],
    seed: u64,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let n = sm.n;
    let g1 = tacit::signal::random_band(len, FS, (5.0, 200.0), 20.0, seed).unwrap();
    let mut g = DMatrix::zeros(n, len);
    for k in 0..len {
        g[(0, k)] = g1[k];
    }
    let ftot = &g + bu * w;
    let xs = sm.simulate(x0, &ftot);
    let (cy, dy) = sm.outputs(&channels()).unwrap();
    let mut y = &cy * &xs + &dy * &ftot;
    let mut rng = tacit::signal::rng(seed + 1000);
    for r in 0..y.nrows() {
        for k in 0..len {
            let e: f64 = StandardNormal.sample(&mut rng);
            y[(r, k)] += noise_std[r] * e;
        }
    }
    (g, y, xs)
}

/// White Gaussian force samples (m × len) with standard deviation `sd`.
pub fn white(m: usize, len: usize, sd: f64, seed: u64) -> DMatrix<f64> {
    let mut rng = tacit::signal::rng(seed);
    DMatrix::from_fn(m, len, |_, _| {
        let e: f64 = StandardNormal.sample(&mut rng);
        sd * e
    })
}

pub fn data<'a>(
    g: &'a DMatrix<f64>,
    y: &'a DMatrix<f64>,
    ch: &'a [(Quantity, usize)],
    bu: &'a DMatrix<f64>,
) -> HorizonData<'a> {
    HorizonData {
        known_force: g,
        measured: y,
        channels: ch,
        unknown: bu,
    }
}

pub fn settings() -> HorizonSettings {
    HorizonSettings::default()
}

/// Max |a − b| / max |b|.
pub fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax()
}

/// Pearson correlation.
pub fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}
