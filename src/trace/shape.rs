//! The restoring-force shape: how well a candidate's law fits the internal
//! force identified along its direction, as a function of the
//! reconstructed relative displacement (or velocity).
//!
//! Two laws on the same pair can remove nearly the same share of the
//! response residual — a clearance and a cubic spring are both odd and
//! stiffening, and the response of a linear structure filters their
//! difference away — yet their forces differ in shape: the clearance is
//! zero inside its gap and grows linearly outside, the cubic grows as
//! `δ³` from zero. Plotting the identified force against the relative
//! displacement is the restoring-force surface method (Masri & Caughey,
//! *J. Appl. Mech.* 46, 1979; Worden & Tomlinson, *Nonlinearity in
//! Structural Dynamics*, 2001, ch. 7); here each law is fitted to that
//! surface by least squares (a contact's or clearance's gap by a scan) and
//! the laws are compared by the share of the force they leave.

use super::candidates::{Candidate, EffectKind};
use nalgebra::DMatrix;

/// Points of the gap scan of [`force_misfit`].
const GAP_GRID: usize = 64;

/// The identified force along the candidate's direction at every sample:
/// `(f_i − f_j) / 2` for a pair (an internal force `±φ` at its two DOFs),
/// `f_i` to ground; None for a candidate with force at several DOFs.
fn along(cand: &Candidate, force: &DMatrix<f64>) -> Option<Vec<f64>> {
    match cand.dofs.as_slice() {
        [i] => Some(force.row(*i).iter().copied().collect()),
        [i, j] if cand.kind != EffectKind::Friction => Some(
            force
                .row(*i)
                .iter()
                .zip(force.row(*j).iter())
                .map(|(a, b)| 0.5 * (a - b))
                .collect(),
        ),
        _ => None,
    }
}

/// The share of the identified force along `cand`'s direction that its
/// law, fitted by least squares (strength free, positive for a gap law;
/// the gap scanned over the upper part of the relative displacement — of
/// its magnitude for a clearance), leaves unexplained: `‖g − θφ‖² / ‖g‖²`
/// in [0, 1]. `force` is n × N (the identification's convention: the
/// candidate's own force has the same sign as [`Candidate::force`]),
/// `states` 2n × N. None when the candidate has no single direction or the
/// force along it is zero.
pub fn force_misfit(cand: &Candidate, force: &DMatrix<f64>, states: &DMatrix<f64>) -> Option<f64> {
    let g = along(cand, force)?;
    let gg: f64 = g.iter().map(|x| x * x).sum();
    if !(gg > 0.0) {
        return None;
    }
    let n = states.nrows() / 2;
    let left = |phi: &[f64], positive: bool| -> f64 {
        let pp: f64 = phi.iter().map(|x| x * x).sum();
        let gp: f64 = phi.iter().zip(&g).map(|(a, b)| a * b).sum();
        if !(pp > 0.0) || (positive && gp <= 0.0) {
            return 1.0;
        }
        ((gg - gp * gp / pp) / gg).clamp(0.0, 1.0)
    };
    if !cand.kind.has_gap() {
        return Some(left(&cand.shape(states, n), false));
    }
    let ns = states.ncols();
    let deltas: Vec<f64> = (0..ns).map(|k| cand.delta(states, k)).collect();
    let mut sorted: Vec<f64> = deltas
        .iter()
        .map(|d| {
            if cand.kind == EffectKind::Clearance {
                d.abs()
            } else {
                *d
            }
        })
        .collect();
    sorted.sort_by(f64::total_cmp);
    let quant = |f: f64| sorted[((sorted.len() - 1) as f64 * f) as usize];
    let (lo, hi) = (quant(0.0).max(0.0), quant(0.995));
    if !(hi > lo) {
        return Some(1.0);
    }
    let best = (0..GAP_GRID)
        .map(|i| {
            let gap = lo + (hi - lo) * i as f64 / GAP_GRID as f64;
            let c = Candidate {
                gap: Some(gap),
                ..cand.clone()
            };
            let phi: Vec<f64> = deltas.iter().map(|&d| c.gap_law(d)).collect();
            left(&phi, true)
        })
        .fold(1.0, f64::min);
    Some(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// States of two DOFs with the relative displacement `u1 − u2` a
    /// sweep of ±1 mm and the force `law(δ)` at DOF 1, `−law(δ)` at DOF 2.
    fn surface(law: &dyn Fn(f64) -> f64) -> (DMatrix<f64>, DMatrix<f64>) {
        let ns = 2000;
        let d = |k: usize| 1e-3 * (k as f64 * 0.0137).sin() * (k as f64 * 0.0011).cos();
        let states = DMatrix::from_fn(4, ns, |r, k| if r == 0 { d(k) } else { 0.0 });
        let force = DMatrix::from_fn(2, ns, |r, k| {
            let f = law(d(k));
            if r == 0 {
                f
            } else {
                -f
            }
        });
        (states, force)
    }

    fn clearance(gap: f64, k: f64) -> impl Fn(f64) -> f64 {
        move |d: f64| k * (d.abs() - gap).max(0.0) * d.signum()
    }

    /// The clearance's force is fitted by its own law and not by the
    /// cubic's; the cubic's force the other way round.
    #[test]
    fn each_law_fits_its_own_force_best() {
        let clr = Candidate::new(EffectKind::Clearance, vec![0, 1]);
        let cub = Candidate::new(EffectKind::Cubic, vec![0, 1]);
        let (s, f) = surface(&clearance(4e-4, 1e6));
        let (mc, mq) = (
            force_misfit(&clr, &f, &s).unwrap(),
            force_misfit(&cub, &f, &s).unwrap(),
        );
        assert!(mc < 1e-3, "clearance on its own force leaves {mc}");
        assert!(mq > 0.01, "cubic on a clearance's force leaves {mq}");
        let (s, f) = surface(&|d: f64| 2e12 * d * d * d);
        let (mc, mq) = (
            force_misfit(&clr, &f, &s).unwrap(),
            force_misfit(&cub, &f, &s).unwrap(),
        );
        assert!(mq < 1e-12, "cubic on its own force leaves {mq}");
        assert!(
            mc > 10.0 * mq && mc > 1e-3,
            "clearance on a cubic's force leaves {mc}"
        );
    }

    /// A one-sided contact fits a one-sided force; a contact in the wrong
    /// direction (positive stiffness required) explains nothing of it.
    #[test]
    fn a_contact_needs_its_direction() {
        let (s, f) = surface(&|d: f64| 1e6 * (d - 3e-4).max(0.0));
        let fwd = Candidate::new(EffectKind::Contact, vec![0, 1]);
        let back = Candidate::new(EffectKind::Contact, vec![1, 0]);
        assert!(force_misfit(&fwd, &f, &s).unwrap() < 1e-3);
        assert!(force_misfit(&back, &f, &s).unwrap() > 0.9);
    }
}
