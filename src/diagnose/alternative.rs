//! The cubic spring in place of a large stiffness change: a stiffness
//! change of more than 50 % on a spring-joined pair that leaves the error
//! far from the noise is refitted as the cubic spring on the same pair,
//! from the `k3` whose equivalent linearization is the change, and
//! replaces it when it scores better (the screen's regression on states
//! the sensors fix poorly can prefer the linear change). A spring to
//! ground is refitted the same way as the cubic spring to ground at its
//! DOF. A quadratic damper is refitted as the cubic damper on the same
//! place and the other way round, from the coefficient that dissipates as
//! much along the reconstructed motion (the regression on reconstructed
//! velocities, smoothed at the peaks, can prefer `ν|ν|` to `ν³`).

use super::effects::{self, AddedEffect};
use crate::model::Model;
use crate::trace::regress::sorted_pair;
use crate::trace::{Candidate, EffectKind, RankedEffect};
use nalgebra::DMatrix;

/// The law to fit in place of `best`: the cubic spring on the pair of a
/// stiffness change of more than `min_change` (relative), with the k3
/// whose equivalent linearization `3 k3 ⟨δ²⟩` (δ the reconstructed
/// relative displacement) is the fitted change; the clearance in place of
/// a cubic spring ([`effects::clearance_alternative`]); the cubic to
/// ground in place of a spring to ground ([`ground_cubic`]); the other
/// damper law ([`other_damper`]). None for any other effect or when the
/// trace did not rank the alternative.
pub(super) fn alternative_law(
    best: &RankedEffect,
    eff: &AddedEffect,
    fitted: &Model,
    ranking: &[RankedEffect],
    states: &DMatrix<f64>,
    min_change: f64,
) -> Option<RankedEffect> {
    if best.candidate.kind == EffectKind::Cubic {
        return effects::clearance_alternative(best, ranking);
    }
    if best.candidate.kind == EffectKind::GroundSpring {
        return ground_cubic(best, eff, fitted, states);
    }
    if matches!(
        best.candidate.kind,
        EffectKind::QuadraticDamping | EffectKind::CubicDamping
    ) {
        return other_damper(best, eff, fitted, ranking, states);
    }
    if best.candidate.kind != EffectKind::Stiffness || best.candidate.dofs.len() != 2 {
        return None;
    }
    let delta = effects::values(fitted, eff)
        .into_iter()
        .find(|v| v.0 == "delta")?
        .1;
    if !(delta.abs() > min_change) {
        return None;
    }
    let pair = sorted_pair(&best.candidate);
    let mut alt = ranking
        .iter()
        .find(|e| e.candidate.kind == EffectKind::Cubic && sorted_pair(&e.candidate) == pair)?
        .clone();
    let k3 = equivalent_k3(&best.candidate, states, delta * eff.nominal)?;
    for p in alt.parameters.iter_mut().filter(|p| p.0 == "k3") {
        p.1 = k3;
    }
    Some(alt)
}

/// The cubic spring to ground at the DOF of a fitted spring to ground
/// `best` (at any stiffness), with the k3 whose equivalent linearization
/// `3 k3 ⟨u²⟩` (u the DOF's displacement in `states`, which must be the
/// spring's own reconstruction: the declared free-free one wanders) is the
/// fitted stiffness. The trace regresses no law against ground (it cannot
/// on the wandering states), so it takes such a cubic for its
/// linearization (a cubic from mass 2 to ground beside a contact 6→7 seen
/// from sensors 1, 2, 6, 7, 8, without a linear record: ground_spring @2).
fn ground_cubic(
    best: &RankedEffect,
    eff: &AddedEffect,
    fitted: &Model,
    states: &DMatrix<f64>,
) -> Option<RankedEffect> {
    let &[d] = best.candidate.dofs.as_slice() else {
        return None;
    };
    let k = effects::values(fitted, eff)
        .into_iter()
        .find(|v| v.0 == "stiffness")?
        .1;
    let k3 = equivalent_k3(&best.candidate, states, k)?;
    let candidate = Candidate::new(EffectKind::Cubic, vec![d]);
    Some(RankedEffect {
        label: candidate.label(),
        candidate,
        parameters: vec![("k3".into(), k3)],
        std_errors: vec![],
        hidden: vec![],
        ..best.clone()
    })
}

/// The other velocity law (quadratic ↔ cubic damper) at the place of a
/// fitted damper `best`, when the trace ranked it, with the coefficient
/// that dissipates the same energy along the relative velocity ν in
/// `states`, `c3 ⟨ν⁴⟩ = c2 ⟨|ν|³⟩` ([`super::laws::other_law_start`]).
fn other_damper(
    best: &RankedEffect,
    eff: &AddedEffect,
    fitted: &Model,
    ranking: &[RankedEffect],
    states: &DMatrix<f64>,
) -> Option<RankedEffect> {
    let c = effects::values(fitted, eff).first()?.1;
    let (kind, name, value) = super::laws::other_law_start(&best.candidate, c, states)?;
    let place = sorted_pair(&best.candidate);
    let mut alt = ranking
        .iter()
        .find(|e| e.candidate.kind == kind && sorted_pair(&e.candidate) == place)?
        .clone();
    for p in alt.parameters.iter_mut().filter(|p| p.0 == name) {
        p.1 = value;
    }
    Some(alt)
}

/// The cubic spring's `k3` whose equivalent linearization `3 k3 ⟨δ²⟩`
/// (δ the candidate's relative displacement, or displacement to ground,
/// in `states`) is the linear stiffness `k`; None unless finite and
/// positive.
fn equivalent_k3(c: &Candidate, states: &DMatrix<f64>, k: f64) -> Option<f64> {
    let ns = states.ncols().max(1);
    let msq = (0..states.ncols())
        .map(|i| c.delta(states, i).powi(2))
        .sum::<f64>()
        / ns as f64;
    let k3 = k / (3.0 * msq.max(f64::MIN_POSITIVE));
    (k3.is_finite() && k3 > 0.0).then_some(k3)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ranked(c: Candidate, parameters: Vec<(&str, f64)>) -> RankedEffect {
        RankedEffect::for_test(c, &parameters)
    }

    /// The cubic alternative of a large stiffness change: `k3` from the
    /// equivalent linearization `3 k3 ⟨δ²⟩ = Δk`; none for a small change.
    #[test]
    fn a_large_stiffness_change_offers_the_cubic_with_its_equivalent_k3() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let model = Model::from_file(std::path::Path::new(p)).unwrap();
        let k0 = model.springs[6].stiffness;
        let mut stiff = Candidate::new(EffectKind::Stiffness, vec![6, 7]);
        stiff.spring = Some(6);
        stiff.nominal = k0;
        let cubic = ranked(
            Candidate::new(EffectKind::Cubic, vec![7, 6]),
            vec![("k3", 1.0)],
        );
        // relative displacement u7 − u8 alternating ±2e-4 m: ⟨δ²⟩ = 4e-8
        let states = DMatrix::from_fn(16, 100, |i, k| match i {
            6 => {
                if k % 2 == 0 {
                    2e-4
                } else {
                    -2e-4
                }
            }
            _ => 0.0,
        });
        for (delta, expect) in [(2.0, true), (0.3, false), (-0.8, false)] {
            let best = ranked(stiff.clone(), vec![("delta", delta)]);
            let mut fitted = model.clone();
            let eff = effects::add(&mut fitted, &best);
            let got = alternative_law(
                &best,
                &eff,
                &fitted,
                std::slice::from_ref(&cubic),
                &states,
                0.5,
            );
            assert_eq!(got.is_some(), expect, "delta {delta}");
            if let Some(alt) = got {
                assert_eq!(alt.candidate.kind, EffectKind::Cubic);
                let k3 = alt.parameters.iter().find(|p| p.0 == "k3").unwrap().1;
                let want = delta * k0 / (3.0 * 4e-8);
                assert!((k3 / want - 1.0).abs() < 1e-9, "{k3} vs {want}");
            }
        }
        // not for another kind
        let contact = ranked(
            Candidate::new(EffectKind::Contact, vec![6, 7]),
            vec![("gap", 1e-4), ("stiffness", 1e6)],
        );
        let mut fitted = model.clone();
        let eff = effects::add(&mut fitted, &contact);
        assert!(alternative_law(&contact, &eff, &fitted, &[cubic], &states, 0.5).is_none());
    }

    /// The cubic to ground in place of a spring to ground at the same DOF:
    /// `k3` from `3 k3 ⟨u²⟩ = k`, whatever the stiffness.
    #[test]
    fn a_spring_to_ground_offers_the_cubic_to_ground_with_its_equivalent_k3() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let model = Model::from_file(std::path::Path::new(p)).unwrap();
        let mut spring = Candidate::new(EffectKind::GroundSpring, vec![1]);
        spring.nominal = 0.0;
        // displacement of mass 2 alternating ±3e-4 m: ⟨u²⟩ = 9e-8
        let states = DMatrix::from_fn(16, 100, |i, k| match (i, k % 2) {
            (1, 0) => 3e-4,
            (1, _) => -3e-4,
            _ => 1e-2,
        });
        for k in [1.1e5, 2e3] {
            let best = ranked(spring.clone(), vec![("stiffness", k)]);
            let mut fitted = model.clone();
            let eff = effects::add(&mut fitted, &best);
            let alt = alternative_law(&best, &eff, &fitted, &[], &states, 0.5).unwrap();
            assert_eq!(alt.candidate.kind, EffectKind::Cubic);
            assert_eq!(alt.candidate.dofs, vec![1]);
            assert_eq!(alt.label, "cubic @2");
            let k3 = alt.parameters.iter().find(|p| p.0 == "k3").unwrap().1;
            let want = k / (3.0 * 9e-8);
            assert!((k3 / want - 1.0).abs() < 1e-9, "{k3} vs {want}");
        }
    }

    /// A quadratic damper offers the cubic damper ranked on its place with
    /// the coefficient that dissipates as much, `c3 ⟨ν⁴⟩ = c2 ⟨|ν|³⟩`, and
    /// the cubic damper the quadratic one the other way; none when the
    /// trace did not rank the other law there.
    #[test]
    fn a_damper_offers_the_other_law_dissipating_as_much() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let model = Model::from_file(std::path::Path::new(p)).unwrap();
        // relative velocity of masses 3–4 cycling 0.1, −0.3 m/s:
        // ⟨|ν|³⟩ = 0.014, ⟨ν⁴⟩ = 0.0041
        let states = DMatrix::from_fn(16, 100, |i, k| match (i, k % 2) {
            (10, 0) => 0.1,
            (10, _) => -0.3,
            _ => 0.0,
        });
        let ratio = 0.014 / 0.0041;
        let quadratic = Candidate::new(EffectKind::QuadraticDamping, vec![2, 3]);
        let cubic = Candidate::new(EffectKind::CubicDamping, vec![3, 2]);
        for (from, to, value, name, want) in [
            (&quadratic, &cubic, 200.0, "c3", 200.0 * ratio),
            (&cubic, &quadratic, 2000.0, "c2", 2000.0 / ratio),
        ] {
            let own = if name == "c3" { "c2" } else { "c3" };
            let best = ranked(from.clone(), vec![(own, value)]);
            let other = ranked(to.clone(), vec![(name, 1.0)]);
            let mut fitted = model.clone();
            let eff = effects::add(&mut fitted, &best);
            let ranking = [best.clone(), other];
            let alt = alternative_law(&best, &eff, &fitted, &ranking, &states, 0.5).unwrap();
            assert_eq!(alt.candidate.kind, to.kind);
            let got = alt.parameters.iter().find(|p| p.0 == name).unwrap().1;
            assert!((got / want - 1.0).abs() < 1e-9, "{name} {got} vs {want}");
            assert!(alternative_law(&best, &eff, &fitted, &ranking[..1], &states, 0.5).is_none());
        }
    }
}
