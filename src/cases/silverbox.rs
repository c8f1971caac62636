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
    /// Seconds.
    pub elapsed_s: f64,
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
             diagnosis: {}\nlinear part: m = {:.5e}, k = {:.5e}, zeta = {:.5}\neffects: {}\ntime {:.1} s",
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
    Ok(SilverboxResult {
        rms_linear: rms(linear_test)?,
        rms_final: rms(&v.after)?,
        rms_estimation: (rms(&cal_report.calibrated_errors)?, rms(&d.after)?),
        rms_output: crate::signal::rms_of(y),
        elapsed_s: t0.elapsed().as_secs_f64(),
        settings,
        diagnosis: d,
    })
}
