//! End-to-end: the Silverbox benchmark (real measurements, Wigren &
//! Schoukens, ECC 2013, read from the shared data set beside the checkout)
//! through `tacit diagnose` as docs/silverbox.md runs it, on a shorter
//! estimation range (two multisine realisations, 40650..57000) to keep the
//! test short; the full figures come from the example and the docs. Skips
//! with a message when the data set is absent (unless
//! TACIT_REQUIRE_SHARED=1).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data")
}

fn tacit(mat: &Path, extra: &[&str], out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tacit"))
        .arg("diagnose")
        .arg("--model")
        .arg(data().join("silverbox.toml"))
        .arg("--settings")
        .arg(data().join("silverbox-settings.toml"))
        .arg("--record")
        .arg(mat)
        .args([
            "--mat-map",
            "V1=force_1,V2=disp_1",
            "--mat-fs",
            "610.3515625",
            "--remove-mean",
            "--band-limited-force",
            "--refine-open-loop",
        ])
        .args(extra)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap()
}

fn rms(v: &serde_json::Value) -> f64 {
    v["rms_per_channel"]["disp_1"].as_f64().unwrap()
}

#[test]
fn silverbox_through_the_cli_finds_the_cubic_and_reaches_the_arrow_bound() {
    let Some(mat) = tacit::record::shared_data("silverbox/SNLS80mV.mat") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sb");
    let ranges = [
        "--samples",
        "40650..57000",
        "--validation-samples",
        "100..40575",
        "--skip",
        "50",
    ];
    let o = tacit(&mat, &ranges, &out);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    let r: serde_json::Value = serde_json::from_str(&text).unwrap();
    eprintln!(
        "{} | record {:.4} -> {:.4} mV, arrow {:.4} -> {:.4} mV",
        r["verdict"],
        1e3 * rms(&r["before"]),
        1e3 * rms(&r["after"]),
        1e3 * rms(&r["validation"]["before"]),
        1e3 * rms(&r["validation"]["after"])
    );
    // a hardening cubic spring to ground at the only DOF comes first
    assert_eq!(r["effects"][0]["label"], "cubic @1");
    assert!(r["effects"][0]["parameters"]["k3"].as_f64().unwrap() > 0.0);
    // the arrow test segment, first 50 samples not scored: the ideal
    // Duffing through the linear interpolation of the force reached
    // 0.947 mV; the benchmark's GP-NARX 0.60 mV
    let arrow = rms(&r["validation"]["after"]);
    assert!(arrow < 0.5e-3, "arrow {arrow}");
    // the starting values of the model file are far off (16.6 mV)
    assert!(rms(&r["validation"]["before"]) > 10e-3);
    // the free mass is calibrated (starting value 5e-6)
    let corr = r["calibration"]["corrections"].as_array().unwrap();
    let m = corr.iter().find(|c| c["name"] == "m1").unwrap();
    assert!(
        (m["value"].as_f64().unwrap() - 5.376e-6).abs() < 0.02e-6,
        "{m}"
    );
}

#[test]
fn silverbox_ranges_and_skip_are_checked_naming_the_option() {
    let Some(mat) = tacit::record::shared_data("silverbox/SNLS80mV.mat") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (&["--samples", "40650..200000"], "--samples 40650..200000"),
        (&["--samples", "500..400"], "--samples"),
        (
            &[
                "--samples",
                "0..1000",
                "--validation-samples",
                "131000..131073",
            ],
            "--validation-samples 131000..131073",
        ),
        (
            &[
                "--samples",
                "0..1000",
                "--validation-samples",
                "0..100",
                "--skip",
                "100",
            ],
            "--skip 100",
        ),
    ];
    for (i, (args, named)) in cases.iter().enumerate() {
        let out = dir.path().join(format!("c{i}"));
        let o = tacit(&mat, args, &out);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} passed");
        assert!(stderr.contains(named), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(!out.exists(), "{args:?} left {}", out.display());
    }
}

#[test]
fn silverbox_bad_mapping_is_a_clear_error() {
    let Some(path) = tacit::record::shared_data("silverbox/SNLS80mV.mat") else {
        return;
    };
    let path = path.as_path();
    let e = tacit::record::read_mat(
        path,
        &tacit::record::MatMapping {
            channels: vec![tacit::record::MatChannel::at_dof(
                "V9",
                tacit::record::Quantity::Force,
                1,
            )],
            fs: 610.35.into(),
            remove_mean: true,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("V9") && e.contains("V1"), "{e}");
}
