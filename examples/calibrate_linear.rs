//! Calibration of the linear part alone: records simulated from lanl8dof
//! with perturbed springs (±3 %, seeded), 2 % modal damping and, on some,
//! an undeclared effect; the declared model is data/lanl8dof.toml. Prints
//! each spring's and damping ratio's truth against its calibrated value.
//!
//! `cargo run --release --example calibrate_linear [-- --seed N]`

use rand::Rng;
use tacit::calibrate::{calibrate, data_of, CalibrationSettings};
use tacit::integrate::SimSettings;
use tacit::model::{Contact, Damping, Model};
use tacit::simulate::{simulate_record, RecordSpec};

fn lanl() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    Model::from_file(std::path::Path::new(p)).unwrap()
}

fn perturbed(seed: u64, spread: f64, zeta: f64) -> Model {
    let mut m = lanl();
    let mut g = tacit::signal::rng(seed);
    for s in &mut m.springs {
        s.stiffness *= 1.0 + spread * (2.0 * g.random::<f64>() - 1.0);
    }
    m.damping = Damping::Modal {
        ratio: Some(zeta),
        ratios: vec![],
    };
    m
}

/// `--model M --record R --out F`: calibrate M on R, write the calibrated
/// model to F.
fn on_files(args: &[String]) -> bool {
    let get = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1))
    };
    let (Some(m), Some(r), Some(o)) = (get("--model"), get("--record"), get("--out")) else {
        return false;
    };
    let model = Model::from_file(std::path::Path::new(m)).unwrap();
    let rec = tacit::record::read(std::path::Path::new(r)).unwrap();
    let d = data_of(&rec, model.ndof(), None, 0).unwrap();
    let cal = calibrate(&model, &[d], &CalibrationSettings::default()).unwrap();
    for c in &cal.corrections {
        println!(
            "{} {:.4e} -> {:.4e} ({:+.2} %)",
            c.name,
            c.declared,
            c.calibrated,
            100.0 * c.change
        );
    }
    println!(
        "error {:.2} % -> {:.2} %",
        100.0 * cal.error_before,
        100.0 * cal.error_after
    );
    std::fs::write(o, cal.model.to_toml_string()).unwrap();
    true
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if on_files(&args) {
        return;
    }
    let seed = args
        .iter()
        .position(|a| a == "--seed")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(5u64);
    for contact in [false, true] {
        let mut truth = perturbed(seed, 0.03, 0.02);
        if contact {
            truth.contacts = vec![Contact {
                dofs: vec![5, 6],
                gap: 0.381e-3,
                stiffness: 2e6,
            }];
        }
        let spec = RecordSpec {
            noise: 0.01,
            sensors: (1..=8).collect(),
            seed: seed + 100,
            settings: SimSettings {
                substeps: 40,
                ..Default::default()
            },
            ..Default::default()
        };
        let rec = simulate_record(&truth, &spec).unwrap().0;
        let d = data_of(&rec, 8, None, 0).unwrap();
        let cal = calibrate(&lanl(), &[d], &CalibrationSettings::default()).unwrap();
        println!(
            "contact {contact}: {:?}, error {:.2} % -> {:.2} %, {} evaluations, {:.2} s",
            cal.status,
            100.0 * cal.error_before,
            100.0 * cal.error_after,
            cal.evaluations,
            cal.seconds
        );
        for c in &cal.corrections {
            let truth_v = c
                .parameter
                .get(&tacit::calibrate::params::per_mode(&truth).unwrap())
                .unwrap_or(f64::NAN);
            println!(
                "  {:>6} declared {:>10.4e} calibrated {:>10.4e} ± {:.2e}  truth {:>10.4e}  ({:+.2} % of truth) {}{}",
                c.name,
                c.declared,
                c.calibrated,
                c.std_error,
                truth_v,
                100.0 * (c.calibrated / truth_v - 1.0),
                if c.significant { "significant" } else { "" },
                if c.identifiable { "" } else { " not identifiable" }
            );
        }
        for r in &cal.residuals {
            print!("{} {:.2} %  ", r.channel, 100.0 * r.relative);
        }
        println!();
    }
}
