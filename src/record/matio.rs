//! MATLAB v5 `.mat` records (compressed or not), through the `matfile`
//! crate, with a variable → channel mapping ([`MatMapping`]).
//!
//! Each mapped variable must be a real numeric vector (one dimension equal
//! to 1); all have the same length. `t0 = 0`, `fs` comes from the mapping,
//! and each channel's mean is subtracted when `remove_mean` is set.
//!
//! Limits of `matfile` 0.5: MATLAB v7.3 files (HDF5-based) are not v5 and
//! are refused; a file holding any int32 array fails to parse (a known bug
//! of the parser), which is reported with the advice to re-save as double.

use super::csvio::{check_finite, Msg};
use super::{Channel, MatMapping, Quantity, Record};
use crate::error::{Result, TacitError};
use std::collections::HashSet;
use std::path::Path;

/// Read a MATLAB v5 record with a variable → channel mapping. Errors name
/// the file and the variable.
pub fn read(path: &Path, mapping: &MatMapping) -> Result<Record> {
    let err = |m: String| TacitError::record(path, m);
    check_mapping(mapping).map_err(err)?;
    let bytes = std::fs::read(path).map_err(|e| TacitError::io(path, e))?;
    let mat = parse(&bytes).map_err(err)?;
    let mut rec = Record {
        t0: 0.0,
        fs: mapping.fs,
        inputs: Vec::new(),
        outputs: Vec::new(),
        truth: None,
        source: path.to_path_buf(),
    };
    let mut first: Option<(&str, usize)> = None;
    for (var, q, dof) in &mapping.channels {
        let mut data = variable(&mat, var).map_err(err)?;
        match first {
            None => first = Some((var.as_str(), data.len())),
            Some((v0, n0)) if data.len() != n0 => {
                return Err(err(format!(
                    "variable {var} has {} samples but {v0} has {n0}",
                    data.len()
                )))
            }
            _ => {}
        }
        let c = Channel::new(*q, *dof, Vec::new());
        check_finite(&data, &format!("variable {var} (channel {})", c.name())).map_err(err)?;
        if mapping.remove_mean && !data.is_empty() {
            let mean = data.iter().sum::<f64>() / data.len() as f64;
            data.iter_mut().for_each(|x| *x -= mean);
        }
        let c = Channel { data, ..c };
        if *q == Quantity::Force {
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

/// A positive rate, at least one channel, DOFs from 1, no channel twice.
fn check_mapping(m: &MatMapping) -> Msg<()> {
    if !(m.fs.is_finite() && m.fs > 0.0) {
        return Err(format!("mapping: sample rate {} Hz is not positive", m.fs));
    }
    if m.channels.is_empty() {
        return Err("mapping: no variable is mapped to a channel".into());
    }
    let mut seen = HashSet::new();
    for (var, q, dof) in &m.channels {
        let name = format!("{}_{dof}", q.prefix());
        if *dof == 0 {
            return Err(format!("mapping {var} → {name}: DOFs are numbered from 1"));
        }
        if !seen.insert(name.clone()) {
            return Err(format!("mapping: channel {name} is mapped twice"));
        }
    }
    Ok(())
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

/// A real numeric vector as f64; errors list the variables found.
fn variable(mat: &matfile::MatFile, var: &str) -> Msg<Vec<f64>> {
    let Some(arr) = mat.find_by_name(var) else {
        let found: Vec<&str> = mat.arrays().iter().map(|a| a.name()).collect();
        return Err(format!(
            "variable {var} not found; the file holds the numeric variables: {}",
            if found.is_empty() {
                "(none)".to_string()
            } else {
                found.join(", ")
            }
        ));
    };
    let size = arr.size();
    if size.iter().filter(|d| **d != 1).count() > 1 {
        let dims: Vec<String> = size.iter().map(|d| d.to_string()).collect();
        return Err(format!(
            "variable {var} has size {}: expected a vector (all dimensions but one equal to 1)",
            dims.join("x")
        ));
    }
    to_f64(arr.data()).ok_or_else(|| format!("variable {var} is complex: expected real values"))
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
                ("V1".into(), Quantity::Force, 1),
                ("V2".into(), Quantity::Disp, 1),
            ],
            fs: 610.3515625,
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
        m.channels.push(("V3".into(), Quantity::Accel, 2));
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
        m.fs = 0.0;
        assert!(read(&silverbox, &m).is_err());
        let mut m = mapping(false);
        m.channels[1] = ("V2".into(), Quantity::Force, 1);
        let e = read(&silverbox, &m).unwrap_err().to_string();
        assert!(e.contains("force_1 is mapped twice"), "{e}");
    }
}
