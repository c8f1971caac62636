//! State reconstruction with the sub-sample ("lifted") unknown force
//! (`tacit::diagnose::lifted`) on simulated LANL 8-DOF records, against the
//! simulator's truth: exact on a linear record, and on a record with the
//! bumper 5→6 start states good enough that the linear model's
//! multiple-shooting error is what the true states give.
//!
//! The full table (R ∈ {1, 4, 8}, noise 0 and 1 %, sensors all / 1, 5, 6,
//! 4096 samples) with timings:
//! `cargo test --release --test lifted_states -- --ignored --nocapture`.

use nalgebra::DMatrix;
use tacit::diagnose::lifted::{reconstruct, LiftedResult, LiftedSettings};
use tacit::integrate::SimSettings;
use tacit::linear::SampledModel;
use tacit::model::Model;
use tacit::record::Quantity;
use tacit::simulate::{simulate_record, RecordSpec};
use tacit::trace::regress::segment_response;

fn model(name: &str) -> Model {
    let p = format!("{}/data/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    Model::from_file(std::path::Path::new(&p)).unwrap()
}

/// A simulated record and its linear sampled model (40 sub-steps, as the
/// simulator).
struct Case {
    sm: SampledModel,
    channels: Vec<(Quantity, usize)>,
    measured: DMatrix<f64>,
    known: DMatrix<f64>,
    /// True states (2n × N).
    truth: DMatrix<f64>,
}

fn case(name: &str, samples: usize, sensors: &[usize], noise: f64, seed: u64) -> Case {
    let m = model(name);
    let spec = RecordSpec {
        samples,
        sensors: sensors.to_vec(),
        noise,
        seed,
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    let (rec, _) = simulate_record(&m, &spec).unwrap();
    let n = m.ndof();
    let sm = SampledModel::from_model(&m.linear_part(), rec.fs, 40).unwrap();
    let channels: Vec<(Quantity, usize)> = rec
        .outputs
        .iter()
        .map(|c| (c.quantity, c.dof - 1))
        .collect();
    let measured = DMatrix::from_fn(channels.len(), rec.len(), |c, k| rec.outputs[c].data[k]);
    let known = tacit::signal::force_matrix(&rec, n);
    let t = rec.truth.as_ref().unwrap();
    let truth = DMatrix::from_fn(2 * n, rec.len(), |i, k| {
        if i < n {
            t.u[i][k]
        } else {
            t.v[i - n][k]
        }
    });
    Case {
        sm,
        channels,
        measured,
        known,
        truth,
    }
}

/// Errors of reconstructed states: (u5 − u6, v, shooting error).
struct Figures {
    rel: f64,
    v: f64,
    shooting: f64,
}

fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm()
}

/// Linear model's multiple-shooting error over 51-sample segments from
/// `states`, against the measured outputs.
fn shooting(c: &Case, states: &DMatrix<f64>) -> f64 {
    let (cy, dy) = c.sm.outputs(&c.channels).unwrap();
    let y = segment_response(&c.sm, &cy, &dy, Some(states), &c.known, 51);
    rel(&y, &c.measured)
}

fn figures(c: &Case, states: &DMatrix<f64>) -> Figures {
    let n = c.sm.n;
    let d = |x: &DMatrix<f64>| DMatrix::from_fn(1, x.ncols(), |_, k| x[(4, k)] - x[(5, k)]);
    Figures {
        rel: rel(&d(states), &d(&c.truth)),
        v: rel(
            &states.rows(n, n).into_owned(),
            &c.truth.rows(n, n).into_owned(),
        ),
        shooting: shooting(c, states),
    }
}

fn run(c: &Case, resolution: usize, lambda: f64) -> (LiftedResult, Figures) {
    let s = LiftedSettings {
        resolution,
        lambda,
        ..Default::default()
    };
    let res = reconstruct(&c.sm, &c.known, &c.measured, &c.channels, &s).unwrap();
    let f = figures(c, &res.states);
    (res, f)
}

const ALL: [usize; 8] = [1, 2, 3, 4, 5, 6, 7, 8];

#[test]
fn linear_record_states_are_exact() {
    for sensors in [&ALL[..], &[1, 5, 6]] {
        let c = case("lanl8dof", 1024, sensors, 0.0, 3);
        for r in [1, 8] {
            let (res, f) = run(&c, r, 1e-2);
            eprintln!(
                "linear {sensors:?} R={r}: u5-u6 {:.2e} v {:.2e} shooting {:.2e} ({})",
                f.rel, f.v, f.shooting, res.status
            );
            assert!(
                f.rel < 0.01,
                "R = {r}, sensors {sensors:?}: u5-u6 error {}",
                f.rel
            );
            assert!(f.shooting < 0.01, "shooting error {}", f.shooting);
            // no force where there is none
            let frms = (res.force.norm_squared() / res.force.len() as f64).sqrt();
            assert!(
                frms < 0.1,
                "identified force RMS {frms} N on a linear record"
            );
        }
    }
}

#[test]
fn contact_record_states_resolve_the_impacts() {
    let c = case("lanl8dof-contact", 1024, &ALL, 0.0, 3);
    let truth = figures(&c, &c.truth);
    let (res1, f1) = run(&c, 1, 1e-2);
    let (res8, f8) = run(&c, 8, 1e-2);
    eprintln!("truth shooting {:.3}", truth.shooting);
    for (r, res, f) in [(1, &res1, &f1), (8, &res8, &f8)] {
        eprintln!(
            "contact R={r}: u5-u6 {:.3} v {:.3} shooting {:.3} ({:.3} s; {})",
            f.rel, f.v, f.shooting, res.elapsed_s, res.status
        );
    }
    assert!(f8.rel < 0.1, "u5-u6 error {}", f8.rel);
    assert!(
        f8.rel < 0.5 * f1.rel,
        "R = 8 {} vs R = 1 {}",
        f8.rel,
        f1.rel
    );
    assert!(
        (f8.shooting - truth.shooting).abs() < 0.1 * truth.shooting,
        "shooting {} vs {} from the true states",
        f8.shooting,
        truth.shooting
    );
    // the force localises at the bumper: DOFs 5 and 6 carry most of it
    let rms = |i: usize| (res8.force.row(i).norm_squared() / res8.force.ncols() as f64).sqrt();
    let rest = (0..8)
        .filter(|i| *i != 4 && *i != 5)
        .map(rms)
        .fold(0.0, f64::max);
    assert!(
        rms(4) > 5.0 * rest && rms(5) > 5.0 * rest,
        "{:?}",
        (0..8).map(rms).collect::<Vec<_>>()
    );
}

/// The report table (release, 4096 samples).
#[test]
#[ignore]
fn table() {
    let samples: usize = std::env::var("LIFTED_SAMPLES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(4096);
    println!("record  noise sensors  R  lambda  u5-u6  v  shooting  (truth shooting)  seconds");
    for name in ["lanl8dof", "lanl8dof-contact"] {
        for noise in [0.0, 0.01] {
            for sensors in [&ALL[..], &[1, 5, 6]] {
                let c = case(name, samples, sensors, noise, 3);
                let t = figures(&c, &c.truth);
                for r in [1, 4, 8] {
                    for lambda in [1e-4, 1e-2, 1.0] {
                        let (res, f) = run(&c, r, lambda);
                        println!(
                            "{name:16} {noise:.2} {:8} {r} {lambda:.0e} {:7.3} {:7.3} {:7.3} ({:.3}) {:.3}  [{}]",
                            if sensors.len() == 8 { "all" } else { "1,5,6" },
                            f.rel,
                            f.v,
                            f.shooting,
                            t.shooting,
                            res.elapsed_s,
                            res.status
                        );
                    }
                }
            }
        }
    }
}

#[test]
#[ignore]
fn explore_dump() {
    let r: usize = std::env::var("R").ok().and_then(|s| s.parse().ok()).unwrap_or(8);
    let lam: f64 = std::env::var("LAM").ok().and_then(|s| s.parse().ok()).unwrap_or(1e-2);
    let c = case("lanl8dof-contact", 1024, &ALL, 0.0, 3);
    let (res, f) = run(&c, r, lam);
    eprintln!("R={r} lam={lam}: u5-u6 {:.3} v {:.3} shooting {:.3} {}", f.rel, f.v, f.shooting, res.status);
    let mut s = String::new();
    for k in 0..c.truth.ncols() {
        let row: Vec<String> = (0..16).map(|i| format!("{:e}", c.truth[(i, k)]))
            .chain((0..16).map(|i| format!("{:e}", res.states[(i, k)])))
            .chain((0..8).map(|i| format!("{:e}", res.force[(i, k)]))).collect();
        s += &row.join(",");
        s += "\n";
    }
    std::fs::write(format!("/tmp/lifted_{r}.csv"), s).unwrap();
}
