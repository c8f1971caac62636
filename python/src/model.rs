//! `tacit.Model`: a structural model (masses, springs, damping and
//! nonlinear elements), read from a TOML file or built from a dict; or a
//! model from mass and stiffness matrices with named points, reduced
//! onto the points of a record when it is used.

use crate::{convert, err};
use numpy::PyArray2;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;
use tacit::model::matrix::{Entries, MatrixModel};

/// A matrix as it crosses from Python: rows, columns, and the entries'
/// row indices, column indices (0-based) and values.
type Triplets = (usize, usize, Vec<i64>, Vec<i64>, Vec<f64>);

/// Check the indices of a matrix given as triplets; `what` names it.
fn entries(t: Triplets, what: &str) -> PyResult<Entries> {
    let (r, c, rows, cols, vals) = t;
    if rows.len() != vals.len() || cols.len() != vals.len() {
        return Err(err(format!(
            "{what}: {} rows, {} columns and {} values of entries",
            rows.len(),
            cols.len(),
            vals.len()
        )));
    }
    let mut e = Vec::with_capacity(vals.len());
    for ((&i, &j), &v) in rows.iter().zip(&cols).zip(&vals) {
        if i < 0 || j < 0 {
            return Err(err(format!("{what}: negative index ({i}, {j})")));
        }
        e.push((i as usize, j as usize, v));
    }
    Ok(((r, c), e))
}

/// A structural model: masses (kg), linear springs (N/m), damping, and
/// nonlinear elements (contact, friction, cubic spring, ...). DOFs are
/// numbered from 1 in every argument and result.
#[pyclass(module = "tacit._tacit", frozen)]
#[derive(Clone)]
pub struct Model {
    pub(crate) inner: tacit::model::Model,
    /// The file it was read from (None when built in memory).
    pub(crate) path: Option<PathBuf>,
    /// A model from matrices before its reduction (`inner` is then empty).
    pub(crate) matrix: Option<Arc<MatrixModel>>,
}

impl Model {
    /// A lumped (or reduced) model.
    pub(crate) fn dense(inner: tacit::model::Model, path: Option<PathBuf>) -> Model {
        Model {
            inner,
            path,
            matrix: None,
        }
    }

    /// The dense model; an error for a model from matrices not yet
    /// reduced, naming `what` needs it.
    pub(crate) fn reduced(&self, what: &str) -> PyResult<&tacit::model::Model> {
        match &self.matrix {
            Some(mm) => Err(err(format!(
                "{what}: model {} is a model from matrices ({} DOFs), reduced onto the points of a record when it is used; reduce it first with Model.reduce(points)",
                mm.source.display(),
                mm.n
            ))),
            None => Ok(&self.inner),
        }
    }

    /// The model for these records: a model from matrices reduced onto
    /// their points (cut-off from their band), else the model itself.
    pub(crate) fn for_records(
        &self,
        records: &[&tacit::record::Record],
    ) -> PyResult<std::borrow::Cow<'_, tacit::model::Model>> {
        match &self.matrix {
            Some(mm) => Ok(std::borrow::Cow::Owned(
                mm.reduce_for_records(records).map_err(err)?,
            )),
            None => Ok(std::borrow::Cow::Borrowed(&self.inner)),
        }
    }
}

#[pymethods]
impl Model {
    /// Read and check a model file (TOML, docs/formats.md).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Model> {
        if tacit::model::matrix::is_matrix_file(&path).map_err(err)? {
            let mm = MatrixModel::from_file(&path).map_err(err)?;
            return Ok(Model {
                inner: tacit::model::Model::default(),
                path: Some(path),
                matrix: Some(Arc::new(mm)),
            });
        }
        let inner = tacit::model::Model::from_file(&path).map_err(err)?;
        Ok(Model::dense(inner, Some(path)))
    }

    /// A model from mass, stiffness and (optionally) damping matrices
    /// given as triplets (rows, columns, row indices, column indices,
    /// values; 0-based) and the rest of a model file as JSON text
    /// (`points`: label → DOF from 1, `fixed`, `interfaces`, `reduction`,
    /// `damping`, `name`, the elements by label); `tacit.Model.from_matrices`
    /// passes NumPy and SciPy matrices here. The checks and errors are the
    /// Matrix Market reader's.
    #[staticmethod]
    #[pyo3(signature = (name, m, k, c, table))]
    fn _from_matrices(
        name: &str,
        m: Triplets,
        k: Triplets,
        c: Option<Triplets>,
        table: &str,
    ) -> PyResult<Model> {
        let json: serde_json::Value =
            serde_json::from_str(table).map_err(|e| err(format!("model {name}: {e}")))?;
        let table: toml::Table = toml::Value::try_from(json)
            .ok()
            .and_then(|v| v.as_table().cloned())
            .ok_or_else(|| err(format!("model {name}: the fields must form a table")))?;
        let c = c.map(|c| entries(c, "damping matrix")).transpose()?;
        let mm = MatrixModel::from_matrices(
            name,
            entries(m, "mass matrix")?,
            entries(k, "stiffness matrix")?,
            c,
            table,
        )
        .map_err(err)?;
        Ok(Model {
            inner: tacit::model::Model::default(),
            path: None,
            matrix: Some(Arc::new(mm)),
        })
    }

    /// A model from matrices reduced (Craig–Bampton) onto `points` (labels)
    /// and the points of its elements and interfaces, with the
    /// fixed-interface modes up to the model's cut-off or twice
    /// `band_top_hz`. The reduced DOFs 1, 2, ... are the kept points in the
    /// order of their DOF in the matrices (`points` of the result), then
    /// the modal coordinates.
    #[pyo3(signature = (points, band_top_hz = None))]
    fn reduce(&self, points: Vec<String>, band_top_hz: Option<f64>) -> PyResult<Model> {
        let mm = self.matrix.as_ref().ok_or_else(|| {
            err(format!(
                "reduce: model {} is not a model from matrices",
                self.inner.name
            ))
        })?;
        let inner = mm.reduce(&points, band_top_hz).map_err(err)?;
        Ok(Model::dense(inner, self.path.clone()))
    }

    /// True for a model from matrices not yet reduced.
    #[getter]
    fn unreduced(&self) -> bool {
        self.matrix.is_some()
    }

    /// Point labels: a reduced model's kept points (reduced DOF i + 1 is
    /// `points[i]`), every labelled DOF of a model from matrices, none for
    /// a lumped model.
    #[getter]
    fn points(&self) -> Vec<String> {
        match &self.matrix {
            Some(mm) => mm.points.iter().map(|p| p.0.clone()).collect(),
            None => self.inner.points.clone(),
        }
    }

    /// A reduced model's reduction (kept points, modes, frequencies of the
    /// full and the reduced model) as JSON text, or None.
    fn reduction_json(&self) -> PyResult<Option<String>> {
        let r = self.inner.matrices.as_ref().and_then(|l| l.report.as_ref());
        r.map(|r| serde_json::to_string(r).map_err(err)).transpose()
    }

    /// A model from TOML text (the model file format).
    #[staticmethod]
    #[pyo3(signature = (text, name = "<string>"))]
    fn from_toml(text: &str, name: &str) -> PyResult<Model> {
        let inner = tacit::model::Model::from_toml_str(text, name).map_err(err)?;
        Ok(Model::dense(inner, None))
    }

    /// A model from its fields as JSON text (the keys of the model file:
    /// `masses`, `spring`, `damping`, `contact`, ...); `tacit.Model.from_dict`
    /// passes a dict here.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Model> {
        let inner: tacit::model::Model =
            serde_json::from_str(text).map_err(|e| err(format!("model <dict>: {e}")))?;
        inner.validate("<dict>").map_err(err)?;
        Ok(Model::dense(inner, None))
    }

    /// The model as TOML text (the model file format).
    fn to_toml(&self) -> PyResult<String> {
        Ok(self.reduced("to_toml")?.to_toml_string())
    }

    /// The model's fields as JSON text (`tacit.Model.to_dict` parses it).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(self.reduced("to_json")?).map_err(err)
    }

    /// Name of the model.
    #[getter]
    fn name(&self) -> String {
        match &self.matrix {
            Some(mm) => mm.source.display().to_string(),
            None => self.inner.name.clone(),
        }
    }

    /// Number of DOFs (of the matrices, for a model from matrices not yet
    /// reduced).
    #[getter]
    fn ndof(&self) -> usize {
        self.matrix.as_ref().map_or(self.inner.ndof(), |mm| mm.n)
    }

    /// The file it was read from, or None.
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.path.clone()
    }

    /// True when the model has nonlinear elements.
    #[getter]
    fn is_nonlinear(&self) -> PyResult<bool> {
        match &self.matrix {
            Some(_) => Ok(self.reduced("is_nonlinear")?.is_nonlinear()),
            None => Ok(self.inner.is_nonlinear()),
        }
    }

    /// The model without its nonlinear elements.
    fn linear_part(&self) -> PyResult<Model> {
        Ok(Model::dense(
            self.reduced("linear_part")?.linear_part(),
            None,
        ))
    }

    /// Mass matrix, kg (ndof × ndof).
    fn mass_matrix<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(convert::matrix(
            py,
            &self.reduced("mass_matrix")?.mass_matrix(),
        ))
    }

    /// Stiffness matrix of the linear springs, N/m (ndof × ndof).
    fn stiffness_matrix<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(convert::matrix(
            py,
            &self.reduced("stiffness_matrix")?.stiffness_matrix(),
        ))
    }

    /// Damping matrix, N s/m (ndof × ndof).
    fn damping_matrix<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let c = self
            .reduced("damping_matrix")?
            .damping_matrix()
            .map_err(err)?;
        Ok(convert::matrix(py, &c))
    }

    fn __repr__(&self) -> String {
        if let Some(mm) = &self.matrix {
            return format!(
                "Model(from matrices {}, ndof={}, points={}, not reduced)",
                mm.source.display(),
                mm.n,
                mm.points.len()
            );
        }
        format!(
            "Model(name={:?}, ndof={}, nonlinear={})",
            self.inner.name,
            self.inner.ndof(),
            self.inner.is_nonlinear()
        )
    }
}
