//! Test records: a uniform time base, input channels (force at a DOF) and
//! output channels (displacement, velocity or acceleration at a DOF), and for
//! simulated records the truth (every DOF's u, v, a and internal force, and
//! the model TOML used).
//!
//! File formats: native HDF5 (`hdf5io`), CSV with a header row (`csvio`),
//! MATLAB v5 `.mat` with a variable→channel mapping (`matio`). Layouts are
//! documented in `docs/formats.md`.

use crate::error::{Result, TacitError};
pub use cut::{compensate_linear_interpolation, SampleRange};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub mod checks;
pub mod csvio;
pub mod cut;
pub mod hdf5io;
pub mod matio;
pub mod model_checks;
pub mod uff;
pub mod units;

/// What a channel measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
pub enum Quantity {
    /// Applied force (input), N.
    Force,
    /// Displacement, m.
    Disp,
    /// Velocity, m/s.
    Vel,
    /// Acceleration, m/s².
    Accel,
}

impl Quantity {
    /// The prefix used in channel names (`force`, `disp`, `vel`, `accel`).
    pub fn prefix(self) -> &'static str {
        match self {
            Quantity::Force => "force",
            Quantity::Disp => "disp",
            Quantity::Vel => "vel",
            Quantity::Accel => "accel",
        }
    }
    /// SI unit.
    pub fn si_unit(self) -> &'static str {
        match self {
            Quantity::Force => "N",
            Quantity::Disp => "m",
            Quantity::Vel => "m/s",
            Quantity::Accel => "m/s^2",
        }
    }
    /// Parse a prefix.
    pub fn from_prefix(s: &str) -> Option<Quantity> {
        match s {
            "force" => Some(Quantity::Force),
            "disp" => Some(Quantity::Disp),
            "vel" => Some(Quantity::Vel),
            "accel" => Some(Quantity::Accel),
            _ => None,
        }
    }
}

/// Parse a channel name `<quantity>:<label>` (`accel:n12:uy`): the
/// quantity and the point label; `None` for any other name.
pub fn parse_point_name(name: &str) -> Option<(Quantity, &str)> {
    let (prefix, label) = name.split_once(':')?;
    let q = Quantity::from_prefix(prefix)?;
    (!label.is_empty() && !label.chars().any(|c| c.is_whitespace() || c == ','))
        .then_some((q, label))
}

/// One measured signal at one DOF.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Channel {
    /// What it measures.
    pub quantity: Quantity,
    /// DOF, numbered from 1; 0 for a channel named by point label until a
    /// model resolves it ([`crate::model::Model::resolve_channels`]).
    pub dof: usize,
    /// Point label of a channel named `<quantity>:<label>` (models built
    /// from matrices); `None` for `<quantity>_<dof>`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub point: Option<String>,
    /// Unit string (SI unless the file says otherwise).
    pub unit: String,
    /// One value per sample.
    pub data: Vec<f64>,
}

impl Channel {
    /// A channel in SI units.
    pub fn new(quantity: Quantity, dof: usize, data: Vec<f64>) -> Self {
        Channel {
            quantity,
            dof,
            point: None,
            unit: quantity.si_unit().to_string(),
            data,
        }
    }
    /// A channel at a labelled point (`accel:n12:uy`), DOF unresolved (0).
    pub fn at_point(quantity: Quantity, point: &str, data: Vec<f64>) -> Self {
        Channel {
            point: Some(point.to_string()),
            ..Channel::new(quantity, 0, data)
        }
    }
    /// Channel name: `accel_5`, or `accel:n12:uy` for a labelled point.
    pub fn name(&self) -> String {
        channel_name(self.quantity, self.dof, self.point.as_deref())
    }
}

/// A channel's name: `<quantity>_<dof>`, or `<quantity>:<label>` at a
/// labelled point.
pub fn channel_name(quantity: Quantity, dof: usize, point: Option<&str>) -> String {
    match point {
        Some(p) => format!("{}:{p}", quantity.prefix()),
        None => format!("{}_{dof}", quantity.prefix()),
    }
}

/// The truth stored with a simulated record: every DOF, every sample.
/// Matrices are stored DOF-major: `u[dof][sample]` (dof from 0 here).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Displacement, m.
    pub u: Vec<Vec<f64>>,
    /// Velocity, m/s.
    pub v: Vec<Vec<f64>>,
    /// Acceleration, m/s².
    pub a: Vec<Vec<f64>>,
    /// Internal (nonlinear-element) force on the left-hand side of
    /// `M a + C v + K u + f_int = f_ext`, N.
    pub fint: Vec<Vec<f64>>,
    /// The model used, as TOML text.
    pub model_toml: String,
}

/// A record: uniform time base, inputs, outputs and optional truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// Time of sample 0, s.
    pub t0: f64,
    /// Sample rate, Hz.
    pub fs: f64,
    /// Input channels (quantity = Force).
    pub inputs: Vec<Channel>,
    /// Output channels (Disp, Vel or Accel).
    pub outputs: Vec<Channel>,
    /// Truth, for simulated records.
    pub truth: Option<Truth>,
    /// Where it was read from (for error messages); empty when built in memory.
    #[serde(skip)]
    pub source: PathBuf,
}

impl Record {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.inputs
            .first()
            .or(self.outputs.first())
            .map_or(0, |c| c.data.len())
    }
    /// True when the record holds no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Sample interval, s.
    pub fn dt(&self) -> f64 {
        1.0 / self.fs
    }
    /// Time of sample k.
    pub fn time(&self, k: usize) -> f64 {
        self.t0 + k as f64 / self.fs
    }
    /// The time vector.
    pub fn times(&self) -> Vec<f64> {
        (0..self.len()).map(|k| self.time(k)).collect()
    }
    /// Find an output channel.
    pub fn output(&self, quantity: Quantity, dof: usize) -> Option<&Channel> {
        self.outputs
            .iter()
            .find(|c| c.quantity == quantity && c.dof == dof)
    }
    /// Samples `start..end` as a new record (time of sample 0 shifted to
    /// `t0 + start/fs`; the truth is sliced too).
    pub fn slice(&self, start: usize, end: usize) -> Result<Record> {
        let n = self.len();
        if !(start < end && end <= n) {
            return Err(TacitError::record(
                self.source.clone(),
                format!("slice {start}..{end} is not within the record's {n} samples"),
            ));
        }
        let cut = |chs: &[Channel]| -> Vec<Channel> {
            chs.iter()
                .map(|c| Channel {
                    data: c.data[start..end].to_vec(),
                    ..c.clone()
                })
                .collect()
        };
        let rows = |m: &[Vec<f64>]| -> Vec<Vec<f64>> {
            m.iter()
                .map(|r| {
                    if r.len() >= end {
                        r[start..end].to_vec()
                    } else {
                        vec![]
                    }
                })
                .collect()
        };
        Ok(Record {
            t0: self.time(start),
            fs: self.fs,
            inputs: cut(&self.inputs),
            outputs: cut(&self.outputs),
            truth: self.truth.as_ref().map(|t| Truth {
                u: rows(&t.u),
                v: rows(&t.v),
                a: rows(&t.a),
                fint: rows(&t.fint),
                model_toml: t.model_toml.clone(),
            }),
            source: self.source.clone(),
        })
    }

    /// Check the record is self-consistent: at least one sample, equal
    /// lengths, finite values, no duplicated channel, a positive rate, DOFs
    /// at least 1 (and at most `ndof` when given). Errors name the channel
    /// and the sample.
    pub fn validate(&self, ndof: Option<usize>) -> Result<()> {
        let path = self.source.clone();
        let err = |m: String| TacitError::record(path.clone(), m);
        if !(self.fs.is_finite() && self.fs > 0.0) {
            return Err(err(format!("sample rate {} Hz is not positive", self.fs)));
        }
        let n = self.len();
        if n == 0 {
            return Err(err("the record holds no samples".into()));
        }
        let mut seen = std::collections::HashSet::new();
        for c in self.inputs.iter().chain(&self.outputs) {
            if !seen.insert(c.name()) {
                return Err(err(format!("channel {} appears twice", c.name())));
            }
            if c.data.len() != n {
                return Err(err(format!(
                    "channel {} has {} samples, expected {}",
                    c.name(),
                    c.data.len(),
                    n
                )));
            }
            if c.dof == 0 && (c.point.is_none() || ndof.is_some()) {
                return Err(err(match c.point {
                    None => format!("channel {}: DOFs are numbered from 1", c.name()),
                    Some(_) => format!(
                        "channel {}: the point label is not resolved against a model built from matrices",
                        c.name()
                    ),
                }));
            }
            if let Some(nd) = ndof {
                if c.dof > nd {
                    return Err(err(format!(
                        "channel {}: DOF {} is outside the model (1..={})",
                        c.name(),
                        c.dof,
                        nd
                    )));
                }
            }
            if let Some(k) = c.data.iter().position(|x| !x.is_finite()) {
                return Err(err(format!(
                    "channel {}: sample {} is {}",
                    c.name(),
                    k,
                    c.data[k]
                )));
            }
        }
        for c in &self.inputs {
            if c.quantity != Quantity::Force {
                return Err(err(format!("input channel {} is not a force", c.name())));
            }
        }
        for c in &self.outputs {
            if c.quantity == Quantity::Force {
                return Err(err(format!("output channel {} is a force", c.name())));
            }
        }
        Ok(())
    }
}

/// File format of a record, chosen from the extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// `.h5` / `.hdf5`.
    Hdf5,
    /// `.csv`.
    Csv,
    /// `.mat` (MATLAB v5).
    Mat,
    /// `.uff` / `.unv` (universal file, ASCII datasets 58; read only).
    Uff,
}

impl Format {
    /// Choose from a path's extension.
    pub fn from_path(path: &Path) -> Result<Format> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref()
        {
            Some("h5") | Some("hdf5") => Ok(Format::Hdf5),
            Some("csv") => Ok(Format::Csv),
            Some("mat") => Ok(Format::Mat),
            Some("uff") | Some("unv") => Ok(Format::Uff),
            _ => Err(TacitError::record(
                path,
                "unknown extension: expected .h5, .hdf5, .csv, .mat, .uff or .unv",
            )),
        }
    }
}

/// How to read a `.mat` file: which variable is which channel, and the rate.
#[derive(Debug, Clone, PartialEq)]
pub struct MatMapping {
    /// The channels, each from a vector variable or one row (column) of a
    /// matrix variable.
    pub channels: Vec<MatChannel>,
    /// Sample rate: a number, or a scalar variable of the file.
    pub fs: MatRate,
    /// Subtract each channel's mean (the Silverbox README asks for it).
    pub remove_mean: bool,
}

/// One channel of a `.mat` file: a variable (one of its signals when it is
/// a matrix) and the channel it becomes.
#[derive(Debug, Clone, PartialEq)]
pub struct MatChannel {
    /// Variable name, e.g. `Acceleration`.
    pub variable: String,
    /// Which signal of a matrix variable, from 1: a row of a matrix with
    /// more columns than rows (signals along the rows, `3 × N`), a column
    /// otherwise (`N × 3`). `None` for a vector variable.
    pub signal: Option<usize>,
    /// What the channel measures.
    pub quantity: Quantity,
    /// DOF from 1 (`accel_2`), or 0 with `point` set.
    pub dof: usize,
    /// Point label (`accel:wing`), for models with named points.
    pub point: Option<String>,
}

impl MatChannel {
    /// A vector variable as the channel `<quantity>_<dof>`.
    pub fn at_dof(variable: &str, quantity: Quantity, dof: usize) -> Self {
        MatChannel {
            variable: variable.to_string(),
            signal: None,
            quantity,
            dof,
            point: None,
        }
    }

    /// Parse `VARIABLE=CHANNEL` or `VARIABLE[k]=CHANNEL` (signal `k` of a
    /// matrix variable, from 1), with CHANNEL `force_1` or `accel:wing`;
    /// the error repeats the pair.
    pub fn parse(pair: &str) -> std::result::Result<MatChannel, String> {
        let bad = |why: &str| format!("'{pair}': {why}");
        let (var, ch) = pair
            .split_once('=')
            .ok_or_else(|| bad("expected VARIABLE=CHANNEL or VARIABLE[k]=CHANNEL"))?;
        let var = var.trim();
        let (variable, signal) = match var.strip_suffix(']').and_then(|v| v.split_once('[')) {
            Some((v, k)) => {
                let k: usize =
                    k.trim().parse().ok().filter(|k| *k >= 1).ok_or_else(|| {
                        bad("the signal index in [k] must be a whole number from 1")
                    })?;
                (v.trim(), Some(k))
            }
            None => (var, None),
        };
        if variable.is_empty() || variable.contains(['[', ']']) {
            return Err(bad("bad variable name"));
        }
        let ch = ch.trim();
        let (quantity, dof, point) = match parse_point_name(ch) {
            Some((q, label)) => (q, 0, Some(label.to_string())),
            None => {
                let (q, d) = ch
                    .split_once('_')
                    .ok_or_else(|| bad("the channel must look like force_1 or accel:wing"))?;
                let q = Quantity::from_prefix(q)
                    .ok_or_else(|| bad("unknown quantity (force, disp, vel, accel)"))?;
                let d: usize = d
                    .parse()
                    .ok()
                    .filter(|d| *d >= 1)
                    .ok_or_else(|| bad("the DOF must be a whole number from 1"))?;
                (q, d, None)
            }
        };
        Ok(MatChannel {
            variable: variable.to_string(),
            signal,
            quantity,
            dof,
            point,
        })
    }

    /// The channel's name (`force_1`, `accel:wing`).
    pub fn name(&self) -> String {
        channel_name(self.quantity, self.dof, self.point.as_deref())
    }

    /// The variable and the signal, for messages: `Acceleration row 2`
    /// style is given by the reader; here `Acceleration[2]`.
    pub fn source(&self) -> String {
        match self.signal {
            Some(r) => format!("{}[{r}]", self.variable),
            None => self.variable.clone(),
        }
    }
}

/// The sample rate of a `.mat` record.
#[derive(Debug, Clone, PartialEq)]
pub enum MatRate {
    /// Given, Hz.
    Hz(f64),
    /// Read from a real scalar variable of the file (any numeric class,
    /// e.g. the `uint16` `Fs` of the F-16 benchmark files), Hz.
    Variable(String),
}

impl MatRate {
    /// A number (Hz) or else a variable name.
    pub fn parse(s: &str) -> MatRate {
        match s.trim().parse::<f64>() {
            Ok(hz) => MatRate::Hz(hz),
            Err(_) => MatRate::Variable(s.trim().to_string()),
        }
    }
}

impl From<f64> for MatRate {
    fn from(hz: f64) -> Self {
        MatRate::Hz(hz)
    }
}

/// A warm-up: the first part of a record, not scored (the transient of a
/// periodic excitation started from rest).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WarmUp {
    /// A number of samples.
    Samples(usize),
    /// A duration, s.
    Seconds(f64),
}

impl WarmUp {
    /// Parse `8192` (samples) or `20.48s` (seconds); the error repeats the
    /// value and the rule.
    pub fn parse(s: &str) -> std::result::Result<WarmUp, String> {
        let t = s.trim();
        if let Some(sec) = t.strip_suffix('s') {
            return match sec.trim().parse::<f64>() {
                Ok(v) if v.is_finite() && v >= 0.0 => Ok(WarmUp::Seconds(v)),
                _ => Err(format!(
                    "warm-up '{s}': seconds must be a number >= 0, e.g. 20.48s"
                )),
            };
        }
        t.parse::<usize>().map(WarmUp::Samples).map_err(|_| {
            format!("warm-up '{s}': give whole samples (8192) or seconds with an s (20.48s)")
        })
    }

    /// Samples at rate `fs` (seconds rounded to the nearest sample).
    pub fn samples(self, fs: f64) -> usize {
        match self {
            WarmUp::Samples(n) => n,
            WarmUp::Seconds(t) => (t * fs).round() as usize,
        }
    }
}

impl Record {
    /// The record without its first `warm_up` (a new record whose `t0`
    /// is the time of the first sample kept); an error naming the record
    /// when nothing would be left.
    pub fn without_warm_up(&self, warm_up: WarmUp) -> Result<Record> {
        let k = warm_up.samples(self.fs);
        if k == 0 {
            return Ok(self.clone());
        }
        let n = self.len();
        if k >= n {
            return Err(TacitError::record(
                self.source.clone(),
                format!("the warm-up of {k} samples leaves nothing of the record's {n} samples"),
            ));
        }
        self.slice(k, n)
    }
}

/// Read a record (HDF5, CSV or universal file dataset 58; `.mat` needs
/// [`read_mat`]), convert its
/// channels to SI by their `unit` and validate it.
pub fn read(path: &Path) -> Result<Record> {
    read_with_conversions(path).map(|(rec, _)| rec)
}

/// [`read`], also returning the unit conversions made.
pub fn read_with_conversions(path: &Path) -> Result<(Record, Vec<units::Conversion>)> {
    let mut rec = match Format::from_path(path)? {
        Format::Hdf5 => hdf5io::read(path)?,
        Format::Csv => csvio::read(path)?,
        Format::Uff => uff::read(path)?,
        Format::Mat => {
            return Err(TacitError::record(
                path,
                "a .mat file needs a channel mapping and a sample rate (--mat-map, --mat-fs)",
            ))
        }
    };
    let conversions = units::to_si(&mut rec)?;
    rec.validate(None)?;
    Ok((rec, conversions))
}

/// Read a MATLAB v5 record with a mapping.
pub fn read_mat(path: &Path, mapping: &MatMapping) -> Result<Record> {
    let rec = matio::read(path, mapping)?;
    rec.validate(None)?;
    Ok(rec)
}

/// Write a record atomically (temporary file in the same directory, then
/// rename): HDF5 or CSV by extension.
pub fn write(rec: &Record, path: &Path) -> Result<()> {
    rec.validate(None)?;
    let fmt = Format::from_path(path)?;
    crate::io::write_atomic(path, |tmp| match fmt {
        Format::Hdf5 => hdf5io::write(rec, tmp),
        Format::Csv => csvio::write(rec, tmp),
        Format::Mat => Err(TacitError::record(path, "writing .mat is not supported")),
        Format::Uff => Err(TacitError::record(
            path,
            "writing universal files is not supported: write .h5 or .csv",
        )),
    })
}

/// A file of the shared data set that sits beside a checkout
/// (`<checkout>/../shared/data/<rel>`), for tests that read measured or
/// reference data the repository does not ship. `None`, with a message
/// on stderr, when it is absent; a panic instead when the environment
/// variable `TACIT_REQUIRE_SHARED` is `1` (CI sets it).
#[doc(hidden)]
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel);
    if path.exists() {
        return Some(path);
    }
    if std::env::var("TACIT_REQUIRE_SHARED").as_deref() == Ok("1") {
        panic!(
            "{} is absent and TACIT_REQUIRE_SHARED=1: the shared data set must sit beside the checkout",
            path.display()
        );
    }
    eprintln!(
        "skipped: {} is absent (the shared data set beside the checkout; set TACIT_REQUIRE_SHARED=1 to make this a failure)",
        path.display()
    );
    None
}

/// Path of the record for messages.
pub fn display_path(rec: &Record) -> PathBuf {
    rec.source.clone()
}

/// Top of the excitation band: the frequency below which 99 % of the
/// power of the force inputs lies (periodogram, mean removed); `None`
/// without a force channel or with a zero force.
pub fn band_top(rec: &Record) -> Option<f64> {
    use rustfft::{num_complex::Complex, FftPlanner};
    let n = rec.len();
    if n < 4 || rec.inputs.is_empty() {
        return None;
    }
    let mut power = vec![0.0; n / 2 + 1];
    let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
    for c in &rec.inputs {
        let mean = c.data.iter().sum::<f64>() / n as f64;
        let mut buf: Vec<Complex<f64>> = c
            .data
            .iter()
            .map(|&x| Complex::new(x - mean, 0.0))
            .collect();
        fft.process(&mut buf);
        for (p, z) in power.iter_mut().zip(&buf) {
            *p += z.norm_sqr();
        }
    }
    let total: f64 = power.iter().sum();
    if !(total > 0.0) {
        return None;
    }
    let mut acc = 0.0;
    for (i, p) in power.iter().enumerate() {
        acc += p;
        if acc >= 0.99 * total {
            return Some((i.max(1)) as f64 * rec.fs / n as f64);
        }
    }
    Some(rec.fs / 2.0)
}

#[cfg(test)]
mod band_tests {
    use super::*;

    #[test]
    fn band_top_of_a_band_limited_force() {
        let fs = 1024.0;
        let f = crate::signal::random_band(8192, fs, (5.0, 200.0), 5.0, 3).unwrap();
        let rec = Record {
            t0: 0.0,
            fs,
            inputs: vec![Channel::new(Quantity::Force, 1, f)],
            outputs: vec![],
            truth: None,
            source: Default::default(),
        };
        let top = band_top(&rec).unwrap();
        assert!(top > 185.0 && top <= 201.0, "{top}");
        let none = Record {
            inputs: vec![],
            ..rec
        };
        assert_eq!(band_top(&none), None);
    }

    #[test]
    fn warm_up_parses_and_cuts() {
        assert_eq!(WarmUp::parse("8192"), Ok(WarmUp::Samples(8192)));
        assert_eq!(WarmUp::parse("20.48s"), Ok(WarmUp::Seconds(20.48)));
        assert_eq!(WarmUp::Seconds(20.48).samples(400.0), 8192);
        assert!(WarmUp::parse("-1s").is_err() && WarmUp::parse("1.5").is_err());
        let rec = Record {
            t0: 0.0,
            fs: 10.0,
            inputs: vec![Channel::new(
                Quantity::Force,
                1,
                (0..10).map(f64::from).collect(),
            )],
            outputs: vec![],
            truth: None,
            source: "r.h5".into(),
        };
        let cut = rec.without_warm_up(WarmUp::Seconds(0.3)).unwrap();
        assert_eq!(cut.len(), 7);
        assert_eq!(cut.inputs[0].data[0], 3.0);
        assert!((cut.t0 - 0.3).abs() < 1e-12);
        let e = rec
            .without_warm_up(WarmUp::Samples(10))
            .unwrap_err()
            .to_string();
        assert!(e.contains("r.h5") && e.contains("warm-up"), "{e}");
    }

    #[test]
    fn mat_channels_parse() {
        let c = MatChannel::parse("Acceleration[2]=accel:wing").unwrap();
        assert_eq!(c.variable, "Acceleration");
        assert_eq!(c.signal, Some(2));
        assert_eq!(c.name(), "accel:wing");
        let c = MatChannel::parse(" V1 = force_1").unwrap();
        assert_eq!((c.variable.as_str(), c.signal, c.dof), ("V1", None, 1));
        for bad in [
            "A[0]=accel_1",
            "A[x]=accel_1",
            "A=strain_1",
            "A",
            "A=accel_0",
        ] {
            let e = MatChannel::parse(bad).unwrap_err();
            assert!(e.contains(bad), "{e}");
        }
        assert_eq!(MatRate::parse("400"), MatRate::Hz(400.0));
        assert_eq!(MatRate::parse("Fs"), MatRate::Variable("Fs".into()));
    }

    #[test]
    fn point_names_parse_and_print() {
        assert_eq!(
            parse_point_name("accel:n12:uy"),
            Some((Quantity::Accel, "n12:uy"))
        );
        assert_eq!(parse_point_name("accel_5"), None);
        assert_eq!(parse_point_name("strain:n1"), None);
        assert_eq!(parse_point_name("accel:"), None);
        let c = Channel::at_point(Quantity::Force, "n20:uy", vec![0.0]);
        assert_eq!(c.name(), "force:n20:uy");
    }
}
