//! Models given as modes: a model TOML with a `[modal]` section that lists
//! the measured points and, per mode, its frequency, damping ratio and
//! mass-normalised shape at those points (what `tacit modal --record ...
//! --write-model` identifies from a test; layout in `docs/formats.md`).
//!
//! **The model.** With `n` modes (`ω_r`, `ζ_r`, shapes `Φ` at `p` points,
//! `p ≤ n`, rows of `Φ` independent) the modal equations
//! `q̈ + 2 Z Ω q̇ + Ω² q = Φᵀ f` are written in coordinates whose first `p`
//! entries *are* the displacements at the points: `q = T x` with
//! `T = [Φ⁺, N]`, `Φ⁺ = Φᵀ (Φ Φᵀ)⁻¹` and `N` an orthonormal basis of the
//! null space of `Φ`, so that `Φ T = [I, 0]` and `u_points = x[0..p]`. The
//! congruence gives
//!
//! $$ M = Tᵀ T = \mathrm{blkdiag}\big((Φ Φᵀ)⁻¹, I\big), \quad K = Tᵀ Ω² T $$
//!
//! whose modes are exactly the given ones (mass-normalised, with the given
//! shapes at the points); the damping is modal with the given ratios. A
//! force at a point acts on its coordinate, and an element between two
//! points acts on the relative displacement of the points, through the
//! shapes. The coordinates after the points carry no physical position.
//!
//! Residual modes (`residual = true`) stand for the modes outside the
//! band: a mode above it with the measured residual flexibility at the
//! points, one below it with the residual mass line; they are modes like
//! the others for the simulation.

use super::matrix::{map_element_labels, LinearMatrices};
use super::{Damping, Model, Spring};
use crate::error::{Result, TacitError};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// One mode of a modal model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModalMode {
    /// Natural frequency, Hz (> 0).
    pub frequency_hz: f64,
    /// Damping ratio, fraction of critical, in [0, 1).
    pub damping: f64,
    /// Mass-normalised shape at the points, in the order of `points`.
    pub shape: Vec<f64>,
    /// A residual mode standing for the modes outside the band.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub residual: bool,
}

/// The `[modal]` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModalSection {
    /// Labels of the measured points, in the order of the shapes' entries.
    pub points: Vec<String>,
    /// Record DOFs the points stand for when a record names its channels
    /// by DOF (`accel_3`); default 1, 2, ...
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dofs: Vec<usize>,
    /// The point where the force was applied (the shapes are
    /// mass-normalised through its measurement).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub driving_point: Option<String>,
    /// The modes.
    #[serde(rename = "mode")]
    pub modes: Vec<ModalMode>,
}

/// True when a model file has a `[modal]` section.
pub fn is_modal_model(text: &str) -> bool {
    text.parse::<toml::Table>()
        .map(|t| t.contains_key("modal"))
        .unwrap_or(false)
}

impl ModalSection {
    /// Check the section; errors name the key (`modal.mode[3].shape`).
    pub fn validate(&self, src: &str) -> Result<()> {
        let err = |m: String| Err(TacitError::model(src, m));
        let p = self.points.len();
        if p == 0 {
            return err("modal.points: at least one point".into());
        }
        let mut seen = std::collections::HashSet::new();
        for l in &self.points {
            if l.is_empty() || l.chars().any(|c| c.is_whitespace() || c == ',') {
                return err(format!(
                    "modal.points \"{l}\": a label may not be empty or hold spaces or commas"
                ));
            }
            if !seen.insert(l) {
                return err(format!("modal.points: \"{l}\" appears twice"));
            }
        }
        if !self.dofs.is_empty() && self.dofs.len() != p {
            return err(format!(
                "modal.dofs: {} DOFs for {p} points",
                self.dofs.len()
            ));
        }
        if let Some(d) = &self.driving_point {
            if !self.points.contains(d) {
                return err(format!(
                    "modal.driving_point \"{d}\" is not in modal.points"
                ));
            }
        }
        if self.modes.len() < p {
            return err(format!(
                "modal.mode: {} modes for {p} points; a modal model needs at least as many modes as points",
                self.modes.len()
            ));
        }
        for (i, m) in self.modes.iter().enumerate() {
            if !(m.frequency_hz.is_finite() && m.frequency_hz > 0.0) {
                return err(format!(
                    "modal.mode[{i}].frequency_hz = {}: must be > 0",
                    m.frequency_hz
                ));
            }
            if !(m.damping.is_finite() && (0.0..1.0).contains(&m.damping)) {
                return err(format!(
                    "modal.mode[{i}].damping = {}: must be in [0, 1)",
                    m.damping
                ));
            }
            if m.shape.len() != p {
                return err(format!(
                    "modal.mode[{i}].shape has {} entries for {p} points",
                    m.shape.len()
                ));
            }
            if let Some(k) = m.shape.iter().position(|v| !v.is_finite()) {
                return err(format!(
                    "modal.mode[{i}].shape[{k}] = {}: not finite",
                    m.shape[k]
                ));
            }
        }
        Ok(())
    }

    /// Modes in ascending frequency (the order of [`Damping::Modal`]).
    fn sorted(&self) -> Vec<&ModalMode> {
        let mut m: Vec<&ModalMode> = self.modes.iter().collect();
        m.sort_by(|a, b| a.frequency_hz.total_cmp(&b.frequency_hz));
        m
    }

    /// The mass and stiffness of the coordinates `[u_points, η]` (module
    /// documentation), modes sorted by frequency; an error when the shapes'
    /// rows at the points are dependent.
    pub fn matrices(&self, src: &str) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let modes = self.sorted();
        let (p, n) = (self.points.len(), modes.len());
        let phi = DMatrix::from_fn(p, n, |i, r| modes[r].shape[i]);
        let gram = &phi * phi.transpose();
        let (vals, _) = crate::modal::sym_eigen(&gram)?;
        let (lo, hi) = (vals[0], vals[p - 1]);
        if !(lo > 1e-12 * hi) {
            return Err(TacitError::model(
                src,
                format!(
                    "modal.mode: the shapes at the points {} are linearly dependent (eigenvalues of Φ Φᵀ from {lo:.3e} to {hi:.3e}): a point is not distinguished by the modes",
                    self.points.join(", ")
                ),
            ));
        }
        let gram_inv = gram
            .try_inverse()
            .ok_or_else(|| TacitError::Numerical("modal model: Φ Φᵀ cannot be inverted".into()))?;
        let t1 = phi.transpose() * &gram_inv;
        // null space of Φ: eigenvectors of I − Φ⁺ Φ with eigenvalue 1
        let proj = DMatrix::identity(n, n) - &t1 * &phi;
        let (_, vecs) = crate::modal::sym_eigen(&((&proj + proj.transpose()) * 0.5))?;
        let mut t = DMatrix::zeros(n, n);
        t.view_mut((0, 0), (n, p)).copy_from(&t1);
        t.view_mut((0, p), (n, n - p))
            .copy_from(&vecs.view((0, p), (n, n - p)));
        let w2 = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
            n,
            modes
                .iter()
                .map(|m| (2.0 * std::f64::consts::PI * m.frequency_hz).powi(2)),
        ));
        let sym = |a: DMatrix<f64>| (&a + a.transpose()) * 0.5;
        Ok((sym(t.transpose() * &t), sym(t.transpose() * w2 * &t)))
    }
}

/// Read the text of a model file with a `[modal]` section as the dense
/// [`Model`] (module documentation; [`Model::from_file`] reads the file);
/// elements are placed by point label; `src` names the source in errors.
pub fn from_toml_str(text: &str, src: &str) -> Result<Model> {
    let (section, rest) = split(text, src)?;
    for key in ["masses", "damping", "matrices"] {
        if rest.contains_key(key) {
            return Err(TacitError::model(
                src,
                format!(
                    "{key}: a modal model takes its masses, stiffness and damping from [modal]"
                ),
            ));
        }
    }
    assemble(&section, rest, src)
}

/// The `[modal]` section of a model file's text, checked; `src` names the
/// source in errors.
pub fn section_from_toml_str(text: &str, src: &str) -> Result<ModalSection> {
    Ok(split(text, src)?.0)
}

/// The checked `[modal]` section and the rest of the table.
fn split(text: &str, src: &str) -> Result<(ModalSection, toml::Table)> {
    let mut rest: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| TacitError::model(src, e.to_string().trim_end()))?;
    let section: ModalSection = rest
        .remove("modal")
        .ok_or_else(|| TacitError::model(src, "no [modal] section"))?
        .try_into()
        .map_err(|e: toml::de::Error| {
            TacitError::model(src, format!("[modal]: {}", e.to_string().trim_end()))
        })?;
    section.validate(src)?;
    Ok((section, rest))
}

/// The dense model: masses = diagonal of M, springs = negative couplings
/// of K between points, the rest in [`LinearMatrices`], modal damping.
fn assemble(section: &ModalSection, mut table: toml::Table, src: &str) -> Result<Model> {
    let (m, k) = section.matrices(src)?;
    let (n, p) = (m.nrows(), section.points.len());
    let label = |l: &str| section.points.iter().position(|x| x == l).map(|i| i + 1);
    map_element_labels(&mut table, &label);
    let masses: Vec<f64> = (0..n).map(|i| m[(i, i)]).collect();
    table.insert(
        "masses".into(),
        toml::Value::Array(masses.iter().map(|&v| toml::Value::Float(v)).collect()),
    );
    let mut model: Model = toml::Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| TacitError::model(src, e.to_string().trim_end()))?;
    let scale = (0..n).fold(0.0f64, |a, i| a.max(k[(i, i)].abs()));
    let mut springs = vec![];
    for i in 0..p {
        for j in i + 1..p {
            if k[(i, j)] < -1e-9 * scale {
                springs.push(Spring {
                    dofs: vec![i + 1, j + 1],
                    stiffness: -k[(i, j)],
                    name: Some(format!("k_{}_{}", section.points[i], section.points[j])),
                });
            }
        }
    }
    let mut k_rest = k;
    for s in &springs {
        super::add_spring(&mut k_rest, s.ends(), -s.stiffness);
    }
    let mut m_off = m;
    m_off.fill_diagonal(0.0);
    let derived = springs.len();
    model.springs.splice(0..0, springs);
    model.damping = Damping::Modal {
        ratio: None,
        ratios: section.sorted().iter().map(|m| m.damping).collect(),
    };
    model.interface_pairs = (1..=p)
        .flat_map(|i| (i + 1..=p).map(move |j| [i, j]))
        .collect();
    model.points = section.points.clone();
    let kept_dofs = if section.dofs.is_empty() {
        (1..=p).collect()
    } else {
        section.dofs.clone()
    };
    model.matrices = Some(Arc::new(LinearMatrices::new(
        m_off, k_rest, None, kept_dofs, derived,
    )));
    model.validate(src)?;
    Ok(model)
}

/// The text of a modal model file: `name`, `description` and the section.
pub fn to_toml_string(name: &str, description: &str, section: &ModalSection) -> String {
    #[derive(Serialize)]
    struct File<'a> {
        name: &'a str,
        description: &'a str,
        modal: &'a ModalSection,
    }
    toml::to_string(&File {
        name,
        description,
        modal: section,
    })
    .unwrap_or_else(|e| format!("# modal model could not be serialized: {e}\n"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section() -> ModalSection {
        ModalSection {
            points: vec!["a".into(), "b".into()],
            dofs: vec![],
            driving_point: Some("a".into()),
            modes: vec![
                ModalMode {
                    frequency_hz: 7.0,
                    damping: 0.02,
                    shape: vec![0.3, -0.5],
                    residual: false,
                },
                ModalMode {
                    frequency_hz: 3.0,
                    damping: 0.01,
                    shape: vec![0.4, 0.6],
                    residual: false,
                },
                ModalMode {
                    frequency_hz: 40.0,
                    damping: 0.05,
                    shape: vec![0.1, 0.05],
                    residual: true,
                },
            ],
        }
    }

    #[test]
    fn the_model_has_the_given_modes_and_shapes() {
        let text = to_toml_string("t", "", &section())
            + "\n[[clearance]]\ndofs = [\"a\", \"b\"]\ngap = 1e-4\nstiffness = 1e5\n";
        let model = from_toml_str(&text, "t").unwrap();
        assert_eq!(model.ndof(), 3);
        assert_eq!(model.points, ["a", "b"]);
        assert_eq!(model.clearances[0].dofs, [1, 2]);
        let modes = crate::modal::solve(&model.mass_matrix(), &model.stiffness_matrix()).unwrap();
        for (got, want) in modes.freq_hz.iter().zip([3.0, 7.0, 40.0]) {
            assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
        }
        // the shapes at the points, up to sign
        let s = &section()
            .sorted()
            .iter()
            .map(|m| m.shape.clone())
            .collect::<Vec<_>>();
        for (r, want) in s.iter().enumerate() {
            let sign = modes.shapes[(0, r)].signum() * want[0].signum();
            for (i, w) in want.iter().enumerate() {
                let d = (modes.shapes[(i, r)] * sign - w).abs();
                assert!(d < 1e-9, "mode {r} point {i}: {}", modes.shapes[(i, r)]);
            }
        }
        // the damping of each mode: ΦᵀCΦ = diag(2 ζ ω)
        let c = model.damping_matrix().unwrap();
        let mc = modes.shapes.transpose() * c * &modes.shapes;
        let w = 2.0 * std::f64::consts::PI * 7.0;
        assert!((mc[(1, 1)] - 2.0 * 0.02 * w).abs() < 1e-9 * w);
        assert!(mc[(0, 1)].abs() < 1e-9 * w);
    }

    #[test]
    fn bad_sections_name_the_key() {
        let mut s = section();
        s.modes[1].shape = vec![0.3];
        let e = from_toml_str(&to_toml_string("t", "", &s), "f.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("modal.mode[1].shape") && e.contains("f.toml"),
            "{e}"
        );
        let mut s = section();
        s.modes.truncate(1);
        let e = from_toml_str(&to_toml_string("t", "", &s), "f")
            .unwrap_err()
            .to_string();
        assert!(e.contains("at least as many modes as points"), "{e}");
        let mut s = section();
        for m in &mut s.modes {
            m.shape = vec![m.shape[0], 2.0 * m.shape[0]];
        }
        let e = from_toml_str(&to_toml_string("t", "", &s), "f")
            .unwrap_err()
            .to_string();
        assert!(e.contains("linearly dependent"), "{e}");
        let text = to_toml_string("t", "", &section()) + "\nmasses = [1.0]\n";
        assert!(from_toml_str(&text, "f").is_err());
    }
}
