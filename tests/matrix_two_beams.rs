//! Issue 17's interface check: two clamped beams (204 DOFs, written by
//! `scripts/two_beams_mtx.py`) joined at their tips by a spring, relative
//! Coulomb friction (0.3 N) and a two-sided clearance (gap 0.6 mm,
//! 2e4 N/m). Recorded by `tacit simulate` at four points, driven at
//! `a20:uy`; `tacit diagnose` of the model without the interface names both
//! effects at the pair `a50:uy`–`b50:uy` with their parameters within 10 %
//! and a validation error at the noise (1 %). About 40 s in release on two
//! shared cores.

mod common;

use common::{json, script_model, simulate_points, tacit, text};
use std::path::Path;

fn simulate(model: &Path, seed: &str, out: &Path) {
    let points = "a20:uy,a50:uy,b20:uy,b50:uy";
    let extra = ["--substeps", "20", "--seed", seed];
    simulate_points(
        model.to_str().unwrap(),
        points,
        "a20:uy",
        "5,200",
        &extra,
        out,
    );
}

#[test]
fn friction_and_clearance_are_found_at_the_interface() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (truth, declared) = (d.join("truth"), d.join("declared"));
    let two_beams = |out: &Path, args: &[&str]| script_model("two_beams_mtx.py", out, args);
    if !two_beams(&truth, &["--joint", "0.3,6e-4,2e4"]) || !two_beams(&declared, &[]) {
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
    let rep = json(&out.join("report.json"));
    let effects = rep["effects"].as_array().unwrap();
    let find = |kind: &str| {
        effects
            .iter()
            .find(|e| e["kind"] == kind)
            .unwrap_or_else(|| panic!("no {kind} found: {t}"))
    };
    let (clearance, friction) = (find("clearance"), find("relative_friction"));
    assert_eq!(effects.len(), 2, "{t}");
    // the reduced DOFs 2 and 4 are the tips a50:uy and b50:uy
    for e in [clearance, friction] {
        assert_eq!(e["dofs"], serde_json::json!([2, 4]), "{e}");
        let label = e["label"].as_str().unwrap();
        assert!(label.ends_with("(a50:uy–b50:uy)"), "{label}");
    }
    let p = |e: &serde_json::Value, name: &str| e["parameters"][name].as_f64().unwrap();
    let within = |v: f64, truth: f64, what: &str| {
        assert!((v / truth - 1.0).abs() < 0.1, "{what} {v} against {truth}");
    };
    within(p(clearance, "gap"), 6e-4, "gap");
    within(p(clearance, "stiffness"), 2e4, "clearance stiffness");
    within(p(friction, "level"), 0.3, "friction level");
    let val = rep["validation"]["after"]["relative_error"]
        .as_f64()
        .unwrap();
    assert!(val < 0.015, "validation error {val}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("`a50:uy` – `b50:uy`"), "{md}");
}
