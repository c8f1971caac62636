//! Linear modal test-analysis correlation and modal updating (paper §2–4,
//! Tables 1–3, Figs 2–3; theory and results in `docs/modal.md`).
//!
//! The chain, one module per step:
//!
//! 1. [`frf`]: H1 frequency response functions with Welch averaging over
//!    segments and records.
//! 2. [`fit`]: curve fit of the FRFs (LSCF poles with a stabilisation check
//!    over model orders, LSFD shapes): frequencies, damping ratios and
//!    shapes at the sensor DOFs. Or [`testmodes`]: read them from a file.
//! 3. [`mac`]: MAC matrix, pairing with the model's modes, frequency error
//!    (Tables 2–3).
//! 4. [`expand`]: SEREP and dynamic expansion of measured shapes to every
//!    model DOF.
//! 5. [`residue`]: force (eq. 4) and hybrid (eqs. 5–6) modal residues and
//!    the per-spring stiffness updating that minimises them (Figs 2–3).
//!
//! [`campaign`] simulates the paper's modal tests (LANL test plan, with or
//! without friction and noise) and [`report`] formats tables and figures.

pub mod campaign;
pub mod expand;
pub mod fit;
pub mod frf;
pub mod mac;
pub mod modelfit;
pub mod report;
pub mod residue;
pub mod testmodes;

pub use campaign::{
    identified_modes, identify_records, with_spring_change, Identification, ModalTest,
};
pub use expand::Expansion;
pub use fit::{identify, FitResult, FitSettings, FitStatus};
pub use frf::{h1, h1_records, Frf, FrfSettings, Window};
pub use mac::{correlate, mac, mac_matrix, Correlation, CorrelationSettings, Pairing};
pub use residue::{update_stiffness, Residue, UpdateResult, UpdateSettings, UpdateStatus};
pub use testmodes::{TestMode, TestModes};

/// The exact modes of a model as test modes at `dofs`: the first `count`
/// flexible modes, mass-normalized, undamped (damping 0). Noise-free
/// "simulated" test data.
pub fn model_test_modes(
    model: &crate::model::Model,
    dofs: &[usize],
    count: usize,
) -> crate::Result<TestModes> {
    let modes = crate::modal::solve(&model.mass_matrix(), &model.stiffness_matrix())?;
    let (phi, f) = mac::flexible_at(&modes, dofs)?;
    let modes: Vec<TestMode> = (0..f.len().min(count))
        .map(|r| TestMode {
            frequency_hz: f[r],
            damping: 0.0,
            shape: phi.column(r).iter().copied().collect(),
        })
        .collect();
    TestModes::new(
        format!("{} (exact modes)", model.name),
        dofs.to_vec(),
        modes,
        true,
        model.ndof(),
    )
}
