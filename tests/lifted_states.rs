//! State reconstruction with the sub-sample ("lifted") unknown force
//! (`tacit::diagnose::lifted`) on simulated LANL 8-DOF records, against the
//! simulator's truth: exact on a linear record, and on a record with the
//! bumper 5→6 start states good enough that the linear model's
//! multiple-shooting error is what the true states give.
//!
//! The full table (R ∈ {1, 4, 8}, noise 0 and 1 %, sensors all / 1, 5, 6,
//! quadratic and sparse force prior, 4096 samples) with timings:
//! `cargo test --release --test lifted_states -- --ignored --nocapture`
//! (`LIFTED_SAMPLES=1024` for a shorter record).

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

/// Errors of reconstructed states against the truth.
struct Figures {
    /// Relative error of u5 − u6.
    rel: f64,
    /// Relative error of all velocities.
    v: f64,
    /// Relative error of the velocities relative to the mass-weighted mean
    /// (the rigid-body velocity, which accelerations do not see, removed).
    v_flex: f64,
    /// Linear model's multiple-shooting error (51-sample segments).
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
    let v = |x: &DMatrix<f64>| x.rows(n, n).into_owned();
    let mtot: f64 = (0..n).map(|i| c.sm.m[(i, i)]).sum();
    let flex = |x: &DMatrix<f64>| {
        DMatrix::from_fn(n, x.ncols(), |i, k| {
            let mean: f64 = (0..n).map(|j| c.sm.m[(j, j)] * x[(n + j, k)]).sum::<f64>() / mtot;
            x[(n + i, k)] - mean
        })
    };
    Figures {
        rel: rel(&d(states), &d(&c.truth)),
        v: rel(&v(states), &v(&c.truth)),
        v_flex: rel(&flex(states), &flex(&c.truth)),
        shooting: shooting(c, states),
    }
}

fn run(c: &Case, resolution: usize, lambda: f64, passes: usize) -> (LiftedResult, Figures) {
    let s = LiftedSettings {
        resolution,
        lambda,
        reweight_passes: passes,
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
        for (r, passes) in [(1, 0), (8, 0), (8, 2)] {
            let (res, f) = run(&c, r, 1e-2, passes);
            eprintln!(
                "linear {sensors:?} R={r} passes={passes}: u5-u6 {:.2e} v {:.2e} shooting {:.2e} ({})",
                f.rel, f.v, f.shooting, res.status
            );
            assert!(
                f.rel < 0.01,
                "R = {r}, sensors {sensors:?}: u5-u6 error {}",
                f.rel
            );
            assert!(f.v < 0.01, "R = {r}, sensors {sensors:?}: v error {}", f.v);
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

/// All 8 accelerations, noise-free: the quadratic prior gets the linear
/// model's segment error right but not u5 − u6 (it removes the contact
/// force's mean); the sparse prior gets both.
#[test]
fn contact_record_states_resolve_the_impacts() {
    let c = case("lanl8dof-contact", 1024, &ALL, 0.0, 3);
    let truth = figures(&c, &c.truth);
    eprintln!("truth shooting {:.3}", truth.shooting);
    let mut out = vec![];
    for (r, passes) in [(1, 0), (8, 0), (8, 4)] {
        let (res, f) = run(&c, r, 1e-2, passes);
        eprintln!(
            "contact R={r} passes={passes}: u5-u6 {:.3} v {:.3} v_flex {:.3} shooting {:.3} ({:.3} s; {})",
            f.rel, f.v, f.v_flex, f.shooting, res.elapsed_s, res.status
        );
        out.push((res, f));
    }
    let close = |f: &Figures| (f.shooting - truth.shooting).abs() < 0.05 * truth.shooting;
    assert!(
        !close(&out[0].1),
        "R = 1 should miss: {}",
        out[0].1.shooting
    );
    assert!(
        close(&out[1].1),
        "R = 8: {} vs {}",
        out[1].1.shooting,
        truth.shooting
    );
    assert!(
        close(&out[2].1),
        "R = 8 sparse: {} vs {}",
        out[2].1.shooting,
        truth.shooting
    );
    let (res, f) = &out[2];
    assert!(f.rel < 0.05, "u5-u6 error {}", f.rel);
    assert!(f.v_flex < 0.15, "flexible velocity error {}", f.v_flex);
    // the force localises at the bumper, equal and opposite
    let rms = |i: usize| (res.force.row(i).norm_squared() / res.force.ncols() as f64).sqrt();
    let rest = (0..8)
        .filter(|i| *i != 4 && *i != 5)
        .map(rms)
        .fold(0.0, f64::max);
    assert!(
        rms(4) > 20.0 * rest && rms(5) > 20.0 * rest,
        "{:?}",
        (0..8).map(rms).collect::<Vec<_>>()
    );
    let pair = (res.force.row(4) + res.force.row(5)).norm() / res.force.row(4).norm();
    assert!(pair < 0.1, "f5 + f6 = {pair} of f5");
}

/// The report table (release, 4096 samples).
#[test]
#[ignore]
fn table() {
    let samples: usize = std::env::var("LIFTED_SAMPLES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(4096);
    let lambda: f64 = std::env::var("LIFTED_LAMBDA")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1e-2);
    println!("record           noise sensors R passes lambda | u5-u6    v   v_flex shooting (truth) | seconds");
    for name in ["lanl8dof", "lanl8dof-contact"] {
        for noise in [0.0, 0.01] {
            for sensors in [&ALL[..], &[1, 5, 6]] {
                let c = case(name, samples, sensors, noise, 3);
                let t = figures(&c, &c.truth);
                for (r, passes) in [(1, 0), (4, 0), (8, 0), (1, 4), (4, 4), (8, 4)] {
                    let (res, f) = run(&c, r, lambda, passes);
                    println!(
                        "{name:16} {noise:.2}  {:7} {r}   {passes}   {lambda:.0e} | {:6.3} {:6.3} {:6.3} {:6.3} ({:.3}) | {:.3}",
                        if sensors.len() == 8 { "all" } else { "1,5,6" },
                        f.rel,
                        f.v,
                        f.v_flex,
                        f.shooting,
                        t.shooting,
                        res.elapsed_s,
                    );
                }
            }
        }
    }
}
