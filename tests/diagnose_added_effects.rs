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

use tacit::diagnose::{diagnose, DiagnoseSettings, Diagnosis};
use tacit::integrate::SimSettings;
use tacit::model::{
    Clearance, Cubic, CubicDamper, Model, Quadratic, QuadraticDamper, RelativeFriction,
};
use tacit::simulate::{simulate_record, RecordSpec};

fn lanl() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    Model::from_file(std::path::Path::new(p)).unwrap()
}

fn run(truth: &Model, seed: u64) -> Diagnosis {
    let spec = |seed| RecordSpec {
        samples: 2048,
        sensors: (1..=8).collect(),
        noise: 0.01,
        seed,
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    let rec = simulate_record(truth, &spec(seed)).unwrap().0;
    let val = simulate_record(truth, &spec(seed + 1000)).unwrap().0;
    let settings = DiagnoseSettings::default();
    let d = diagnose(&lanl(), &rec, Some(&val), None, &settings, &|_| {}).unwrap();
    eprintln!(
        "{} | before {:?} after {:?} | validation {:?} → {:?}",
        d.verdict,
        d.before.relative_error,
        d.after.relative_error,
        d.validation.as_ref().map(|v| v.before.relative_error),
        d.validation.as_ref().map(|v| v.after.relative_error)
    );
    for e in &d.effects {
        eprintln!("  {} {:?}", e.label, e.parameters);
    }
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
    let (b, a) = (
        d.before.relative_error.unwrap(),
        d.after.relative_error.unwrap(),
    );
    assert!(a <= b / 5.0, "relative_error {b} → {a}");
    let v = d.validation.as_ref().unwrap();
    let (b, a) = (
        v.before.relative_error.unwrap(),
        v.after.relative_error.unwrap(),
    );
    assert!(a <= b / 5.0, "validation relative_error {b} → {a}");
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
