//! Applications and the paper's case set-ups, built on the library: they
//! read or simulate their data and run the library's methods end to end.
//! Shared by the examples, the benchmarks and the tests; the library's
//! methods do not depend on them.
//!
//! - [`table4`]: the cubic 4-DOF chain of the paper's §6.1 (Table 4,
//!   Figs 5–6);
//! - [`contact_case`]: the bumper of `data/lanl8dof-contact.toml` fitted
//!   open loop and by multiple shooting;
//! - [`f16`]: the F-16 ground vibration test: a modal model from the
//!   low-level record, diagnosed on a high-level one;
//! - [`silverbox`]: the Silverbox benchmark (a Duffing-type circuit)
//!   diagnosed end to end.

pub mod contact_case;
pub mod f16;
pub mod silverbox;
pub mod table4;
