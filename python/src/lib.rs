//! Python bindings of tacit (`import tacit`): the extension module
//! `tacit._tacit`, wrapped by the pure-Python package in `pysrc/tacit`.
//!
//! Every tacit error becomes a `tacit.TacitError` carrying tacit's message
//! (the file, channel, key or option it names). Long computations release
//! the interpreter lock. Arrays cross as NumPy `float64` arrays, channels
//! × samples (or DOFs × samples), SI units.

use pyo3::prelude::*;

mod convert;
mod group;
mod model;
mod record;
mod run;

pyo3::create_exception!(
    _tacit,
    TacitError,
    pyo3::exceptions::PyException,
    "An error reported by tacit; the message names the file, channel, key or option at fault."
);

/// A tacit error as a Python exception.
pub(crate) fn err(e: impl std::fmt::Display) -> PyErr {
    TacitError::new_err(e.to_string())
}

/// The extension module.
#[pymodule]
fn _tacit(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("TacitError", m.py().get_type::<TacitError>())?;
    m.add("__version__", tacit_version())?;
    m.add_class::<model::Model>()?;
    m.add_class::<record::Record>()?;
    m.add_function(wrap_pyfunction!(run::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(run::modal, m)?)?;
    m.add_function(wrap_pyfunction!(run::identify, m)?)?;
    m.add_function(wrap_pyfunction!(run::diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(group::group_estimates, m)?)?;
    Ok(())
}

/// The version of the tacit library compiled in.
fn tacit_version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}
