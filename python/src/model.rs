//! `tacit.Model`: a lumped structural model (masses, springs, damping and
//! nonlinear elements), read from a TOML file or built from a dict.

use crate::{convert, err};
use numpy::PyArray2;
use pyo3::prelude::*;
use std::path::PathBuf;

/// A structural model: masses (kg), linear springs (N/m), damping, and
/// nonlinear elements (contact, friction, cubic spring, ...). DOFs are
/// numbered from 1 in every argument and result.
#[pyclass(module = "tacit._tacit", frozen)]
#[derive(Clone)]
pub struct Model {
    pub(crate) inner: tacit::model::Model,
    /// The file it was read from (None when built in memory).
    pub(crate) path: Option<PathBuf>,
}

#[pymethods]
impl Model {
    /// Read and check a model file (TOML, docs/formats.md).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Model> {
        let inner = tacit::model::Model::from_file(&path).map_err(err)?;
        Ok(Model {
            inner,
            path: Some(path),
        })
    }

    /// A model from TOML text (the model file format).
    #[staticmethod]
    #[pyo3(signature = (text, name = "<string>"))]
    fn from_toml(text: &str, name: &str) -> PyResult<Model> {
        let inner = tacit::model::Model::from_toml_str(text, name).map_err(err)?;
        Ok(Model { inner, path: None })
    }

    /// A model from its fields as JSON text (the keys of the model file:
    /// `masses`, `spring`, `damping`, `contact`, ...); `tacit.Model.from_dict`
    /// passes a dict here.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Model> {
        let inner: tacit::model::Model =
            serde_json::from_str(text).map_err(|e| err(format!("model <dict>: {e}")))?;
        inner.validate("<dict>").map_err(err)?;
        Ok(Model { inner, path: None })
    }

    /// The model as TOML text (the model file format).
    fn to_toml(&self) -> String {
        self.inner.to_toml_string()
    }

    /// The model's fields as JSON text (`tacit.Model.to_dict` parses it).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.inner).map_err(err)
    }

    /// Name of the model.
    #[getter]
    fn name(&self) -> String {
        self.inner.name.clone()
    }

    /// Number of DOFs.
    #[getter]
    fn ndof(&self) -> usize {
        self.inner.ndof()
    }

    /// The file it was read from, or None.
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.path.clone()
    }

    /// True when the model has nonlinear elements.
    #[getter]
    fn is_nonlinear(&self) -> bool {
        self.inner.is_nonlinear()
    }

    /// The model without its nonlinear elements.
    fn linear_part(&self) -> Model {
        Model {
            inner: self.inner.linear_part(),
            path: None,
        }
    }

    /// Mass matrix, kg (ndof × ndof).
    fn mass_matrix<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        convert::matrix(py, &self.inner.mass_matrix())
    }

    /// Stiffness matrix of the linear springs, N/m (ndof × ndof).
    fn stiffness_matrix<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        convert::matrix(py, &self.inner.stiffness_matrix())
    }

    /// Damping matrix, N s/m (ndof × ndof).
    fn damping_matrix<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let c = self.inner.damping_matrix().map_err(err)?;
        Ok(convert::matrix(py, &c))
    }

    fn __repr__(&self) -> String {
        format!(
            "Model(name={:?}, ndof={}, nonlinear={})",
            self.inner.name,
            self.inner.ndof(),
            self.inner.is_nonlinear()
        )
    }
}
