//! MATLAB v5 `.mat` records (compressed or not), through the `matfile`
//! crate, with a variable → channel mapping ([`MatMapping`]).
//!
//! A mapped variable is a real numeric vector (one dimension equal to 1),
//! or one signal of a real numeric matrix: a row of a matrix with more
//! columns than rows (`Acceleration` 3 × 73728, three signals along the
//! rows), a column of one with more rows than columns. Every channel has
//! the same length. `t0 = 0`; the rate is given or read from a real scalar
//! variable of any numeric class ([`MatRate`]); each channel's mean is
//! subtracted when `remove_mean` is set.
//!
//! Limits of `matfile` 0.5: MATLAB v7.3 files (HDF5-based) are not v5 and
//! are refused; a file holding any int32 array fails to parse (a known bug
//! of the parser), which is reported with the advice to re-save as double.

use super::csvio::{check_finite, Msg};
use super::{Channel, MatChannel, MatMapping, MatRate, Quantity, Record};
use crate::error::{Result, TacitError};
use std::collections::HashSet;
use std::path::Path;

/// Read a MATLAB v5 record with a variable → channel mapping. Errors name
/// the file, the variable and the row or column.
pub fn read(path: &Path, mapping: &MatMapping) -> Result<Record> {
    let err = |m: String| TacitError::record(path, m);
    check_mapping(mapping).map_err(err)?;
    let bytes = std::fs::read(path).map_err(|e| TacitError::io(path, e))?;
    let mat = parse(&bytes).map_err(err)?;
    let fs = rate(&mat, &mapping.fs).map_err(err)?;
    let mut rec = Record {
        t0: 0.0,
        fs,
        inputs: Vec::new(),
        outputs: Vec::new(),
        truth: None,
        source: path.to_path_buf(),
    };
    let mut first: Option<(String, usize)> = None;
    for ch in &mapping.channels {
        let mut data = signal(&mat, ch).map_err(err)?;
        let src = describe(ch);
        match &first {
            None => first = Some((src.clone(), data.len())),
            Some((v0, n0)) if data.len() != *n0 => {
                return Err(err(format!(
                    "{src} has {} samples but {v0} has {n0}",
                    data.len()
                )))
            }
            _ => {}
        }
        check_finite(&data, &format!("{src} (channel {})", ch.name())).map_err(err)?;
        if mapping.remove_mean && !data.is_empty() {
            let mean = data.iter().sum::<f64>() / data.len() as f64;
            data.iter_mut().for_each(|x| *x -= mean);
        }
        let c = Channel {
            point: ch.point.clone(),
            ..Channel::new(ch.quantity, ch.dof, data)
        };
        if ch.quantity == Quantity::Force {
            rec.inputs.push(c);
        } else {
            rec.outputs.push(c);
        }
    }
    if rec.is_empty() {
        return Err(err("the mapped variables hold no samples".into()));
    }
    Ok(rec)
}

/// `variable Acceleration[2]`: the mapped signal, for messages.
fn describe(ch: &MatChannel) -> String {
    format!("variable {}", ch.source())
}

/// A positive rate, at least one channel, DOFs from 1 (or a point label),
/// signals from 1, no channel twice.
fn check_mapping(m: &MatMapping) -> Msg<()> {
    match &m.fs {
        MatRate::Hz(fs) if !(fs.is_finite() && *fs > 0.0) => {
            return Err(format!("mapping: sample rate {fs} Hz is not positive"));
        }
        MatRate::Variable(v) if v.is_empty() => {
            return Err("mapping: the sample-rate variable has no name".into());
        }
        _ => {}
    }
    if m.channels.is_empty() {
        return Err("mapping: no variable is mapped to a channel".into());
    }
    let mut seen = HashSet::new();
    for ch in &m.channels {
        let name = ch.name();
        let var = ch.source();
        if ch.dof == 0 && ch.point.is_none() {
            return Err(format!("mapping {var} → {name}: DOFs are numbered from 1"));
        }
        if ch.signal == Some(0) {
            return Err(format!(
                "mapping {var} → {name}: rows and columns are numbered from 1"
            ));
        }
        if !seen.insert(name.clone()) {
            return Err(format!("mapping: channel {name} is mapped twice"));
        }
    }
    Ok(())
}

/// The sample rate: given, or a real positive scalar variable of the file.
fn rate(mat: &matfile::MatFile, fs: &MatRate) -> Msg<f64> {
    let var = match fs {
        MatRate::Hz(hz) => return Ok(*hz),
        MatRate::Variable(v) => v,
    };
    let arr = find(mat, var)?;
    let vals = to_f64(arr.data())
        .ok_or_else(|| format!("sample-rate variable {var} is complex: expected a real scalar"))?;
    match vals.as_slice() {
        [v] if v.is_finite() && *v > 0.0 => Ok(*v),
        [v] => Err(format!(
            "sample-rate variable {var} = {v}: a rate must be finite and > 0 Hz"
        )),
        _ => Err(format!(
            "sample-rate variable {var} has {} values ({}): expected a scalar",
            vals.len(),
            dims(arr.size())
        )),
    }
}

/// `3x73728`.
fn dims(size: &[usize]) -> String {
    let d: Vec<String> = size.iter().map(|d| d.to_string()).collect();
    d.join("x")
}

/// Parse the bytes of a MAT v5 file; never panics.
fn parse(bytes: &[u8]) -> Msg<matfile::MatFile> {
    if bytes.is_empty() {
        return Err("the file is empty".into());
    }
    if bytes.len() < 128 || !bytes.starts_with(b"MATLAB") {
        return Err("not a MATLAB .mat file (no MATLAB header)".into());
    }
    if bytes.starts_with(b"MATLAB 7.3") {
        return Err(
            "MATLAB v7.3 (HDF5-based) files are not supported: re-save with save(..., '-v7') or export to CSV"
                .into(),
        );
    }
    let parsed = std::panic::catch_unwind(|| matfile::MatFile::parse(bytes));
    match parsed {
        Ok(Ok(mat)) => Ok(mat),
        Ok(Err(e)) => Err(format!(
            "cannot parse as MATLAB v5 ({e}); note that the reader cannot handle files holding int32 arrays: re-save them as double"
        )),
        Err(_) => Err("the MATLAB v5 parser failed on this file (corrupt or unsupported content)".into()),
    }
}

/// The variable named `var`; the error lists the variables found.
fn find<'a>(mat: &'a matfile::MatFile, var: &str) -> Msg<&'a matfile::Array> {
    mat.find_by_name(var).ok_or_else(|| {
        let found: Vec<&str> = mat.arrays().iter().map(|a| a.name()).collect();
        format!(
            "variable {var} not found; the file holds the numeric variables: {}",
            if found.is_empty() {
                "(none)".to_string()
            } else {
                found.join(", ")
            }
        )
    })
}

/// The mapped signal as f64: a whole vector variable, or one row (column)
/// of a matrix whose longer dimension is time. Errors name the variable,
/// its size and the row.
fn signal(mat: &matfile::MatFile, ch: &MatChannel) -> Msg<Vec<f64>> {
    let var = &ch.variable;
    let arr = find(mat, var)?;
    let size = arr.size();
    let data = to_f64(arr.data())
        .ok_or_else(|| format!("variable {var} is complex: expected real values"))?;
    let non_unit = size.iter().filter(|d| **d != 1).count();
    if non_unit <= 1 {
        return match ch.signal {
            None | Some(1) => Ok(data),
            Some(r) => Err(format!(
                "variable {var} has size {}: a vector holds one signal, not signal {r}",
                dims(size)
            )),
        };
    }
    if size.len() != 2 {
        return Err(format!(
            "variable {var} has size {}: expected a vector or a matrix",
            dims(size)
        ));
    }
    let (rows, cols) = (size[0], size[1]);
    let Some(r) = ch.signal else {
        return Err(format!(
            "variable {var} is a {rows}x{cols} matrix: name its signal, e.g. {var}[1]=... (rows of a wide matrix, columns of a tall one)"
        ));
    };
    if rows == cols {
        return Err(format!(
            "variable {var} is a square {rows}x{cols} matrix: which dimension is time is ambiguous"
        ));
    }
    // column-major storage: element (i, j) at i + rows * j
    if rows < cols {
        if r > rows {
            return Err(format!(
                "variable {var} row {r}: the {rows}x{cols} matrix has {rows} rows (signals along its rows)"
            ));
        }
        Ok((0..cols).map(|j| data[(r - 1) + rows * j]).collect())
    } else {
        if r > cols {
            return Err(format!(
                "variable {var} column {r}: the {rows}x{cols} matrix has {cols} columns (signals along its columns)"
            ));
        }
        Ok(data[rows * (r - 1)..rows * r].to_vec())
    }
}

/// Real part as f64, `None` for complex data.
fn to_f64(data: &matfile::NumericData) -> Option<Vec<f64>> {
    use matfile::NumericData as D;
    fn conv<T: Copy>(real: &[T], imag: &Option<Vec<T>>, f: fn(T) -> f64) -> Option<Vec<f64>> {
        imag.is_none().then(|| real.iter().map(|x| f(*x)).collect())
    }
    match data {
        D::Int8 { real, imag } => conv(real, imag, f64::from),
        D::UInt8 { real, imag } => conv(real, imag, f64::from),
        D::Int16 { real, imag } => conv(real, imag, f64::from),
        D::UInt16 { real, imag } => conv(real, imag, f64::from),
        D::Int32 { real, imag } => conv(real, imag, f64::from),
        D::UInt32 { real, imag } => conv(real, imag, f64::from),
        D::Int64 { real, imag } => conv(real, imag, |x| x as f64),
        D::UInt64 { real, imag } => conv(real, imag, |x| x as f64),
        D::Single { real, imag } => conv(real, imag, f64::from),
        D::Double { real, imag } => conv(real, imag, |x| x),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Silverbox file, or `None` (test skipped) when absent.
    fn silverbox() -> Option<std::path::PathBuf> {
        crate::record::shared_data("silverbox/SNLS80mV.mat")
    }

    fn mapping(remove_mean: bool) -> MatMapping {
        MatMapping {
            channels: vec![
                MatChannel::at_dof("V1", Quantity::Force, 1),
                MatChannel::at_dof("V2", Quantity::Disp, 1),
            ],
            fs: MatRate::Hz(610.3515625),
            remove_mean,
        }
    }

    fn mean(x: &[f64]) -> f64 {
        x.iter().sum::<f64>() / x.len() as f64
    }

    #[test]
    fn reads_silverbox() {
        let Some(silverbox) = silverbox() else {
            return;
        };
        let rec = read(&silverbox, &mapping(false)).unwrap();
        assert_eq!(rec.len(), 131072);
        assert_eq!(rec.fs, 610.3515625);
        assert_eq!(rec.t0, 0.0);
        assert_eq!(rec.inputs[0].name(), "force_1");
        assert_eq!(rec.outputs[0].name(), "disp_1");
        assert_eq!(rec.outputs[0].data.len(), 131072);
        let m = mean(&rec.inputs[0].data);
        assert!((m - 0.006182).abs() < 1e-5, "V1 mean = {m}");
        rec.validate(Some(1)).unwrap();
    }

    #[test]
    fn removes_mean() {
        let Some(silverbox) = silverbox() else {
            return;
        };
        let rec = read(&silverbox, &mapping(true)).unwrap();
        assert!(mean(&rec.inputs[0].data).abs() < 1e-12);
        assert!(mean(&rec.outputs[0].data).abs() < 1e-12);
    }

    #[test]
    fn missing_variable_lists_found() {
        let Some(silverbox) = silverbox() else {
            return;
        };
        let mut m = mapping(false);
        m.channels
            .push(MatChannel::at_dof("V3", Quantity::Accel, 2));
        let e = read(&silverbox, &m).unwrap_err().to_string();
        assert!(e.contains("variable V3 not found"), "{e}");
        assert!(e.contains("V1") && e.contains("V2"), "{e}");
    }

    #[test]
    fn bad_files_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("empty.mat");
        std::fs::write(&p, b"").unwrap();
        let e = read(&p, &mapping(false)).unwrap_err().to_string();
        assert!(e.contains("empty"), "{e}");

        let p = dir.path().join("garbage.mat");
        std::fs::write(&p, vec![0x5au8; 1000]).unwrap();
        let e = read(&p, &mapping(false)).unwrap_err().to_string();
        assert!(
            e.contains("garbage.mat") && e.contains("not a MATLAB"),
            "{e}"
        );

        // A valid header followed by garbage.
        let mut bytes = b"MATLAB 5.0 MAT-file, Platform: GLNXA64".to_vec();
        bytes.resize(116, b' ');
        bytes.extend_from_slice(&[0; 8]);
        bytes.extend_from_slice(&[0x00, 0x01, b'I', b'M']);
        bytes.extend_from_slice(&[0xff; 300]);
        let p = dir.path().join("corrupt.mat");
        std::fs::write(&p, bytes).unwrap();
        assert!(read(&p, &mapping(false)).is_err());
    }

    #[test]
    fn bad_mapping_is_an_error() {
        let Some(silverbox) = silverbox() else {
            return;
        };
        let mut m = mapping(false);
        m.fs = MatRate::Hz(0.0);
        assert!(read(&silverbox, &m).is_err());
        let mut m = mapping(false);
        m.channels[1] = MatChannel::at_dof("V2", Quantity::Force, 1);
        let e = read(&silverbox, &m).unwrap_err().to_string();
        assert!(e.contains("force_1 is mapped twice"), "{e}");
    }

    /// The F-16 Level-1 file, or `None` (test skipped) when absent.
    fn f16() -> Option<std::path::PathBuf> {
        crate::record::shared_data("f16/F16Data_FullMSine_Level1.mat")
    }

    fn row(r: usize, point: &str) -> MatChannel {
        MatChannel {
            variable: "Acceleration".into(),
            signal: Some(r),
            quantity: Quantity::Accel,
            dof: 0,
            point: Some(point.into()),
        }
    }

    fn f16_mapping() -> MatMapping {
        MatMapping {
            channels: vec![
                MatChannel {
                    point: Some("exc".into()),
                    ..MatChannel::at_dof("Force", Quantity::Force, 0)
                },
                row(1, "exc"),
                row(2, "wing"),
                row(3, "payload"),
            ],
            fs: MatRate::Variable("Fs".into()),
            remove_mean: false,
        }
    }

    #[test]
    fn reads_f16_rows_and_uint16_rate() {
        let Some(p) = f16() else {
            return;
        };
        let rec = read(&p, &f16_mapping()).unwrap();
        assert_eq!(rec.fs, 400.0);
        assert_eq!(rec.len(), 73728);
        let names: Vec<String> = rec.outputs.iter().map(|c| c.name()).collect();
        assert_eq!(names, ["accel:exc", "accel:wing", "accel:payload"]);
        assert_eq!(rec.inputs[0].name(), "force:exc");
        // the rows are distinct signals (not one row read three times, nor
        // a column-major mix-up, which would interleave them)
        let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
        let r: Vec<f64> = rec.outputs.iter().map(|c| rms(&c.data)).collect();
        assert!(r[0] != r[1] && r[1] != r[2], "{r:?}");
        let f = rms(&rec.inputs[0].data);
        assert!((f - 12.4).abs() < 0.3, "force RMS {f} N (SOURCE: 12.4 N)");
        // mapping one signal alone gives the same samples as the full read
        let one = MatMapping {
            channels: vec![row(2, "wing")],
            ..f16_mapping()
        };
        let alone = read(&p, &one).unwrap();
        assert_eq!(alone.outputs[0].data, rec.outputs[1].data);
    }

    #[test]
    fn f16_bad_rows_and_rates_are_named() {
        let Some(p) = f16() else {
            return;
        };
        let mut m = f16_mapping();
        m.channels[3] = row(4, "payload");
        let e = read(&p, &m).unwrap_err().to_string();
        assert!(
            e.contains("Acceleration row 4") && e.contains("3 rows") && e.contains("Level1"),
            "{e}"
        );
        let mut m = f16_mapping();
        m.channels[1].signal = None;
        let e = read(&p, &m).unwrap_err().to_string();
        assert!(e.contains("Acceleration") && e.contains("3x73728"), "{e}");
        let mut m = f16_mapping();
        m.fs = MatRate::Variable("Force".into());
        let e = read(&p, &m).unwrap_err().to_string();
        assert!(e.contains("Force") && e.contains("scalar"), "{e}");
        let mut m = f16_mapping();
        m.fs = MatRate::Variable("fs".into());
        let e = read(&p, &m).unwrap_err().to_string();
        assert!(
            e.contains("variable fs not found") && e.contains("Fs"),
            "{e}"
        );
    }

    /// A MATLAB v5 file (uncompressed, little-endian) holding real double
    /// matrices `(name, rows, cols, column-major data)`, built byte by byte
    /// after the MAT-file format description.
    fn v5_file(vars: &[(&str, usize, usize, Vec<f64>)]) -> Vec<u8> {
        let mut b = b"MATLAB 5.0 MAT-file, written by a tacit test".to_vec();
        b.resize(116, b' ');
        b.extend_from_slice(&[0; 8]);
        b.extend_from_slice(&0x0100u16.to_le_bytes());
        b.extend_from_slice(b"IM");
        let tag = |t: u32, n: usize| [t.to_le_bytes(), (n as u32).to_le_bytes()].concat();
        for (name, r, c, data) in vars {
            let mut e = tag(6, 8);
            e.extend_from_slice(&6u32.to_le_bytes()); // mxDOUBLE_CLASS
            e.extend_from_slice(&0u32.to_le_bytes());
            e.extend(tag(5, 8));
            e.extend_from_slice(&(*r as i32).to_le_bytes());
            e.extend_from_slice(&(*c as i32).to_le_bytes());
            e.extend(tag(1, name.len()));
            e.extend_from_slice(name.as_bytes());
            e.resize(e.len().div_ceil(8) * 8, 0);
            e.extend(tag(9, 8 * data.len()));
            data.iter()
                .for_each(|v| e.extend_from_slice(&v.to_le_bytes()));
            b.extend(tag(14, e.len()));
            b.extend(e);
        }
        b
    }

    #[test]
    fn tall_matrices_map_columns_and_wide_ones_rows() {
        let n = 6;
        // column-major: a tall N x 2 matrix, column j holds 10 j + k
        let tall: Vec<f64> = (0..2)
            .flat_map(|j| (0..n).map(move |k| (10 * j + k) as f64))
            .collect();
        // a wide 2 x N matrix, row i holds 100 i + k
        let wide: Vec<f64> = (0..n)
            .flat_map(|k| (0..2).map(move |i| (100 * i + k) as f64))
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.mat");
        let bytes = v5_file(&[
            ("T", n, 2, tall),
            ("W", 2, n, wide),
            ("fs", 1, 1, vec![50.0]),
        ]);
        std::fs::write(&p, bytes).unwrap();
        let ch = |v: &str, k: usize, d: usize| MatChannel {
            signal: Some(k),
            ..MatChannel::at_dof(v, Quantity::Accel, d)
        };
        let m = MatMapping {
            channels: vec![ch("T", 2, 1), ch("W", 2, 2)],
            fs: MatRate::Variable("fs".into()),
            remove_mean: false,
        };
        let rec = read(&p, &m).unwrap();
        assert_eq!(rec.fs, 50.0);
        assert_eq!(rec.outputs[0].data, [10.0, 11.0, 12.0, 13.0, 14.0, 15.0]);
        assert_eq!(
            rec.outputs[1].data,
            [100.0, 101.0, 102.0, 103.0, 104.0, 105.0]
        );
        let m = MatMapping {
            channels: vec![ch("T", 3, 1)],
            ..m
        };
        let e = read(&p, &m).unwrap_err().to_string();
        assert!(
            e.contains("variable T column 3") && e.contains("2 columns"),
            "{e}"
        );
    }
}
