//! `tacit update` end to end: a good run writes its outputs, bad input
//! fails with a clear message and writes nothing.

use std::process::Command;
use tacit::cases::table4;

fn record_file(dir: &std::path::Path) -> std::path::PathBuf {
    let case = table4::case(0.0, 1).unwrap();
    let path = dir.join("t4.h5");
    tacit::record::write(&case.record, &path).unwrap();
    let model = dir.join("model.toml");
    std::fs::write(&model, table4::MODEL_TOML).unwrap();
    path
}

fn tacit() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tacit"))
}

#[test]
fn update_writes_summary_report_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let rec = record_file(dir.path());
    let out = dir.path().join("out");
    let o = tacit()
        .args(["update", "--model"])
        .arg(dir.path().join("model.toml"))
        .arg("--record")
        .arg(&rec)
        .args([
            "--free",
            "k1..k4,cubic",
            "--metric",
            "gls",
            "--data",
            "disp,vel",
        ])
        .args([
            "--dofs",
            "1,3,4",
            "--reduce",
            "serep",
            "--optimizer",
            "lm",
            "-o",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(out.join("summary.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let k3 = v["parameters"][2]["percent_change"].as_f64().unwrap();
    let cubic = v["parameters"][4]["percent_change"].as_f64().unwrap();
    assert!(
        (k3 + 15.0).abs() < 0.5 && (cubic - 25.0).abs() < 0.5,
        "{k3} {cubic}"
    );
    assert!(v["errors_after"]["overall"].as_f64().unwrap() < 0.05);
    // a reduced model: sensitivities requested (the default), finite
    // differences used, and the summary says why
    assert_eq!(v["jacobian"], "central_difference");
    assert!(v["jacobian_note"].as_str().unwrap().contains("reduced"));
    assert_eq!(v["sensitivity_simulations"], 0);
    assert!(
        v["identifiability"]["singular_values"]
            .as_array()
            .unwrap()
            .len()
            == 5
    );
    for f in [
        "report.md",
        "update_before.png",
        "update_before.svg",
        "update_after.png",
        "update_after.svg",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
}

#[test]
fn bad_input_fails_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let rec = record_file(dir.path());
    let model = dir.path().join("model.toml");
    let cases: [(&[&str], &str); 5] = [
        (&["--free", "k9"], "'k9'"),
        (&["--free", "k1", "--data", "strain"], "strain"),
        (&["--free", "k1", "--data", "accel"], "accel"),
        (&["--free", "k1", "--dofs", "2"], "disp_2"),
        (&["--free", "k1", "--jacobian", "exact"], "sens"),
    ];
    for (i, (args, needle)) in cases.iter().enumerate() {
        let out = dir.path().join(format!("out{i}"));
        let o = tacit()
            .args(["update", "--model"])
            .arg(&model)
            .arg("--record")
            .arg(&rec)
            .args(*args)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} left {}", out.display());
    }
}
