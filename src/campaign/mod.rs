//! Campaigns: many records of one structure diagnosed against one model,
//! summarized side by side, and one set of effect parameters fitted to
//! all of them at once.
//!
//! A campaign is a [`Manifest`] (TOML: the model, the records with their
//! group — a force level, a sensor set — and options) or a directory of
//! records ([`Manifest::from_dir`]). Each record is diagnosed as by
//! `tacit diagnose` ([`run_record`]), its report written into its own
//! directory; [`summary`] reads the reports back into one table (effects,
//! parameters with units, errors before and after) with the spread of each
//! parameter across records; [`joint`] fits one set of parameters of the
//! effect the records share to all of them together and compares it with
//! the per-record fits. Records are independent: the command line runs
//! them in parallel and skips those already done (docs/cli.md).

pub mod joint;
pub mod summary;

use crate::diagnose::{calibrated, report, DiagnoseSettings};
use crate::error::{Result, TacitError};
use crate::model::Model;
use crate::record::{model_checks, Record};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One record of a campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Entry {
    /// The record file (.h5, .csv), relative to the manifest's directory.
    pub path: PathBuf,
    /// Name of the record in the summary and of its output directory
    /// (default: the file's stem). Letters, digits, `-`, `_`, `.` only.
    #[serde(default)]
    pub name: String,
    /// Group (a force level, a sensor set) shown in the summary.
    #[serde(default)]
    pub group: String,
    /// A validation record for this one.
    #[serde(default)]
    pub validate: Option<PathBuf>,
    /// Sensor DOFs (from 1) for this record (default: the campaign's).
    #[serde(default)]
    pub sensors: Option<Vec<usize>>,
}

/// The joint fit's options.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointOptions {
    /// Effect whose parameters are shared, by its label in the reports
    /// (`contact 5→6`); default: the effect found in most records.
    #[serde(default)]
    pub effect: Option<String>,
    /// Skip the joint fit.
    #[serde(default)]
    pub off: bool,
}

/// A campaign: one model, many records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// The declared model file, relative to the manifest's directory.
    pub model: PathBuf,
    /// Sensor DOFs (from 1) of every record (default: every output
    /// channel).
    #[serde(default)]
    pub sensors: Option<Vec<usize>>,
    /// Diagnosis settings file (TOML or a report.json), relative to the
    /// manifest's directory (default: the library's defaults).
    #[serde(default)]
    pub settings: Option<PathBuf>,
    /// Trust the declared linear part (no calibration).
    #[serde(default)]
    pub trust_linear: bool,
    /// Records at a level where the structure behaves linearly, used to
    /// calibrate the linear part for every record.
    #[serde(default)]
    pub linear_records: Vec<PathBuf>,
    /// The records.
    #[serde(rename = "record")]
    pub records: Vec<Entry>,
    /// The joint fit.
    #[serde(default)]
    pub joint: JointOptions,
}

fn bad(file: &Path, msg: String) -> TacitError {
    TacitError::Setting(format!("campaign {}: {msg}", file.display()))
}

impl Manifest {
    /// Read a manifest; relative paths are resolved against its directory;
    /// names are filled in and checked (unique, file-name safe).
    pub fn from_file(path: &Path) -> Result<Manifest> {
        let text = std::fs::read_to_string(path).map_err(|e| TacitError::io(path, e))?;
        let mut m: Manifest =
            toml::from_str(&text).map_err(|e| bad(path, e.to_string().trim_end().to_string()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        let join = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        join(&mut m.model);
        m.settings.as_mut().map(join);
        m.linear_records.iter_mut().for_each(join);
        for e in &mut m.records {
            join(&mut e.path);
            e.validate.as_mut().map(join);
        }
        m.finish(path)?;
        Ok(m)
    }

    /// Every record file (.h5, .csv) of `dir`, in name order, against
    /// `model`.
    pub fn from_dir(dir: &Path, model: &Path) -> Result<Manifest> {
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(|e| TacitError::io(dir, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension()
                    .is_some_and(|x| x == "h5" || x == "hdf5" || x == "csv")
                    && !p.to_string_lossy().ends_with("-truth.csv")
            })
            .collect();
        files.sort();
        let mut m = Manifest {
            model: model.to_path_buf(),
            sensors: None,
            settings: None,
            trust_linear: false,
            linear_records: vec![],
            records: files
                .into_iter()
                .map(|path| Entry {
                    path,
                    name: String::new(),
                    group: String::new(),
                    validate: None,
                    sensors: None,
                })
                .collect(),
            joint: JointOptions::default(),
        };
        m.finish(dir)?;
        Ok(m)
    }

    /// Fill in default names; check names and that there is a record.
    fn finish(&mut self, src: &Path) -> Result<()> {
        if self.records.is_empty() {
            return Err(bad(
                src,
                "no record (give [[record]] entries with path = ...)".into(),
            ));
        }
        for (i, e) in self.records.iter_mut().enumerate() {
            if e.name.is_empty() {
                e.name = e.path.file_stem().map_or(format!("record-{}", i + 1), |s| {
                    s.to_string_lossy().into_owned()
                });
            }
            let ok = e
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
            if !ok || e.name.starts_with('.') {
                return Err(bad(
                    src,
                    format!(
                        "record[{i}].name \"{}\": use letters, digits, '-', '_' and '.' only (it names a directory)",
                        e.name
                    ),
                ));
            }
        }
        for (i, e) in self.records.iter().enumerate() {
            if self.records[..i].iter().any(|o| o.name == e.name) {
                return Err(bad(
                    src,
                    format!("record name \"{}\" is used twice", e.name),
                ));
            }
        }
        Ok(())
    }

    /// The diagnosis settings (the file's or the defaults), validated.
    pub fn diagnose_settings(&self) -> Result<DiagnoseSettings> {
        let s = match &self.settings {
            Some(p) => DiagnoseSettings::from_file(p)?,
            None => DiagnoseSettings::default(),
        };
        s.validate()?;
        Ok(s)
    }

    /// The sensors of one record.
    pub fn sensors_of<'a>(&'a self, e: &'a Entry) -> Option<&'a [usize]> {
        e.sensors.as_deref().or(self.sensors.as_deref())
    }
}

/// Diagnose one record of `m` (as `tacit diagnose`) and write its report
/// into `dir` (created; its parent must exist). The record checks of
/// [`model_checks`] run first: their warnings go into the report, their
/// errors fail the record. `linear`: the campaign's
/// linear records, read once.
pub fn run_record(
    m: &Manifest,
    e: &Entry,
    model: &Model,
    linear: &[Record],
    settings: &DiagnoseSettings,
    dir: &Path,
) -> Result<()> {
    let read = |p: &Path| -> Result<Record> {
        let mut r = crate::record::read(p)?;
        model.resolve_channels(&mut r)?;
        Ok(r)
    };
    let rec = read(&e.path)?;
    let val = e.validate.as_deref().map(read).transpose()?;
    let sensors = m.sensors_of(e);
    let mut warnings = vec![];
    for r in std::iter::once(&rec).chain(val.as_ref()) {
        let found = model_checks::warnings(r, model, sensors)?;
        warnings.extend(model_checks::labelled(
            &r.source.display().to_string(),
            &found,
        ));
    }
    let cal = calibrated::CalibratedSettings {
        off: m.trust_linear,
        ..Default::default()
    };
    let d = calibrated::diagnose_calibrated(
        model,
        &rec,
        val.as_ref(),
        linear,
        sensors,
        settings,
        &cal,
        &|_| {},
    )?;
    let meta = report::Meta {
        model: m.model.display().to_string(),
        record: e.path.display().to_string(),
        validation_record: e.validate.as_ref().map(|p| p.display().to_string()),
        sensors: d.prepared.channels.iter().map(|c| c.1 + 1).collect(),
        tacit_version: env!("CARGO_PKG_VERSION").to_string(),
        warnings,
    };
    report::write(dir, &meta, &d, settings)?;
    Ok(())
}
