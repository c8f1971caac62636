//! Time integration of `M ü + C u̇ + K u + f_int(u, u̇) = f_ext(t)`.
//!
//! [`newmark`]: Newmark average acceleration (γ = 1/2, β = 1/4) or HHT-α,
//! with Newton iterations on the nonlinear elements, a fixed number of
//! sub-steps per sample and the external force linearly interpolated
//! between samples; [`Integrator::run_sensitivities`] also differentiates
//! the discrete solution with respect to the initial state and model
//! parameters (forward sensitivities); [`Integrator::run_taped`] records
//! what they read of the simulation ([`Tape`]), and
//! [`Integrator::sensitivities_from_tape`] propagates them later without
//! simulating again.

pub mod newmark;

pub use newmark::{
    ElementSeed, Integrator, ParamSeed, Seeds, Sensitivities, SimSettings, SimStatus, Simulation,
    Tape,
};
