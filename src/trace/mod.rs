//! Trace the missing force to a physical effect and to where it acts.
//!
//! A library of candidate effects ([`Candidate`]) is evaluated on the
//! reconstructed states `x̂ = [û; v̂]` (from the force identification). Each
//! candidate's internal force is linear in its strength `θ` once its shape
//! is fixed (for a contact, once its gap is fixed):
//! `f_int(t) = θ d φ(x̂(t))` (left-hand-side convention, as the simulator's
//! `f_int`). Its effect on the measured channels is computed segment by
//! segment with the model's exact sampled map ([`crate::linear`]), so each
//! candidate is scored by how much of the multiple-shooting residual it
//! removes — the same residual as the headline `relative_error`. Effects are
//! selected greedily (forward stepwise regression) while each one lowers the
//! Bayesian information criterion and removes at least a set fraction of
//! what is left ([`TraceSettings::min_gain`]); noise and integration error
//! therefore select nothing.

pub mod candidates;
pub mod regress;

pub use candidates::{Candidate, EffectKind};
pub use regress::{acts_along, trace, RankedEffect, TraceInput, TraceResult, TraceSettings};
