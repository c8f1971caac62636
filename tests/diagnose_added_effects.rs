//! End-to-end: records simulated from lanl8dof with one of the added
//! element kinds at a place (8 sensors, 1 % noise, 2048 samples),
//! diagnosed with the declared linear model: the kind, the place and the
//! parameters within 10 %, the error 5× lower on both records.
//!
//! The quadratic spring, the quadratic damper and the friction between
//! two DOFs pass. Three cases are not found yet and are kept, ignored,
//! with what they give (run them with `-- --ignored`):
//! - the cubic spring to ground at 1: traced as a stiffness change of
//!   spring 1–2 (+42 %, error 78 → 70 %); the grounded cubic is evaluated
//!   on reconstructed absolute displacements, which carry the free-free
//!   model's unobservable rigid-body drift;
//! - the cubic damper 2–3: traced and fitted as a quadratic damper 2–3
//!   (c2 292, error 24.5 → 5.2 %, validation 4.7 %): on the linear
//!   model's states the regression prefers ν|ν| to ν³;
//! - the clearance 6–7 (±0.2 mm, 2e6 N/m; error before 81 %): the cubic
//!   6–7 is proposed first (34.8 % of the residual against 33.8 % for
//!   the clearance) and fitted to 62 %; the clearance, fitted as its
//!   alternative from the trace's gap 0.14 mm and 3.4e5 N/m and the gap
//!   scan, ends at 70 %.

mod diagnose_common;

use diagnose_common::{assert_improved_by, lanl};
use tacit::diagnose::Diagnosis;
use tacit::model::{
    Clearance, Cubic, CubicDamper, Model, Quadratic, QuadraticDamper, RelativeFriction,
};

/// The records of `truth` at all eight sensors diagnosed
/// ([`diagnose_common::run`]), with the first round's ranking and the
/// rounds printed.
fn run(truth: &Model, seed: u64) -> Diagnosis {
    let d = diagnose_common::run(truth, &(1..=8).collect::<Vec<_>>(), seed);
    for r in d.ranking.iter().take(6) {
        eprintln!(
            "  ranked {} {:?} gain {:.4} bic {:.1}",
            r.label, r.parameters, r.residual_explained, r.bic_change
        );
    }
    for r in &d.rounds {
        eprintln!(
            "  round {:?} kept {}: {} | fit: {:?}",
            r.proposed,
            r.kept(),
            tacit::diagnose::report::note(&r.decision),
            r.fit
        );
    }
    d
}

/// The one effect found is `kind` at `dofs` (from 1) with each parameter
/// within 10 % of the truth; the error falls 5× on both records.
fn check(d: &Diagnosis, kind: &str, dofs: &[usize], truth: &[(&str, f64)]) {
    assert_eq!(d.effects.len(), 1, "{}", d.verdict);
    let e = &d.effects[0];
    assert_eq!(e.kind.name(), kind, "{}", d.verdict);
    assert_eq!(e.dofs, dofs, "{}", d.verdict);
    for (name, t) in truth {
        let x = e.parameters[*name];
        assert!((x / t - 1.0).abs() <= 0.1, "{name} {x} vs {t}");
    }
    assert_improved_by(d, 5.0, 5.0);
}

#[test]
#[ignore = "not found yet: traced as a stiffness change of spring 1-2"]
fn cubic_spring_to_ground_at_1() {
    let mut truth = lanl();
    truth.cubics = vec![Cubic {
        dofs: vec![1],
        k3: 2e11,
    }];
    let d = run(&truth, 61);
    check(&d, "cubic", &[1], &[("k3", 2e11)]);
}

#[test]
fn quadratic_spring_5_6() {
    let mut truth = lanl();
    truth.quadratics = vec![Quadratic {
        dofs: vec![5, 6],
        k2: 8e6,
    }];
    let d = run(&truth, 62);
    check(&d, "quadratic", &[5, 6], &[("k2", 8e6)]);
}

#[test]
fn quadratic_damper_3_4() {
    let mut truth = lanl();
    truth.quadratic_dampers = vec![QuadraticDamper {
        dofs: vec![3, 4],
        c2: 200.0,
    }];
    let d = run(&truth, 63);
    check(&d, "quadratic_damping", &[3, 4], &[("c2", 200.0)]);
}

#[test]
#[ignore = "not found yet: fitted as a quadratic damper 2-3"]
fn cubic_damper_2_3() {
    let mut truth = lanl();
    truth.cubic_dampers = vec![CubicDamper {
        dofs: vec![2, 3],
        c3: 2000.0,
    }];
    let d = run(&truth, 64);
    check(&d, "cubic_damping", &[2, 3], &[("c3", 2000.0)]);
}

#[test]
#[ignore = "not found yet: the cubic 6-7 and the clearance fits stall at 62 and 70 %"]
fn clearance_6_7() {
    let mut truth = lanl();
    truth.clearances = vec![Clearance {
        dofs: vec![6, 7],
        gap: 0.2e-3,
        stiffness: 2e6,
    }];
    let d = run(&truth, 65);
    check(
        &d,
        "clearance",
        &[6, 7],
        &[("gap", 0.2e-3), ("stiffness", 2e6)],
    );
}

#[test]
fn relative_friction_4_5() {
    let mut truth = lanl();
    truth.relative_frictions = vec![RelativeFriction {
        dofs: vec![4, 5],
        level: 1.0,
        velocity: 1e-3,
    }];
    let d = run(&truth, 66);
    check(&d, "relative_friction", &[4, 5], &[("level", 1.0)]);
}
