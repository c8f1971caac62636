//! Whether a finished simulation stayed bounded, and the step's facts
//! when it did not.
//!
//! For a passive model (positive semi-definite `M`, `C`, `K`; contacts,
//! hardening springs and friction store or dissipate energy) the energy
//! `E = ½ vᵀ M v + ½ uᵀ K u` grows only by the work of the external
//! force: `dE/dt ≤ fᵀ v ≤ ‖f‖_{M⁻¹} √(2E)`, so
//! `√E(t) ≤ √E(0) + ∫₀ᵗ ‖f‖_{M⁻¹} dt / √2`. A discrete state far above
//! that bound ([`GROWTH`] times) comes from the integrator, not from the
//! model: typically a step too long for the stiffest element, whose round
//! off the implicit step amplifies by `(ω h)²`.

use super::{Integrator, Simulation};
use nalgebra::DMatrixView;

/// √E above this many times its bound is divergence.
pub const GROWTH: f64 = 10.0;

/// The most sub-steps per sample a run may take (the command line's
/// limit: work and memory grow with them).
pub const MAX_SUBSTEPS: usize = 1000;

/// `ω_max h` at or below which the stiffest element is resolved (about
/// six sub-steps per period).
pub const RESOLVED_OMEGA_H: f64 = 1.0;

/// A simulation whose energy left its bound.
#[derive(Debug, Clone, PartialEq)]
pub struct Divergence {
    /// First sample (from 0) above the bound.
    pub sample: usize,
    /// DOF (from 1) holding the largest kinetic energy there.
    pub dof: usize,
    /// Its acceleration there, m/s².
    pub accel: f64,
    /// √E over its bound at that sample.
    pub growth: f64,
}

impl Integrator {
    /// Upper bound of the highest natural frequency (rad/s): Gershgorin's
    /// bound of `M⁻¹ K` on the diagonal masses, every contact closed.
    pub fn highest_omega(&self) -> f64 {
        let n = self.n;
        let mut row: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|j| self.k[(i, j)].abs()).sum())
            .collect();
        for e in &self.elements {
            if let crate::model::elements::Element::Contact { i, j, k, .. } = *e {
                row[i] += k.abs() * if j.is_some() { 2.0 } else { 1.0 };
                if let Some(j) = j {
                    row[j] += 2.0 * k.abs();
                }
            }
        }
        (0..n)
            .map(|i| row[i] / self.m[(i, i)])
            .fold(0.0f64, f64::max)
            .sqrt()
    }

    /// Sub-steps per sample at which `ω_max h` reaches
    /// [`RESOLVED_OMEGA_H`].
    pub fn substeps_to_resolve(&self) -> f64 {
        let fs = 1.0 / (self.h * self.settings.substeps as f64);
        (self.highest_omega() / (RESOLVED_OMEGA_H * fs)).ceil()
    }

    /// The first sample where the simulation's energy exceeds its bound
    /// ([`GROWTH`]), or None when it stays bounded.
    pub fn divergence(&self, force: DMatrixView<'_, f64>, sim: &Simulation) -> Option<Divergence> {
        let dt = self.h * self.settings.substeps as f64;
        let minv = self.m.clone().try_inverse()?;
        let fnorm = |k: usize| {
            let f = force.column(k);
            (f.transpose() * &minv * f)[(0, 0)].max(0.0).sqrt()
        };
        let energy = |k: usize| {
            let (u, v) = (sim.u.column(k), sim.v.column(k));
            0.5 * ((v.transpose() * &self.m * v)[(0, 0)] + (u.transpose() * &self.k * u)[(0, 0)])
        };
        let mut bound = energy(0).max(0.0).sqrt();
        let mut f_prev = fnorm(0);
        for k in 1..sim.u.ncols() {
            let f_next = fnorm(k);
            bound += f_prev.max(f_next) * dt / std::f64::consts::SQRT_2;
            f_prev = f_next;
            let e = energy(k);
            let root = e.max(0.0).sqrt();
            if !e.is_finite() || root > GROWTH * bound.max(f64::MIN_POSITIVE) {
                return Some(self.divergence_at(sim, k, root / bound));
            }
        }
        None
    }

    fn divergence_at(&self, sim: &Simulation, k: usize, growth: f64) -> Divergence {
        let kinetic = |i: usize| self.m[(i, i)] * sim.v[(i, k)].powi(2);
        let dof = (0..self.n)
            .max_by(|&a, &b| kinetic(a).total_cmp(&kinetic(b)))
            .unwrap_or(0);
        Divergence {
            sample: k,
            dof: dof + 1,
            accel: sim.a[(dof, k)],
            growth,
        }
    }

    /// The step's facts in words: the highest frequency, `ω h`, and the
    /// sub-steps that resolve it.
    pub fn describe_step(&self) -> String {
        let w = self.highest_omega();
        let need = self.substeps_to_resolve();
        let limit = MAX_SUBSTEPS as f64;
        let advice = if need > limit {
            format!(
                "resolving it needs {need:.0} sub-steps per sample, beyond the {limit:.0} allowed: the stiffest element is too stiff for the record's rate (lower its stiffness or join the DOFs it links)"
            )
        } else {
            format!("at least {need:.0} sub-steps per sample (--substeps) resolve it")
        };
        format!(
            "the highest natural frequency is about {:.3e} Hz and the sub-step {:.3e} s (ω h = {:.3e} at {} sub-steps per sample); {advice}",
            w / (2.0 * std::f64::consts::PI),
            self.h,
            w * self.h,
            self.settings.substeps,
        )
    }
}

#[cfg(test)]
mod tests {
    use crate::integrate::{Integrator, SimSettings};
    use crate::model::Model;
    use nalgebra::DMatrix;

    fn chain(k2: f64) -> Model {
        let s = format!(
            "name = \"c\"\nmasses = [1.0, 1.0, 1.0]\n[[spring]]\ndofs = [1, 2]\nstiffness = 1e4\n[[spring]]\ndofs = [2, 3]\nstiffness = {k2:e}\n"
        );
        Model::from_toml_str(&s, "t").unwrap()
    }

    fn force(n: usize, ns: usize) -> DMatrix<f64> {
        DMatrix::from_fn(
            n,
            ns,
            |i, k| if i == 0 { (k as f64 * 0.3).sin() } else { 0.0 },
        )
    }

    #[test]
    fn a_sound_run_stays_below_the_bound() {
        let integ = Integrator::new(&chain(1e4), 512.0, SimSettings::default()).unwrap();
        let f = force(3, 2048);
        let sim = integ.run(f.as_view(), &[0.0; 3], &[0.0; 3]);
        assert!(sim.completed());
        assert_eq!(integ.divergence(f.as_view(), &sim), None);
        // ω_max ≤ √(2·1e4 + 2·1e4)/1 = 200 rad/s (Gershgorin); 512 Hz × 10
        assert!((integ.highest_omega() - 200.0).abs() < 1e-9);
        assert_eq!(integ.substeps_to_resolve(), 1.0);
    }

    #[test]
    fn a_stiff_spring_diverges_and_is_named() {
        // the testbed with spring 5 at 1e20 N/m, undamped
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let at = text.find("name = \"k5\"").unwrap();
        let k = at + text[at..].find("56700.0").unwrap();
        let text = format!("{}1e20{}", &text[..k], &text[k + 7..]);
        let text = format!(
            "{}[damping]\nkind = \"none\"\n",
            &text[..text.find("[damping]").unwrap()]
        );
        let model = Model::from_toml_str(&text, "t").unwrap();
        let integ = Integrator::new(&model, 512.0, SimSettings::default()).unwrap();
        let f = force(8, 4096);
        let sim = integ.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
        let d = integ.divergence(f.as_view(), &sim).expect("diverges");
        assert!(d.growth > super::GROWTH, "{d:?}");
        assert!(d.dof == 5 || d.dof == 6, "{d:?}");
        let s = integ.describe_step();
        // ω_max ≤ √((2e20 + 2·56700)/0.4194) = 2.184e10 rad/s: 3.476e9 Hz
        assert!(
            s.contains("3.476e9 Hz") && s.contains("42651158 sub-steps"),
            "{s}"
        );
    }
}
