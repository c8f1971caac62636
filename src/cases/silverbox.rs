//! The Silverbox benchmark (a measured electronic Duffing-type oscillator,
//! Wigren & Schoukens, ECC 2013) through the calibrated diagnosis, as
//! `tacit diagnose` runs it (docs/silverbox.md gives the command):
//!
//! - the record: `V1` → `force_1`, `V2` → `disp_1` at 10⁷/2¹⁴ Hz, means
//!   removed, the force compensated for the integrators' linear
//!   interpolation ([`Record::with_band_limited_force`]), then cut to the
//!   estimation and test ranges ([`SampleRange`]);
//! - the model: `data/silverbox.toml`, one DOF whose m, k and damping are
//!   marked free (starting values);
//! - the settings: `data/silverbox-settings.toml`, the first
//!   [`Settings::skip`] test samples not scored;
//! - [`crate::diagnose::calibrated::diagnose_calibrated`] with the
//!   open-loop refinement, the library function the command calls.
//!
//! The open-loop RMS errors come from the diagnosis's `rms_per_channel`.

use crate::diagnose::calibrated::{diagnose_calibrated, CalibratedSettings};
use crate::diagnose::{self, DiagnoseSettings, Diagnosis};
use crate::error::{Result, TacitError};
use crate::model::Model;
use crate::record::{self, MatChannel, MatMapping, Quantity, Record, SampleRange};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Settings (the benchmark's conventions by default).
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    /// Sample rate, Hz (10⁷ / 2¹⁴).
    pub fs: f64,
    /// Estimation samples (default 40650..127400, the multisines).
    pub estimation: (usize, usize),
    /// Test samples (default 100..40575, the arrow).
    pub test: (usize, usize),
    /// Samples at the start of each record left out of the open-loop
    /// error (state initialisation; the benchmark allows 50).
    pub skip: usize,
    /// The model file (default `data/silverbox.toml` of this checkout).
    pub model: PathBuf,
    /// The diagnosis settings file (default `data/silverbox-settings.toml`).
    pub settings: PathBuf,
}

impl Default for Settings {
    fn default() -> Self {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
        Settings {
            fs: 1e7 / 16384.0,
            estimation: (40650, 127400),
            test: (100, 40575),
            skip: 50,
            model: data.join("silverbox.toml"),
            settings: data.join("silverbox-settings.toml"),
        }
    }
}

/// What came out.
#[derive(Debug, Clone)]
pub struct SilverboxResult {
    /// The whole diagnosis (as written to report.json).
    pub diagnosis: Diagnosis,
    /// The settings of the diagnosis (with the skip).
    pub settings: DiagnoseSettings,
    /// Open-loop RMS error on the test segment of the calibrated linear
    /// model, V.
    pub rms_linear: f64,
    /// The same of the final model, V.
    pub rms_final: f64,
    /// The same errors on the estimation segment, V.
    pub rms_estimation: (f64, f64),
    /// RMS of the test output over the samples scored, V.
    pub rms_output: f64,
    /// What the final model's error is made of: on the test segment and
    /// on the estimation segment.
    pub breakdown: (Breakdown, Breakdown),
    /// Seconds.
    pub elapsed_s: f64,
}

/// What an open-loop error is made of: by amplitude (equal blocks of the
/// record) and by frequency (shares of the residual's mean square).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Breakdown {
    /// Mean of the residual (measured − simulated), V.
    pub mean: f64,
    /// Per block of the scored samples, in order: the output's RMS and the
    /// error's RMS, V.
    pub blocks: Vec<(f64, f64)>,
    /// Share of the residual's mean square in each band (low Hz, high Hz,
    /// share in [0, 1]); the mean's share is [`Breakdown::mean_share`].
    pub bands: Vec<(f64, f64, f64)>,
    /// Share of the residual's mean square in its mean.
    pub mean_share: f64,
}

impl Breakdown {
    /// Lines for people, in mV and per cent.
    pub fn describe(&self, what: &str) -> String {
        let blocks: Vec<String> = self
            .blocks
            .iter()
            .map(|(y, e)| format!("{:.1}: {:.3}", 1e3 * y, 1e3 * e))
            .collect();
        let bands: Vec<String> = self
            .bands
            .iter()
            .map(|(lo, hi, p)| format!("{lo:.0}–{hi:.0} Hz {:.1} %", 100.0 * p))
            .collect();
        format!(
            "{what} error by block (output RMS mV: error RMS mV): {}\n\
             {what} error's mean square by band: {}; mean {:.3} mV ({:.1} %)\n",
            blocks.join(", "),
            bands.join(", "),
            1e3 * self.mean,
            100.0 * self.mean_share
        )
    }
}

/// The bands of [`Breakdown::bands`], Hz: below the resonance, around it
/// (the resonance near 70 Hz), the rest of the excitation band (up to
/// 200 Hz) and above it (third harmonics, up to the Nyquist frequency).
pub const BANDS: [(f64, f64); 5] = [
    (0.0, 10.0),
    (10.0, 65.0),
    (65.0, 75.0),
    (75.0, 200.0),
    (200.0, 305.2),
];

/// The breakdown of `y − pred` (both over the scored samples) into
/// `nblocks` equal blocks and the bands `bands` at sample rate `fs`.
pub fn breakdown(
    y: &[f64],
    pred: &[f64],
    fs: f64,
    nblocks: usize,
    bands: &[(f64, f64)],
) -> Breakdown {
    let r: Vec<f64> = y.iter().zip(pred).map(|(a, b)| a - b).collect();
    let n = r.len().max(1);
    let mean = r.iter().sum::<f64>() / n as f64;
    let b = (r.len() / nblocks.max(1)).max(1);
    let blocks = (0..nblocks)
        .filter(|i| (i + 1) * b <= r.len())
        .map(|i| {
            let span = i * b..(i + 1) * b;
            (
                crate::signal::rms_of(&y[span.clone()]),
                crate::signal::rms_of(&r[span]),
            )
        })
        .collect();
    let ms = r.iter().map(|v| v * v).sum::<f64>() / n as f64;
    let centred: Vec<f64> = r.iter().map(|v| v - mean).collect();
    let rms = crate::signal::band_rms(std::slice::from_ref(&centred), fs, bands);
    let bands = bands
        .iter()
        .zip(&rms[0])
        .map(|(&(lo, hi), v)| (lo, hi, v * v / ms))
        .collect();
    Breakdown {
        mean,
        blocks,
        bands,
        mean_share: mean * mean / ms,
    }
}

impl SilverboxResult {
    /// A few lines for people.
    pub fn summary(&self) -> String {
        let d = &self.diagnosis;
        let p = |name: &str| {
            d.calibration
                .as_ref()
                .and_then(|c| c.corrections.iter().find(|x| x.name == name))
                .map_or(f64::NAN, |x| x.value)
        };
        let effects: Vec<String> = d
            .effects
            .iter()
            .map(|e| format!("{} {:?}", e.label, e.parameters))
            .collect();
        format!(
            "Silverbox, test segment (open-loop RMS error): linear {:.3} mV, after the loop {:.3} mV (test output RMS {:.1} mV)\n\
             estimation segment: linear {:.3} mV, final {:.3} mV\n\
             diagnosis: {}\nlinear part: m = {:.5e}, k = {:.5e}, zeta = {:.5}\neffects: {}\n{}{}time {:.1} s",
            1e3 * self.rms_linear,
            1e3 * self.rms_final,
            1e3 * self.rms_output,
            1e3 * self.rms_estimation.0,
            1e3 * self.rms_estimation.1,
            d.verdict,
            p("m1"),
            p("k"),
            p("zeta1"),
            effects.join("; "),
            self.breakdown.0.describe("test"),
            self.breakdown.1.describe("estimation"),
            self.elapsed_s
        )
    }
}

/// Read the Silverbox `.mat` file as `--mat-map V1=force_1,V2=disp_1
/// --mat-fs FS --remove-mean` does.
pub fn read(path: &Path, fs: f64) -> Result<Record> {
    record::read_mat(
        path,
        &MatMapping {
            channels: vec![
                MatChannel::at_dof("V1", Quantity::Force, 1),
                MatChannel::at_dof("V2", Quantity::Disp, 1),
            ],
            fs: fs.into(),
            remove_mean: true,
        },
    )
}

/// The open-loop RMS error of the only channel in `set`.
fn rms(set: &diagnose::ErrorSet) -> Result<f64> {
    set.rms_per_channel
        .get("disp_1")
        .copied()
        .flatten()
        .ok_or_else(|| TacitError::Numerical(format!("no open-loop error: {}", set.status)))
}

/// The breakdown of the open-loop error of `set` on the scored samples `y`.
fn of_errors(set: &diagnose::ErrorSet, y: &[f64], s: &Settings) -> Result<Breakdown> {
    let pred = set
        .open_loop_prediction
        .as_ref()
        .ok_or_else(|| TacitError::Numerical(format!("no open-loop prediction: {}", set.status)))?;
    let pred: Vec<f64> = pred.row(0).iter().skip(s.skip).copied().collect();
    Ok(breakdown(y, &pred, s.fs, 8, &BANDS))
}

/// The whole study; the report goes to `out` when given.
pub fn run(path: &Path, s: &Settings, out: Option<&Path>) -> Result<SilverboxResult> {
    let t0 = std::time::Instant::now();
    let whole = read(path, s.fs)?.with_band_limited_force();
    let range = |(a, b): (usize, usize)| SampleRange { start: a, end: b };
    let est = range(s.estimation).cut(&whole)?;
    let test = range(s.test).cut(&whole)?;
    let model = Model::load(&s.model, &mut [])?;
    let settings = DiagnoseSettings {
        unscored: s.skip,
        ..DiagnoseSettings::from_file(&s.settings)?
    };
    let cal = CalibratedSettings {
        open_loop: true,
        ..Default::default()
    };
    let d = diagnose_calibrated(
        &model,
        &est,
        Some(&test),
        &[],
        None,
        &settings,
        &cal,
        &|_| {},
    )?;
    if let Some(dir) = out {
        let meta = diagnose::report::Meta {
            model: s.model.display().to_string(),
            record: format!(
                "{} [{}..{})",
                path.display(),
                s.estimation.0,
                s.estimation.1
            ),
            validation_record: Some(format!("{} [{}..{})", path.display(), s.test.0, s.test.1)),
            sensors: vec![1],
            tacit_version: env!("CARGO_PKG_VERSION").into(),
            warnings: vec![],
        };
        diagnose::report::write(dir, &meta, &d, &settings)?;
    }
    let cal_report = d.calibration.as_ref().ok_or_else(|| {
        TacitError::Numerical("the Silverbox diagnosis was not calibrated".into())
    })?;
    let v = d.validation.as_ref().ok_or_else(|| {
        TacitError::Numerical("the Silverbox diagnosis has no test errors".into())
    })?;
    let linear_test = cal_report
        .calibrated_validation_errors
        .as_ref()
        .ok_or_else(|| TacitError::Numerical("no calibrated test errors".into()))?;
    let y = &test.outputs[0].data[s.skip.min(test.len())..];
    let breakdown = (
        of_errors(&v.after, y, s)?,
        of_errors(&d.after, &est.outputs[0].data[s.skip.min(est.len())..], s)?,
    );
    Ok(SilverboxResult {
        breakdown,
        rms_linear: rms(linear_test)?,
        rms_final: rms(&v.after)?,
        rms_estimation: (rms(&cal_report.calibrated_errors)?, rms(&d.after)?),
        rms_output: crate::signal::rms_of(y),
        elapsed_s: t0.elapsed().as_secs_f64(),
        settings,
        diagnosis: d,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A residual made of a mean, a 70 Hz sine and a 250 Hz sine: the
    /// shares are the parts' mean squares over the total, the blocks' error
    /// RMS the whole's.
    #[test]
    fn breakdown_splits_a_known_residual() {
        let fs = 1e7 / 16384.0;
        let n = 8 * 4096;
        let y: Vec<f64> = (0..n).map(|k| (k as f64 * 1e-3).sin()).collect();
        let t = |k: usize| k as f64 / fs;
        let w = |f: f64, k: usize| (2.0 * std::f64::consts::PI * f * t(k)).sin();
        let r: Vec<f64> = (0..n)
            .map(|k| 0.1 + 0.3 * w(70.0, k) + 0.2 * w(250.0, k))
            .collect();
        let pred: Vec<f64> = y.iter().zip(&r).map(|(a, b)| a - b).collect();
        let b = breakdown(&y, &pred, fs, 8, &BANDS);
        let ms = 0.01 + 0.09 / 2.0 + 0.04 / 2.0;
        assert!((b.mean - 0.1).abs() < 1e-3, "{}", b.mean);
        assert!((b.mean_share - 0.01 / ms).abs() < 2e-3, "{}", b.mean_share);
        assert!((b.bands[2].2 - 0.045 / ms).abs() < 1e-2, "{:?}", b.bands);
        assert!((b.bands[4].2 - 0.02 / ms).abs() < 1e-2, "{:?}", b.bands);
        assert!(b.bands[0].2 < 1e-3 && b.bands[3].2 < 1e-2, "{:?}", b.bands);
        let total: f64 = b.bands.iter().map(|x| x.2).sum::<f64>() + b.mean_share;
        assert!((total - 1.0).abs() < 1e-6, "{total}");
        assert_eq!(b.blocks.len(), 8);
        for (_, e) in &b.blocks {
            assert!((e - ms.sqrt()).abs() < 5e-3, "{e}");
        }
    }
}
