//! The other law of a nonlinear damper, tried at the open-loop
//! refinement.
//!
//! The trace ranks the quadratic damper `c₂ ν|ν|` and the cubic one
//! `c₃ ν³` on the same place by a regression on the reconstructed states,
//! and the loop fits the first by multiple shooting over segments of a few
//! periods. The two laws differ most at the largest velocities, which a
//! short segment rarely holds and the open-loop error over the whole
//! record weighs. So when the open-loop refinement runs, each nonlinear
//! damper found is also tried in the other law: put in its place at the
//! coefficient that dissipates the same mean power on the reconstructed
//! relative velocities ([`equal_power`]), every parameter refined again by
//! the open-loop error, and the law kept whose error on the record (never
//! the validation record's) is lower.

use super::calibrated::Estimated;
use super::effects::AddedEffect;
use super::{Diagnosis, EffectReport};
use crate::error::Result;
use crate::model::elements::{CubicDamper, QuadraticDamper};
use crate::model::Model;
use crate::trace::{Candidate, EffectKind};
use crate::update::Target;
use nalgebra::DMatrix;

/// A diagnosis's model with one nonlinear damper in the other law.
#[derive(Debug, Clone)]
pub(super) struct Swapped {
    /// The model with the damper replaced.
    pub model: Model,
    /// The effects' bookkeeping, the replaced one in its place.
    pub added: Vec<AddedEffect>,
    /// The effects' reports, the replaced one relabelled.
    pub effects: Vec<EffectReport>,
    /// In words: which damper, from which law to which, at what start.
    pub what: String,
}

/// `d` with its effect `i` in the other law when it is a nonlinear damper
/// (module docs); None for another effect or when the reconstructed
/// velocities there are zero.
pub(super) fn swap_at(d: &Diagnosis, i: usize) -> Option<Swapped> {
    swap(&d.model, &d.added, &d.effects, i, &d.prepared.recon.states)
}

/// A refinement of a diagnosis in place: its note and, when kept, the
/// parameters with their standard errors.
pub(super) type Refine<'a> =
    dyn Fn(&mut Diagnosis) -> Result<(String, Option<Vec<Estimated>>)> + 'a;

/// Each nonlinear damper of `d` in the other law, refined by `refine`
/// and kept in `d` when `refine` keeps it (module docs); the notes, and
/// the parameters of the last law kept.
pub(super) fn keep_better_laws(
    d: &mut Diagnosis,
    refine: &Refine<'_>,
    progress: &dyn Fn(&str),
) -> Result<(Vec<String>, Option<Vec<Estimated>>)> {
    let (mut notes, mut kept) = (vec![], None);
    for i in 0..d.added.len() {
        let Some(alt) = swap_at(d, i) else {
            continue;
        };
        progress("try the other law of a nonlinear damper");
        let mut trial = d.clone();
        (trial.model, trial.added, trial.effects) = (alt.model, alt.added, alt.effects);
        let (n, est) = refine(&mut trial)?;
        notes.push(format!("{}: {n}", alt.what));
        if est.is_some() {
            (*d, kept) = (trial, est);
        }
    }
    Ok((notes, kept))
}

/// The damper law that replaces `kind`, with the exponents of the old and
/// the new law's force in the velocity.
fn other(kind: EffectKind) -> Option<(EffectKind, i32, i32)> {
    match kind {
        EffectKind::CubicDamping => Some((EffectKind::QuadraticDamping, 3, 2)),
        EffectKind::QuadraticDamping => Some((EffectKind::CubicDamping, 2, 3)),
        _ => None,
    }
}

/// The coefficient of `|ν|^to` that dissipates the same mean power as
/// `coef |ν|^from` on the velocities `nu`: `coef ⟨|ν|^(from+1)⟩ /
/// ⟨|ν|^(to+1)⟩`; None when it is not finite and positive.
fn equal_power(coef: f64, from: i32, to: i32, nu: &[f64]) -> Option<f64> {
    let moment = |p: i32| nu.iter().map(|v| v.abs().powi(p)).sum::<f64>();
    let c = coef * moment(from + 1) / moment(to + 1);
    Some(c).filter(|c| c.is_finite() && *c > 0.0)
}

/// The other law of the nonlinear damper `c` of coefficient `coef`: its
/// kind, its coefficient's name and the coefficient that dissipates the
/// same mean power on the relative velocities in `states`
/// ([`equal_power`]); None for another kind or no motion.
pub(super) fn other_law_start(
    c: &Candidate,
    coef: f64,
    states: &DMatrix<f64>,
) -> Option<(EffectKind, &'static str, f64)> {
    let (kind, from, to) = other(c.kind)?;
    let n = states.nrows() / 2;
    let nu: Vec<f64> = (0..states.ncols())
        .map(|k| c.delta_rate(states, n, k))
        .collect();
    let start = equal_power(coef, from, to, &nu)?;
    let name = if kind == EffectKind::CubicDamping {
        "c3"
    } else {
        "c2"
    };
    Some((kind, name, start))
}

/// `model` with effect `i` of `added` (a nonlinear damper) in the other
/// law, or None for any other effect.
fn swap(
    model: &Model,
    added: &[AddedEffect],
    effects: &[EffectReport],
    i: usize,
    states: &DMatrix<f64>,
) -> Option<Swapped> {
    let e = &added[i];
    let target = *e.targets.first()?;
    let coef = target.get(model).ok()?;
    let (kind, name, start) = other_law_start(&e.candidate, coef, states)?;
    let mut m = model.clone();
    let mut added = added.to_vec();
    let dofs: Vec<usize> = e.candidate.dofs.iter().map(|d| d + 1).collect();
    let new_target = match target {
        Target::DamperC3(j) => {
            m.cubic_dampers.remove(j);
            shift(&mut added, |t| matches!(t, Target::DamperC3(x) if *x > j));
            m.quadratic_dampers
                .push(QuadraticDamper { dofs, c2: start });
            Target::DamperC2(m.quadratic_dampers.len() - 1)
        }
        Target::DamperC2(j) => {
            m.quadratic_dampers.remove(j);
            shift(&mut added, |t| matches!(t, Target::DamperC2(x) if *x > j));
            m.cubic_dampers.push(CubicDamper { dofs, c3: start });
            Target::DamperC3(m.cubic_dampers.len() - 1)
        }
        _ => return None,
    };
    let old_label = e.label.clone();
    let a = &mut added[i];
    a.candidate.kind = kind;
    a.targets = vec![new_target];
    a.names = vec![name.into()];
    a.traced = vec![start];
    a.label = m.label_at_points(&a.candidate.label(), &a.candidate.dofs);
    let mut effects = effects.to_vec();
    if let Some(r) = effects.get_mut(i) {
        r.kind = kind;
        r.label = a.label.clone();
        r.parameters = [(name.to_string(), start)].into_iter().collect();
        r.std_errors.clear();
        r.group_estimates.clear();
    }
    let what = format!(
        "{old_label} tried as {} (start {name} = {start:.4e}, the same mean power on the reconstructed velocities)",
        a.label
    );
    Some(Swapped {
        model: m,
        added,
        effects,
        what,
    })
}

/// Lower by one the index of every target of `added` that `after` picks
/// (the element before it in its list was removed).
fn shift(added: &mut [AddedEffect], after: impl Fn(&Target) -> bool) {
    for t in added.iter_mut().flat_map(|a| a.targets.iter_mut()) {
        if after(t) {
            *t = match *t {
                Target::DamperC2(x) => Target::DamperC2(x - 1),
                Target::DamperC3(x) => Target::DamperC3(x - 1),
                other => other,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::effects;
    use crate::trace::{Candidate, RankedEffect};

    fn ranked(kind: EffectKind, dofs: Vec<usize>, name: &str, v: f64) -> RankedEffect {
        RankedEffect::for_test(Candidate::new(kind, dofs), &[(name, v)])
    }

    /// Two cubic dampers and a quadratic one on the testbed: the first
    /// cubic swapped leaves the second's target moved down one place, puts
    /// a quadratic damper last at the equal-power coefficient on the
    /// pair's relative velocity, and touches nothing else.
    #[test]
    fn a_cubic_damper_becomes_quadratic_and_the_other_targets_follow() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let mut model = Model::from_file(std::path::Path::new(p)).unwrap();
        let added: Vec<AddedEffect> = [
            ranked(EffectKind::CubicDamping, vec![4, 5], "c3", 7.0),
            ranked(EffectKind::QuadraticDamping, vec![1], "c2", 3.0),
            ranked(EffectKind::CubicDamping, vec![1, 2], "c3", 5.0),
        ]
        .iter()
        .map(|r| effects::add(&mut model, r))
        .collect();
        // relative velocity v5 − v6 = 0.3 sin(·) (states: 8 displacements,
        // then 8 velocities)
        let states = DMatrix::from_fn(16, 400, |i, k| match i {
            12 => 0.3 * (0.05 * k as f64).sin(),
            _ => 0.0,
        });
        let s = swap(&model, &added, &[], 0, &states).unwrap();
        assert_eq!(s.model.cubic_dampers.len(), 1);
        assert_eq!(s.model.cubic_dampers[0].c3, 5.0);
        assert_eq!(s.model.quadratic_dampers.len(), 2);
        assert_eq!(s.model.quadratic_dampers[0].c2, 3.0);
        assert_eq!(s.added[0].targets, vec![Target::DamperC2(1)]);
        assert_eq!(s.added[0].candidate.kind, EffectKind::QuadraticDamping);
        assert_eq!(s.added[1].targets, vec![Target::DamperC2(0)]);
        assert_eq!(s.added[2].targets, vec![Target::DamperC3(0)]);
        let nu: Vec<f64> = (0..400).map(|k| 0.3 * (0.05 * k as f64).sin()).collect();
        let want = equal_power(7.0, 3, 2, &nu).unwrap();
        let got = s.model.quadratic_dampers[1].c2;
        assert!((got / want - 1.0).abs() < 1e-12, "{got} vs {want}");
        assert_eq!(s.model.quadratic_dampers[1].dofs, vec![5, 6]);
        // no velocity at the ground damper: nothing to swap; a stiffness
        // change has no other law
        assert!(swap(&model, &added, &[], 1, &states).is_none());
        assert!(other(EffectKind::Stiffness).is_none());
    }

    /// On a sine of amplitude V, ⟨|ν|⁴⟩/⟨|ν|³⟩ = (3/8) V⁴ / ((4/(3π)) V³)
    /// = 9π V / 32: the quadratic damper dissipating as the cubic one has
    /// c₂ = c₃ · 9π V / 32.
    #[test]
    fn equal_power_on_a_sine_matches_the_closed_form() {
        let v = 0.7;
        let nu: Vec<f64> = (0..100_000)
            .map(|k| v * (2.0 * std::f64::consts::PI * k as f64 / 100_000.0).sin())
            .collect();
        let c2 = equal_power(2.0, 3, 2, &nu).unwrap();
        let want = 2.0 * 9.0 * std::f64::consts::PI * v / 32.0;
        assert!((c2 / want - 1.0).abs() < 1e-6, "{c2} vs {want}");
        // and back
        let c3 = equal_power(c2, 2, 3, &nu).unwrap();
        assert!((c3 / 2.0 - 1.0).abs() < 1e-12, "{c3}");
        assert!(equal_power(1.0, 3, 2, &[0.0; 10]).is_none());
        assert!(equal_power(-1.0, 3, 2, &nu).is_none());
    }

    /// A one-DOF oscillator with a quadratic damper (c₂ = 40 N s²/m²), 1 %
    /// stiffness error in the declared model, 2048 samples: the loop finds
    /// a nonlinear damper; put in the cubic law (when the loop did not),
    /// refined by the open-loop error and then tried in the other law, the
    /// quadratic one comes back with c₂ within 2 %, and tried again, it
    /// stays.
    #[test]
    fn the_wrong_damper_law_is_swapped_back_by_the_open_loop_error() {
        use crate::diagnose::calibrated::{diagnose_calibrated, CalibratedSettings};
        use crate::diagnose::DiagnoseSettings;
        use crate::integrate::SimSettings;
        use crate::simulate::{simulate_record, InputSpec, RecordSpec};
        let linear = "masses = [1.0]\n[[spring]]\nname = \"k\"\ndofs = [1]\nstiffness = STIFF\n[damping]\nkind = \"modal\"\nratio = 0.02\n";
        let truth = format!(
            "{}[[quadratic_damper]]\ndofs = [1]\nc2 = 40.0\n",
            linear.replace("STIFF", "1.0e5")
        );
        let truth = Model::from_toml_str(&truth, "truth").unwrap();
        let spec = RecordSpec {
            input: InputSpec::Random {
                band: (5.0, 150.0),
                rms: 30.0,
            },
            sensors: vec![1],
            kinds: vec![crate::record::Quantity::Disp],
            noise: 0.005,
            seed: 3,
            settings: SimSettings {
                substeps: 20,
                ..Default::default()
            },
            samples: 2048,
            ..Default::default()
        };
        let rec = simulate_record(&truth, &spec).unwrap().0;
        let declared = format!(
            "{}[free]\nsprings = true\ndamping = true\n",
            linear.replace("STIFF", "1.01e5")
        );
        let declared = Model::from_toml_str(&declared, "declared").unwrap();
        let settings = DiagnoseSettings::default();
        let cal = CalibratedSettings::default();
        let mut d = diagnose_calibrated(&declared, &rec, None, &[], None, &settings, &cal, &|_| {})
            .unwrap();
        assert_eq!(d.added.len(), 1, "{}", d.verdict);
        // start from the wrong law
        if d.added[0].candidate.kind == EffectKind::QuadraticDamping {
            let alt = swap_at(&d, 0).expect("the cubic law");
            (d.model, d.added, d.effects) = (alt.model, alt.added, alt.effects);
        }
        assert_eq!(d.added[0].candidate.kind, EffectKind::CubicDamping);
        let refine = |t: &mut Diagnosis| {
            super::super::open_loop::refine(t, &cal.calibration, &settings, 40, None)
        };
        // the open-loop refinement of the cubic law, then the other law
        refine(&mut d).unwrap();
        let (notes, kept) = keep_better_laws(&mut d, &refine, &|_| {}).unwrap();
        assert!(kept.is_some(), "{notes:?}");
        assert_eq!(d.added[0].candidate.kind, EffectKind::QuadraticDamping);
        assert!(d.model.cubic_dampers.is_empty());
        assert_eq!(d.effects[0].label, "quadratic_damping @1");
        // the right law stays
        let mut again = d.clone();
        let (notes, kept) = keep_better_laws(&mut again, &refine, &|_| {}).unwrap();
        assert!(kept.is_none(), "{notes:?}");
        assert_eq!(again.added[0].candidate.kind, EffectKind::QuadraticDamping);
        let c2 = d.model.quadratic_dampers[0].c2;
        assert!((c2 / 40.0 - 1.0).abs() < 0.02, "c2 {c2}");
    }
}
