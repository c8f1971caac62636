//! `tacit.Record`: measured (or simulated) time histories on a uniform
//! time base, read from HDF5, CSV or MAT files, written to HDF5 or CSV, or
//! built from NumPy arrays.

use crate::{convert, err};
use numpy::{PyArray1, PyArray2, PyReadonlyArray1};
use pyo3::prelude::*;
use std::path::PathBuf;
use tacit::record::{Channel, Quantity};

/// A record: input forces (N) and measured responses (m, m/s or m/s²) at
/// DOFs numbered from 1, sampled at `fs` Hz, and, for a simulated record,
/// the truth (states and the internal force of every DOF).
#[pyclass(module = "tacit._tacit", frozen)]
#[derive(Clone)]
pub struct Record {
    pub(crate) inner: tacit::record::Record,
}

/// The quantity of a name (`force`, `disp`, `vel`, `accel`).
fn quantity(name: &str) -> PyResult<Quantity> {
    Quantity::from_prefix(name).ok_or_else(|| {
        err(format!(
            "quantity \"{name}\": give one of force, disp, vel, accel"
        ))
    })
}

#[pymethods]
impl Record {
    /// A record from arrays: `inputs` maps a DOF (from 1) to its force
    /// history (N); `outputs` is a list of `(quantity, dof, data)` with
    /// quantity `disp` (m), `vel` (m/s) or `accel` (m/s²). Every history
    /// has the same length. Checked as a file would be.
    #[new]
    #[pyo3(signature = (fs, inputs, outputs, t0 = 0.0))]
    fn new(
        fs: f64,
        inputs: Vec<(usize, PyReadonlyArray1<'_, f64>)>,
        outputs: Vec<(String, usize, PyReadonlyArray1<'_, f64>)>,
        t0: f64,
    ) -> PyResult<Record> {
        let inputs = inputs
            .iter()
            .map(|(d, a)| Channel::new(Quantity::Force, *d, convert::to_vec(a)))
            .collect();
        let outputs = outputs
            .iter()
            .map(|(q, d, a)| Ok(Channel::new(quantity(q)?, *d, convert::to_vec(a))))
            .collect::<PyResult<Vec<_>>>()?;
        let inner = tacit::record::Record {
            t0,
            fs,
            inputs,
            outputs,
            truth: None,
            source: PathBuf::new(),
        };
        inner.validate(None).map_err(err)?;
        Ok(Record { inner })
    }

    /// Read a record file (.h5, .csv, .mat; units converted to SI).
    #[staticmethod]
    fn read(py: Python<'_>, path: PathBuf) -> PyResult<Record> {
        let inner = py.detach(|| tacit::record::read(&path)).map_err(err)?;
        Ok(Record { inner })
    }

    /// Write the record (.h5 keeps the truth; .csv writes it beside).
    fn write(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| tacit::record::write(&self.inner, &path))
            .map_err(err)
    }

    /// Sample rate, Hz.
    #[getter]
    fn fs(&self) -> f64 {
        self.inner.fs
    }

    /// Time of sample 0, s.
    #[getter]
    fn t0(&self) -> f64 {
        self.inner.t0
    }

    /// The file it was read from ('' when built in memory).
    #[getter]
    fn source(&self) -> PathBuf {
        self.inner.source.clone()
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// Time of every sample, s.
    fn time<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        convert::vector(py, &self.inner.times())
    }

    /// Input channels: `[(name, dof, unit, data)]` (data in N).
    fn inputs<'py>(
        &self,
        py: Python<'py>,
    ) -> Vec<(String, usize, String, Bound<'py, PyArray1<f64>>)> {
        channels(py, &self.inner.inputs)
    }

    /// Output channels: `[(name, dof, unit, data)]` (SI units).
    fn outputs<'py>(
        &self,
        py: Python<'py>,
    ) -> Vec<(String, usize, String, Bound<'py, PyArray1<f64>>)> {
        channels(py, &self.inner.outputs)
    }

    /// The true internal force of a simulated record, N (ndof × samples;
    /// left-hand side of M a + C v + K u + f = f_ext), or None.
    fn truth_force<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.inner
            .truth
            .as_ref()
            .map(|t| convert::rows(py, &t.fint))
    }

    /// The true displacements of a simulated record, m (ndof × samples),
    /// or None.
    fn truth_displacement<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.inner.truth.as_ref().map(|t| convert::rows(py, &t.u))
    }

    fn __repr__(&self) -> String {
        let names: Vec<String> = self.inner.outputs.iter().map(Channel::name).collect();
        format!(
            "Record(fs={} Hz, samples={}, inputs={}, outputs=[{}], truth={})",
            self.inner.fs,
            self.inner.len(),
            self.inner.inputs.len(),
            names.join(", "),
            self.inner.truth.is_some()
        )
    }
}

/// Channels as `(name, dof, unit, data)`.
fn channels<'py>(
    py: Python<'py>,
    chs: &[Channel],
) -> Vec<(String, usize, String, Bound<'py, PyArray1<f64>>)> {
    chs.iter()
        .map(|c| {
            (
                c.name(),
                c.dof,
                c.unit.clone(),
                convert::vector(py, &c.data),
            )
        })
        .collect()
}
