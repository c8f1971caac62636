//! The calibrated diagnosis ([`tacit::diagnose::calibrated`]) of a record
//! whose structure departs from the declared model data/lanl8dof.toml
//! (1 % damping, nominal springs) without a record at a linear level: the
//! bumper 5→6 seen from three accelerometers on a structure with 2 %
//! modal damping and springs perturbed by up to ±3 %, as the row "bumper
//! 5→6, sensors 1, 5, 6, modal 2 %" of `examples/imperfect_matrix.rs`
//! (seed 71129).

mod diagnose_common;

use diagnose_common::{
    assert_validation_at_noise, calibrated_without_linear_record, imperfect, imperfect_with,
    matrix_record, record,
};
use tacit::diagnose::{diagnose, DiagnoseSettings, Diagnosis};
use tacit::model::{Contact, Damping, Friction, Spring};

/// `d` named exactly the effects `labels`, and each `(effect, parameter,
/// truth)` of `wants` within 10 % of the truth.
fn assert_named_within(d: &Diagnosis, labels: &[&str], wants: &[(usize, &str, f64)]) {
    let named: Vec<&str> = d.effects.iter().map(|e| e.label.as_str()).collect();
    assert_eq!(named, labels, "{}", d.verdict);
    for &(i, name, want) in wants {
        let p = &d.effects[i].parameters;
        assert!((p[name] / want - 1.0).abs() <= 0.1, "{name}: {p:?}");
    }
}

/// The declared damping is half the true one, so the diagnosis with the
/// declared linear part leaves about 26 % on the record, and the
/// calibration on the record itself absorbs the bumper (a spring 5–6
/// stiffened by a third). The joint refinement of the declared linear part
/// with the contact it found must reach the noise: started from the start
/// states refined for the diagnosed model, some segments start in the
/// wrong basin of the impact once the damping doubles, and only a pass
/// from start states refined again for the model reached leaves them. The
/// contact comes back within 10 % and the validation error is within 1.5
/// × the measured noise.
#[test]
fn the_bumper_seen_from_three_sensors_without_a_linear_record() {
    let mut truth = imperfect(71129 + 7);
    truth.contacts = vec![Contact {
        dofs: vec![5, 6],
        gap: 0.381e-3,
        stiffness: 2e6,
    }];
    let sensors = [1, 5, 6];
    let (rec, val) = (
        record(&truth, &sensors, 4096, 711291),
        record(&truth, &sensors, 4096, 711292),
    );
    let d = calibrated_without_linear_record(&rec, &val);
    assert_named_within(
        &d,
        &["contact 5→6"],
        &[(0, "gap", 0.381e-3), (0, "stiffness", 2e6)],
    );
    assert_validation_at_noise(&d);
}

/// The friction on every mass behind a damping that took it: the linear
/// part as the calibrated diagnosis refines it on a record of the bumper
/// 7→6 with 0.3 N of Coulomb friction on every mass and 2 % modal damping
/// (row "bumper 7→6 + friction 0.3 N on every mass, modal 2 %" of
/// `examples/imperfect_matrix.rs`, seed 9001: the refinement with the
/// contact alone raised the modal ratios to 2.4–3.3 %, the friction's
/// equivalent viscous part), declared with the true springs. After the
/// contact, the trace's regression and the joint linearization at zero
/// friction see only what the friction adds to its viscous part; the
/// friction on every mass must still be fitted with the damping freed
/// beside it and named, the damping brought back towards 2 %, and the
/// error brought to the noise.
#[test]
fn friction_on_every_mass_behind_a_damping_that_took_it() {
    let mut truth = imperfect(9001 + 2);
    truth.contacts = vec![Contact {
        dofs: vec![7, 6],
        gap: 0.4e-3,
        stiffness: 1.5e6,
    }];
    truth.frictions = (1..=8)
        .map(|dof| Friction {
            dof,
            level: 0.3,
            velocity: 1e-3,
        })
        .collect();
    let mut declared = truth.clone();
    declared.contacts.clear();
    declared.frictions.clear();
    declared.damping = Damping::Modal {
        ratio: None,
        ratios: vec![0.0332, 0.0285, 0.0259, 0.0248, 0.0244, 0.0239, 0.0238],
    };
    let all: Vec<usize> = (1..=8).collect();
    let (rec, val) = (
        record(&truth, &all, 4096, 90011),
        record(&truth, &all, 4096, 90012),
    );
    let settings = DiagnoseSettings::default();
    let d = diagnose(&declared, &rec, Some(&val), None, &settings, &|_| {}).unwrap();
    for r in &d.rounds {
        eprintln!("{:?}: {:?}", r.proposed, r.decision);
    }
    assert_named_within(
        &d,
        &["contact 7→6", "friction @1,2,3,4,5,6,7,8"],
        &[(1, "level", 0.3)],
    );
    assert_validation_at_noise(&d);
}

/// A contact 2→3 beside a spring of 1500 N/m from mass 8 to ground, on a
/// structure with 3 % modal damping and springs within ±4 %, without a
/// linear record: the row "contact 2→3 + ground spring at 8, modal 3 %"
/// of `examples/imperfect_matrix.rs` on matrix seed `seed` (its records,
/// 4096 samples). The free-free declared model cannot give the rigid-body
/// mode the spring's frequency, the force is located along pair 2–3 only,
/// and the refinement with the contact alone leaves 8–11 % on the record.
/// The spring to ground calibrated at each DOF and refined with the
/// contact must be named at 8 with the contact, both within 10 %, and the
/// validation error within 1.5 × the measured noise.
fn contact_beside_a_spring_to_ground(seed: u64) {
    // the matrix's structure of row 6
    let mut truth = imperfect_with(seed + 6, 0.04, 0.03);
    truth.contacts = vec![Contact {
        dofs: vec![2, 3],
        gap: 0.35e-3,
        stiffness: 2e6,
    }];
    truth.springs.push(Spring {
        dofs: vec![8],
        stiffness: 1500.0,
        name: None,
    });
    let all: Vec<usize> = (1..=8).collect();
    let (rec, val) = (
        record(&truth, &all, 4096, seed * 10 + 1),
        record(&truth, &all, 4096, seed * 10 + 2),
    );
    let d = calibrated_without_linear_record(&rec, &val);
    assert_named_within(
        &d,
        &["contact 2→3", "ground_spring @8"],
        &[
            (0, "gap", 0.35e-3),
            (0, "stiffness", 2e6),
            (1, "stiffness", 1500.0),
        ],
    );
    assert_validation_at_noise(&d);
}

/// Seed 93557: the spring to ground ranked first is at 8.
#[test]
fn a_contact_beside_a_spring_to_ground_without_a_linear_record() {
    contact_beside_a_spring_to_ground(93557);
}

/// Seed 7543: the springs to ground at 5, 4, 8, 1, 3 and 6 lower the
/// linear part's output error by 2–4 % each, 6 comes first after a quick
/// refinement and is refined to 7.6 % only; the one at 8, tried next,
/// reaches the noise.
#[test]
fn the_spring_to_ground_tried_second_reaches_the_noise() {
    contact_beside_a_spring_to_ground(7543);
}

/// The structure of `examples/imperfect_matrix.rs`'s row "clearance 2–3,
/// modal 2.5 %, sensors 2, 3, 7" for matrix seed `seed` (the 15th row:
/// springs seeded with `seed + 14`, ±3 %, 2.5 % modal damping) with its
/// clearance 2–3 of 0.15 mm and 1e6 N/m.
fn clearance_row(seed: u64) -> tacit::model::Model {
    let mut truth = imperfect_with(seed + 14, 0.03, 0.025);
    truth.clearances.push(tacit::model::Clearance {
        dofs: vec![2, 3],
        gap: 0.15e-3,
        stiffness: 1e6,
    });
    truth
}

/// An exact model is scored at the noise from three sensors: the
/// clearance 2–3 (0.15 mm, 1e6 N/m, engaged mode above the Nyquist
/// frequency) on lanl8dof with springs within ±3 % and 2.5 % modal
/// damping, seen from sensors 2, 3 and 7 at 1 % noise, as the validation
/// record of the row "clearance 2–3, modal 2.5 %, sensors 2, 3, 7" of
/// `examples/imperfect_matrix.rs` (seed 16180). The true model's
/// multiple-shooting error, its start states refined as a validation
/// record's are, must be within 1.5 × the noise: along one path of three
/// Gauss–Newton iterations segments stayed far above the others and it
/// scored 7.37 %.
#[test]
fn the_exact_clearance_model_scores_at_the_noise_from_three_sensors() {
    let seed = 16180;
    let truth = clearance_row(seed);
    let val = record(&truth, &[2, 3, 7], 4096, seed * 10 + 2);
    let settings = DiagnoseSettings::default();
    let prep = tacit::diagnose::prepare(&truth, &val, None, &settings).unwrap();
    let sim = tacit::integrate::SimSettings {
        substeps: 40,
        ..Default::default()
    };
    let cmp = &prep.comparison;
    let (_, y, fit) = tacit::diagnose::starts::refine_both(
        cmp,
        &truth,
        sim,
        &cmp.segments,
        cmp.starts.iterations,
    );
    let e = cmp.total_error(&y);
    assert!(e <= 0.015, "the exact model scored {e}: {fit:?}");
}

/// The clearance 2–3 (0.15 mm, 1e6 N/m, engaged mode near 357 Hz, above
/// the 256 Hz Nyquist frequency) on lanl8dof with springs within ±3 % and
/// 2.5 % modal damping, seen from sensors 2, 3 and 7 at 1 % noise: the
/// record of the row "clearance 2–3, modal 2.5 %, sensors 2, 3, 7" of
/// `examples/imperfect_matrix.rs` on seed 15833. From the true linear
/// part with the clearance's gap × 1.067 and stiffness × 1.037 (where the
/// calibrated diagnosis's joint refinement stalled on this row: the joint
/// fit of gap, stiffness and start states from there leaves the gap
/// unmoved), the gap search must bring both parameters within 1 % of the
/// truth and the record's multiple-shooting error below a fifth of the
/// start's.
#[test]
fn the_gap_search_finds_a_clearance_seen_from_three_sensors() {
    let seed = 15833;
    let truth = clearance_row(seed);
    let rec = matrix_record(&truth, &[2, 3, 7], seed * 10 + 1);
    let mut linear = truth.clone();
    linear.clearances.clear();
    let settings = DiagnoseSettings::default();
    let prep = tacit::diagnose::prepare(&linear, &rec, None, &settings).unwrap();
    let sim = tacit::integrate::SimSettings {
        substeps: 40,
        ..Default::default()
    };
    let mut start = truth.clone();
    start.clearances[0].gap *= 1.067;
    start.clearances[0].stiffness *= 1.037;
    let cmp = &prep.comparison;
    assert!(tacit::diagnose::gap_search::applies(cmp, &start));
    let s = tacit::diagnose::gap_search::search(cmp, &start, sim, 0.0).unwrap();
    let c = &s.model.clearances[0];
    eprintln!(
        "{} models: {:.4} → {:.4}; gap {:.4e}, stiffness {:.4e}",
        s.trials, s.error.1, s.error.0, c.gap, c.stiffness
    );
    assert!((c.gap / 0.15e-3 - 1.0).abs() <= 0.01, "gap {}", c.gap);
    assert!(
        (c.stiffness / 1e6 - 1.0).abs() <= 0.01,
        "stiffness {}",
        c.stiffness
    );
    assert!(s.error.0 <= 0.2 * s.error.1, "{:?}", s.error);
}

/// A velocity law on a structure with 3 % modal damping and springs
/// within ±4 % (seed 3131), seen from all eight sensors without a linear
/// record (4096 samples, seeds 31311 and 31312): `add` puts the law in.
fn damper_law(add: impl FnOnce(&mut tacit::model::Model)) -> Diagnosis {
    let mut truth = imperfect_with(3131, 0.04, 0.03);
    add(&mut truth);
    let all: Vec<usize> = (1..=8).collect();
    let (rec, val) = (
        record(&truth, &all, 4096, 31311),
        record(&truth, &all, 4096, 31312),
    );
    calibrated_without_linear_record(&rec, &val)
}

/// A cubic damper 6–7 (c3 = 3000 N s³/m³) the trace ranks as a quadratic
/// damper: the quadratic one leaves 5.6 %, the cubic refitted from the
/// coefficient that dissipates as much must be named within 10 % and the
/// validation error reach the noise.
#[test]
fn a_cubic_damper_taken_for_a_quadratic_one_is_refitted() {
    let d = damper_law(|m| {
        m.cubic_dampers = vec![tacit::model::CubicDamper {
            dofs: vec![6, 7],
            c3: 3000.0,
        }]
    });
    assert_named_within(&d, &["cubic_damping 6–7"], &[(0, "c3", 3000.0)]);
    assert_validation_at_noise(&d);
}

/// A quadratic damper 7–8 (c2 = 300 N s²/m²): the cubic tried in its place
/// scores higher, and the quadratic stays.
#[test]
fn a_quadratic_damper_stays_quadratic() {
    let d = damper_law(|m| {
        m.quadratic_dampers = vec![tacit::model::QuadraticDamper {
            dofs: vec![7, 8],
            c2: 300.0,
        }]
    });
    assert_named_within(&d, &["quadratic_damping 7–8"], &[(0, "c2", 300.0)]);
    assert_validation_at_noise(&d);
}
