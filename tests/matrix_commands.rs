//! `tacit identify`, `tacit update` and `tacit modal` on a model from
//! Matrix Market files (the clamped beam of `data/beam100`, 202 DOFs),
//! through the binary: the stop at the tip located and reconstructed at
//! its point, its gap and stiffness updated from a perturbed start, the
//! beam's modes identified from a record against the full model's; the
//! options that take DOF numbers refused with the option named.

mod common;

use common::{json, simulate_points, tacit, text};
use std::path::{Path, PathBuf};

/// Simulate `model` at five points, driven at `n20:uy` in `band` (Hz), 1 %
/// noise.
fn simulate(model: &str, band: &str, seed: &str, samples: &str, substeps: &str, out: &Path) {
    let points = "n20:uy,n40:uy,n60:uy,n80:uy,n100:uy";
    let extra = ["--substeps", substeps, "--samples", samples, "--seed", seed];
    simulate_points(model, points, "n20:uy", band, &extra, out);
}

/// The beam with the stop at the tip (gap 2e-4 m, 5e4 N/m), 4096 samples.
fn stop_record(dir: &Path) -> PathBuf {
    let r = dir.join("stop.h5");
    simulate(
        "data/beam100-stop/model.toml",
        "5,200",
        "7",
        "4096",
        "20",
        &r,
    );
    r
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
    let (ma, mb) = (mean(a), mean(b));
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += (x - ma) * (y - mb);
        aa += (x - ma) * (x - ma);
        bb += (y - mb) * (y - mb);
    }
    ab / (aa * bb).sqrt()
}

#[test]
fn identify_locates_the_stop_at_the_tip_point() {
    let dir = tempfile::tempdir().unwrap();
    let rec = stop_record(dir.path());
    let out = dir.path().join("id");
    let o = tacit(&[
        "identify",
        "--model",
        "data/beam100/model.toml",
        "--record",
        rec.to_str().unwrap(),
        "--no-figures",
        "-o",
        out.to_str().unwrap(),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("force located at point n100:uy"), "{t}");
    // the force at the tip, by label, against the record's true stop force
    let csv = std::fs::read_to_string(out.join("forces_at_points.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header,
        ["time", "n20:uy", "n40:uy", "n60:uy", "n80:uy", "n100:uy"]
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let tip: Vec<f64> = rows.iter().map(|r| r[5]).collect();
    let truth = tacit::record::read(&rec).unwrap().truth.unwrap();
    // the simulation kept the same five points, the tip fifth
    let true_tip = &truth.fint[4];
    assert_eq!(true_tip.len(), tip.len());
    let c = correlation(&tip, true_tip);
    assert!(c >= 0.9, "correlation with the true stop force {c}");
    // nothing at the other points
    for i in 1..5 {
        let rms = (rows.iter().map(|r| r[i] * r[i]).sum::<f64>() / rows.len() as f64).sqrt();
        assert!(rms < 1e-6, "force at {} of RMS {rms}", header[i]);
    }
    let points = json(&out.join("points.json"));
    assert_eq!(points["located"], serde_json::json!(["n100:uy"]));
    assert_eq!(points["points"][4]["label"], "n100:uy");
    let c2 = points["points"][4]["correlation_with_truth"]
        .as_f64()
        .unwrap();
    assert!((c2 - c).abs() < 1e-6, "{c2} {c}");
    assert!(points["reduction"]["full_dofs"] == 202, "{points}");
}

#[test]
fn update_finds_the_stop_from_a_perturbed_start() {
    let dir = tempfile::tempdir().unwrap();
    let rec = stop_record(dir.path());
    // the stop's gap 15 % wide and its stiffness 20 % soft
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let toml = std::fs::read_to_string(root.join("data/beam100-stop/model.toml"))
        .unwrap()
        .replace(
            "../beam100/",
            &format!("{}/", root.join("data/beam100").display()),
        )
        .replace("gap = 0.0002", "gap = 0.00023")
        .replace("stiffness = 50000.0", "stiffness = 40000.0");
    assert!(toml.contains("gap = 0.00023") && toml.contains("stiffness = 40000.0"));
    let model = dir.path().join("start.toml");
    std::fs::write(&model, toml).unwrap();
    let out = dir.path().join("up");
    let o = tacit(&[
        "update",
        "--model",
        model.to_str().unwrap(),
        "--record",
        rec.to_str().unwrap(),
        "--free",
        "gap1,kc1",
        "--data",
        "accel",
        "--segment",
        "128",
        "--substeps",
        "20",
        "-o",
        out.to_str().unwrap(),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("gap1 (n100:uy)"), "{t}");
    let s = json(&out.join("summary.json"));
    let value = |name: &str| {
        s["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap()["value"]
            .as_f64()
            .unwrap()
    };
    let (gap, k) = (value("gap1"), value("kc1"));
    assert!((gap / 2e-4 - 1.0).abs() < 0.05, "gap {gap}");
    assert!((k / 5e4 - 1.0).abs() < 0.05, "stiffness {k}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| gap1 | n100:uy |"), "{md}");
    assert!(md.contains("| accel:n100:uy |"), "{md}");
}

#[test]
fn modal_identifies_the_beam_modes_at_the_points() {
    let dir = tempfile::tempdir().unwrap();
    // the record from a finer reduction (cut-off 2 kHz) than the one
    // modal builds, so the identified frequencies are the beam's own
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let toml = std::fs::read_to_string(root.join("data/beam100/model.toml"))
        .unwrap()
        .replace(
            "mass = \"",
            &format!("mass = \"{}/", root.join("data/beam100").display()),
        )
        .replace(
            "stiffness = \"",
            &format!("stiffness = \"{}/", root.join("data/beam100").display()),
        );
    let fine = dir.path().join("fine.toml");
    std::fs::write(&fine, format!("{toml}\n[reduction]\ncutoff_hz = 2000.0\n")).unwrap();
    let rec = dir.path().join("lin.h5");
    simulate(fine.to_str().unwrap(), "2,200", "3", "32768", "10", &rec);
    let o = tacit(&[
        "modal",
        "--model",
        "data/beam100/model.toml",
        "--record",
        rec.to_str().unwrap(),
        "--band",
        "4,200",
        "--segment",
        "8192",
        "--json",
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        doc["points"],
        serde_json::json!(["n20:uy", "n40:uy", "n60:uy", "n80:uy", "n100:uy"])
    );
    // the full model's frequencies in the band, from the reduction check
    let full: Vec<f64> = doc["reduction"]["frequencies"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["full_hz"].as_f64().unwrap())
        .filter(|&f| f < 200.0)
        .collect();
    assert_eq!(full.len(), 3, "{full:?}");
    let test: Vec<f64> = doc["test_modes"]["mode"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["frequency_hz"].as_f64().unwrap())
        .collect();
    assert_eq!(test.len(), 3, "{test:?}");
    for (f, g) in test.iter().zip(&full) {
        assert!(
            (f / g - 1.0).abs() < 0.01,
            "identified {f} Hz, full model {g} Hz"
        );
    }
    // the shapes at the points correlate with the model's
    for p in doc["correlation"]["pairs"].as_array().unwrap() {
        assert!(p["mac"].as_f64().unwrap() > 0.99, "{p}");
    }
    // without a record: the full model's modes up to a frequency
    let o = tacit(&[
        "modal",
        "--model",
        "data/beam100/model.toml",
        "--up-to",
        "200",
        "--points",
        "n100:uy",
        "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let m: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let f: Vec<f64> = serde_json::from_value(m["freq_hz"].clone()).unwrap();
    assert_eq!(f.len(), 3, "{f:?}");
    for (a, b) in f.iter().zip(&full) {
        assert!((a / b - 1.0).abs() < 1e-6, "{a} {b}");
    }
    // a clamped-free beam's first three frequencies: (β_r L)² √(EI/ρA)/2π
    // with β L = 1.8751, 4.6941, 7.8548 (EI = 700 N m², ρA = 3.14 kg/m)
    for (a, bl) in f.iter().zip([1.875104, 4.694091, 7.854757]) {
        let (ei, rho_a) = (210e9 * 0.04 * 0.01f64.powi(3) / 12.0, 7850.0 * 0.04 * 0.01);
        let exact = bl * bl * (ei / rho_a).sqrt() / (2.0 * std::f64::consts::PI);
        assert!((a / exact - 1.0).abs() < 1e-3, "{a} {exact}");
    }
}

#[test]
fn options_by_dof_are_refused_on_a_model_from_matrices() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let o = out.to_str().unwrap();
    let m = "data/beam100/model.toml";
    let rec = "data/lanl8dof-bumper.h5";
    let cases: [(&[&str], &str); 7] = [
        (
            &[
                "identify",
                "--model",
                m,
                "--record",
                rec,
                "--sensors",
                "1,2",
                "-o",
                o,
            ],
            "--sensors",
        ),
        (
            &[
                "identify", "--model", m, "--record", rec, "--upper", "1:5", "-o", o,
            ],
            "--upper",
        ),
        (
            &[
                "update", "--model", m, "--record", rec, "--free", "zeta", "--dofs", "1", "-o", o,
            ],
            "--dofs",
        ),
        (
            &[
                "update", "--model", m, "--record", rec, "--free", "zeta", "--reduce", "guyan",
                "-o", o,
            ],
            "--reduce",
        ),
        (
            &["modal", "--model", m, "--record", rec, "--update", "force"],
            "--update",
        ),
        (
            &["modal", "--model", m, "--record", rec, "--input-dof", "1"],
            "--input-dof",
        ),
        (&["modal", "--model", m], "--up-to"),
    ];
    for (args, option) in cases {
        let r = tacit(args);
        let t = text(&r);
        assert_eq!(r.status.code(), Some(1), "{args:?}: {t}");
        assert!(t.contains(option), "{args:?}: {t}");
        assert!(!t.contains("panicked"), "{t}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    // a point the reduced model has not kept
    let rec = stop_record(dir.path());
    let rec = rec.to_str().unwrap();
    let r = tacit(&[
        "update", "--model", m, "--record", rec, "--free", "zeta", "--points", "n30:uy", "-o", o,
    ]);
    let t = text(&r);
    assert_eq!(r.status.code(), Some(1), "{t}");
    assert!(t.contains("--points") && t.contains("\"n30:uy\""), "{t}");
    assert!(!out.exists());
}
