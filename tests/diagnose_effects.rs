//! End-to-end: records simulated from lanl8dof with an effect the model
//! file does not declare (1 % noise), diagnosed with the declared linear
//! model. Each must name the right kind and DOFs, recover the parameters
//! within 10 %, and end with a multiple-shooting error at most 1/5 of the
//! one before, on its validation record too; a linear record must give
//! "no missing effect found".

mod diagnose_common;

use diagnose_common::{assert_improved_by, lanl, run};
use tacit::diagnose::Diagnosis;
use tacit::integrate::SimSettings;
use tacit::model::{Contact, Cubic, Friction, Spring};

fn assert_improved(d: &Diagnosis) {
    assert_improved_by(d, 5.0, 5.0);
}

fn param(d: &Diagnosis, kind: &str, name: &str) -> f64 {
    let e = d
        .effects
        .iter()
        .find(|e| e.kind.name() == kind)
        .unwrap_or_else(|| panic!("no {kind} in {}", d.verdict));
    e.parameters[name]
}

fn within(x: f64, truth: f64, tol: f64) {
    assert!((x / truth - 1.0).abs() <= tol, "{x} vs {truth}");
}

fn bumper_case(gap: f64, sensors: &[usize], seed: u64, on_validation: f64) {
    let mut truth = lanl();
    truth.contacts = vec![Contact {
        dofs: vec![5, 6],
        gap,
        stiffness: 2e6,
    }];
    let d = run(&truth, sensors, seed);
    assert_eq!(d.effects.len(), 1, "{}", d.verdict);
    assert_eq!(d.effects[0].kind.name(), "contact");
    assert_eq!(d.effects[0].dofs, vec![5, 6]);
    within(param(&d, "contact", "gap"), gap, 0.1);
    within(param(&d, "contact", "stiffness"), 2e6, 0.1);
    assert_improved_by(&d, 5.0, on_validation);
}

#[test]
fn bumper_0381_all_sensors() {
    // measured 66.8 % → 2.8 % (24×) on the record, 69.4 % → 9.3 % (7.5×)
    // on the validation record
    bumper_case(0.381e-3, &[1, 2, 3, 4, 5, 6, 7, 8], 21, 5.0);
}

#[test]
fn bumper_0203_sensors_156() {
    bumper_case(0.203e-3, &[1, 5, 6], 21, 5.0);
}

#[test]
fn linear_record_gives_no_effect() {
    let d = run(&lanl(), &[1, 5, 6], 31);
    assert_eq!(d.verdict, "no missing effect found");
    assert!(d.effects.is_empty());
}

#[test]
fn friction_on_every_mass() {
    let mut fr = lanl();
    fr.frictions = (1..=8)
        .map(|d| Friction {
            dof: d,
            level: 0.5,
            velocity: 1e-3,
        })
        .collect();
    let d = run(&fr, &[1, 2, 3, 4, 5, 6, 7, 8], 41);
    within(param(&d, "friction", "level"), 0.5, 0.1);
    // measured 11.6 % → 2.0 % (5.8×) on the record, 10.2 % → 1.6 % (6.2×)
    // on the validation record
    assert_improved(&d);
}

fn cubic_case(sensors: &[usize], seed: u64) {
    let mut cu = lanl();
    cu.cubics = vec![Cubic {
        dofs: vec![3, 4],
        k3: 2e12,
    }];
    let d = run(&cu, sensors, seed);
    assert_eq!(d.effects.len(), 1, "{}", d.verdict);
    assert_eq!(d.effects[0].dofs, vec![3, 4]);
    within(param(&d, "cubic", "k3"), 2e12, 0.1);
    assert_improved(&d);
}

#[test]
fn cubic_spring_between_masses() {
    cubic_case(&[1, 2, 3, 4, 5, 6, 7, 8], 42);
}

#[test]
fn cubic_spring_between_masses_sensors_156() {
    cubic_case(&[1, 5, 6], 44);
}

/// A weak spring to ground: the declared model already predicts the
/// segments to about 5 %, of which 1 % is noise and 1 % the integration
/// error of 10 sub-steps (the record is simulated with 40), so 1/5 of the
/// error before is below what the exact model reaches. The check: the right
/// kind, DOF and stiffness, and an error down to the exact model's, scored
/// the same way, on both records.
#[test]
fn ground_spring_at_dof_1() {
    let mut gs = lanl();
    gs.springs.push(Spring {
        dofs: vec![1],
        stiffness: 2000.0,
        name: None,
    });
    for sensors in [vec![1, 5, 6], vec![1, 2, 3, 4, 5, 6, 7, 8]] {
        let d = run(&gs, &sensors, 43);
        assert_eq!(d.effects.len(), 1, "{}", d.verdict);
        assert_eq!(d.effects[0].kind.name(), "ground_spring");
        assert_eq!(d.effects[0].dofs, vec![1]);
        within(param(&d, "ground_spring", "stiffness"), 2000.0, 0.1);
        let sim = SimSettings {
            substeps: d.substeps.1,
            ..Default::default()
        };
        let exact = d
            .prepared
            .comparison
            .errors(&gs, sim)
            .0
            .relative_error
            .unwrap();
        let (b, a) = (
            d.before.relative_error.unwrap(),
            d.after.relative_error.unwrap(),
        );
        assert!(a <= 1.05 * exact, "after {a} vs exact model {exact}");
        assert!(a <= b / 3.5, "relative_error {b} → {a}");
        let v = d.validation.as_ref().unwrap();
        let (vb, va) = (
            v.before.relative_error.unwrap(),
            v.after.relative_error.unwrap(),
        );
        assert!(va <= vb / 3.5, "validation {vb} → {va}");
    }
}

/// Seed 51: the contact fitted alone absorbs part of the softer spring
/// (its stiffness −25 %); the spring, taken in on its predicted gain, is
/// fitted from the joint linearization's step and from the contact scanned
/// again beside it (it ended in a local minimum at delta −7.5 % before,
/// 67 % → 11.5 %).
#[test]
fn bumper_with_softer_spring_5() {
    let mut truth = lanl();
    truth.contacts = vec![Contact {
        dofs: vec![5, 6],
        gap: 0.381e-3,
        stiffness: 2e6,
    }];
    truth.springs[4].stiffness *= 0.86;
    let d = run(&truth, &[1, 2, 3, 4, 5, 6, 7, 8], 51);
    within(param(&d, "contact", "gap"), 0.381e-3, 0.1);
    within(param(&d, "contact", "stiffness"), 2e6, 0.1);
    let delta = param(&d, "stiffness", "delta");
    assert!((delta + 0.14).abs() < 0.014, "delta {delta}");
    assert_improved(&d);
}

/// Two effects in another combination and at other DOFs: a contact
/// closing when u4 − u3 exceeds 0.3 mm and Coulomb friction at mass 8
/// alone. The friction's share of the residual left after the contact is
/// below the screen's 5 %, so it comes in through the gain the joint
/// linearization predicts for it.
#[test]
fn contact_4_3_and_friction_at_8() {
    let mut truth = lanl();
    truth.contacts = vec![Contact {
        dofs: vec![4, 3],
        gap: 0.3e-3,
        stiffness: 1.5e6,
    }];
    truth.frictions = vec![Friction {
        dof: 8,
        level: 1.0,
        velocity: 1e-3,
    }];
    let d = run(&truth, &[1, 2, 3, 4, 5, 6, 7, 8], 61);
    assert_eq!(d.effects.len(), 2, "{}", d.verdict);
    let contact = d
        .effects
        .iter()
        .find(|e| e.kind.name() == "contact")
        .unwrap();
    assert_eq!(contact.dofs, vec![4, 3]);
    let friction = d
        .effects
        .iter()
        .find(|e| e.kind.name() == "friction")
        .unwrap();
    assert_eq!(friction.dofs, vec![8]);
    within(param(&d, "contact", "gap"), 0.3e-3, 0.1);
    within(param(&d, "contact", "stiffness"), 1.5e6, 0.1);
    within(param(&d, "friction", "level"), 1.0, 0.1);
    assert_improved(&d);
}

/// Two contacts, one traced to switch on at zero gap (its fit starts from
/// a small positive gap instead of failing): 5→6 at 0.381 mm and 2→1 at
/// 0.3 mm.
#[test]
fn two_contacts() {
    let mut truth = lanl();
    truth.contacts = vec![
        Contact {
            dofs: vec![5, 6],
            gap: 0.381e-3,
            stiffness: 2e6,
        },
        Contact {
            dofs: vec![2, 1],
            gap: 0.3e-3,
            stiffness: 1e6,
        },
    ];
    let d = run(&truth, &[1, 2, 3, 4, 5, 6, 7, 8], 71);
    assert_eq!(d.effects.len(), 2, "{}", d.verdict);
    for (dofs, gap, k) in [(vec![5, 6], 0.381e-3, 2e6), (vec![2, 1], 0.3e-3, 1e6)] {
        let e = d
            .effects
            .iter()
            .find(|e| e.kind.name() == "contact" && e.dofs == dofs)
            .unwrap_or_else(|| panic!("no contact {dofs:?} in {}", d.verdict));
        within(e.parameters["gap"], gap, 0.1);
        within(e.parameters["stiffness"], k, 0.1);
    }
    assert_improved(&d);
}

/// A contact and a spring to ground together: 6→7 at 0.3 mm and 1500 N/m
/// from mass 8 to ground. The spring makes the absolute position, which
/// the declared free-free model's reconstruction leaves to its prior,
/// drive a force: a model with it is fitted and scored from the states
/// reconstructed with its own linear part (from the declared model's the
/// exact model scored 73 %).
#[test]
fn contact_6_7_and_ground_spring_at_8() {
    let mut truth = lanl();
    truth.contacts = vec![Contact {
        dofs: vec![6, 7],
        gap: 0.3e-3,
        stiffness: 2e6,
    }];
    truth.springs.push(Spring {
        dofs: vec![8],
        stiffness: 1500.0,
        name: None,
    });
    let d = run(&truth, &[1, 2, 3, 4, 5, 6, 7, 8], 71);
    let contact = d.effects.iter().find(|e| e.kind.name() == "contact");
    assert_eq!(
        contact.map(|c| c.dofs.clone()),
        Some(vec![6, 7]),
        "{}",
        d.verdict
    );
    let ground = d.effects.iter().find(|e| e.kind.name() == "ground_spring");
    assert_eq!(
        ground.map(|c| c.dofs.clone()),
        Some(vec![8]),
        "{}",
        d.verdict
    );
    within(param(&d, "contact", "gap"), 0.3e-3, 0.1);
    within(param(&d, "contact", "stiffness"), 2e6, 0.1);
    within(param(&d, "ground_spring", "stiffness"), 1500.0, 0.1);
    assert_improved(&d);
}

/// Two effects at two places, neither dominating the location search
/// alone: a cubic spring 5–6 and a contact closing when u2 − u1 exceeds
/// 0.25 mm. The pair of directions is located together (alone, each left
/// the other's force to the prior, and the cubic came out as a +160 %
/// stiffness change).
#[test]
fn cubic_5_6_and_contact_2_1() {
    let mut truth = lanl();
    truth.cubics = vec![Cubic {
        dofs: vec![5, 6],
        k3: 1e12,
    }];
    truth.contacts = vec![Contact {
        dofs: vec![2, 1],
        gap: 0.25e-3,
        stiffness: 1.5e6,
    }];
    let d = run(&truth, &[1, 2, 3, 4, 5, 6, 7, 8], 81);
    assert!(
        d.identification.contains("pair 1–2") && d.identification.contains("pair 5–6"),
        "{}",
        d.identification
    );
    assert_eq!(d.effects.len(), 2, "{}", d.verdict);
    let cubic = d.effects.iter().find(|e| e.kind.name() == "cubic").unwrap();
    assert_eq!(cubic.dofs, vec![5, 6]);
    let contact = d
        .effects
        .iter()
        .find(|e| e.kind.name() == "contact")
        .unwrap();
    assert_eq!(contact.dofs, vec![2, 1]);
    within(param(&d, "cubic", "k3"), 1e12, 0.1);
    within(param(&d, "contact", "gap"), 0.25e-3, 0.1);
    within(param(&d, "contact", "stiffness"), 1.5e6, 0.1);
    assert_improved(&d);
}
