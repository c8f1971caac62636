//! tacit: find what a linear structural model misses in a nonlinear
//! vibration test, reconstruct the missing internal forces, trace them to a
//! physical effect, add it to the model and fit it.
//!
//! Source: F. M. Hemez and S. W. Doebling, "Test-analysis correlation and
//! finite element model updating for nonlinear, transient dynamics" (LANL).
//!
//! # Modules
//!
//! Data and models:
//! - [`model`]: structural models (masses, springs, damping, contacts,
//!   friction, cubic springs) read from TOML;
//! - [`record`]: test records (input and output channels, the truth of a
//!   simulated record); [`signal`]: input signals, noise, conversions;
//! - [`error`]: the error type, naming the file, key, channel or sample.
//!
//! Numerical core (no files written):
//! - [`integrate`]: time integration of the nonlinear model (Newmark,
//!   HHT-α) with forward sensitivities; [`simulate`]: simulated records;
//! - [`linear`]: the sampled linear model; [`modal`]: real modes
//!   ([`conditioning`]: which are rigid, and whether they are resolved);
//!   [`reduce`]: reduction onto kept DOFs; [`metrics`]: correlation
//!   metrics;
//! - [`correlate`]: linear modal correlation and modal updating;
//! - [`lsq`]: the bounded least-squares driver (Levenberg–Marquardt,
//!   Gauss–Newton) of the updating, the joint fit and the start-state
//!   refinement; [`riccati`]: the Riccati core of the two smoothers;
//! - [`update`]: time-domain parametric model updating (multiple shooting,
//!   Levenberg–Marquardt and other optimizers);
//! - [`identify`], [`horizon`]: internal-force identification (sliding
//!   windows; the full-horizon smoother);
//! - [`trace`]: the residual traced to candidate effects;
//! - [`diagnose`]: the close-the-loop diagnosis, tacit's main job;
//!   [`calibrate`]: the declared model's linear part calibrated on
//!   records; [`campaign`]: many records of one structure diagnosed and
//!   fitted together.
//!
//! Output: [`plot`] (figures), [`io`] (atomic writes), [`diagnose::report`]
//! (the diagnosis's files).
//!
//! Applications and the paper's case set-ups, outside the core:
//! [`cases`] (Table 4's cubic chain, the bumper shooting check, the
//! Silverbox benchmark and the F-16 ground vibration test run end to
//! end).
//!
//! # The diagnosis pipeline
//!
//! [`diagnose::diagnose`] runs, in order ([`diagnose`] has the details):
//!
//! 1. prepare the record ([`diagnose::prepare`]);
//! 2. locate the missing force's directions ([`identify::locate`]);
//! 3. identify states and force with the lifted smoother along them
//!    ([`identify::lifted`]);
//! 4. score the declared model ([`diagnose::errors`], start states refined
//!    by [`diagnose::starts`]);
//! 5. rounds of trace ([`trace`]) → screen → fit ([`update`],
//!    [`diagnose::joint`]) → decide ([`diagnose::Decision`]);
//! 6. score the final model, with standard errors;
//! 7. validate on a second record.
//!
//! Every threshold is in [`diagnose::DiagnoseSettings`].
#![warn(missing_docs)]
// `!(x > 0.0)` is the idiom that also rejects NaN; it is used on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod conditioning;
pub mod error;
pub mod integrate;
pub mod io;
pub mod lsq;
pub mod metrics;
pub mod modal;
pub mod model;
pub mod plot;
pub mod record;
pub mod riccati;
pub mod signal;
pub mod simulate;

pub use error::{Result, TacitError};
pub mod calibrate;
pub mod campaign;
pub mod cases;
pub mod correlate;
pub mod diagnose;
pub mod horizon;
pub mod identify;
pub mod linear;
pub mod reduce;
pub mod trace;
pub mod update;
