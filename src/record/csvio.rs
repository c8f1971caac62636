//! CSV records: one header row, then one row per sample.
//!
//! Columns: `time` (s), then any of `force_<dof>` (N), `accel_<dof>`
//! (m/s²), `vel_<dof>` (m/s), `disp_<dof>` (m), DOFs numbered from 1, in any
//! order and any subset. The time column must be strictly increasing and
//! uniform: every stamp lies within `1e-6·dt` (plus `1e-10·|t|`, the rounding
//! of a stamp printed with 10 decimals) of the grid `t0 + k·dt`, where `dt`
//! is the mean step. The rate is `fs = (N − 1)/(t_{N−1} − t_0)` and
//! `t0 = t_0`. Lines starting with `#` are comments.
//!
//! Truth files ([`write_truth`], [`read_truth`]) hold
//! `time, disp_1..n, vel_1..n, accel_1..n, fint_1..n` (accel optional).
//!
//! Numbers are written in the shortest exponent form that reads back to the
//! same `f64` bit for bit.

use super::{Channel, Quantity, Record, Truth};
use crate::error::{Result, TacitError};
use std::collections::HashMap;
use std::path::Path;

/// Result with a plain message; the caller adds the file name.
pub(crate) type Msg<T> = std::result::Result<T, String>;

/// Relative tolerance on the time grid, in units of the mean step.
pub(crate) const TIME_RTOL: f64 = 1e-6;

/// Read a CSV record. Errors name the file, the column or channel, the
/// sample index and the line.
pub fn read(path: &Path) -> Result<Record> {
    let err = |m: String| TacitError::record(path, m);
    let table = read_table(path, |name| {
        if name == "time" {
            return Ok(());
        }
        if super::parse_point_name(name).is_some() {
            return Ok(());
        }
        parse_channel_name(name).map(|_| ())
    })?;
    let time = table.column("time").ok_or_else(|| {
        err("no time column: the header must hold `time` and channel columns such as force_1, accel_2".into())
    })?;
    let (t0, fs) = time_base_with(time, table.time_resolution).map_err(err)?;
    let mut rec = Record {
        t0,
        fs,
        inputs: Vec::new(),
        outputs: Vec::new(),
        truth: None,
        source: path.to_path_buf(),
    };
    for (name, data) in table.names.iter().zip(table.cols) {
        if name == "time" {
            continue;
        }
        let c = match super::parse_point_name(name) {
            Some((q, point)) => Channel::at_point(q, point, data),
            None => {
                let (q, dof) = parse_channel_name(name).map_err(err)?;
                Channel::new(q, dof, data)
            }
        };
        let q = c.quantity;
        if q == Quantity::Force {
            rec.inputs.push(c);
        } else {
            rec.outputs.push(c);
        }
    }
    if rec.inputs.is_empty() && rec.outputs.is_empty() {
        return Err(err(
            "no channel columns besides time (expected force_<dof>, accel_<dof>, vel_<dof> or disp_<dof>)".into(),
        ));
    }
    Ok(rec)
}

/// Write a record as CSV: `time`, then the inputs, then the outputs. The
/// truth is not written (see [`write_truth`]).
pub fn write(rec: &Record, path: &Path) -> Result<()> {
    let err = |m: String| TacitError::record(path, m);
    let n = rec.len();
    check_channel_lengths(rec).map_err(err)?;
    if rec.inputs.is_empty() && rec.outputs.is_empty() {
        return Err(err("the record holds no channel to write".into()));
    }
    let chans: Vec<&Channel> = rec.inputs.iter().chain(&rec.outputs).collect();
    let mut header = vec!["time".to_string()];
    header.extend(chans.iter().map(|c| c.name()));
    let cols: Vec<&[f64]> = chans.iter().map(|c| c.data.as_slice()).collect();
    write_table(path, &header, &rec.times(), &cols, n)
}

/// Write the truth of a simulated record as CSV:
/// `time, disp_1..n, vel_1..n, accel_1..n, fint_1..n` (the accel columns
/// only when the truth holds accelerations). The model TOML is not written.
pub fn write_truth(rec: &Record, path: &Path) -> Result<()> {
    let err = |m: String| TacitError::record(path, m);
    let truth = rec
        .truth
        .as_ref()
        .ok_or_else(|| err("the record holds no truth to write".into()))?;
    let n = truth.u.first().map_or(0, |r| r.len());
    check_truth(truth, n).map_err(err)?;
    let mut header = vec!["time".to_string()];
    let mut cols: Vec<&[f64]> = Vec::new();
    for (prefix, m) in [
        ("disp", &truth.u),
        ("vel", &truth.v),
        ("accel", &truth.a),
        ("fint", &truth.fint),
    ] {
        for (i, row) in m.iter().enumerate() {
            header.push(format!("{prefix}_{}", i + 1));
            cols.push(row);
        }
    }
    let times: Vec<f64> = (0..n).map(|k| rec.time(k)).collect();
    write_table(path, &header, &times, &cols, n)
}

/// Read a truth CSV (`time, disp_i, vel_i, fint_i` required for every DOF
/// `1..=n`, `accel_i` optional). Returns the time column and the truth (with
/// an empty `a` when there are no accel columns, and an empty model TOML).
pub fn read_truth(path: &Path) -> Result<(Vec<f64>, Truth)> {
    let err = |m: String| TacitError::record(path, m);
    let table = read_table(path, |name| {
        if name == "time" {
            return Ok(());
        }
        parse_truth_name(name).map(|_| ())
    })?;
    let time = table
        .column("time")
        .ok_or_else(|| err("no time column".into()))?
        .to_vec();
    time_base_with(&time, table.time_resolution).map_err(err)?;
    let mut by_kind: HashMap<&str, Vec<(usize, Vec<f64>)>> = HashMap::new();
    for (name, data) in table.names.iter().zip(table.cols) {
        if name != "time" {
            let (kind, dof) = parse_truth_name(name).map_err(err)?;
            by_kind.entry(kind).or_default().push((dof, data));
        }
    }
    let ndof = by_kind
        .get("disp")
        .and_then(|v| v.iter().map(|(d, _)| *d).max())
        .ok_or_else(|| err("no disp_<dof> column".into()))?;
    let mut take = |kind: &str, required: bool| -> Msg<Vec<Vec<f64>>> {
        let Some(mut cols) = by_kind.remove(kind) else {
            return if required {
                Err(format!("column {kind}_1 is missing"))
            } else {
                Ok(Vec::new())
            };
        };
        cols.sort_by_key(|(d, _)| *d);
        for i in 0..ndof {
            if cols.get(i).map(|(d, _)| *d) != Some(i + 1) {
                return Err(format!("column {kind}_{} is missing", i + 1));
            }
        }
        if let Some((d, _)) = cols.get(ndof) {
            return Err(format!("column {kind}_{d} has no matching disp_{d}"));
        }
        Ok(cols.into_iter().map(|(_, d)| d).collect())
    };
    let truth = Truth {
        u: take("disp", true).map_err(err)?,
        v: take("vel", true).map_err(err)?,
        a: take("accel", false).map_err(err)?,
        fint: take("fint", true).map_err(err)?,
        model_toml: String::new(),
    };
    Ok((time, truth))
}

/// Parse a channel name `<quantity>_<dof>` (`accel_5`), DOF from 1.
pub(crate) fn parse_channel_name(name: &str) -> Msg<(Quantity, usize)> {
    let bad = || {
        format!(
            "unknown column \"{name}\": expected time, force_<dof>, accel_<dof>, vel_<dof> or disp_<dof> (DOF from 1)"
        )
    };
    let (prefix, dof) = name.split_once('_').ok_or_else(bad)?;
    let q = Quantity::from_prefix(prefix).ok_or_else(bad)?;
    let dof = parse_dof(dof).ok_or_else(bad)?;
    Ok((q, dof))
}

/// Parse a truth column name `<disp|vel|accel|fint>_<dof>`.
fn parse_truth_name(name: &str) -> Msg<(&'static str, usize)> {
    let bad = || {
        format!(
            "unknown column \"{name}\": expected time, disp_<dof>, vel_<dof>, accel_<dof> or fint_<dof> (DOF from 1)"
        )
    };
    let (prefix, dof) = name.split_once('_').ok_or_else(bad)?;
    let kind = ["disp", "vel", "accel", "fint"]
        .into_iter()
        .find(|k| *k == prefix)
        .ok_or_else(bad)?;
    Ok((kind, parse_dof(dof).ok_or_else(bad)?))
}

/// A DOF number: decimal digits only, at least 1.
fn parse_dof(s: &str) -> Option<usize> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok().filter(|d| *d >= 1)
}

/// Check a time column: finite, strictly increasing, at least 2 samples and
/// on a uniform grid. Returns `(t0, fs)`; errors name the sample.
pub(crate) fn time_base(t: &[f64]) -> Msg<(f64, f64)> {
    time_base_with(t, 0.0)
}

/// [`time_base`] with stamps known only to `resolution` seconds (half a
/// unit of the last printed decimal).
pub(crate) fn time_base_with(t: &[f64], resolution: f64) -> Msg<(f64, f64)> {
    check_finite(t, "time")?;
    if t.len() < 2 {
        return Err(format!(
            "{} sample(s): at least 2 are needed to define the sample rate",
            t.len()
        ));
    }
    for k in 1..t.len() {
        if t[k] <= t[k - 1] {
            return Err(format!(
                "time: sample {k} is not increasing ({} s after {} s)",
                t[k],
                t[k - 1]
            ));
        }
    }
    let n = t.len();
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    if resolution > 0.25 * dt {
        return Err(format!(
            "time: the stamps are printed to {} s, too coarse for a step of {dt} s (print more decimals)",
            2.0 * resolution
        ));
    }
    for (k, &tk) in t.iter().enumerate() {
        let expected = t[0] + k as f64 * dt;
        // a stamp's own rounding and that of the two ends defining the grid
        let tol = (TIME_RTOL * dt + 1e-10 * tk.abs()).max(2.0 * resolution);
        if (tk - expected).abs() > tol {
            return Err(format!(
                "time: sample {k} is not on a uniform grid: {tk} s, expected {expected} s (mean step {dt} s, tolerance {tol:.3e} s)"
            ));
        }
    }
    Ok((t[0], (n - 1) as f64 / (t[n - 1] - t[0])))
}

/// Error naming the first non-finite sample: `"{label}: sample 17 is NaN"`.
pub(crate) fn check_finite(data: &[f64], label: &str) -> Msg<()> {
    match data.iter().position(|x| !x.is_finite()) {
        Some(k) => Err(format!("{label}: sample {k} is {}", data[k])),
        None => Ok(()),
    }
}

/// Every channel holds `rec.len()` samples.
pub(crate) fn check_channel_lengths(rec: &Record) -> Msg<()> {
    let n = rec.len();
    for c in rec.inputs.iter().chain(&rec.outputs) {
        if c.data.len() != n {
            return Err(format!(
                "channel {} has {} samples, expected {n}",
                c.name(),
                c.data.len()
            ));
        }
    }
    Ok(())
}

/// The truth is rectangular: u, v, fint (and a, unless empty) have the same
/// number of DOFs (at least 1) and `n` samples per DOF.
pub(crate) fn check_truth(t: &Truth, n: usize) -> Msg<()> {
    let ndof = t.u.len();
    if ndof == 0 {
        return Err("the truth holds no DOF".into());
    }
    for (name, m) in [("u", &t.u), ("v", &t.v), ("a", &t.a), ("fint", &t.fint)] {
        if name == "a" && m.is_empty() {
            continue;
        }
        if m.len() != ndof {
            return Err(format!("truth {name} has {} DOFs, u has {ndof}", m.len()));
        }
        if let Some(i) = m.iter().position(|r| r.len() != n) {
            return Err(format!(
                "truth {name} at DOF {} has {} samples, expected {n}",
                i + 1,
                m[i].len()
            ));
        }
    }
    Ok(())
}

/// A CSV file read column by column.
struct Table {
    names: Vec<String>,
    cols: Vec<Vec<f64>>,
    /// How finely the time column is known, s ([`time_resolution`]).
    time_resolution: f64,
}

/// Decimals of a number's mantissa as printed and its exponent:
/// `0.001953` → (6, 0), `1.953125e-3` → (6, -3), `12` → (0, 0).
fn printed_digits(field: &str) -> (usize, i32) {
    let (mantissa, exp) = match field.find(['e', 'E']) {
        Some(i) => (&field[..i], field[i + 1..].parse::<i32>().unwrap_or(0)),
        None => (field, 0),
    };
    (mantissa.split_once('.').map_or(0, |(_, f)| f.len()), exp)
}

/// How finely a time column is known: a column printed with a fixed
/// count `d > 0` of decimals (as `%.6f` or `%.6e` write it) is known to
/// half a unit of its last decimal, `0.5·10^(e−d)` at the largest
/// exponent `e`; a column printed in shortest form (varying counts) or as
/// integers is taken as exact (0).
fn time_resolution(digits: &[(usize, i32)]) -> f64 {
    let Some(&(d, _)) = digits.first() else {
        return 0.0;
    };
    if d == 0 || digits.iter().any(|&(di, _)| di != d) {
        return 0.0;
    }
    let e = digits.iter().map(|&(_, e)| e).max().unwrap_or(0);
    0.5 * 10f64.powi(e - d as i32)
}

impl Table {
    fn column(&self, name: &str) -> Option<&[f64]> {
        let i = self.names.iter().position(|n| n == name)?;
        Some(&self.cols[i])
    }
}

/// Read a numeric CSV with a header; `check_name` accepts or rejects each
/// column name before any value is read.
fn read_table(path: &Path, check_name: impl Fn(&str) -> Msg<()>) -> Result<Table> {
    let err = |m: String| TacitError::record(path, m);
    let file = std::fs::File::open(path).map_err(|e| TacitError::io(path, e))?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(std::io::BufReader::new(file));
    let names: Vec<String> = rdr
        .headers()
        .map_err(|e| err(format!("cannot read the header: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    if names.is_empty() || names.iter().all(|n| n.is_empty()) {
        return Err(err("the file is empty (no header row)".into()));
    }
    check_header(&names, &check_name).map_err(err)?;
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut row = csv::StringRecord::new();
    let mut k = 0usize;
    let time_col = names.iter().position(|n| n == "time");
    let mut time_digits = vec![];
    loop {
        match rdr.read_record(&mut row) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(err(format!("sample {k}: {e}"))),
        }
        let line = row.position().map_or(0, |p| p.line());
        if row.len() != names.len() {
            return Err(err(format!(
                "line {line} (sample {k}) has {} fields, the header has {}",
                row.len(),
                names.len()
            )));
        }
        for ((field, col), name) in row.iter().zip(&mut cols).zip(&names) {
            col.push(parse_value(field, name, k, line).map_err(err)?);
        }
        if let Some(field) = time_col.and_then(|i| row.get(i)) {
            time_digits.push(printed_digits(field));
        }
        k += 1;
    }
    match k {
        0 => Err(err("no data rows (header only)".into())),
        1 => Err(err("only 1 sample: at least 2 are needed".into())),
        _ => Ok(Table {
            names,
            cols,
            time_resolution: time_resolution(&time_digits),
        }),
    }
}

/// Header names are known and unique.
fn check_header(names: &[String], check_name: &impl Fn(&str) -> Msg<()>) -> Msg<()> {
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for (i, name) in names.iter().enumerate() {
        if let Some(j) = seen.insert(name, i) {
            return Err(format!(
                "column {name} appears twice (columns {} and {})",
                j + 1,
                i + 1
            ));
        }
        check_name(name).map_err(|m| format!("{m} (column {})", i + 1))?;
    }
    Ok(())
}

/// One finite number; errors name the channel, sample and line.
fn parse_value(field: &str, name: &str, k: usize, line: u64) -> Msg<f64> {
    let label = if name == "time" {
        "time".to_string()
    } else {
        format!("channel {name}")
    };
    if field.is_empty() {
        return Err(format!("{label}: sample {k} is empty (line {line})"));
    }
    match field.parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        Ok(x) => Err(format!("{label}: sample {k} is {x} (line {line})")),
        Err(_) => Err(format!(
            "{label}: sample {k} is not a number: \"{field}\" (line {line})"
        )),
    }
}

/// Write `time` and columns, `n` rows, numbers in round-trip form.
fn write_table(
    path: &Path,
    header: &[String],
    time: &[f64],
    cols: &[&[f64]],
    n: usize,
) -> Result<()> {
    let err = |e: csv::Error| TacitError::record(path, format!("cannot write: {e}"));
    let mut w = csv::Writer::from_path(path).map_err(err)?;
    w.write_record(header).map_err(err)?;
    let mut row: Vec<String> = Vec::with_capacity(header.len());
    for k in 0..n {
        row.clear();
        row.push(format!("{:e}", time[k]));
        row.extend(cols.iter().map(|c| format!("{:e}", c[k])));
        w.write_record(&row).map_err(err)?;
    }
    w.flush().map_err(|e| TacitError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_record() -> Record {
        let n = 50;
        let f: Vec<f64> = (0..n).map(|k| (k as f64 * 0.37).sin() * 3.1).collect();
        let a: Vec<f64> = (0..n).map(|k| (k as f64 * 0.11).cos() * 1e-7).collect();
        let d: Vec<f64> = (0..n).map(|k| 1.0 / (k as f64 + 3.0)).collect();
        Record {
            t0: 0.0,
            fs: 1024.0,
            inputs: vec![Channel::new(Quantity::Force, 2, f)],
            outputs: vec![
                Channel::new(Quantity::Accel, 10, a),
                Channel::new(Quantity::Disp, 1, d),
            ],
            truth: None,
            source: Default::default(),
        }
    }

    /// Write `text` to a file in a fresh directory and read it as a record.
    fn read_text(text: &str) -> Result<Record> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.csv");
        std::fs::write(&p, text).unwrap();
        read(&p)
    }

    fn err_text(text: &str) -> String {
        read_text(text).unwrap_err().to_string()
    }

    #[test]
    fn round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rec.csv");
        let rec = sample_record();
        write(&rec, &p).unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back.inputs, rec.inputs);
        assert_eq!(back.outputs, rec.outputs);
        assert_eq!(back.t0, rec.t0);
        assert!((back.fs - rec.fs).abs() <= 1e-12 * rec.fs);
        assert_eq!(back.source, p);
    }

    #[test]
    fn round_trip_with_offset_and_odd_rate() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rec.csv");
        let mut rec = sample_record();
        rec.t0 = 12.345;
        rec.fs = 610.3515625 * 3.0 / 7.0;
        write(&rec, &p).unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back.outputs, rec.outputs);
        assert_eq!(back.t0, rec.t0);
        assert!((back.fs - rec.fs).abs() <= 1e-9 * rec.fs, "{}", back.fs);
    }

    #[test]
    fn reads_reference_record() {
        let Some(path) = crate::record::shared_data("reference/lanl8dof-contact-ref.csv") else {
            return;
        };
        let rec = read(&path).unwrap();
        assert_eq!(rec.len(), 4096);
        assert!((rec.fs - 512.0).abs() < 1e-9, "fs = {}", rec.fs);
        assert_eq!(rec.t0, 0.0);
        let names: Vec<String> = rec.inputs.iter().map(|c| c.name()).collect();
        assert_eq!(names, ["force_1"]);
        let names: Vec<String> = rec.outputs.iter().map(|c| c.name()).collect();
        let want: Vec<String> = (1..=8).map(|i| format!("accel_{i}")).collect();
        assert_eq!(names, want);
        let a1 = &rec.output(Quantity::Accel, 1).unwrap().data;
        assert_eq!(a1[0], 0.0);
        assert!((a1[1] - -1.1640454842e+01).abs() < 1e-9);
        assert!((a1[2] - 1.3752018907e+01).abs() < 1e-9);
        assert!((rec.inputs[0].data[1] - -6.9713849568e+00).abs() < 1e-9);
        assert_eq!(rec.inputs[0].unit, "N");
        rec.validate(Some(8)).unwrap();
    }

    #[test]
    fn reads_reference_truth() {
        let Some(path) = crate::record::shared_data("reference/lanl8dof-contact-ref-truth.csv")
        else {
            return;
        };
        let (time, truth) = read_truth(&path).unwrap();
        assert_eq!(time.len(), 4096);
        assert!((time[1] - 1.953125e-3).abs() < 1e-15);
        assert_eq!(truth.u.len(), 8);
        assert_eq!(truth.v.len(), 8);
        assert_eq!(truth.fint.len(), 8);
        assert!(truth.a.is_empty());
        assert!(truth.u.iter().all(|r| r.len() == 4096));
        assert!((truth.u[0][1] - -7.7576821914e-06).abs() < 1e-15);
        assert!((truth.v[0][1] - -1.1753118196e-02).abs() < 1e-12);
        // Contact 5→6: equal and opposite internal forces, active sometimes.
        let active = truth.fint[4].iter().filter(|f| **f > 0.0).count();
        assert!(active > 0);
        for k in 0..4096 {
            assert!((truth.fint[4][k] + truth.fint[5][k]).abs() < 1e-6);
        }
    }

    #[test]
    fn truth_round_trip_with_accel() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("truth.csv");
        let mut rec = sample_record();
        let row = |s: f64| (0..rec.len()).map(|k| s * (k as f64).sqrt()).collect();
        let truth = Truth {
            u: vec![row(1e-6), row(2e-6)],
            v: vec![row(1e-3), row(-2e-3)],
            a: vec![row(1.5), row(2.5)],
            fint: vec![row(0.0), row(7.0)],
            model_toml: String::new(),
        };
        rec.truth = Some(truth.clone());
        write_truth(&rec, &p).unwrap();
        let header = std::fs::read_to_string(&p).unwrap();
        assert!(
            header.starts_with("time,disp_1,disp_2,vel_1,vel_2,accel_1,accel_2,fint_1,fint_2\n")
        );
        let (time, back) = read_truth(&p).unwrap();
        assert_eq!(back, truth);
        assert_eq!(time, rec.times());
    }

    #[test]
    fn truth_missing_column_is_named() {
        let e =
            read_truth_text("time,disp_1,disp_2,vel_1,vel_2,fint_1\n0,1,1,1,1,1\n1,1,1,1,1,1\n");
        assert!(e.contains("fint_2"), "{e}");
        let e = read_truth_text("time,disp_1,vel_1\n0,1,1\n1,1,1\n");
        assert!(e.contains("fint_1"), "{e}");
    }

    fn read_truth_text(text: &str) -> String {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.csv");
        std::fs::write(&p, text).unwrap();
        read_truth(&p).unwrap_err().to_string()
    }

    #[test]
    fn write_truth_without_truth_fails() {
        let dir = tempfile::tempdir().unwrap();
        let e = write_truth(&sample_record(), &dir.path().join("t.csv")).unwrap_err();
        assert!(e.to_string().contains("no truth"), "{e}");
    }

    #[test]
    fn nan_names_channel_and_sample() {
        let e = err_text("time,force_1,accel_5\n0,1,2\n0.1,1,2\n0.2,1,NaN\n0.3,1,2\n");
        assert!(e.contains("channel accel_5: sample 2 is NaN"), "{e}");
        assert!(e.contains("line 4"), "{e}");
        let e = err_text("time,force_1\n0,1\n0.1,inf\n");
        assert!(e.contains("channel force_1: sample 1 is inf"), "{e}");
        let e = err_text("time,force_1\n0,1\n0.1,abc\n");
        assert!(
            e.contains("sample 1 is not a number") && e.contains("abc"),
            "{e}"
        );
    }

    #[test]
    fn non_uniform_time_names_sample() {
        let e = err_text("time,force_1\n0,1\n0.1,1\n0.2,1\n0.31,1\n0.4,1\n");
        assert!(e.contains("time: sample 3"), "{e}");
        let e = err_text("time,force_1\n0,1\n0.1,1\n0.1,1\n0.3,1\n");
        assert!(e.contains("time: sample 2 is not increasing"), "{e}");
    }

    #[test]
    fn header_errors_are_named() {
        let e = err_text("time,force_1,force_1\n0,1,1\n1,1,1\n");
        assert!(e.contains("force_1 appears twice"), "{e}");
        let e = err_text("time,force_1,strain_2\n0,1,1\n1,1,1\n");
        assert!(e.contains("unknown column \"strain_2\""), "{e}");
        let e = err_text("time,accel_0\n0,1\n1,1\n");
        assert!(e.contains("accel_0"), "{e}");
        let e = err_text("force_1,accel_1\n0,1\n1,1\n");
        assert!(e.contains("no time column"), "{e}");
        let e = err_text("time\n0\n1\n");
        assert!(e.contains("no channel"), "{e}");
    }

    #[test]
    fn truncated_row_names_line() {
        let e = err_text("time,force_1,accel_1\n0,1,1\n0.5,1\n1,1,1\n");
        assert!(e.contains("line 3") && e.contains("2 fields"), "{e}");
    }

    #[test]
    fn empty_and_short_files() {
        assert!(err_text("").contains("empty"));
        assert!(err_text("time,force_1\n").contains("header only"));
        assert!(err_text("time,force_1\n0,1\n").contains("only 1 sample"));
        let e = err_text("");
        assert!(e.contains("r.csv"), "the message names the file: {e}");
        let e = read_truth_text("time,disp_1,vel_1,fint_1,fint_2\n0,1,1,1,1\n1,1,1,1,1\n");
        assert!(e.contains("fint_2 has no matching disp_2"), "{e}");
    }

    #[test]
    fn spaces_and_column_order_are_accepted() {
        let rec =
            read_text("accel_2, time ,force_3\n1.5, 0.0, 2\n2.5, 0.25, 3\n3.5,0.5,4\n").unwrap();
        assert_eq!(rec.fs, 4.0);
        assert_eq!(rec.inputs[0].name(), "force_3");
        assert_eq!(rec.outputs[0].data, [1.5, 2.5, 3.5]);
    }

    #[test]
    fn long_record_with_ten_decimals_is_uniform() {
        // 100 s at 1 kHz printed with {:.10e}: stamp rounding 5e-10 s > 1e-6·dt.
        let t: Vec<f64> = (0..100_000)
            .map(|k| format!("{:.10e}", k as f64 / 1000.0).parse().unwrap())
            .collect();
        let (t0, fs) = time_base(&t).unwrap();
        assert_eq!(t0, 0.0);
        assert!((fs - 1000.0).abs() < 1e-6);
    }

    #[test]
    fn six_decimal_stamps_are_accepted_and_coarser_ones_named() {
        // 8 s at 512 Hz printed with %.6f (rounding up to 5e-7 s = 2.6e-4 step)
        let mut text = String::from("time,force_1\n");
        for k in 0..4096 {
            text.push_str(&format!("{:.6},1\n", k as f64 / 512.0));
        }
        let rec = read_text(&text).unwrap();
        assert!((rec.fs - 512.0).abs() < 1e-3, "{}", rec.fs);
        // a real jump of 2e-5 s is still found
        let mut bad = String::from("time,force_1\n");
        for k in 0..64 {
            let t = k as f64 / 512.0 + if k == 40 { 2e-5 } else { 0.0 };
            bad.push_str(&format!("{t:.6},1\n"));
        }
        let e = err_text(&bad);
        assert!(
            e.contains("time: sample 40 is not on a uniform grid"),
            "{e}"
        );
        // two decimals cannot resolve a 512 Hz step
        let e = err_text("time,force_1\n0.00,1\n0.00,1\n");
        assert!(e.contains("not increasing"), "{e}");
        let mut coarse = String::from("time,force_1\n");
        for k in 0..10 {
            coarse.push_str(&format!("{:.2},1\n", k as f64 / 64.0));
        }
        let e = err_text(&coarse);
        assert!(e.contains("too coarse"), "{e}");
        let r = |fields: &[&str]| {
            time_resolution(&fields.iter().map(|f| printed_digits(f)).collect::<Vec<_>>())
        };
        assert!((r(&["0.000000", "0.001953"]) / 5e-7 - 1.0).abs() < 1e-12);
        assert!((r(&["1.953125e-3", "3.906250e-3"]) / 5e-10 - 1.0).abs() < 1e-12);
        assert_eq!(r(&["0", "0.1", "0.25"]), 0.0, "shortest form is exact");
        assert_eq!(r(&["0", "1", "2"]), 0.0, "integers are exact");
    }
}
