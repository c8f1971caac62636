//! `tacit modal` with test modes: tables, JSON, errors.

use std::process::Command;

fn tacit() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tacit"))
}

const MODEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");

fn write_modes(dir: &std::path::Path) -> std::path::PathBuf {
    let p = std::path::Path::new(MODEL);
    let nominal = tacit::model::Model::from_file(p).unwrap();
    let damaged = tacit::correlate::with_spring_change(&nominal, "k5", -0.14).unwrap();
    let t = tacit::correlate::model_test_modes(&damaged, &[1, 4, 7], 5).unwrap();
    let f = dir.join("modes.toml");
    std::fs::write(&f, t.to_toml_string()).unwrap();
    f
}

#[test]
fn model_only_keeps_the_old_output() {
    let out = tacit().args(["modal", "--model", MODEL]).output().unwrap();
    assert!(out.status.success());
    let s = String::from_utf8_lossy(&out.stdout);
    assert!(s.contains("rigid") && s.contains("21.97"), "{s}");
}

#[test]
fn correlation_and_update_from_a_test_modes_file() {
    let dir = tempfile::tempdir().unwrap();
    let f = write_modes(dir.path());
    let plot = dir.path().join("fig");
    let out = tacit()
        .args(["modal", "--model", MODEL, "--test-modes"])
        .arg(&f)
        .args(["--update", "force", "--expansion", "dynamic", "--plot"])
        .arg(&plot)
        .output()
        .unwrap();
    let s = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{s}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(s.contains("MAC %") && s.contains("-14.00%"), "{s}");
    assert!(dir.path().join("fig_mac.png").exists());
    assert!(dir.path().join("fig_update.svg").exists());
    let out = tacit()
        .args(["modal", "--model", MODEL, "--json", "--test-modes"])
        .arg(&f)
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let pairs = v["correlation"]["pairs"].as_array().unwrap();
    assert_eq!(pairs.len(), 5);
    assert!(pairs[0]["mac"].as_f64().unwrap() > 0.99);
}

#[test]
fn unmatched_dof_names_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let f = write_modes(dir.path());
    let text = std::fs::read_to_string(&f)
        .unwrap()
        .replace("dofs = [1, 4, 7]", "dofs = [1, \"dof4\", \"rod\"]");
    std::fs::write(&f, text).unwrap();
    let out = tacit()
        .args(["modal", "--model", MODEL, "--test-modes"])
        .arg(&f)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("modes.toml") && e.contains("\"rod\""), "{e}");
}
