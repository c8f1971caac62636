//! Test modes: natural frequencies, damping ratios and mode shapes at the
//! measured DOFs, identified by [`super::fit`] or read from a file.
//!
//! # File format (TOML)
//!
//! ```toml
//! name = "damaged testbed, identified"   # optional
//! dofs = [1, 4, 7]                       # measured DOFs, in the order of the shape entries
//! mass_normalized = false                # optional (default false): shapes scaled so φᵀMφ = 1
//!
//! [[mode]]
//! frequency_hz = 22.3
//! damping = 0.136                        # optional ratio (not %), default 0
//! shape = [1.0, 0.31, -0.62]             # one value per entry of `dofs`
//! ```
//!
//! A DOF is named by its number (from 1) or as a string `"5"` or
//! `"dof5"` (any case). Names that do not match a model DOF, repeated DOFs
//! and shapes of the wrong length are errors that name the file, the mode
//! and the DOF. TOML was chosen over CSV because a test-mode set is a small
//! nested document (a DOF list, then per mode a frequency, a damping ratio
//! and a shape), which TOML states without conventions.

use crate::error::{Result, TacitError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One test mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestMode {
    /// Natural frequency, Hz.
    pub frequency_hz: f64,
    /// Damping ratio (fraction of critical, not %).
    #[serde(default)]
    pub damping: f64,
    /// Shape at the measured DOFs, in the order of [`TestModes::dofs`].
    pub shape: Vec<f64>,
}

/// A set of test modes measured at the same DOFs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TestModes {
    /// Free text.
    pub name: String,
    /// Measured DOFs, from 1.
    pub dofs: Vec<usize>,
    /// True when the shapes are mass-normalized (φᵀMφ = 1 over the full
    /// model); false when their scale is arbitrary.
    pub mass_normalized: bool,
    /// Modes in ascending frequency.
    #[serde(rename = "mode")]
    pub modes: Vec<TestMode>,
}

/// A DOF as written in a file: a number or a name.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum DofName {
    Number(i64),
    Name(String),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileDoc {
    #[serde(default)]
    name: String,
    dofs: Vec<DofName>,
    #[serde(default)]
    mass_normalized: bool,
    #[serde(default, rename = "mode")]
    modes: Vec<TestMode>,
}

impl TestModes {
    /// Build and check a set (see [`TestModes::validate`]).
    pub fn new(
        name: impl Into<String>,
        dofs: Vec<usize>,
        modes: Vec<TestMode>,
        mass_normalized: bool,
        ndof: usize,
    ) -> Result<TestModes> {
        let t = TestModes {
            name: name.into(),
            dofs,
            mass_normalized,
            modes,
        };
        t.validate(ndof, "<test modes>")?;
        Ok(t)
    }

    /// Read a test-modes TOML file and check it against a model of `ndof`
    /// DOFs.
    pub fn from_file(path: &Path, ndof: usize) -> Result<TestModes> {
        let text = std::fs::read_to_string(path).map_err(|e| TacitError::io(path, e))?;
        Self::from_toml_str(&text, &path.display().to_string(), ndof)
    }

    /// Parse TOML text; `source` names it in errors.
    pub fn from_toml_str(text: &str, source: &str, ndof: usize) -> Result<TestModes> {
        let err = |m: String| TacitError::Setting(format!("test-modes file {source}: {m}"));
        let doc: FileDoc = toml::from_str(text).map_err(|e| err(e.to_string().trim().into()))?;
        let mut dofs = Vec::with_capacity(doc.dofs.len());
        for (i, d) in doc.dofs.iter().enumerate() {
            dofs.push(parse_dof(d, ndof).map_err(|m| err(format!("dofs[{i}] {m}")))?);
        }
        let t = TestModes {
            name: doc.name,
            dofs,
            mass_normalized: doc.mass_normalized,
            modes: doc.modes,
        };
        t.validate(ndof, &format!("file {source}"))?;
        Ok(t)
    }

    /// TOML text in the file format above.
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# not serializable: {e}\n"))
    }

    /// Check: at least one DOF and one mode, DOFs in 1..=ndof and distinct,
    /// one shape value per DOF, finite positive frequencies, damping in
    /// [0, 1), finite non-zero shapes. Errors name `source`, the mode and
    /// the DOF.
    pub fn validate(&self, ndof: usize, source: &str) -> Result<()> {
        let err = |m: String| Err(TacitError::Setting(format!("test modes {source}: {m}")));
        if self.dofs.is_empty() {
            return err("no measured DOF (dofs = [])".into());
        }
        for (i, &d) in self.dofs.iter().enumerate() {
            if d < 1 || d > ndof {
                return err(format!("DOF {d} is not in the model (1..={ndof})"));
            }
            if self.dofs[..i].contains(&d) {
                return err(format!("DOF {d} is listed twice"));
            }
        }
        if self.modes.is_empty() {
            return err("no mode ([[mode]] tables)".into());
        }
        for (r, m) in self.modes.iter().enumerate() {
            let id = format!("mode {} ({} Hz)", r + 1, m.frequency_hz);
            if !(m.frequency_hz.is_finite() && m.frequency_hz > 0.0) {
                return err(format!("{id}: the frequency must be > 0"));
            }
            if !(m.damping.is_finite() && (0.0..1.0).contains(&m.damping)) {
                return err(format!("{id}: damping {} must be in [0, 1)", m.damping));
            }
            if m.shape.len() != self.dofs.len() {
                return err(format!(
                    "{id}: the shape has {} values for {} DOFs {:?}",
                    m.shape.len(),
                    self.dofs.len(),
                    self.dofs
                ));
            }
            if let Some(i) = m.shape.iter().position(|v| !v.is_finite()) {
                return err(format!(
                    "{id}: the value at DOF {} is not finite",
                    self.dofs[i]
                ));
            }
            if m.shape.iter().all(|v| *v == 0.0) {
                return err(format!("{id}: the shape is zero"));
            }
        }
        Ok(())
    }

    /// The shapes as a (DOFs × modes) matrix.
    pub fn shape_matrix(&self) -> nalgebra::DMatrix<f64> {
        nalgebra::DMatrix::from_fn(self.dofs.len(), self.modes.len(), |i, r| {
            self.modes[r].shape[i]
        })
    }

    /// Keep only the given DOFs (e.g. 1, 4, 7 out of all 8), in that order.
    /// Errors name a DOF that was not measured.
    pub fn restrict(&self, dofs: &[usize]) -> Result<TestModes> {
        let mut idx = Vec::with_capacity(dofs.len());
        for &d in dofs {
            idx.push(self.dofs.iter().position(|&x| x == d).ok_or_else(|| {
                TacitError::Setting(format!(
                    "test modes {}: DOF {d} was not measured (measured: {:?})",
                    self.name, self.dofs
                ))
            })?);
        }
        Ok(TestModes {
            name: self.name.clone(),
            dofs: dofs.to_vec(),
            mass_normalized: self.mass_normalized,
            modes: self
                .modes
                .iter()
                .map(|m| TestMode {
                    shape: idx.iter().map(|&i| m.shape[i]).collect(),
                    ..m.clone()
                })
                .collect(),
        })
    }

    /// Keep the first `n` modes.
    pub fn first(&self, n: usize) -> TestModes {
        TestModes {
            modes: self.modes.iter().take(n).cloned().collect(),
            ..self.clone()
        }
    }
}

fn parse_dof(d: &DofName, ndof: usize) -> std::result::Result<usize, String> {
    let n: i64 = match d {
        DofName::Number(n) => *n,
        DofName::Name(s) => {
            let t = s.trim().to_ascii_lowercase();
            let t = t.strip_prefix("dof").unwrap_or(&t);
            t.trim().parse().map_err(|_| {
                format!(
                    "= \"{s}\" does not name a model DOF (expected 1..={ndof} or \"dof1\"..\"dof{ndof}\")"
                )
            })?
        }
    };
    if n < 1 || n as usize > ndof {
        let shown = match d {
            DofName::Number(n) => n.to_string(),
            DofName::Name(s) => format!("\"{s}\""),
        };
        return Err(format!(
            "= {shown} does not name a model DOF (the model has DOFs 1..={ndof})"
        ));
    }
    Ok(n as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = r#"
name = "t"
dofs = [1, "dof4", "7"]
[[mode]]
frequency_hz = 22.3
damping = 0.136
shape = [1.0, 0.3, -0.6]
"#;

    #[test]
    fn reads_names_and_numbers() {
        let t = TestModes::from_toml_str(FILE, "f.toml", 8).unwrap();
        assert_eq!(t.dofs, vec![1, 4, 7]);
        assert_eq!(t.modes[0].damping, 0.136);
        let again = TestModes::from_toml_str(&t.to_toml_string(), "rt", 8).unwrap();
        assert_eq!(again, t);
    }

    #[test]
    fn errors_name_the_dof_and_mode() {
        let e = TestModes::from_toml_str(&FILE.replace("\"7\"", "\"x7\""), "f.toml", 8)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("f.toml") && e.contains("x7") && e.contains("dofs[2]"),
            "{e}"
        );
        let e = TestModes::from_toml_str(&FILE.replace("\"7\"", "9"), "f.toml", 8)
            .unwrap_err()
            .to_string();
        assert!(e.contains("9") && e.contains("1..=8"), "{e}");
        let e = TestModes::from_toml_str(&FILE.replace(", -0.6]", "]"), "f.toml", 8)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("f.toml") && e.contains("mode 1") && e.contains("2 values for 3 DOFs"),
            "{e}"
        );
        let e = TestModes::from_toml_str(&FILE.replace("\"7\"", "4"), "f.toml", 8)
            .unwrap_err()
            .to_string();
        assert!(e.contains("DOF 4 is listed twice"), "{e}");
    }
}
