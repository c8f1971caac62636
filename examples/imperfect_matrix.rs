//! Diagnoses of records whose structure departs from the declared model
//! (data/lanl8dof.toml) as real tests do: damping 2–5 % (modal or
//! Rayleigh), springs perturbed ±3–5 % (seeded), friction on every mass on
//! some, one or two localized effects, all eight sensors or three, noise
//! 0.3–3 %, some records cut from a running test. Each is diagnosed twice:
//! calibrated on the record itself, and with a record of the same
//! structure at a level where it behaves linearly (`--linear-record`).
//! Prints a Markdown table (docs/calibration.md holds the last run).
//!
//! `cargo run --release --example imperfect_matrix [-- --seed N] [--only TEXT] [--variants no|yes]`

mod matrix_common;

use matrix_common::{effects_cell, lanl, sensors_cell};
use rand::Rng;
use tacit::diagnose::calibrated::{diagnose_calibrated, CalibratedSettings};
use tacit::diagnose::DiagnoseSettings;
use tacit::integrate::SimSettings;
use tacit::model::{Contact, Cubic, Damping, Friction, Model, Spring};
use tacit::record::Record;
use tacit::simulate::{simulate_record, RecordSpec};

/// The declared model with springs within ±`spread` and the damping given.
fn structure(seed: u64, spread: f64, damping: Damping, friction: f64) -> Model {
    let mut m = lanl();
    let mut g = tacit::signal::rng(seed);
    for s in &mut m.springs {
        s.stiffness *= 1.0 + spread * (2.0 * g.random::<f64>() - 1.0);
    }
    m.damping = damping;
    if friction > 0.0 {
        m.frictions = (1..=8)
            .map(|d| Friction {
                dof: d,
                level: friction,
                velocity: 1e-3,
            })
            .collect();
    }
    m
}

fn modal(z: f64) -> Damping {
    Damping::Modal {
        ratio: Some(z),
        ratios: vec![],
    }
}

struct Case {
    name: &'static str,
    truth: Model,
    linear: Model,
    effects: String,
    sensors: Vec<usize>,
    noise: f64,
    running: bool,
}

fn contact(i: usize, j: usize, gap: f64, k: f64) -> Contact {
    Contact {
        dofs: vec![i, j],
        gap,
        stiffness: k,
    }
}

fn cases(seed: u64) -> Vec<Case> {
    let all: Vec<usize> = (1..=8).collect();
    let mut out = vec![];
    let mut add =
        |name, base: Model, f: &dyn Fn(&mut Model) -> String, sensors: &[usize], noise, running| {
            let mut truth = base.clone();
            let effects = f(&mut truth);
            out.push(Case {
                name,
                truth,
                linear: base,
                effects,
                sensors: sensors.to_vec(),
                noise,
                running,
            });
        };
    // the data file's bumper: contact 5→6, gap 0.381 mm, 2e6 N/m
    let bumper = |m: &mut Model| {
        m.contacts = vec![contact(5, 6, 0.381e-3, 2e6)];
        "contact 5→6 gap 0.381 mm, 2e6 N/m".to_string()
    };
    let s = seed;
    add(
        "bumper 5→6, modal 3 %, springs ±4 %",
        structure(s, 0.04, modal(0.03), 0.0),
        &bumper,
        &all,
        0.01,
        false,
    );
    add(
        "contact 3→2, Rayleigh, springs ±5 %, 0.3 % noise",
        structure(
            s + 1,
            0.05,
            Damping::Rayleigh {
                alpha: 2.0,
                beta: 6e-5,
            },
            0.0,
        ),
        &|m| {
            m.contacts = vec![contact(3, 2, 0.3e-3, 2e6)];
            "contact 3→2 gap 0.3 mm, 2e6 N/m".into()
        },
        &all,
        0.003,
        false,
    );
    add(
        "bumper 7→6 + friction 0.3 N on every mass, modal 2 %",
        structure(s + 2, 0.03, modal(0.02), 0.3),
        &|m| {
            m.contacts = vec![contact(7, 6, 0.4e-3, 1.5e6)];
            "contact 7→6 gap 0.4 mm, 1.5e6 N/m".into()
        },
        &all,
        0.01,
        false,
    );
    add(
        "cubic 6–7, modal 4 %, springs ±3 %",
        structure(s + 3, 0.03, modal(0.04), 0.0),
        &|m| {
            m.cubics = vec![Cubic {
                dofs: vec![6, 7],
                k3: 2e12,
            }];
            "cubic 6–7 k3 2e12 N/m³".into()
        },
        &all,
        0.01,
        false,
    );
    add(
        "bumper 5→6, 3 % noise, modal 2 %",
        structure(s + 4, 0.03, modal(0.02), 0.0),
        &bumper,
        &all,
        0.03,
        false,
    );
    add(
        "bumper 5→6 from a running test, modal 2.5 %",
        structure(s + 5, 0.03, modal(0.025), 0.0),
        &bumper,
        &all,
        0.01,
        true,
    );
    add(
        "contact 2→3 + ground spring at 8, modal 3 %",
        structure(s + 6, 0.04, modal(0.03), 0.0),
        &|m| {
            m.contacts = vec![contact(2, 3, 0.35e-3, 2e6)];
            m.springs.push(Spring {
                dofs: vec![8],
                stiffness: 1500.0,
                name: None,
            });
            "contact 2→3 gap 0.35 mm, 2e6 N/m; ground spring at 8, 1500 N/m".into()
        },
        &all,
        0.01,
        false,
    );
    add(
        "bumper 5→6, sensors 1, 5, 6, modal 2 %",
        structure(s + 7, 0.03, modal(0.02), 0.0),
        &bumper,
        &[1, 5, 6],
        0.01,
        false,
    );
    add(
        "cubic 1–2, Rayleigh, friction 0.1 N",
        structure(
            s + 8,
            0.03,
            Damping::Rayleigh {
                alpha: 3.0,
                beta: 4e-5,
            },
            0.1,
        ),
        &|m| {
            m.cubics = vec![Cubic {
                dofs: vec![1, 2],
                k3: 3e12,
            }];
            "cubic 1–2 k3 3e12 N/m³".into()
        },
        &all,
        0.01,
        false,
    );
    add(
        "linear, modal 5 %, springs ±5 %",
        structure(s + 9, 0.05, modal(0.05), 0.0),
        &|_| "none".into(),
        &all,
        0.01,
        false,
    );
    add(
        "linear, modal 2 %, springs ±3 %, sensors 1, 5, 6",
        structure(s + 10, 0.03, modal(0.02), 0.0),
        &|_| "none".into(),
        &[1, 5, 6],
        0.01,
        false,
    );
    add(
        "contact 4→5 0.2 mm, modal 3 %, 0.3 % noise",
        structure(s + 11, 0.03, modal(0.03), 0.0),
        &|m| {
            m.contacts = vec![contact(4, 5, 0.2e-3, 3e6)];
            "contact 4→5 gap 0.2 mm, 3e6 N/m".into()
        },
        &all,
        0.003,
        false,
    );
    out
}

fn record(m: &Model, c: &Case, seed: u64, samples: usize) -> Record {
    let spec = RecordSpec {
        samples,
        sensors: c.sensors.clone(),
        noise: c.noise,
        seed,
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    let r = simulate_record(m, &spec).unwrap().0;
    if c.running {
        // cut from a running test: the first 1024 samples dropped
        r.slice(1024, samples).unwrap()
    } else {
        r
    }
}

fn pct(x: Option<f64>) -> String {
    x.map_or("failed".into(), |v| format!("{:.2} %", 100.0 * v))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let seed: u64 = arg("--seed").and_then(|s| s.parse().ok()).unwrap_or(9001);
    let only = arg("--only");
    // `--variants no` or `--variants yes`: only the diagnoses without or
    // with the linear record
    let variants = arg("--variants");
    println!("| record | truth | sensors | noise | linear record | found | parameters | error before → after | validation before → after | corrections significant | time |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for c in cases(seed) {
        if only.as_ref().is_some_and(|o| !c.name.contains(o.as_str())) {
            continue;
        }
        let samples = if c.running { 5120 } else { 4096 };
        let rec = record(&c.truth, &c, seed * 10 + 1, samples);
        let val = record(&c.truth, &c, seed * 10 + 2, samples);
        let low = record(&c.linear, &c, seed * 10 + 3, samples);
        for with_low in [false, true] {
            if variants
                .as_deref()
                .is_some_and(|v| (v == "yes") != with_low)
            {
                continue;
            }
            let lin = if with_low { vec![low.clone()] } else { vec![] };
            let t = std::time::Instant::now();
            let d = diagnose_calibrated(
                &lanl(),
                &rec,
                Some(&val),
                &lin,
                None,
                &DiagnoseSettings::default(),
                &CalibratedSettings::default(),
                &|_| {},
            );
            let d = match d {
                Ok(d) => d,
                Err(e) => {
                    println!(
                        "| {} | {} | | | {with_low} | error: {e} | | | | | |",
                        c.name, c.effects
                    );
                    continue;
                }
            };
            if let Some(cal) = &d.calibration {
                eprintln!("{}: {}; {}", c.name, cal.refinement, cal.choice);
            }
            let sig: Vec<String> = d
                .calibration
                .as_ref()
                .filter(|c| c.used)
                .map(|cal| {
                    cal.corrections
                        .iter()
                        .filter(|x| x.significant)
                        .map(|x| format!("{} {:+.1} %", x.name, 100.0 * x.change))
                        .collect()
                })
                .unwrap_or_default();
            let v = d.validation.as_ref().unwrap();
            println!(
                "| {} | {} | {} | {:.1} % | {} | {} | {} | {} → {} | {} → {} | {} | {:.1} s |",
                c.name,
                c.effects,
                sensors_cell(&c.sensors),
                100.0 * c.noise,
                if with_low { "yes" } else { "no" },
                d.verdict,
                effects_cell(&d.effects),
                pct(d.before.relative_error),
                pct(d.after.relative_error),
                pct(v.before.relative_error),
                pct(v.after.relative_error),
                if sig.is_empty() {
                    "—".into()
                } else {
                    sig.join(", ")
                },
                t.elapsed().as_secs_f64()
            );
        }
    }
}
