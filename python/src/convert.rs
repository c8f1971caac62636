//! Matrices and vectors between nalgebra and NumPy.

use nalgebra::DMatrix;
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyReadonlyArray1};
use pyo3::prelude::*;

/// A nalgebra matrix as a new 2-D NumPy array (same rows and columns).
pub fn matrix<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    let a = Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)]);
    PyArray2::from_owned_array(py, a)
}

/// Rows of equal length as a new 2-D NumPy array.
pub fn rows<'py>(py: Python<'py>, r: &[Vec<f64>]) -> Bound<'py, PyArray2<f64>> {
    let n = r.first().map_or(0, Vec::len);
    let a = Array2::from_shape_fn((r.len(), n), |(i, j)| r[i][j]);
    PyArray2::from_owned_array(py, a)
}

/// A slice as a new 1-D NumPy array.
pub fn vector<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v)
}

/// A 1-D NumPy array (any strides) as a vector.
pub fn to_vec(a: &PyReadonlyArray1<'_, f64>) -> Vec<f64> {
    a.as_array().iter().copied().collect()
}
