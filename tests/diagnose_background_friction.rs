//! A small real effect above the measured noise is not called noise: a
//! cubic spring 1–2 on a structure with 0.1 N of Coulomb friction on every
//! mass, diagnosed with a linear part whose modal damping took the
//! friction's share of the dissipation (the per-mode ratios a calibration
//! on a linear record of this structure gives, `cargo run --release
//! --example imperfect_matrix -- --seed 77909 --rows 8-8
//! --calibration-only`). With the cubic fitted the error is below the
//! noise floor assumed from a 1 % level (2.5 %), yet above 1.5 × the
//! measured noise; the friction, which the trace's regression rates at a
//! tenth of its level (the damping took its share), must be named and
//! fitted near its level.

mod diagnose_common;

use diagnose_common::{
    assert_validation_at_noise, calibrated_without_linear_record, imperfect_with, lanl,
    matrix_record, record,
};
use tacit::diagnose::{diagnose, Decision, DiagnoseSettings, Diagnosis, EffectReport};
use tacit::model::{Contact, Cubic, Damping, Friction, Model};

/// The structure: lanl8dof with Rayleigh damping, 0.1 N of friction on
/// every mass and a cubic spring 1–2.
fn truth() -> Model {
    with_friction_and_cubic(lanl())
}

/// `m` with Rayleigh damping (3 s⁻¹, 4e-5 s), 0.1 N of friction on every
/// mass and a cubic spring 1–2 of 3e12 N/m³.
fn with_friction_and_cubic(mut m: Model) -> Model {
    m.damping = Damping::Rayleigh {
        alpha: 3.0,
        beta: 4e-5,
    };
    m.frictions = (1..=8)
        .map(|d| Friction {
            dof: d,
            level: 0.1,
            velocity: 1e-3,
        })
        .collect();
    m.cubics = vec![Cubic {
        dofs: vec![1, 2],
        k3: 3e12,
    }];
    m
}

/// The declared model: lanl8dof with the damping a calibration on a
/// linear record of the structure gives (friction absorbed: the lowest
/// mode's ratio 1.73 % where Rayleigh gives 1.36 %).
fn declared() -> Model {
    let mut m = lanl();
    m.damping = Damping::Modal {
        ratio: None,
        ratios: vec![0.0173, 0.0130, 0.0132, 0.0143, 0.0156, 0.0166, 0.0174],
    };
    m
}

/// The records of `truth` (seeds `seeds`: the record, the validation
/// record; 4096 samples, every mass) diagnosed with `declared`; the
/// verdict, errors and effects printed.
fn diagnosed(declared: &Model, truth: &Model, seeds: (u64, u64)) -> Diagnosis {
    let all: Vec<usize> = (1..=8).collect();
    let rec = record(truth, &all, 4096, seeds.0);
    let val = record(truth, &all, 4096, seeds.1);
    let settings = DiagnoseSettings::default();
    let d = diagnose(declared, &rec, Some(&val), None, &settings, &|_| {}).unwrap();
    let noise = d.noise.as_ref().unwrap().level;
    let v = d.validation.as_ref().unwrap().after.relative_error.unwrap();
    eprintln!(
        "{} | after {:?} | validation {v} | noise {noise}",
        d.verdict, d.after.relative_error
    );
    for e in &d.effects {
        eprintln!("  {} {:?}", e.label, e.parameters);
    }
    d
}

/// The effect of `kind` that `d` named.
fn named<'a>(d: &'a Diagnosis, kind: &str) -> &'a EffectReport {
    d.effects
        .iter()
        .find(|e| e.kind.name() == kind)
        .unwrap_or_else(|| panic!("no {kind}: {}", d.verdict))
}

#[test]
fn friction_beside_a_cubic_is_not_taken_for_noise() {
    let d = diagnosed(&declared(), &truth(), (779091, 779092));
    let cubic = named(&d, "cubic");
    assert_eq!(cubic.dofs, vec![1, 2]);
    let k3 = cubic.parameters["k3"];
    assert!((k3 / 3e12 - 1.0).abs() <= 0.1, "k3 {k3}");
    let level = named(&d, "friction").parameters["level"];
    assert!((level / 0.1 - 1.0).abs() <= 0.1, "friction level {level}");
    assert_validation_at_noise(&d);
}

/// A bumper 7→6 (gap 0.4 mm, 1.5e6 N/m) on lanl8dof with 2 % modal
/// damping and 0.3 N of friction on every mass, diagnosed with a linear
/// part whose modal damping took more than the friction's share (1.3 ×
/// the ratios a refinement of the linear part beside the contact reached
/// on such a record, which were +136 to +253 % of the true 2 %). After the
/// contact and a damping change the error is 3.4 % at 1.5 % measured
/// noise; the friction on every mass is predicted to remove 18 % of the
/// fit cost, below the 20 % screen of a candidate below the trace's, and
/// must be fitted all the same (`screen.dissipative_far`). Named, it takes
/// the validation error to the noise; its level is not checked closely:
/// the damping change scales every mode's ratio alike and leaves part of
/// the friction in the damping (the calibrated diagnosis frees each mode
/// and reaches 0.300 N on such a record).
#[test]
fn friction_beside_a_bumper_is_fitted_far_above_the_noise() {
    let mut t = lanl();
    t.damping = Damping::Modal {
        ratio: Some(0.02),
        ratios: vec![],
    };
    t.frictions = (1..=8)
        .map(|d| Friction {
            dof: d,
            level: 0.3,
            velocity: 1e-3,
        })
        .collect();
    t.contacts = vec![Contact {
        dofs: vec![7, 6],
        gap: 0.4e-3,
        stiffness: 1.5e6,
    }];
    let mut declared = lanl();
    declared.damping = Damping::Modal {
        ratio: None,
        ratios: vec![0.0459, 0.0373, 0.0346, 0.0321, 0.0319, 0.0307, 0.0308],
    };
    let d = diagnosed(&declared, &t, (314151, 314152));
    assert_eq!(named(&d, "contact").dofs, vec![7, 6]);
    let f = named(&d, "friction");
    assert_eq!(f.dofs, (1..=8).collect::<Vec<_>>());
    let level = f.parameters["level"];
    assert!((0.1..=0.45).contains(&level), "friction level {level}");
    assert_validation_at_noise(&d);
}

/// The imperfect matrix's cubic 1–2 with 0.1 N of friction on every mass
/// on `seed` (lanl8dof with springs within ±3 % seeded by the row, the
/// records at 400 sub-steps), diagnosed calibrated without a linear record.
fn matrix_row_diagnosed(seed: u64) -> Diagnosis {
    let truth = with_friction_and_cubic(imperfect_with(seed + 8, 0.03, 0.0));
    let all: Vec<usize> = (1..=8).collect();
    let rec = matrix_record(&truth, &all, seed * 10 + 1);
    let val = matrix_record(&truth, &all, seed * 10 + 2);
    calibrated_without_linear_record(&rec, &val)
}

/// The imperfect matrix's cubic 1–2 with 0.1 N of friction on every mass
/// (`cargo run --release --example imperfect_matrix -- --seed 15833 --only
/// "friction 0.1" --variants no`): lanl8dof with springs within ±3 %
/// (seeded), Rayleigh damping (3 s⁻¹, 4e-5 s), the friction and the cubic,
/// records integrated at 400 sub-steps; the calibrated diagnosis without a
/// linear record. Raced on the start states reconstructed with the linear
/// model, the friction fitted beside the cubic on the refined linear part
/// scored 1.67 % against 1.90 % without it on the loop's start states (3
/// Gauss–Newton iterations; measured noise 1.16 %), too little to keep,
/// and was kept only when judged on start states refined to convergence
/// (1.33 % against 1.72 %); raced on the start states fitted for the cubic
/// model it scores 1.50 % against 2.09 % and is kept in its round. It
/// must be named and kept, and the validation error end at the noise
/// (with the friction withdrawn it ended at 1.96 %).
#[test]
fn friction_beside_a_cubic_is_kept_without_a_linear_record() {
    let d = matrix_row_diagnosed(15833);
    let v = d.validation.as_ref().unwrap().after.relative_error;
    eprintln!(
        "{} | after {:?} | validation {v:?}",
        d.verdict, d.after.relative_error
    );
    for e in &d.effects {
        eprintln!("  {} {:?}", e.label, e.parameters);
    }
    let cubic = named(&d, "cubic");
    assert_eq!(cubic.dofs, vec![1, 2]);
    let k3 = cubic.parameters["k3"];
    assert!((k3 / 3e12 - 1.0).abs() <= 0.1, "k3 {k3}");
    let f = named(&d, "friction");
    assert_eq!(f.dofs, (1..=8).collect::<Vec<_>>());
    let kept = d.rounds.iter().any(|r| {
        r.proposed.as_deref() == Some(f.label.as_str())
            && matches!(r.decision, Decision::Kept { .. })
    });
    assert!(kept, "the friction's round: {:?}", d.rounds);
    assert_validation_at_noise(&d);
}

/// The same row on seed 49529 (`cargo run --release --example
/// imperfect_matrix -- --seed 49529 --only "friction 0.1" --variants no`):
/// there the trace never ranks the friction (beside the cubic the
/// calibration held leaves 7.60 %, mostly the linear part's error), and the
/// refinement gives the damping the friction's share (the ratios +31 to
/// +78 %): cubic only, 2.08 % on the record, 8.17 % on validation, the
/// friction's amplitude-independent dissipation missed at the validation
/// record's amplitudes. Above the noise without friction, the refined path
/// tries friction on every mass from half the level that dissipates what
/// the refined damping does. The friction must be named — by the rounds,
/// or tried after the refinement and kept there — fitted within 10 % of
/// 0.1 N, and the validation error end at the noise.
#[test]
fn friction_the_trace_never_ranks_is_tried_after_the_refinement() {
    let d = matrix_row_diagnosed(49529);
    let refinement = &d.calibration.as_ref().unwrap().refinement;
    eprintln!("{} | after {:?}", d.verdict, d.after.relative_error);
    eprintln!("{refinement}");
    let tried = refinement
        .split_once("friction on every mass from")
        .map(|(_, rest)| rest.split("; ").next().unwrap_or(""));
    assert!(tried.is_none_or(|t| t.ends_with(": kept")), "{refinement}");
    let k3 = named(&d, "cubic").parameters["k3"];
    assert!((k3 / 3e12 - 1.0).abs() <= 0.1, "k3 {k3}");
    let level = named(&d, "friction").parameters["level"];
    assert!((level / 0.1 - 1.0).abs() <= 0.1, "friction level {level}");
    assert_validation_at_noise(&d);
}
