//! The cubic spring in place of a large stiffness change: a stiffness
//! change of more than 50 % on a spring-joined pair that leaves the error
//! far from the noise is refitted as the cubic spring on the same pair,
//! from the `k3` whose equivalent linearization is the change, and
//! replaces it when it scores better (the screen's regression on states
//! the sensors fix poorly can prefer the linear change).

use super::effects::{self, AddedEffect};
use crate::model::Model;
use crate::trace::regress::sorted_pair;
use crate::trace::{EffectKind, RankedEffect};
use nalgebra::DMatrix;

/// The cubic spring on the pair of a stiffness change of more than
/// `min_change` (relative),
/// with the k3 whose equivalent linearization `3 k3 ⟨δ²⟩` (δ the
/// reconstructed relative displacement) is the fitted change; None for any
/// other effect or when the trace did not rank that cubic.
pub(super) fn cubic_alternative(
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
    let ns = states.ncols().max(1);
    let msq = (0..states.ncols())
        .map(|k| best.candidate.delta(states, k).powi(2))
        .sum::<f64>()
        / ns as f64;
    let k3 = delta * eff.nominal / (3.0 * msq.max(f64::MIN_POSITIVE));
    if !(k3.is_finite() && k3 > 0.0) {
        return None;
    }
    for p in alt.parameters.iter_mut().filter(|p| p.0 == "k3") {
        p.1 = k3;
    }
    Some(alt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Candidate;

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
            let got = cubic_alternative(
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
        assert!(cubic_alternative(&contact, &eff, &fitted, &[cubic], &states, 0.5).is_none());
    }
}
