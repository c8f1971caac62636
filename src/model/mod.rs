//! Structural models: lumped masses, linear springs, damping and nonlinear
//! elements, read from TOML files (layout in `docs/formats.md`).
//!
//! Equation of motion, with the internal force of the nonlinear elements on
//! the left-hand side (the sign convention of the reference record):
//!
//! $$ M \ddot u + C \dot u + K u + f_{int}(u, \dot u) = f_{ext}(t) $$
//!
//! DOFs are numbered from 1 in files, reports and on the command line, and
//! from 0 inside the numerical core.

pub mod elements;
pub mod matrix;
pub mod modal;

use crate::error::{Result, TacitError};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;

pub use elements::{
    Clearance, Contact, Cubic, CubicDamper, Friction, Jenkins, Quadratic, QuadraticDamper,
    RelativeFriction, Saturating,
};

/// A linear spring between two DOFs, or from a DOF to ground.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spring {
    /// `[i, j]` (between DOFs i and j) or `[i]` (DOF i to ground); from 1.
    pub dofs: Vec<usize>,
    /// Stiffness, N/m (> 0).
    pub stiffness: f64,
    /// Optional label, e.g. "k5".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
}

impl Spring {
    /// The two DOFs, 0-based; `None` for ground.
    pub fn ends(&self) -> (usize, Option<usize>) {
        (self.dofs[0] - 1, self.dofs.get(1).map(|j| j - 1))
    }
    /// Label: `name` or `k<index+1>`.
    pub fn label(&self, index: usize) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| format!("k{}", index + 1))
    }
}

/// Damping model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
#[derive(Default)]
pub enum Damping {
    /// No damping.
    #[default]
    None,
    /// Modal damping: `ratio` applies to every flexible mode, or `ratios`
    /// gives one value per flexible mode in ascending frequency (missing
    /// modes take the last value). Rigid-body modes are left undamped.
    Modal {
        /// One ratio for every flexible mode.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        ratio: Option<f64>,
        /// Ratios per flexible mode.
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        ratios: Vec<f64>,
    },
    /// Rayleigh damping `C = alpha M + beta K`.
    Rayleigh {
        /// Mass-proportional coefficient, 1/s.
        alpha: f64,
        /// Stiffness-proportional coefficient, s.
        beta: f64,
    },
}

impl Damping {
    /// The same damping with every ratio or coefficient times `f`.
    pub fn scaled(&self, f: f64) -> Damping {
        match self {
            Damping::None => Damping::None,
            Damping::Modal { ratio, ratios } => Damping::Modal {
                ratio: ratio.map(|z| z * f),
                ratios: ratios.iter().map(|z| z * f).collect(),
            },
            Damping::Rayleigh { alpha, beta } => Damping::Rayleigh {
                alpha: alpha * f,
                beta: beta * f,
            },
        }
    }
}

/// A structural model.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// Short name.
    #[serde(default)]
    pub name: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    /// Mass of each DOF, kg (> 0). The number of DOFs is `masses.len()`.
    pub masses: Vec<f64>,
    /// Linear springs.
    #[serde(default, rename = "spring", skip_serializing_if = "Vec::is_empty")]
    pub springs: Vec<Spring>,
    /// Damping.
    #[serde(default)]
    pub damping: Damping,
    /// Penalty contacts.
    #[serde(default, rename = "contact", skip_serializing_if = "Vec::is_empty")]
    pub contacts: Vec<Contact>,
    /// Coulomb friction elements.
    #[serde(default, rename = "friction", skip_serializing_if = "Vec::is_empty")]
    pub frictions: Vec<Friction>,
    /// Cubic springs.
    #[serde(default, rename = "cubic", skip_serializing_if = "Vec::is_empty")]
    pub cubics: Vec<Cubic>,
    /// Quadratic (asymmetric) springs.
    #[serde(default, rename = "quadratic", skip_serializing_if = "Vec::is_empty")]
    pub quadratics: Vec<Quadratic>,
    /// Quadratic dampers.
    #[serde(
        default,
        rename = "quadratic_damper",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub quadratic_dampers: Vec<QuadraticDamper>,
    /// Cubic dampers.
    #[serde(
        default,
        rename = "cubic_damper",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub cubic_dampers: Vec<CubicDamper>,
    /// Two-sided clearances (dead zones).
    #[serde(default, rename = "clearance", skip_serializing_if = "Vec::is_empty")]
    pub clearances: Vec<Clearance>,
    /// Coulomb friction between two DOFs.
    #[serde(
        default,
        rename = "relative_friction",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub relative_frictions: Vec<RelativeFriction>,
    /// Jenkins elements (a spring in series with a Coulomb slider).
    #[serde(default, rename = "jenkins", skip_serializing_if = "Vec::is_empty")]
    pub jenkins: Vec<Jenkins>,
    /// Saturating springs (elastic softening: `k δ` clipped at `±F`).
    #[serde(default, rename = "saturating", skip_serializing_if = "Vec::is_empty")]
    pub saturating: Vec<Saturating>,
    /// Linear parameters marked free (`[free]`: `masses`, `springs`,
    /// `damping`, each true or false, defaults those of
    /// [`crate::calibrate::Freedom`]): their values are starting values,
    /// estimated from the records by the calibration and the refinement,
    /// not declared ones. None: the declared linear part (calibrated with
    /// the calibration's own settings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub free: Option<crate::calibrate::Freedom>,
    /// Point labels of DOFs `1..=points.len()` (models built from
    /// matrices: the kept points; the DOFs after them are modal
    /// coordinates). Empty for a lumped model.
    #[serde(skip)]
    pub points: Vec<String>,
    /// Interface pairs (DOFs from 1) tried as effect locations besides the
    /// spring-joined pairs.
    #[serde(skip)]
    pub interface_pairs: Vec<[usize; 2]>,
    /// The linear part given as (reduced) matrices, added to the masses and
    /// springs ([`matrix::LinearMatrices`]).
    #[serde(skip)]
    pub matrices: Option<Arc<matrix::LinearMatrices>>,
}

/// Checks an element's DOF list: key, DOFs, whether one DOF (to ground)
/// is allowed.
type DofCheck<'a> = dyn Fn(String, &[usize], bool) -> Result<()> + 'a;

impl Model {
    /// Number of DOFs.
    pub fn ndof(&self) -> usize {
        self.masses.len()
    }

    /// DOFs that are physical points (candidates for effects and
    /// channels): all of them for a lumped model, the kept points for a
    /// reduced one.
    pub fn physical_ndof(&self) -> usize {
        if self.points.is_empty() {
            self.ndof()
        } else {
            self.points.len()
        }
    }

    /// Name of DOF `d` (from 1) in reports: its point label, or the number.
    pub fn dof_name(&self, d: usize) -> String {
        d.checked_sub(1)
            .and_then(|i| self.points.get(i))
            .cloned()
            .unwrap_or_else(|| d.to_string())
    }

    /// An effect's label with the points of its DOFs (0-based) when the
    /// model names them: `contact @5 (n100:uy)`, `stiffness 2–3
    /// (n40:uy–n60:uy)`; the label as it is otherwise.
    pub fn label_at_points(&self, label: &str, dofs: &[usize]) -> String {
        let names: Option<Vec<&str>> = dofs
            .iter()
            .map(|&d| self.points.get(d).map(String::as_str))
            .collect();
        match names {
            Some(n) if !n.is_empty() => format!("{label} ({})", n.join("–")),
            _ => label.to_string(),
        }
    }

    /// Read a model file for the given records: a lumped model as
    /// [`Model::from_file`]; a model from matrices ([`matrix`]) reduced
    /// onto its element and interface points and the records' labelled
    /// channels, with the cut-off set from the records' excitation band.
    /// The records' labelled channels are then resolved
    /// ([`Model::resolve_channels`]).
    pub fn load(path: &Path, records: &mut [&mut crate::record::Record]) -> Result<Model> {
        let text = std::fs::read_to_string(path).map_err(|e| TacitError::io(path, e))?;
        let model = if modal::is_modal_model(&text) {
            modal::from_toml_str(&text, &path.display().to_string())?
        } else if matrix::is_matrix_model(&text) {
            let mm = matrix::MatrixModel::from_file(path)?;
            let recs: Vec<&crate::record::Record> = records.iter().map(|r| &**r).collect();
            mm.reduce_for_records(&recs)?
        } else {
            Model::from_toml_str(&text, &path.display().to_string())?
        };
        for r in records.iter_mut() {
            model.resolve_channels(r)?;
        }
        Ok(model)
    }

    /// Give each labelled channel of `rec` (`accel:n12:uy`) the DOF of its
    /// point; an error names the channel when the model has no such point.
    /// A channel that carries a DOF beside its point (a universal file's
    /// node and direction) keeps the DOF on a model without point labels.
    /// A channel named by DOF (`accel_5`) on a model from matrices means DOF 5
    /// of the matrices: it gets the reduced DOF of that point (call once).
    pub fn resolve_channels(&self, rec: &mut crate::record::Record) -> Result<()> {
        let kept = self.matrices.as_ref().map(|l| &l.kept_dofs);
        for c in rec.inputs.iter_mut().chain(rec.outputs.iter_mut()) {
            let Some(p) = &c.point else {
                if let Some(kept) = kept {
                    c.dof = kept.iter().position(|&d| d == c.dof).map_or(0, |i| i + 1);
                }
                continue;
            };
            if self.points.is_empty() && c.dof != 0 {
                // a universal file's node and direction on a model without
                // point labels: the node is the DOF
                c.point = None;
                continue;
            }
            let d = self.points.iter().position(|l| l == p).ok_or_else(|| {
                TacitError::record(
                    rec.source.clone(),
                    if self.points.is_empty() {
                        format!("channel {}: the model has no point labels (it is a lumped model: name channels like {}_<dof>)", c.name(), c.quantity.prefix())
                    } else {
                        format!("channel {}: point \"{p}\" is not a point of the model", c.name())
                    },
                )
            })?;
            c.dof = d + 1;
        }
        Ok(())
    }

    /// Read and validate a lumped model file or a modal model
    /// ([`modal`]); a model from matrices is an error that says where it is
    /// taken ([`Model::load`]).
    pub fn from_file(path: &Path) -> Result<Model> {
        let text = std::fs::read_to_string(path).map_err(|e| TacitError::io(path, e))?;
        if modal::is_modal_model(&text) {
            return modal::from_toml_str(&text, &path.display().to_string());
        }
        if matrix::is_matrix_model(&text) {
            return Err(TacitError::model(
                path.display().to_string(),
                "a model from matrices ([matrices]) is reduced onto the points of a record: read it with the records it meets (`Model::load`, as the commands do) or reduce it (`MatrixModel::reduce`)",
            ));
        }
        Model::from_toml_str(&text, &path.display().to_string())
    }

    /// Parse and validate TOML text; `source_name` is used in errors.
    pub fn from_toml_str(text: &str, source_name: &str) -> Result<Model> {
        let model: Model = toml::from_str(text)
            .map_err(|e| TacitError::model(source_name, e.to_string().trim_end().to_string()))?;
        model.validate(source_name)?;
        Ok(model)
    }

    /// Serialize to TOML text. A reduced model from matrices is written
    /// with its masses and springs only, under a comment that says so.
    pub fn to_toml_string(&self) -> String {
        let text = toml::to_string(self)
            .unwrap_or_else(|e| format!("# model could not be serialized: {e}\n"));
        match &self.matrices {
            Some(_) => format!(
                "# reduced model from matrices, points {}: its off-diagonal mass and the\n# stiffness beyond these springs are not in this text\n{text}",
                self.points.join(", ")
            ),
            None => text,
        }
    }

    /// True when the model has nonlinear elements.
    pub fn is_nonlinear(&self) -> bool {
        !(self.contacts.is_empty()
            && self.frictions.is_empty()
            && self.cubics.is_empty()
            && self.quadratics.is_empty()
            && self.quadratic_dampers.is_empty()
            && self.cubic_dampers.is_empty()
            && self.clearances.is_empty()
            && self.relative_frictions.is_empty()
            && self.jenkins.is_empty()
            && self.saturating.is_empty())
    }

    /// A copy without nonlinear elements.
    pub fn linear_part(&self) -> Model {
        Model {
            contacts: vec![],
            frictions: vec![],
            cubics: vec![],
            quadratics: vec![],
            quadratic_dampers: vec![],
            cubic_dampers: vec![],
            clearances: vec![],
            relative_frictions: vec![],
            jenkins: vec![],
            saturating: vec![],
            ..self.clone()
        }
    }

    /// Push the spring to ground `s`, the flexible modes keeping their
    /// per-mode damping ratios ([`keep_modal_ratios`]: the former
    /// rigid-body mode takes a ratio of its own instead of every mode
    /// taking its lower neighbour's). A model whose modes cannot be
    /// computed gets the spring alone (the same eigenproblem fails, and is
    /// reported, where the model is used).
    pub fn push_ground_spring(&mut self, s: Spring) {
        let before = flexible_frequencies(self).ok();
        self.springs.push(s);
        if let Some(b) = before {
            keep_modal_ratios(self, &b).ok();
        }
    }

    /// True when a spring joins a DOF to ground.
    pub fn has_ground_spring(&self) -> bool {
        self.springs.iter().any(|s| s.dofs.len() == 1)
    }

    /// True when a spring or a nonlinear element joins a DOF to ground
    /// (friction against ground included): the structure's rigid-body
    /// momentum is then not conserved.
    pub fn has_ground_element(&self) -> bool {
        self.has_ground_spring() || elements::compile(self).iter().any(|e| e.ends().1.is_none())
    }

    /// Check every value; errors name the key (`spring[2].dofs`, ...).
    pub fn validate(&self, src: &str) -> Result<()> {
        let err = |m: String| Err(TacitError::model(src, m));
        let n = self.ndof();
        if n == 0 {
            return err("masses: the model needs at least one DOF".into());
        }
        for (i, &m) in self.masses.iter().enumerate() {
            if !(m.is_finite() && m > 0.0) {
                return err(format!(
                    "masses[{i}] (DOF {}) = {m}: a mass must be > 0",
                    i + 1
                ));
            }
        }
        let check_dofs = |key: String, dofs: &[usize], allow_ground: bool| -> Result<()> {
            let ok_len = if allow_ground {
                dofs.len() == 1 || dofs.len() == 2
            } else {
                dofs.len() == 2
            };
            if !ok_len {
                let want = if allow_ground {
                    "[i, j] or [i]"
                } else {
                    "[i, j]"
                };
                return Err(TacitError::model(
                    src,
                    format!("{key}.dofs = {dofs:?}: expected {want}"),
                ));
            }
            for &d in dofs {
                if d < 1 || d > n {
                    return Err(TacitError::model(
                        src,
                        format!("{key}.dofs = {dofs:?}: DOF {d} is out of range 1..={n}"),
                    ));
                }
            }
            if dofs.len() == 2 && dofs[0] == dofs[1] {
                return Err(TacitError::model(
                    src,
                    format!("{key}.dofs = {dofs:?}: the two DOFs must differ"),
                ));
            }
            Ok(())
        };
        for (i, s) in self.springs.iter().enumerate() {
            check_dofs(format!("spring[{i}]"), &s.dofs, true)?;
            if !(s.stiffness.is_finite() && s.stiffness > 0.0) {
                return err(format!(
                    "spring[{i}].stiffness = {}: must be > 0",
                    s.stiffness
                ));
            }
        }
        for (i, c) in self.contacts.iter().enumerate() {
            check_dofs(format!("contact[{i}]"), &c.dofs, true)?;
            if !(c.gap.is_finite() && c.gap >= 0.0) {
                return err(format!("contact[{i}].gap = {}: must be >= 0", c.gap));
            }
            if !(c.stiffness.is_finite() && c.stiffness > 0.0) {
                return err(format!(
                    "contact[{i}].stiffness = {}: must be > 0",
                    c.stiffness
                ));
            }
        }
        for (i, f) in self.frictions.iter().enumerate() {
            if f.dof < 1 || f.dof > n {
                return err(format!(
                    "friction[{i}].dof = {}: out of range 1..={n}",
                    f.dof
                ));
            }
            if !(f.level.is_finite() && f.level >= 0.0) {
                return err(format!("friction[{i}].level = {}: must be >= 0", f.level));
            }
            if !(f.velocity.is_finite() && f.velocity > 0.0) {
                return err(format!(
                    "friction[{i}].velocity = {}: must be > 0",
                    f.velocity
                ));
            }
        }
        for (i, c) in self.cubics.iter().enumerate() {
            check_dofs(format!("cubic[{i}]"), &c.dofs, true)?;
            if !c.k3.is_finite() {
                return err(format!("cubic[{i}].k3 = {}: must be finite", c.k3));
            }
        }
        self.validate_added_elements(src, &check_dofs)?;
        match &self.damping {
            Damping::None => {}
            Damping::Modal { ratio, ratios } => {
                if ratio.is_some() != ratios.is_empty() {
                    return err("damping: give exactly one of `ratio` or `ratios`".into());
                }
                for (i, z) in ratio.iter().chain(ratios).enumerate() {
                    if !(z.is_finite() && *z >= 0.0 && *z < 1.0) {
                        return err(format!("damping.ratios[{i}] = {z}: must be in [0, 1)"));
                    }
                }
            }
            Damping::Rayleigh { alpha, beta } => {
                if !(alpha.is_finite() && *alpha >= 0.0 && beta.is_finite() && *beta >= 0.0) {
                    return err(format!(
                        "damping: rayleigh alpha = {alpha}, beta = {beta}: must be >= 0"
                    ));
                }
            }
        }
        Ok(())
    }

    /// Check the quadratic springs, nonlinear dampers, clearances and
    /// friction between DOFs (`check_dofs(key, dofs, allow_ground)` checks
    /// the DOF lists).
    fn validate_added_elements(&self, src: &str, check_dofs: &DofCheck<'_>) -> Result<()> {
        let err = |m: String| Err(TacitError::model(src, m));
        for (i, q) in self.quadratics.iter().enumerate() {
            check_dofs(format!("quadratic[{i}]"), &q.dofs, true)?;
            if !q.k2.is_finite() {
                return err(format!("quadratic[{i}].k2 = {}: must be finite", q.k2));
            }
        }
        for (i, d) in self.quadratic_dampers.iter().enumerate() {
            check_dofs(format!("quadratic_damper[{i}]"), &d.dofs, true)?;
            if !(d.c2.is_finite() && d.c2 >= 0.0) {
                return err(format!("quadratic_damper[{i}].c2 = {}: must be >= 0", d.c2));
            }
        }
        for (i, d) in self.cubic_dampers.iter().enumerate() {
            check_dofs(format!("cubic_damper[{i}]"), &d.dofs, true)?;
            if !(d.c3.is_finite() && d.c3 >= 0.0) {
                return err(format!("cubic_damper[{i}].c3 = {}: must be >= 0", d.c3));
            }
        }
        for (i, c) in self.clearances.iter().enumerate() {
            check_dofs(format!("clearance[{i}]"), &c.dofs, false)?;
            if !(c.gap.is_finite() && c.gap >= 0.0) {
                return err(format!("clearance[{i}].gap = {}: must be >= 0", c.gap));
            }
            if !(c.stiffness.is_finite() && c.stiffness > 0.0) {
                return err(format!(
                    "clearance[{i}].stiffness = {}: must be > 0",
                    c.stiffness
                ));
            }
        }
        for (i, f) in self.relative_frictions.iter().enumerate() {
            check_dofs(format!("relative_friction[{i}]"), &f.dofs, false)?;
            if !(f.level.is_finite() && f.level >= 0.0) {
                return err(format!(
                    "relative_friction[{i}].level = {}: must be >= 0",
                    f.level
                ));
            }
            if !(f.velocity.is_finite() && f.velocity > 0.0) {
                return err(format!(
                    "relative_friction[{i}].velocity = {}: must be > 0",
                    f.velocity
                ));
            }
        }
        for (i, e) in self.jenkins.iter().enumerate() {
            check_dofs(format!("jenkins[{i}]"), &e.dofs, true)?;
            if !(e.stiffness.is_finite() && e.stiffness > 0.0) {
                return err(format!(
                    "jenkins[{i}].stiffness = {}: must be > 0",
                    e.stiffness
                ));
            }
            if !(e.slip_force.is_finite() && e.slip_force >= 0.0) {
                return err(format!(
                    "jenkins[{i}].slip_force = {}: must be >= 0",
                    e.slip_force
                ));
            }
        }
        for (i, e) in self.saturating.iter().enumerate() {
            check_dofs(format!("saturating[{i}]"), &e.dofs, true)?;
            if !(e.stiffness.is_finite() && e.stiffness > 0.0) {
                return err(format!(
                    "saturating[{i}].stiffness = {}: must be > 0",
                    e.stiffness
                ));
            }
            if !(e.force.is_finite() && e.force > 0.0) {
                return err(format!("saturating[{i}].force = {}: must be > 0", e.force));
            }
        }
        Ok(())
    }

    /// Mass matrix: the masses on the diagonal, plus the off-diagonal mass
    /// of a model from matrices (times its mass scale).
    pub fn mass_matrix(&self) -> DMatrix<f64> {
        let d = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(self.masses.clone()));
        match &self.matrices {
            Some(lin) => d + &lin.m_offdiag * lin.mass_scale,
            None => d,
        }
    }

    /// True for a model from Matrix Market matrices whose stiffness is not
    /// all in point-to-point springs: its springs are the couplings of a
    /// reduction, and the calibration corrects the scales of the whole
    /// stiffness and mass instead ([`crate::calibrate::Freedom`]). False for
    /// a lumped model, a lumped model written as matrices (all its
    /// stiffness in springs, within 1e-9 of the stiffest) and a modal model
    /// (`[modal]`, calibrated by its springs and modal ratios).
    pub fn calibrated_by_scales(&self) -> bool {
        let Some(lin) = self.matrices.as_ref().filter(|l| l.by_scales) else {
            return false;
        };
        let top = self.springs.iter().fold(0.0f64, |a, s| a.max(s.stiffness));
        let rest = lin.k_rest.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        !(lin.derived_springs > 0 && rest <= 1e-9 * top)
    }

    /// The stiffness or mass scale of a model from matrices
    /// ([`matrix::LinearMatrices`]); None for a lumped model.
    pub fn matrix_scale(&self, stiffness: bool) -> Option<f64> {
        self.matrices.as_ref().map(|l| {
            if stiffness {
                l.stiffness_scale
            } else {
                l.mass_scale
            }
        })
    }

    /// Set the stiffness scale (it multiplies the matrices' stiffness and
    /// the derived springs as stored, see [`Model::stiffness_matrix`]) or
    /// the mass scale (the diagonal masses move with it) of a model from
    /// matrices; nothing on a lumped model.
    pub fn set_matrix_scale(&mut self, stiffness: bool, value: f64) {
        let Some(lin) = self.matrices.as_mut() else {
            return;
        };
        let lin = Arc::make_mut(lin);
        if stiffness {
            lin.stiffness_scale = value;
        } else {
            let ratio = value / lin.mass_scale;
            lin.mass_scale = value;
            self.masses.iter_mut().for_each(|m| *m *= ratio);
        }
    }

    /// The factor spring `i` enters the stiffness with: the stiffness
    /// scale for a spring derived from the matrices, else 1.
    pub fn spring_factor(&self, i: usize) -> f64 {
        match &self.matrices {
            Some(lin) if i < lin.derived_springs => lin.stiffness_scale,
            _ => 1.0,
        }
    }

    /// `∂K/∂(stiffness scale)` or `∂M/∂(mass scale)` of a model from
    /// matrices: the matrices' part of K as stored (without the springs of
    /// the file's elements), or the whole M over the scale.
    pub fn matrix_scale_derivative(&self, stiffness: bool) -> Option<DMatrix<f64>> {
        let lin = self.matrices.as_ref()?;
        Some(if stiffness {
            let mut k = lin.k_rest.clone();
            for s in self.springs.iter().take(lin.derived_springs) {
                add_spring(&mut k, s.ends(), s.stiffness);
            }
            k
        } else {
            self.mass_matrix() / lin.mass_scale
        })
    }

    /// Linear stiffness matrix: the springs, plus the rest of the
    /// stiffness of a model from matrices; the stiffness scale of a model
    /// from matrices multiplies that rest and the springs derived from the
    /// matrices (a stiffness change of a derived spring is stored in it, so
    /// it scales too), not the springs of the file's elements.
    pub fn stiffness_matrix(&self) -> DMatrix<f64> {
        let n = self.ndof();
        let mut k = match &self.matrices {
            Some(lin) => &lin.k_rest * lin.stiffness_scale,
            None => DMatrix::zeros(n, n),
        };
        for (i, s) in self.springs.iter().enumerate() {
            add_spring(&mut k, s.ends(), s.stiffness * self.spring_factor(i));
        }
        k
    }

    /// Damping matrix from the damping model. Modal damping:
    /// `C = M Φ diag(2 ζ_r ω_r) Φᵀ M` with mass-normalized Φ; rigid-body
    /// modes (ω ≈ 0) get no damping.
    pub fn damping_matrix(&self) -> Result<DMatrix<f64>> {
        let m = self.mass_matrix();
        let k = self.stiffness_matrix();
        let c = damping_matrix(&self.damping, &m, &k)?;
        match self.matrices.as_ref().and_then(|l| l.c.as_ref()) {
            Some(c0) => Ok(c + c0),
            None => Ok(c),
        }
    }
}

/// Damping matrix for any (M, K) pair (also reduced models).
pub fn damping_matrix(d: &Damping, m: &DMatrix<f64>, k: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    let n = m.nrows();
    match d {
        Damping::None => Ok(DMatrix::zeros(n, n)),
        Damping::Rayleigh { alpha, beta } => Ok(m * *alpha + k * *beta),
        Damping::Modal { ratio, ratios } => {
            let modes = crate::modal::solve(m, k)?;
            let mut diag = vec![0.0; n];
            let mut flex = 0usize;
            for (r, dr) in diag.iter_mut().enumerate() {
                if modes.rigid[r] {
                    continue;
                }
                let z = match ratio {
                    Some(z) => *z,
                    None => modal_ratio_index(flex, ratios.len()).map_or(0.0, |i| ratios[i]),
                };
                *dr = 2.0 * z * modes.omega[r];
                flex += 1;
            }
            let mphi = m * &modes.shapes;
            let d = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(diag));
            let c = &mphi * d * mphi.transpose();
            Ok((&c + c.transpose()) * 0.5)
        }
    }
}

/// The circular frequencies of the flexible modes of `model`, ascending
/// (rigid-body modes left out), rad/s.
pub fn flexible_frequencies(model: &Model) -> Result<Vec<f64>> {
    let modes = crate::modal::solve(&model.mass_matrix(), &model.stiffness_matrix())?;
    Ok(modes
        .omega
        .iter()
        .zip(&modes.rigid)
        .filter(|(_, r)| !**r)
        .map(|(w, _)| *w)
        .collect())
}

/// Keep each flexible mode's own per-mode damping ratio across a change of
/// `model`'s structure that added or took away one flexible mode (a spring
/// to ground added to a free-free structure, or its stiffness set to zero);
/// `before` are the flexible frequencies before the change
/// ([`flexible_frequencies`]). Per-mode ratios go to the flexible modes in
/// ascending frequency ([`modal_ratio_index`]): without this every mode
/// above the new one would take its lower neighbour's ratio. The mode
/// added (taken away) is the one whose removal from the longer list leaves
/// frequencies nearest the shorter one (least sum of squared log ratios);
/// an added mode takes its upper neighbour's ratio. Nothing changes unless
/// the model has one ratio per flexible mode before the change and the
/// count moved by one.
pub fn keep_modal_ratios(model: &mut Model, before: &[f64]) -> Result<()> {
    let per_mode = matches!(&model.damping, Damping::Modal { ratio: None, ratios } if ratios.len() == before.len() && !ratios.is_empty());
    if !per_mode {
        return Ok(());
    }
    let after = flexible_frequencies(model)?;
    let Damping::Modal { ratios, .. } = &mut model.damping else {
        return Ok(());
    };
    if after.len() == before.len() + 1 {
        let j = odd_one_out(&after, before);
        let z = ratios[j.min(ratios.len() - 1)];
        ratios.insert(j, z);
    } else if after.len() + 1 == before.len() && ratios.len() > 1 {
        ratios.remove(odd_one_out(before, &after));
    }
    Ok(())
}

/// The flexible mode of `after` that `before` does not have, when
/// `after` has one flexible mode more and a per-mode ratio for it
/// ([`keep_modal_ratios`]: a spring to ground added): its index among
/// `after`'s flexible modes (ascending frequency). A per-mode ratio `r`
/// of `before` is ratio `r + 1` of `after` from that index on. None
/// otherwise, or when the modes cannot be computed.
pub fn added_mode(before: &Model, after: &Model) -> Option<usize> {
    let count = |m: &Model| match &m.damping {
        Damping::Modal {
            ratio: None,
            ratios,
        } => ratios.len(),
        _ => 0,
    };
    let (b, a) = (
        flexible_frequencies(before).ok()?,
        flexible_frequencies(after).ok()?,
    );
    (a.len() == b.len() + 1 && count(before) == b.len() && count(after) == a.len())
        .then(|| odd_one_out(&a, &b))
}

/// The index of `longer` (one more than `shorter`, both ascending) whose
/// removal leaves the list nearest `shorter` (least sum of squared log
/// ratios; a zero frequency counts as the smallest positive one).
fn odd_one_out(longer: &[f64], shorter: &[f64]) -> usize {
    let floor = longer
        .iter()
        .chain(shorter)
        .copied()
        .filter(|w| *w > 0.0)
        .fold(f64::INFINITY, f64::min)
        .min(1.0);
    let ln = |w: f64| w.max(floor).ln();
    (0..longer.len())
        .map(|j| {
            let rest = longer.iter().enumerate().filter(|(i, _)| *i != j);
            let cost: f64 = rest
                .zip(shorter)
                .map(|((_, a), b)| (ln(*a) - ln(*b)).powi(2))
                .sum();
            (j, cost)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(j, _)| j)
}

/// Which of `count` per-mode damping ratios the flexible mode `flex`
/// (from 0) takes: its own, the last one beyond them, None without ratios.
pub fn modal_ratio_index(flex: usize, count: usize) -> Option<usize> {
    count.checked_sub(1).map(|last| flex.min(last))
}

/// Add a spring of stiffness `k` between `ends` into a stiffness matrix.
pub fn add_spring(kmat: &mut DMatrix<f64>, ends: (usize, Option<usize>), k: f64) {
    let (i, j) = ends;
    kmat[(i, i)] += k;
    if let Some(j) = j {
        kmat[(j, j)] += k;
        kmat[(i, j)] -= k;
        kmat[(j, i)] -= k;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CHAIN: &str = r#"
name = "chain"
masses = [1.0, 2.0]
[[spring]]
dofs = [1, 2]
stiffness = 100.0
[[spring]]
dofs = [1]
stiffness = 50.0
[damping]
kind = "rayleigh"
alpha = 0.1
beta = 0.001
"#;

    #[test]
    fn an_element_to_ground_of_any_kind_grounds_the_model() {
        let free =
            "name = \"free\"\nmasses = [1.0, 2.0]\n[[spring]]\ndofs = [1, 2]\nstiffness = 100.0\n";
        let with = |extra: &str| Model::from_toml_str(&format!("{free}{extra}"), "t").unwrap();
        assert!(!with("").has_ground_element());
        let between = "[[relative_friction]]\ndofs = [1, 2]\nlevel = 0.1\n[[quadratic]]\ndofs = [2, 1]\nk2 = 1e6\n";
        assert!(!with(between).has_ground_element());
        let quadratic = with("[[quadratic]]\ndofs = [2]\nk2 = 1e6\n");
        assert!(quadratic.has_ground_element() && !quadratic.has_ground_spring());
        assert!(with("[[spring]]\ndofs = [1]\nstiffness = 5.0\n").has_ground_element());
        assert!(with("[[friction]]\ndof = 2\nlevel = 0.1\n").has_ground_element());
    }

    #[test]
    fn parses_and_assembles() {
        let m = Model::from_toml_str(CHAIN, "t").unwrap();
        let k = m.stiffness_matrix();
        assert_eq!(k[(0, 0)], 150.0);
        assert_eq!(k[(0, 1)], -100.0);
        assert_eq!(k[(1, 1)], 100.0);
        let c = m.damping_matrix().unwrap();
        approx::assert_relative_eq!(c[(1, 1)], 0.1 * 2.0 + 0.001 * 100.0);
        // round trip
        let again = Model::from_toml_str(&m.to_toml_string(), "rt").unwrap();
        assert_eq!(again, m);
    }

    #[test]
    fn errors_name_the_key() {
        let bad = CHAIN.replace("masses = [1.0, 2.0]", "masses = [1.0, -2.0]");
        let e = Model::from_toml_str(&bad, "t").unwrap_err().to_string();
        assert!(e.contains("masses[1]"), "{e}");
        let bad = CHAIN.replace("dofs = [1, 2]", "dofs = [1, 3]");
        let e = Model::from_toml_str(&bad, "t").unwrap_err().to_string();
        assert!(e.contains("spring[0].dofs") && e.contains("DOF 3"), "{e}");
        let bad = format!("{CHAIN}\n[[contact]]\ndofs = [1, 2]\ngap = -1e-3\nstiffness = 1e6\n");
        let e = Model::from_toml_str(&bad, "t").unwrap_err().to_string();
        assert!(e.contains("contact[0].gap"), "{e}");
        let bad = CHAIN.replace("name = \"chain\"", "name = \"chain\"\nmass = 3");
        let e = Model::from_toml_str(&bad, "t").unwrap_err().to_string();
        assert!(e.contains("mass"), "{e}");
        let bad = format!("{CHAIN}\n[[friction]]\ndof = 1\nlevel = 0.3\nvelocty = 1e-3\n");
        let e = Model::from_toml_str(&bad, "t").unwrap_err().to_string();
        assert!(e.contains("velocty"), "{e}");
    }
    /// The modal damping ratio mode `r` of `model` carries: `φᵀ C φ / 2ω`
    /// with mass-normalized φ.
    fn modal_ratio(model: &Model, r: usize) -> f64 {
        let modes = crate::modal::solve(&model.mass_matrix(), &model.stiffness_matrix()).unwrap();
        let phi = modes.shapes.column(r);
        let c = model.damping_matrix().unwrap();
        (phi.transpose() * c * phi)[(0, 0)] / (2.0 * modes.omega[r])
    }

    /// A spring to ground added to a free-free chain with per-mode ratios
    /// turns its rigid-body mode into the lowest flexible one: the modes
    /// above keep their own ratios (without [`keep_modal_ratios`] the
    /// second flexible mode would take the first's 1 %), and taking the
    /// spring away again restores the ratios.
    #[test]
    fn a_spring_to_ground_keeps_every_mode_its_ratio() {
        let free = "name = \"free\"\nmasses = [1.0, 2.0, 1.5]\n[[spring]]\ndofs = [1, 2]\nstiffness = 1e4\n[[spring]]\ndofs = [2, 3]\nstiffness = 2e4\n[damping]\nkind = \"modal\"\nratios = [0.01, 0.03]\n";
        let mut m = Model::from_toml_str(free, "t").unwrap();
        let before = flexible_frequencies(&m).unwrap();
        assert_eq!(before.len(), 2);
        m.springs.push(Spring {
            dofs: vec![3],
            stiffness: 10.0,
            name: None,
        });
        keep_modal_ratios(&mut m, &before).unwrap();
        let Damping::Modal { ratios, .. } = &m.damping else {
            panic!("modal")
        };
        assert_eq!(ratios, &vec![0.01, 0.01, 0.03]);
        let free_model = Model::from_toml_str(free, "t").unwrap();
        assert_eq!(added_mode(&free_model, &m), Some(0));
        assert_eq!(added_mode(&m, &free_model), None);
        // the former flexible modes are now modes 2 and 3 (0-based 1, 2)
        assert!((modal_ratio(&m, 1) - 0.01).abs() < 1e-9);
        assert!((modal_ratio(&m, 2) - 0.03).abs() < 1e-9);
        let grounded = flexible_frequencies(&m).unwrap();
        m.springs[2].stiffness = 0.0;
        keep_modal_ratios(&mut m, &grounded).unwrap();
        let Damping::Modal { ratios, .. } = &m.damping else {
            panic!("modal")
        };
        assert_eq!(ratios, &vec![0.01, 0.03]);
        assert!((modal_ratio(&m, 2) - 0.03).abs() < 1e-9);
    }

    /// A spring to ground stiffer than the structure's own springs adds a
    /// mode above the others: the ratio goes in at its place.
    #[test]
    fn a_stiff_spring_to_ground_adds_its_mode_in_frequency_order() {
        let before = [10.0, 100.0];
        assert_eq!(odd_one_out(&[0.5, 10.0, 100.0], &before), 0);
        assert_eq!(odd_one_out(&[10.2, 99.0, 400.0], &before), 2);
        assert_eq!(odd_one_out(&[10.1, 50.0, 100.5], &before), 1);
    }
}
