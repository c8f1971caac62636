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

/// A model that cannot be simulated on the record is an error with its
/// facts, a non-zero exit and no output: (a) a softening cubic whose
/// Newton iterations fail at the start values; (b) a spring of 1e20 N/m
/// without damping, whose simulation completes but diverges (energy above
/// what the force can put in), which the updating used to fit and write
/// with exit 0.
#[test]
fn a_model_that_cannot_be_simulated_is_an_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let rec = record_file(dir.path());
    let soft = dir.path().join("soft.toml");
    std::fs::write(
        &soft,
        table4::MODEL_TOML.replace("k3 = 3.0e8", "k3 = -3.0e12"),
    )
    .unwrap();
    assert!(std::fs::read_to_string(&soft).unwrap().contains("-3.0e12"));
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let lanl = std::fs::read_to_string(root.join("data/lanl8dof.toml")).unwrap();
    let k5 = lanl.find("name = \"k5\"").unwrap();
    let at = k5 + lanl[k5..].find("stiffness = 56700.0").unwrap();
    let stiff = format!(
        "{}stiffness = 1e20{}",
        &lanl[..at],
        &lanl[at + "stiffness = 56700.0".len()..]
    )
    .replace("kind = \"modal\"\nratio = 0.01", "kind = \"none\"");
    let stiff_path = dir.path().join("stiff.toml");
    std::fs::write(&stiff_path, stiff).unwrap();
    let bumper = root.join("data/lanl8dof-bumper.h5");
    let cases: [(&std::path::Path, &std::path::Path, &[&str], &[&str]); 2] = [
        (
            &soft,
            &rec,
            &["--free", "k1..k4", "--data", "disp,vel"],
            &[
                "the model at the start values (k1 = 2.6e5",
                "Newton iterations did not converge at t = ",
                "nothing was fitted",
            ],
        ),
        (
            &stiff_path,
            &bumper,
            &["--free", "k1", "--data", "accel"],
            &[
                "the fitted model (k1 = ",
                "segment 0 diverges from its sample 65",
                "DOF 5 at ",
                "the highest natural frequency is about 3.476e9 Hz",
            ],
        ),
    ];
    for (i, (model, record, args, needles)) in cases.iter().enumerate() {
        let out = dir.path().join(format!("out{i}"));
        let o = tacit()
            .args(["update", "--model"])
            .arg(model)
            .arg("--record")
            .arg(record)
            .args(*args)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "case {i}: {err}");
        for n in *needles {
            assert!(err.contains(n), "case {i}: no {n:?} in {err}");
        }
        assert!(!out.exists(), "case {i} left {}", out.display());
    }
}
