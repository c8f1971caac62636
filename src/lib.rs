//! tacit: find what a linear structural model misses in a nonlinear
//! vibration test, reconstruct the missing internal forces, trace them to a
//! physical effect, add it to the model and fit it.
//!
//! Source: F. M. Hemez and S. W. Doebling, "Test-analysis correlation and
//! finite element model updating for nonlinear, transient dynamics" (LANL).
#![warn(missing_docs)]
// `!(x > 0.0)` is the idiom that also rejects NaN; it is used on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod error;
pub mod integrate;
pub mod io;
pub mod metrics;
pub mod modal;
pub mod model;
pub mod plot;
pub mod record;
pub mod signal;
pub mod simulate;

pub use error::{Result, TacitError};
pub mod calibrate;
pub mod correlate;
pub mod diagnose;
pub mod horizon;
pub mod identify;
pub mod linear;
pub mod reduce;
pub mod silverbox;
pub mod trace;
pub mod update;
