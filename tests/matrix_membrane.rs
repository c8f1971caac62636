//! A stop on a membrane, whose reduced model carries more modal
//! coordinates than points: the clamped membrane of
//! `scripts/membrane_mtx.py` at 40 × 25 elements (1 066 DOFs), a one-sided
//! stop against ground at `p30_15:uz` (gap 0.8 mm, 2e4 N/m), five points,
//! driven at `p10_10:uz` (5 N RMS, 5–150 Hz, 1 % noise). The reduction
//! keeps the five points and 16 fixed-interface modes up to 297.5 Hz;
//! `tacit diagnose` of the membrane without the stop, its linear part
//! trusted, names the stop at `p30_15:uz` with gap and stiffness within
//! 10 % and a validation error at the noise. The force located at the
//! stop's point fits the data closer than half the noise at the default
//! weight of the force prior (weighted residual 0.32), so the weight is
//! raised (to 0.1, residual 0.51). About 17 s in release on two shared
//! cores.

mod common;

use common::{json, script_model, simulate_points, tacit, text};
use std::path::Path;

const POINTS: &str = "p10_10:uz,p20_12:uz,p30_15:uz,p25_5:uz,p8_20:uz";

/// Write the 40 × 25 membrane into `out` with `args`; false (with a
/// message) when there is no `python3`.
fn membrane(out: &Path, args: &[&str]) -> bool {
    let mut all = vec!["--nx", "40", "--ny", "25"];
    all.extend_from_slice(args);
    script_model("membrane_mtx.py", out, &all)
}

fn simulate(model: &Path, seed: &str, out: &Path) {
    let extra = ["--substeps", "20", "--seed", seed];
    simulate_points(
        model.to_str().unwrap(),
        POINTS,
        "p10_10:uz",
        "5,150",
        &extra,
        out,
    );
}

#[test]
fn stop_on_a_membrane_is_found_at_its_point() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (truth, declared) = (d.join("truth"), d.join("declared"));
    if !membrane(&truth, &["--stop", "p30_15:uz,8e-4,2e4"]) || !membrane(&declared, &[]) {
        return;
    }
    let (r7, r8) = (d.join("r7.h5"), d.join("r8.h5"));
    simulate(&truth.join("model.toml"), "7", &r7);
    simulate(&truth.join("model.toml"), "8", &r8);
    let out = d.join("out");
    let o = tacit(&[
        "diagnose",
        "--model",
        declared.join("model.toml").to_str().unwrap(),
        "--record",
        r7.to_str().unwrap(),
        "--validate",
        r8.to_str().unwrap(),
        "--trust-linear",
        "-o",
        out.to_str().unwrap(),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let (rep, red) = (
        json(&out.join("report.json")),
        json(&out.join("reduction.json")),
    );
    assert!(red["modal_coordinates"].as_u64().unwrap() > 10, "{red}");
    assert!(red["damped_above_cutoff"].as_u64().unwrap() > 0, "{red}");
    let ident = rep["identification"].as_str().unwrap();
    assert!(ident.contains("force-prior weight raised"), "{ident}");
    let effects = rep["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 1, "{t}");
    let e = &effects[0];
    assert_eq!(e["kind"], "contact", "{e}");
    let label = e["label"].as_str().unwrap();
    assert!(label.ends_with("(p30_15:uz)"), "{label}");
    let p = |name: &str| e["parameters"][name].as_f64().unwrap();
    let (gap, k) = (p("gap"), p("stiffness"));
    assert!((gap / 8e-4 - 1.0).abs() < 0.1, "gap {gap}");
    assert!((k / 2e4 - 1.0).abs() < 0.1, "stiffness {k}");
    let val = |when: &str| rep["validation"][when]["relative_error"].as_f64().unwrap();
    assert!(val("before") > 0.1, "validation before {}", val("before"));
    assert!(val("after") < 0.015, "validation error {}", val("after"));
}
