//! The cubic spring in place of a large stiffness change: a stiffness
//! change of more than 50 % on a spring-joined pair that leaves the error
//! far from the noise is refitted as the cubic spring on the same pair,
//! from the `k3` whose equivalent linearization is the change, and
//! replaces it when it scores better (the screen's regression on states
//! the sensors fix poorly can prefer the linear change).

use super::effects::{self, AddedEffect};
use super::round::{Context, State, Trial};
use crate::error::Result;
use crate::model::Model;
use crate::trace::{EffectKind, RankedEffect};
use nalgebra::DMatrix;
use serde::Serialize;

/// The cubic spring tried in place of a stiffness change.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlternativeTried {
    /// The cubic spring's label.
    pub label: String,
    /// Its start, N/m³ (the change's equivalent).
    pub k3: f64,
    /// Its multiple-shooting error, fitted (None when it failed).
    pub error: Option<f64>,
    /// Whether it replaced the stiffness change.
    pub taken: bool,
    /// The stiffness change: label and error.
    pub instead_of: (String, Option<f64>),
}

/// Try the cubic alternative of `trial` (module docs); returns the trial
/// that scores better and what was tried, if anything.
pub(super) fn try_cubic(
    ctx: &Context<'_>,
    st: &mut State,
    trial: Trial,
    ranking: &[RankedEffect],
    progress: &dyn Fn(&str),
) -> Result<(Trial, Option<AlternativeTried>)> {
    let s = &ctx.settings.screen;
    let floor = s.alternative_floor * ctx.settings.noise_floor();
    let far = trial.scored.error.is_some_and(|e| e > floor);
    let states = &ctx.prep.recon.states;
    let (best, eff, fitted) = (&trial.best, &trial.effect, &trial.fit.model);
    let alt = match cubic_alternative(best, eff, fitted, ranking, states, s.alternative_change) {
        Some(alt) if far => alt,
        _ => return Ok((trial, None)),
    };
    progress(&format!("fit {} (alternative)", alt.label));
    let k3 = alt
        .parameters
        .iter()
        .find(|p| p.0 == "k3")
        .map_or(f64::NAN, |p| p.1);
    let second = ctx.fit_scored(st, alt, None, None)?;
    let (e1, e2) = (trial.scored.error, second.scored.error);
    let taken = e2.is_some_and(|e2| e1.is_none_or(|e| e2 < e));
    let tried = AlternativeTried {
        label: second.best.label.clone(),
        k3,
        error: e2,
        taken,
        instead_of: (trial.best.label.clone(), e1),
    };
    Ok((if taken { second } else { trial }, Some(tried)))
}

/// The cubic spring on the pair of a stiffness change of more than
/// `min_change` (relative),
/// with the k3 whose equivalent linearization `3 k3 ⟨δ²⟩` (δ the
/// reconstructed relative displacement) is the fitted change; None for any
/// other effect or when the trace did not rank that cubic.
fn cubic_alternative(
    best: &RankedEffect,
    eff: &AddedEffect,
    fitted: &Model,
    ranking: &[RankedEffect],
    states: &DMatrix<f64>,
    min_change: f64,
) -> Option<RankedEffect> {
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
    let mut alt = ranking
        .iter()
        .find(|e| {
            e.candidate.kind == EffectKind::Cubic && {
                let (mut a, mut b) = (e.candidate.dofs.clone(), best.candidate.dofs.clone());
                a.sort_unstable();
                b.sort_unstable();
                a == b
            }
        })?
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
        RankedEffect {
            label: c.label(),
            candidate: c,
            parameters: parameters.into_iter().map(|(n, v)| (n.into(), v)).collect(),
            std_errors: vec![],
            residual_explained: 0.3,
            force_explained: None,
            bic_change: -100.0,
            hidden: vec![],
        }
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
