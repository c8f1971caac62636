//! Models given as matrices: a model TOML with a `[matrices]` section that
//! points to mass and stiffness matrices (damping optional) in Matrix
//! Market coordinate format, a `[points]` table of labels, fixed DOFs by
//! label, possible `[interfaces]`, and the nonlinear elements placed by
//! label (layout in `docs/formats.md`).
//!
//! [`MatrixModel::reduce`] turns it into the dense [`Model`] the rest of
//! tacit runs on: a Craig–Bampton reduction ([`crate::reduce::cb`]) that
//! keeps physical the element points, the interface points and the
//! measured and driven points, with fixed-interface modes up to a cut-off
//! (by default twice the top of the excitation band). The reduced
//! coordinates are the kept points in the order of their DOF in the
//! matrices, numbered from 1, then the modal coordinates.

use super::{Model, Spring};
use crate::error::{Result, TacitError};
use crate::reduce::cb::{craig_bampton, CbSettings};
use crate::reduce::sparse::{self, Factor, SpMat};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Sections of the model file that name the matrices.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct MatricesSpec {
    mass: String,
    stiffness: String,
    #[serde(default)]
    damping: Option<String>,
    #[serde(default)]
    fixed: Vec<String>,
}

/// `[interfaces]`: points (and pairs of points) where an effect may act
/// that no sensor sees.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct InterfacesSpec {
    #[serde(default)]
    points: Vec<String>,
    #[serde(default)]
    pairs: Vec<[String; 2]>,
}

/// `[reduction]`: the cut-off of the fixed-interface modes.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReductionSpec {
    /// Fixed explicit cut-off, Hz (default: `band_factor` × band top).
    #[serde(default)]
    pub cutoff_hz: Option<f64>,
    /// Cut-off as a multiple of the top of the excitation band (default 2).
    #[serde(default)]
    pub band_factor: Option<f64>,
    /// Most fixed-interface modes (default 200).
    #[serde(default)]
    pub max_modes: Option<usize>,
    /// Damping ratio added to the reduced model's modes above the cut-off
    /// (default [`ABOVE_CUTOFF_DAMPING`]; 0 leaves them as the damping
    /// model makes them).
    #[serde(default)]
    pub above_cutoff_damping: Option<f64>,
}

/// A matrix in memory: its size (rows, columns) and its entries
/// `(row, column, value)`, 0-based.
pub type Entries = ((usize, usize), Vec<(usize, usize, f64)>);

/// Default cut-off over band top.
pub const BAND_FACTOR: f64 = 2.0;
/// Default most fixed-interface modes.
pub const MAX_MODES: usize = 200;
/// Default damping ratio added to the modes of a reduced model above its
/// cut-off: the frequencies there are the reduction's, not the full
/// model's (docs/formats.md, "Reduction").
pub const ABOVE_CUTOFF_DAMPING: f64 = 0.7;

/// A model read from matrices, before reduction.
#[derive(Debug, Clone)]
pub struct MatrixModel {
    /// The model file.
    pub source: PathBuf,
    /// Number of DOFs of the matrices.
    pub n: usize,
    m: SpMat,
    k: SpMat,
    c: Option<SpMat>,
    /// Point labels and their DOF (0-based), by DOF.
    pub points: Vec<(String, usize)>,
    index: HashMap<String, usize>,
    fixed: Vec<usize>,
    interfaces: InterfacesSpec,
    /// Reduction settings from the file.
    pub reduction: ReductionSpec,
    /// The rest of the file (name, damping, elements with point labels).
    rest: toml::Table,
    /// Labels the elements use.
    element_points: Vec<String>,
}

/// One frequency of the reduction check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrequencyCheck {
    /// Full model, Hz.
    pub full_hz: f64,
    /// Reduced model, Hz.
    pub reduced_hz: f64,
    /// Relative error.
    pub error: f64,
}

/// What the reduction kept and how well it reproduces the full model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReductionReport {
    /// DOFs of the matrices.
    pub full_dofs: usize,
    /// Fixed DOFs.
    pub fixed_dofs: usize,
    /// Kept points, in the order of the reduced DOFs 1, 2, ...
    pub kept: Vec<String>,
    /// Interface pairs tried as effect locations besides the coupled pairs.
    pub interface_pairs: Vec<[String; 2]>,
    /// Fixed-interface modes kept.
    pub modal_coordinates: usize,
    /// Cut-off of the fixed-interface modes, Hz.
    pub cutoff_hz: f64,
    /// Top of the excitation band, Hz (when known).
    pub band_top_hz: Option<f64>,
    /// False when `max_modes` stopped the modes before the cut-off.
    pub complete: bool,
    /// Full and reduced frequencies up to `check_up_to_hz`.
    pub frequencies: Vec<FrequencyCheck>,
    /// The check's upper frequency (twice the band top, or the cut-off).
    pub check_up_to_hz: f64,
    /// Largest relative frequency error in the band (0 when no mode is in it).
    pub max_error_in_band: f64,
    /// Largest relative frequency error up to `check_up_to_hz`.
    pub max_error: f64,
    /// Modes of the reduced model above the cut-off given the added
    /// damping ratio `above_cutoff_damping` (0 when the reduction is exact:
    /// every DOF kept or every interior mode retained).
    pub damped_above_cutoff: usize,
    /// Damping ratio added to those modes.
    pub above_cutoff_damping: f64,
    /// Time to build the reduction, s.
    pub seconds: f64,
}

impl ReductionReport {
    /// Markdown section for the report.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "## Reduction\n\nCraig–Bampton: {} DOFs ({} fixed) → {} kept points + {} fixed-interface modes up to {:.1} Hz{}; built in {:.2} s.\n\n",
            self.full_dofs,
            self.fixed_dofs,
            self.kept.len(),
            self.modal_coordinates,
            self.cutoff_hz,
            if self.complete { "" } else { " (stopped by max_modes below the cut-off)" },
            self.seconds
        );
        let pts: Vec<String> = self
            .kept
            .iter()
            .enumerate()
            .map(|(i, p)| format!("{} = `{p}`", i + 1))
            .collect();
        if self.damped_above_cutoff > 0 {
            s += &format!(
                "The {} modes of the reduced model above the cut-off (frequencies of the reduction, not of the full model) carry an added damping ratio of {}.\n\n",
                self.damped_above_cutoff, self.above_cutoff_damping
            );
        }
        s += &format!("Kept points (reduced DOF = label), each tried to ground as an effect location: {}.\n\n", pts.join(", "));
        if !self.interface_pairs.is_empty() {
            let pr: Vec<String> = self
                .interface_pairs
                .iter()
                .map(|[a, b]| format!("`{a}`–`{b}`"))
                .collect();
            s += &format!("Interface pairs tried: {}.\n\n", pr.join(", "));
        }
        s += &format!(
            "Frequencies up to {:.1} Hz (largest error {:.3} % in the band, {:.3} % up to {:.1} Hz):\n\n| full, Hz | reduced, Hz | error |\n|---|---|---|\n",
            self.check_up_to_hz,
            100.0 * self.max_error_in_band,
            100.0 * self.max_error,
            self.check_up_to_hz
        );
        for f in &self.frequencies {
            s += &format!(
                "| {:.3} | {:.3} | {:.4} % |\n",
                f.full_hz,
                f.reduced_hz,
                100.0 * f.error
            );
        }
        s
    }
}

/// The linear part of a model given as matrices, after reduction.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearMatrices {
    /// Mass matrix without its diagonal (the diagonal is `Model::masses`).
    pub m_offdiag: DMatrix<f64>,
    /// Stiffness matrix less the springs derived from it (`Model::springs`).
    pub k_rest: DMatrix<f64>,
    /// Damping matrix from a file (reduced), plus the damping added to the
    /// modes above the reduction's cut-off; `None` when neither.
    pub c: Option<DMatrix<f64>>,
    /// The reduction and its check.
    pub report: Option<ReductionReport>,
    /// DOF in the matrices (from 1) of each kept point.
    pub kept_dofs: Vec<usize>,
    /// The first `derived_springs` of `Model::springs` are couplings of the
    /// matrices (the elements of the file come after them).
    pub derived_springs: usize,
    /// Multiplier of the matrices' stiffness (`k_rest` and the derived
    /// springs, which are stored unscaled; 1 as read): the calibration's
    /// `stiffness_scale`.
    pub stiffness_scale: f64,
    /// Multiplier of the matrices' mass (1 as read): `mass_scale`.
    pub mass_scale: f64,
    /// Calibrated by the scales (a finite element model: true) rather than
    /// by its springs (a modal model: false); see
    /// [`Model::calibrated_by_scales`].
    pub by_scales: bool,
}

impl LinearMatrices {
    /// Reduced matrices as read (scales 1, no reduction report, calibrated
    /// by springs until `by_scales` is set).
    pub fn new(
        m_offdiag: DMatrix<f64>,
        k_rest: DMatrix<f64>,
        c: Option<DMatrix<f64>>,
        kept_dofs: Vec<usize>,
        derived_springs: usize,
    ) -> LinearMatrices {
        LinearMatrices {
            m_offdiag,
            k_rest,
            c,
            report: None,
            kept_dofs,
            derived_springs,
            stiffness_scale: 1.0,
            mass_scale: 1.0,
            by_scales: false,
        }
    }
}

fn model_err(src: &Path, m: String) -> TacitError {
    TacitError::model(src.display().to_string(), m)
}

/// True when a model file has a `[matrices]` section.
pub fn is_matrix_model(text: &str) -> bool {
    text.parse::<toml::Table>()
        .map(|t| t.contains_key("matrices"))
        .unwrap_or(false)
}

/// Read a Matrix Market file (coordinate, real, general or symmetric) as a
/// sparse matrix with duplicates summed; checks it is `n × n` (when `n` is
/// given) and symmetric.
pub fn read_matrix_market(path: &Path, what: &str, n: Option<usize>) -> Result<SpMat> {
    let err = |m: String| TacitError::model(path.display().to_string(), format!("{what}: {m}"));
    if !path.exists() {
        return Err(err("file not found".into()));
    }
    let coo = nalgebra_sparse::io::load_coo_from_matrix_market_file::<f64, _>(path)
        .map_err(|e| err(format!("not a real Matrix Market coordinate matrix: {e}")))?;
    let e: Vec<(usize, usize, f64)> = coo.triplet_iter().map(|(i, j, &v)| (i, j, v)).collect();
    checked_matrix((coo.nrows(), coo.ncols()), e, n).map_err(err)
}

/// A sparse matrix from its entries `(row, column, value)` (0-based,
/// duplicates summed), checked: square, `n × n` when `n` (the mass
/// matrix's size) is given, indices in range, finite, symmetric within
/// 1e-9 of the largest entry. The error names the entry (from 1).
pub fn checked_matrix(
    (r, c): (usize, usize),
    mut e: Vec<(usize, usize, f64)>,
    n: Option<usize>,
) -> std::result::Result<SpMat, String> {
    if r != c {
        return Err(format!("the matrix is {r} × {c}; it must be square"));
    }
    if let Some(n) = n {
        if r != n {
            return Err(format!(
                "the matrix is {r} × {r} but the mass matrix is {n} × {n}"
            ));
        }
    }
    if let Some(&(i, j, _)) = e.iter().find(|t| t.0 >= r || t.1 >= r) {
        return Err(format!(
            "entry ({}, {}) is outside the {r} × {r} matrix",
            i + 1,
            j + 1
        ));
    }
    if let Some(&(i, j, v)) = e.iter().find(|t| !t.2.is_finite()) {
        return Err(format!("entry ({}, {}) = {v} is not finite", i + 1, j + 1));
    }
    e.retain(|t| t.2 != 0.0);
    let a = sparse::from_entries(r, r, &e).map_err(|e| e.to_string())?;
    check_symmetric(&a)?;
    Ok(a)
}

/// Symmetry within 1e-9 of the largest entry; the error names the entry.
fn check_symmetric(a: &SpMat) -> std::result::Result<(), String> {
    let e = sparse::entries(a);
    let scale = e.iter().fold(0.0f64, |m, t| m.max(t.2.abs()));
    let map: HashMap<(usize, usize), f64> = e.iter().map(|&(i, j, v)| ((i, j), v)).collect();
    for &(i, j, v) in &e {
        let w = map.get(&(j, i)).copied().unwrap_or(0.0);
        if (v - w).abs() > 1e-9 * scale {
            return Err(format!(
                "not symmetric: entry ({}, {}) = {v:e} but ({}, {}) = {w:e}",
                i + 1,
                j + 1,
                j + 1,
                i + 1
            ));
        }
    }
    Ok(())
}

impl MatrixModel {
    /// Read and check a model file with a `[matrices]` section.
    pub fn from_file(path: &Path) -> Result<MatrixModel> {
        let text = std::fs::read_to_string(path).map_err(|e| TacitError::io(path, e))?;
        let mut rest: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| model_err(path, e.to_string().trim_end().into()))?;
        let take = |t: &mut toml::Table, key: &str| t.remove(key);
        let spec: MatricesSpec = take(&mut rest, "matrices")
            .ok_or_else(|| model_err(path, "no [matrices] section".into()))?
            .try_into()
            .map_err(|e: toml::de::Error| model_err(path, format!("[matrices]: {e}")))?;
        let points_t = take(&mut rest, "points").ok_or_else(|| {
            model_err(
                path,
                "[points]: a model from matrices needs a table of point labels".into(),
            )
        })?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let m = read_matrix_market(&dir.join(&spec.mass), "[matrices] mass", None)?;
        let n = m.nrows();
        let k = read_matrix_market(&dir.join(&spec.stiffness), "[matrices] stiffness", Some(n))?;
        let c = match &spec.damping {
            Some(f) => Some(read_matrix_market(
                &dir.join(f),
                "[matrices] damping",
                Some(n),
            )?),
            None => None,
        };
        Self::from_parts(path, (m, k, c), &spec.fixed, points_t, rest)
    }

    /// A model from matrices held in memory (mass `m`, stiffness `k`,
    /// damping `c`, each checked by [`checked_matrix`] and named so in
    /// errors) and the rest of a model file as a table: `[points]`, and
    /// optionally `fixed` (labels), `[interfaces]`, `[reduction]`,
    /// `[damping]`, `name` and the elements placed by label. `name` names
    /// the model in errors. The checks are those of [`MatrixModel::from_file`].
    pub fn from_matrices(
        name: &str,
        m: Entries,
        k: Entries,
        c: Option<Entries>,
        mut table: toml::Table,
    ) -> Result<MatrixModel> {
        let path = Path::new(name);
        let err = |what: &'static str| move |e: String| model_err(path, format!("{what}: {e}"));
        let m = checked_matrix(m.0, m.1, None).map_err(err("mass matrix"))?;
        let n = m.nrows();
        let k = checked_matrix(k.0, k.1, Some(n)).map_err(err("stiffness matrix"))?;
        let c = match c {
            Some(c) => Some(checked_matrix(c.0, c.1, Some(n)).map_err(err("damping matrix"))?),
            None => None,
        };
        let fixed: Vec<String> = match table.remove("fixed") {
            Some(v) => v
                .try_into()
                .map_err(|e: toml::de::Error| model_err(path, format!("fixed: {e}")))?,
            None => vec![],
        };
        let points_t = table.remove("points").ok_or_else(|| {
            model_err(
                path,
                "points: a model from matrices needs point labels".into(),
            )
        })?;
        Self::from_parts(path, (m, k, c), &fixed, points_t, table)
    }

    /// The checks and the model once the matrices are read.
    fn from_parts(
        path: &Path,
        (m, k, c): (SpMat, SpMat, Option<SpMat>),
        fixed_labels: &[String],
        points_t: toml::Value,
        mut rest: toml::Table,
    ) -> Result<MatrixModel> {
        let take = |t: &mut toml::Table, key: &str| t.remove(key);
        let interfaces: InterfacesSpec = match take(&mut rest, "interfaces") {
            Some(v) => v
                .try_into()
                .map_err(|e: toml::de::Error| model_err(path, format!("[interfaces]: {e}")))?,
            None => InterfacesSpec::default(),
        };
        let reduction: ReductionSpec = match take(&mut rest, "reduction") {
            Some(v) => v
                .try_into()
                .map_err(|e: toml::de::Error| model_err(path, format!("[reduction]: {e}")))?,
            None => ReductionSpec::default(),
        };
        if rest.contains_key("masses") {
            return Err(model_err(
                path,
                "masses: a model from matrices takes its masses from [matrices] mass".into(),
            ));
        }
        let n = m.nrows();
        let (points, index) = read_points(path, points_t, n)?;
        let label_of = |what: &str, l: &str| -> Result<usize> {
            index
                .get(l)
                .copied()
                .ok_or_else(|| model_err(path, format!("{what}: point \"{l}\" is not in [points]")))
        };
        let mut fixed = vec![];
        for l in fixed_labels {
            fixed.push(label_of("[matrices] fixed", l)?);
        }
        fixed.sort_unstable();
        fixed.dedup();
        for l in interfaces
            .points
            .iter()
            .chain(interfaces.pairs.iter().flatten())
        {
            label_of("[interfaces]", l)?;
        }
        let element_points = element_labels(path, &rest, &index)?;
        let mm = MatrixModel {
            source: path.to_path_buf(),
            n,
            m,
            k,
            c,
            points,
            index,
            fixed,
            interfaces,
            reduction,
            rest,
            element_points,
        };
        mm.check_mass()?;
        Ok(mm)
    }

    /// Reduce onto the points of the records' channels (a channel named by
    /// DOF, `accel_5`, stands for DOF 5 of the matrices, which must have a
    /// label), the cut-off from the widest band of the records; errors
    /// name the record, the channel and the point. The channels are not
    /// resolved here ([`Model::resolve_channels`]).
    pub fn reduce_for_records(&self, records: &[&crate::record::Record]) -> Result<Model> {
        let src = self.source.display();
        let mut labels = vec![];
        for r in records {
            for c in r.inputs.iter().chain(&r.outputs) {
                let l = match &c.point {
                    Some(p) if self.dof_of(p).is_none() => {
                        return Err(TacitError::record(
                            r.source.clone(),
                            format!("channel {}: point \"{p}\" is not in [points] of {src}", c.name()),
                        ))
                    }
                    Some(p) => p.as_str(),
                    None => self.label_of(c.dof).ok_or_else(|| {
                        TacitError::record(
                            r.source.clone(),
                            format!("channel {}: DOF {} of the matrices has no label in [points] of {src}", c.name(), c.dof),
                        )
                    })?,
                };
                labels.push(l.to_string());
            }
        }
        let top = records
            .iter()
            .filter_map(|r| crate::record::band_top(r))
            .fold(None, |a: Option<f64>, b| Some(a.map_or(b, |a| a.max(b))));
        self.reduce(&labels, top)
    }

    /// The label's DOF (0-based).
    pub fn dof_of(&self, label: &str) -> Option<usize> {
        self.index.get(label).copied()
    }

    /// The label of DOF `d` of the matrices (from 1), if it has one.
    pub fn label_of(&self, d: usize) -> Option<&str> {
        self.points
            .iter()
            .find(|p| p.1 + 1 == d)
            .map(|p| p.0.as_str())
    }

    fn free(&self) -> Vec<usize> {
        let mut is_fixed = vec![false; self.n];
        for &d in &self.fixed {
            is_fixed[d] = true;
        }
        (0..self.n).filter(|&d| !is_fixed[d]).collect()
    }

    fn label_at(&self, dof: usize) -> String {
        self.points
            .iter()
            .find(|p| p.1 == dof)
            .map_or_else(|| format!("DOF {}", dof + 1), |p| format!("\"{}\"", p.0))
    }

    /// The mass matrix of the free DOFs must be positive definite.
    fn check_mass(&self) -> Result<()> {
        let free = self.free();
        let mut diag = vec![0.0; self.n];
        for (i, j, v) in sparse::entries(&self.m) {
            if i == j {
                diag[i] += v;
            }
        }
        for &d in &free {
            let v = diag[d];
            if !(v > 0.0) {
                return Err(model_err(
                    &self.source,
                    format!(
                        "[matrices] mass: diagonal entry ({}, {}) = {v} at {}: the mass matrix must be positive definite (every free DOF needs mass)",
                        d + 1,
                        d + 1,
                        self.label_at(d)
                    ),
                ));
            }
        }
        let mff = sparse::block(&self.m, &free, &free)?;
        if Factor::new(&mff).is_none() {
            return Err(model_err(
                &self.source,
                format!("[matrices] mass: the mass matrix of the {} free DOFs is singular or indefinite (its Cholesky factorization fails)", free.len()),
            ));
        }
        Ok(())
    }

    /// Reduce onto the element, interface and `measured` points, with the
    /// fixed-interface modes up to the file's cut-off or `band_factor` ×
    /// `band_top_hz`. Errors name the label.
    pub fn reduce(&self, measured: &[String], band_top_hz: Option<f64>) -> Result<Model> {
        let t0 = std::time::Instant::now();
        let src = &self.source;
        let mut kept_dofs = vec![];
        let ip = &self.interfaces;
        for l in self
            .element_points
            .iter()
            .chain(&ip.points)
            .chain(ip.pairs.iter().flatten())
            .chain(measured)
        {
            let d = self.dof_of(l).ok_or_else(|| {
                model_err(
                    src,
                    format!("point \"{l}\" (a record channel) is not in [points]"),
                )
            })?;
            if self.fixed.binary_search(&d).is_ok() {
                return Err(model_err(src, format!("point \"{l}\" is fixed ([matrices] fixed) and cannot be kept, measured or driven")));
            }
            kept_dofs.push(d);
        }
        kept_dofs.sort_unstable();
        kept_dofs.dedup();
        let cutoff = self.cutoff(band_top_hz)?;
        let free = self.free();
        let mut pos = vec![usize::MAX; self.n];
        for (i, &d) in free.iter().enumerate() {
            pos[d] = i;
        }
        let kept_free: Vec<usize> = kept_dofs.iter().map(|&d| pos[d]).collect();
        let mff = sparse::block(&self.m, &free, &free)?;
        let kff = sparse::block(&self.k, &free, &free)?;
        let cff = match &self.c {
            Some(c) => Some(sparse::block(c, &free, &free)?),
            None => None,
        };
        let settings = CbSettings {
            cutoff_hz: cutoff,
            max_modes: self.reduction.max_modes.unwrap_or(MAX_MODES),
        };
        let cb = craig_bampton(&mff, &kff, cff.as_ref(), &kept_free, &settings)
            .map_err(|e| model_err(src, e.to_string()))?;
        let kept: Vec<String> = kept_dofs.iter().map(|&d| self.label_at_plain(d)).collect();
        let mut cb = cb;
        let exact = cb.modes_hz.len() + kept_free.len() == free.len();
        let zeta_hi = self.above_cutoff_damping()?;
        let reduced = crate::modal::solve(&cb.m, &cb.k)?;
        let damped = if exact {
            0
        } else {
            damp_above_cutoff(&mut cb, &reduced, cutoff, zeta_hi)
        };
        let reduced_hz = reduced.freq_hz;
        let check_top = band_top_hz.map_or(cutoff, |b| 2.0 * b);
        let frequencies = check_frequencies(&mff, &kff, &reduced_hz, check_top)
            .map_err(|e| model_err(src, format!("reduction check: {e}")))?;
        let err_below = |f: f64| {
            frequencies
                .iter()
                .filter(|c| c.full_hz <= f)
                .fold(0.0f64, |m, c| m.max(c.error))
        };
        let report = ReductionReport {
            full_dofs: self.n,
            fixed_dofs: self.fixed.len(),
            interface_pairs: ip.pairs.clone(),
            modal_coordinates: cb.modes_hz.len(),
            cutoff_hz: cutoff,
            band_top_hz,
            complete: cb.complete,
            max_error_in_band: band_top_hz.map_or(0.0, err_below),
            max_error: err_below(f64::INFINITY),
            frequencies,
            check_up_to_hz: check_top,
            damped_above_cutoff: damped,
            above_cutoff_damping: zeta_hi,
            seconds: 0.0,
            kept: kept.clone(),
        };
        let mut model = self.assemble(cb, kept)?;
        if let Some(lin) = model.matrices.as_mut() {
            Arc::make_mut(lin).kept_dofs = kept_dofs.iter().map(|d| d + 1).collect();
        }
        let secs = t0.elapsed().as_secs_f64();
        if let Some(lin) = model.matrices.as_mut() {
            Arc::make_mut(lin).report = Some(ReductionReport {
                seconds: secs,
                ..report
            });
        }
        Ok(model)
    }

    fn above_cutoff_damping(&self) -> Result<f64> {
        let z = self
            .reduction
            .above_cutoff_damping
            .unwrap_or(ABOVE_CUTOFF_DAMPING);
        if !(z.is_finite() && (0.0..=1.0).contains(&z)) {
            return Err(model_err(
                &self.source,
                format!("[reduction]: above_cutoff_damping = {z} must be in [0, 1]"),
            ));
        }
        Ok(z)
    }

    fn label_at_plain(&self, dof: usize) -> String {
        self.points
            .iter()
            .find(|p| p.1 == dof)
            .map_or_else(|| format!("{}", dof + 1), |p| p.0.clone())
    }

    fn cutoff(&self, band_top_hz: Option<f64>) -> Result<f64> {
        let r = &self.reduction;
        let f = match (r.cutoff_hz, band_top_hz) {
            (Some(c), _) => c,
            (None, Some(b)) => r.band_factor.unwrap_or(BAND_FACTOR) * b,
            (None, None) => {
                return Err(model_err(
                    &self.source,
                    "[reduction]: no cut-off; give cutoff_hz, or a record (its excitation band sets it)".into(),
                ))
            }
        };
        if !(f.is_finite() && f > 0.0) {
            return Err(model_err(
                &self.source,
                format!("[reduction]: cut-off {f} Hz must be > 0"),
            ));
        }
        Ok(f)
    }

    /// The dense model of the reduced matrices: masses = the diagonal of
    /// the reduced mass; springs = the negative couplings between kept
    /// points; the rest of M and K in [`LinearMatrices`]; elements mapped to
    /// the reduced numbering.
    fn assemble(&self, cb: crate::reduce::cb::CbModel, kept: Vec<String>) -> Result<Model> {
        let nr = cb.m.nrows();
        let masses: Vec<f64> = (0..nr).map(|i| cb.m[(i, i)]).collect();
        let mut m_off = cb.m.clone();
        m_off.fill_diagonal(0.0);
        let scale = (0..nr).fold(0.0f64, |a, i| a.max(cb.k[(i, i)].abs()));
        let mut springs = vec![];
        for i in 0..cb.kept {
            for j in i + 1..cb.kept {
                let v = cb.k[(i, j)];
                if v < -1e-9 * scale {
                    springs.push(Spring {
                        dofs: vec![i + 1, j + 1],
                        stiffness: -v,
                        name: None,
                    });
                }
            }
        }
        let mut k_rest = cb.k.clone();
        for s in &springs {
            let (i, j) = s.ends();
            super::add_spring(&mut k_rest, (i, j), -s.stiffness);
        }
        let mut table = self.rest.clone();
        let reduced_index: HashMap<&str, usize> = kept
            .iter()
            .enumerate()
            .map(|(i, l)| (l.as_str(), i + 1))
            .collect();
        map_element_labels(&mut table, &|l| reduced_index.get(l).copied());
        table.insert(
            "masses".into(),
            toml::Value::Array(masses.iter().map(|&v| toml::Value::Float(v)).collect()),
        );
        let src = self.source.display().to_string();
        let mut model: Model = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| TacitError::model(&src, e.to_string()))?;
        let derived = springs.len();
        model.springs.splice(0..0, springs);
        model.interface_pairs = self
            .interfaces
            .pairs
            .iter()
            .map(|[a, b]| [reduced_index[a.as_str()], reduced_index[b.as_str()]])
            .collect();
        model.points = kept;
        model.matrices = Some(Arc::new(LinearMatrices {
            by_scales: true,
            ..LinearMatrices::new(m_off, k_rest, cb.c, vec![], derived)
        }));
        model.validate(&src)?;
        Ok(model)
    }
}

/// Add the damping ratio `zeta` to every mode of the reduced model above
/// `cutoff_hz`, as the viscous matrix `Σ_r 2 ζ ω_r (M φ_r)(M φ_r)ᵀ` (mass-
/// normalised φ_r) in the reduced damping; returns how many modes. Above
/// the cut-off the reduced model's modes are those of its constraint
/// modes, not the full model's (the first one can lie at twice the full
/// model's frequency): left lightly damped they ring at those frequencies
/// whenever a contact strikes or the force's linear interpolation between
/// samples reaches them (its images at multiples of the sample rate), and
/// an acceleration sampled without an anti-alias filter folds that ringing
/// into the band, where it depends on the cut-off chosen. Damped, the
/// sampled response converges with the cut-off; below the cut-off nothing
/// changes (the matrix is M-orthogonal to the modes there).
fn damp_above_cutoff(
    cb: &mut crate::reduce::cb::CbModel,
    modes: &crate::modal::Modes,
    cutoff_hz: f64,
    zeta: f64,
) -> usize {
    let above: Vec<usize> = (0..modes.freq_hz.len())
        .filter(|&r| modes.freq_hz[r] > cutoff_hz)
        .collect();
    if above.is_empty() || zeta == 0.0 {
        return 0;
    }
    let n = cb.m.nrows();
    let mut c = cb.c.take().unwrap_or_else(|| DMatrix::zeros(n, n));
    for &r in &above {
        let mphi = &cb.m * modes.shapes.column(r);
        c += (&mphi * mphi.transpose()) * (2.0 * zeta * modes.omega[r]);
    }
    cb.c = Some((&c + c.transpose()) * 0.5);
    above.len()
}

/// Modes of the full model (every free DOF) up to a frequency.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FullModes {
    /// Frequencies, Hz, ascending.
    pub freq_hz: Vec<f64>,
    /// The points the shapes are given at.
    pub points: Vec<String>,
    /// Mass-normalised shape of each mode at `points` (one row per mode).
    pub shapes: Vec<Vec<f64>>,
    /// False when `max_modes` stopped the modes below `up_to_hz`.
    pub complete: bool,
    /// The upper frequency asked for, Hz.
    pub up_to_hz: f64,
}

impl MatrixModel {
    /// The full model's modes up to `up_to_hz` (at most `max_modes`),
    /// from a sparse factorization and the sparse eigensolver, with the
    /// shapes at `points` (labels; a fixed point's value is 0). Errors
    /// name the label.
    pub fn full_modes(
        &self,
        up_to_hz: f64,
        max_modes: usize,
        points: &[String],
    ) -> Result<FullModes> {
        let free = self.free();
        let mut pos = vec![usize::MAX; self.n];
        for (i, &d) in free.iter().enumerate() {
            pos[d] = i;
        }
        let mut rows = vec![];
        for l in points {
            let d = self.dof_of(l).ok_or_else(|| {
                model_err(&self.source, format!("point \"{l}\" is not in [points]"))
            })?;
            rows.push(pos[d]);
        }
        let mff = sparse::block(&self.m, &free, &free)?;
        let kff = sparse::block(&self.k, &free, &free)?;
        let factor = shifted_factor(&mff, &kff, up_to_hz)
            .map_err(|e| model_err(&self.source, e.to_string()))?;
        let (modes, complete) = sparse::modes_up_to(&kff, &mff, &factor, up_to_hz, max_modes)?;
        let shapes = (0..modes.omega2.len())
            .map(|r| {
                rows.iter()
                    .map(|&i| {
                        if i == usize::MAX {
                            0.0
                        } else {
                            modes.shapes[(i, r)]
                        }
                    })
                    .collect()
            })
            .collect();
        Ok(FullModes {
            freq_hz: modes.freq_hz(),
            points: points.to_vec(),
            shapes,
            complete,
            up_to_hz,
        })
    }
}

/// The Cholesky factor of `K + σM` with σ = (2π · 0.01 · `top`)²: K may be
/// singular (a free structure).
fn shifted_factor(m: &SpMat, k: &SpMat, top: f64) -> Result<Factor> {
    let sigma = (2.0 * std::f64::consts::PI * top * 0.01).powi(2);
    let shifted = sparse::from_entries(
        k.nrows(),
        k.ncols(),
        &sparse::entries(k)
            .into_iter()
            .chain(
                sparse::entries(m)
                    .into_iter()
                    .map(|(i, j, v)| (i, j, sigma * v)),
            )
            .collect::<Vec<_>>(),
    )?;
    Factor::new(&shifted).ok_or_else(|| {
        TacitError::Numerical(
            "the full stiffness is not positive semi-definite (K + σM has no Cholesky factor)"
                .into(),
        )
    })
}

/// Full-model frequencies up to `top` Hz against the reduced ones.
fn check_frequencies(
    m: &SpMat,
    k: &SpMat,
    reduced_hz: &[f64],
    top: f64,
) -> Result<Vec<FrequencyCheck>> {
    // K may be singular (a free structure): factor K + σM with σ below the
    // band; the Ritz step uses K itself
    let factor = shifted_factor(m, k, top)?;
    let (modes, _) = sparse::modes_up_to(k, m, &factor, top, 2 * reduced_hz.len() + 20)?;
    Ok(modes
        .freq_hz()
        .iter()
        .zip(reduced_hz)
        .map(|(&f, &r)| FrequencyCheck {
            full_hz: f,
            reduced_hz: r,
            error: if f > 1e-6 * top {
                (r - f).abs() / f
            } else {
                (r - f).abs() / top
            },
        })
        .collect())
}

/// Point labels with their DOF (0-based), by DOF, and the label index.
type Points = (Vec<(String, usize)>, HashMap<String, usize>);

/// Parse `[points]`: label → DOF from 1; each DOF at most one label.
fn read_points(path: &Path, t: toml::Value, n: usize) -> Result<Points> {
    let t = match t {
        toml::Value::Table(t) => t,
        _ => {
            return Err(model_err(
                path,
                "[points] must be a table of label = DOF".into(),
            ))
        }
    };
    let mut by_dof: HashMap<usize, String> = HashMap::new();
    let mut points = vec![];
    for (label, v) in t {
        if label.is_empty() || label.chars().any(|c| c.is_whitespace() || c == ',') {
            return Err(model_err(
                path,
                format!("[points] \"{label}\": a label may not be empty or hold spaces or commas"),
            ));
        }
        let d = v.as_integer().ok_or_else(|| {
            model_err(
                path,
                format!("[points] \"{label}\" = {v}: expected a DOF number (from 1)"),
            )
        })?;
        if d < 1 || d as usize > n {
            return Err(model_err(
                path,
                format!("[points] \"{label}\" = {d}: DOF out of range 1..={n} (the matrices are {n} × {n})"),
            ));
        }
        let d = d as usize - 1;
        if let Some(other) = by_dof.insert(d, label.clone()) {
            return Err(model_err(
                path,
                format!(
                    "[points] \"{label}\" = {}: DOF {} already has the label \"{other}\"",
                    d + 1,
                    d + 1
                ),
            ));
        }
        points.push((label, d));
    }
    points.sort_by_key(|p| p.1);
    let index = points.iter().map(|(l, d)| (l.clone(), *d)).collect();
    Ok((points, index))
}

/// The element arrays of a model file (`[[contact]]`, `[[spring]]`, ...).
fn element_arrays(t: &mut toml::Table) -> Vec<(&String, &mut Vec<toml::Value>)> {
    t.iter_mut()
        .filter_map(|(k, v)| match v {
            toml::Value::Array(a) if a.iter().all(|x| x.is_table()) && !a.is_empty() => {
                Some((k, a))
            }
            _ => None,
        })
        .collect()
}

/// Labels placed in the elements' `dofs` / `dof`; errors name the key.
fn element_labels(
    path: &Path,
    rest: &toml::Table,
    index: &HashMap<String, usize>,
) -> Result<Vec<String>> {
    let mut t = rest.clone();
    let mut out = vec![];
    for (key, arr) in element_arrays(&mut t) {
        for (i, e) in arr.iter().enumerate() {
            let tbl = e.as_table().expect("element arrays hold tables");
            for f in ["dofs", "dof"] {
                let vals: Vec<&toml::Value> = match tbl.get(f) {
                    Some(toml::Value::Array(a)) => a.iter().collect(),
                    Some(v) => vec![v],
                    None => continue,
                };
                for v in vals {
                    let l = v.as_str().ok_or_else(|| {
                        model_err(path, format!("{key}[{i}].{f}: a model from matrices places elements by point label (\"n12:uy\"), not by DOF number ({v})"))
                    })?;
                    if !index.contains_key(l) {
                        return Err(model_err(
                            path,
                            format!("{key}[{i}].{f}: point \"{l}\" is not in [points]"),
                        ));
                    }
                    out.push(l.to_string());
                }
            }
        }
    }
    Ok(out)
}

/// Replace the labels in the elements' `dofs` / `dof` by reduced DOFs.
pub(super) fn map_element_labels(t: &mut toml::Table, to: &dyn Fn(&str) -> Option<usize>) {
    let conv = |v: &mut toml::Value| {
        if let Some(d) = v.as_str().and_then(to) {
            *v = toml::Value::Integer(d as i64);
        }
    };
    for (_, arr) in element_arrays(t) {
        for e in arr.iter_mut() {
            let Some(tbl) = e.as_table_mut() else {
                continue;
            };
            for f in ["dofs", "dof"] {
                match tbl.get_mut(f) {
                    Some(toml::Value::Array(a)) => a.iter_mut().for_each(conv),
                    Some(v) => conv(v),
                    None => {}
                }
            }
        }
    }
}

/// True when the model file at `path` has a `[matrices]` section; an
/// unreadable file is an error naming it.
pub fn is_matrix_file(path: &Path) -> Result<bool> {
    let text = std::fs::read_to_string(path).map_err(|e| TacitError::io(path, e))?;
    Ok(is_matrix_model(&text))
}

/// The DOFs (from 1) of point labels of a model that names its points (a
/// reduced model from matrices, a modal model). The error names `option`,
/// the label and the points the model has.
pub fn point_dofs(model: &Model, labels: &[String], option: &str) -> Result<Vec<usize>> {
    if model.points.is_empty() {
        return Err(TacitError::Setting(format!(
            "{option}: model {} names no points (a lumped model); give DOF numbers instead",
            model.name
        )));
    }
    let mut out: Vec<usize> = vec![];
    for l in labels {
        let d = model.points.iter().position(|p| p == l).ok_or_else(|| {
            TacitError::Setting(format!(
                "{option}: point \"{l}\" is not a point of model {} (points: {})",
                model.name,
                model.points.join(", ")
            ))
        })? + 1;
        if out.contains(&d) {
            return Err(TacitError::Setting(format!(
                "{option}: point \"{l}\" is listed twice"
            )));
        }
        out.push(d);
    }
    if out.is_empty() {
        return Err(TacitError::Setting(format!("{option}: no point given")));
    }
    Ok(out)
}

/// Add the reduction to a diagnose report directory: `reduction.json`
/// and a section at the end of `report.md` that also names the points of
/// the `effects` found (label, DOFs from 1).
pub fn append_report(
    dir: &Path,
    r: &ReductionReport,
    effects: &[(String, Vec<usize>)],
) -> Result<()> {
    use std::io::Write;
    let json = serde_json::to_string_pretty(r)
        .map_err(|e| TacitError::Numerical(format!("reduction report: {e}")))?;
    let p = dir.join("reduction.json");
    std::fs::write(&p, json).map_err(|e| TacitError::io(&p, e))?;
    let p = dir.join("report.md");
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&p)
        .map_err(|e| TacitError::io(&p, e))?;
    let name = |d: usize| {
        r.kept
            .get(d - 1)
            .map_or(d.to_string(), |l| format!("`{l}`"))
    };
    let mut s = String::new();
    if !effects.is_empty() {
        s += "## Effects at points\n\n";
        for (label, dofs) in effects {
            let at: Vec<String> = dofs.iter().map(|&d| name(d)).collect();
            let ground = if dofs.len() == 1 { " (to ground)" } else { "" };
            s += &format!("- {label} at {}{ground}\n", at.join(" – "));
        }
        s += "\n";
    }
    write!(f, "\n{s}{}", r.markdown()).map_err(|e| TacitError::io(&p, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain of three unit masses and unit springs, the first to
    /// ground, labelled `a`, `b`, `c`; `extra` is added to the table.
    fn chain(extra: &str) -> Result<MatrixModel> {
        let m = ((3, 3), (0..3).map(|i| (i, i, 1.0)).collect());
        let k = (
            (3, 3),
            vec![
                (0, 0, 2.0),
                (1, 1, 2.0),
                (2, 2, 1.0),
                (0, 1, -1.0),
                (1, 0, -1.0),
                (1, 2, -1.0),
                (2, 1, -1.0),
            ],
        );
        let table: toml::Table = format!("[points]\na = 1\nb = 2\nc = 3\n{extra}")
            .parse()
            .unwrap();
        MatrixModel::from_matrices("chain", m, k, None, table)
    }

    /// A fixed-free chain of `n` unit masses and springs of 1e4, points
    /// `p1`…`pn`, no damping model.
    fn long_chain(n: usize, extra: &str) -> MatrixModel {
        let m = ((n, n), (0..n).map(|i| (i, i, 1.0)).collect());
        let mut k = vec![];
        for i in 0..n {
            k.push((i, i, if i + 1 < n { 2e4 } else { 1e4 }));
            if i + 1 < n {
                k.push((i, i + 1, -1e4));
                k.push((i + 1, i, -1e4));
            }
        }
        let pts: String = (0..n)
            .map(|i| format!("p{} = {}\n", i + 1, i + 1))
            .collect();
        let table: toml::Table = format!("[points]\n{pts}{extra}").parse().unwrap();
        MatrixModel::from_matrices("long", m, ((n, n), k), None, table).unwrap()
    }

    #[test]
    fn modes_above_the_cut_off_are_damped_and_the_others_left_alone() {
        let mm = long_chain(40, "[reduction]\ncutoff_hz = 20.0\n");
        let model = mm.reduce(&["p10".into(), "p40".into()], None).unwrap();
        let rep = model.matrices.as_ref().unwrap().report.clone().unwrap();
        let (m, k) = (model.mass_matrix(), model.stiffness_matrix());
        let c = model.damping_matrix().unwrap();
        let modes = crate::modal::solve(&m, &k).unwrap();
        let mut above = 0;
        for r in 0..modes.omega.len() {
            let phi = modes.shapes.column(r);
            let zeta = (phi.transpose() * &c * phi)[(0, 0)] / (2.0 * modes.omega[r]);
            if modes.freq_hz[r] > 20.0 {
                above += 1;
                approx::assert_relative_eq!(zeta, ABOVE_CUTOFF_DAMPING, max_relative = 1e-9);
            } else {
                assert!(
                    zeta.abs() < 1e-12,
                    "mode {r} at {} Hz: {zeta}",
                    modes.freq_hz[r]
                );
            }
        }
        assert!(
            above > 0 && above == rep.damped_above_cutoff,
            "{above} {rep:?}"
        );
        assert_eq!(rep.above_cutoff_damping, ABOVE_CUTOFF_DAMPING);
        // every DOF kept: the reduction is exact, nothing is added
        let all: Vec<String> = (1..=40).map(|i| format!("p{i}")).collect();
        let exact = mm.reduce(&all, None).unwrap();
        let lin = exact.matrices.as_ref().unwrap();
        assert_eq!(lin.report.as_ref().unwrap().damped_above_cutoff, 0);
        assert!(lin.c.is_none());
        // a ratio outside [0, 1] is an error naming the key
        let bad = long_chain(
            40,
            "[reduction]\ncutoff_hz = 20.0\nabove_cutoff_damping = 1.5\n",
        );
        let e = bad.reduce(&["p10".into()], None).unwrap_err().to_string();
        assert!(e.contains("above_cutoff_damping = 1.5"), "{e}");
    }

    #[test]
    fn matrices_in_memory_are_checked_as_files_are() {
        let mm = chain("").unwrap();
        assert_eq!(mm.n, 3);
        assert_eq!(mm.dof_of("c"), Some(2));
        let e = checked_matrix((2, 2), vec![(0, 1, 1.0), (1, 0, 2.0)], None).unwrap_err();
        assert!(e.contains("not symmetric") && e.contains("(1, 2)"), "{e}");
        let e = checked_matrix((2, 2), vec![(0, 2, 1.0)], None).unwrap_err();
        assert!(
            e.contains("entry (1, 3) is outside the 2 × 2 matrix"),
            "{e}"
        );
        let e = checked_matrix((2, 2), vec![], Some(3)).unwrap_err();
        assert!(e.contains("mass matrix is 3 × 3"), "{e}");
        let e = checked_matrix((2, 2), vec![(1, 1, f64::INFINITY)], None).unwrap_err();
        assert!(e.contains("(2, 2) = inf is not finite"), "{e}");
        let e = chain("d = 3\n").unwrap_err().to_string();
        assert!(
            e.contains("chain") && e.contains("\"d\"") && e.contains("\"c\""),
            "{e}"
        );
        let e = chain("[[contact]]\ndofs = [\"z\"]\ngap = 1e-3\nstiffness = 1.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("contact[0].dofs") && e.contains("\"z\""), "{e}");
    }

    #[test]
    fn full_modes_are_the_chains_and_point_dofs_name_the_points() {
        let mm = chain("").unwrap();
        // eigenvalues of [[2,-1,0],[-1,2,-1],[0,-1,1]]: 2 − 2 cos((2r − 1)π/7)
        let modes = mm.full_modes(1.0, 10, &["c".to_string()]).unwrap();
        assert_eq!(modes.freq_hz.len(), 3);
        for (r, f) in modes.freq_hz.iter().enumerate() {
            let lam = 2.0 - 2.0 * ((2 * r + 1) as f64 * std::f64::consts::PI / 7.0).cos();
            let exact = lam.sqrt() / (2.0 * std::f64::consts::PI);
            assert!((f / exact - 1.0).abs() < 1e-9, "{f} {exact}");
        }
        // mass-normalised: the shapes at every point have unit length
        let all: Vec<String> = ["a", "b", "c"].iter().map(|s| s.to_string()).collect();
        let m = mm.full_modes(1.0, 10, &all).unwrap();
        for s in &m.shapes {
            let n2: f64 = s.iter().map(|x| x * x).sum();
            assert!((n2 - 1.0).abs() < 1e-9, "{n2}");
        }
        let red = mm
            .reduce(&["b".to_string(), "c".to_string()], Some(1.0))
            .unwrap();
        assert_eq!(red.points, ["b", "c"]);
        let d = point_dofs(&red, &["c".to_string(), "b".to_string()], "--points").unwrap();
        assert_eq!(d, vec![2, 1]);
        let e = point_dofs(&red, &["a".to_string()], "--points")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--points") && e.contains("\"a\"") && e.contains("b, c"),
            "{e}"
        );
        let lumped = Model::from_toml_str("masses = [1.0]\n", "m").unwrap();
        let e = point_dofs(&lumped, &["a".to_string()], "--points")
            .unwrap_err()
            .to_string();
        assert!(e.contains("names no points"), "{e}");
    }
}
