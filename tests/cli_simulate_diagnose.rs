//! End-to-end through the `tacit` binary: simulate, modal, diagnose, and
//! bad input (clear message, non-zero exit, no output file).

mod common;

use common::{tacit, text};

#[test]
fn simulate_writes_hdf5_and_csv_with_truth() {
    let dir = tempfile::tempdir().unwrap();
    // the contact testbed, 512 samples at 1, 5, 6, seed 3
    let simulate = |path: &std::path::Path| {
        tacit(&[
            "simulate",
            "--model",
            "data/lanl8dof-contact.toml",
            "--samples",
            "512",
            "--sensors",
            "1,5,6",
            "--noise",
            "0.01",
            "--seed",
            "3",
            "-o",
            path.to_str().unwrap(),
        ])
    };
    let h5 = dir.path().join("rec.h5");
    let o = simulate(&h5);
    assert!(o.status.success(), "{}", text(&o));
    let rec = tacit::record::read(&h5).unwrap();
    assert_eq!(rec.len(), 512);
    assert_eq!(rec.outputs.len(), 3);
    let truth = rec.truth.as_ref().unwrap();
    // the bumper was active: internal force at 5 and 6, equal and opposite
    let f5: f64 = truth.fint[4].iter().map(|x| x.abs()).sum();
    let f56: f64 = truth.fint[4]
        .iter()
        .zip(&truth.fint[5])
        .map(|(a, b)| (a + b).abs())
        .sum();
    assert!(f5 > 0.0 && f56 < 1e-9 * f5);
    // same seed, same record
    let h5b = dir.path().join("rec2.h5");
    let o = simulate(&h5b);
    assert!(o.status.success());
    assert_eq!(tacit::record::read(&h5b).unwrap().outputs, rec.outputs);
    let csv = dir.path().join("rec.csv");
    let o = tacit(&[
        "simulate",
        "--model",
        "data/lanl8dof.toml",
        "--samples",
        "256",
        "-o",
        csv.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(dir.path().join("rec-truth.csv").exists());
    assert_eq!(tacit::record::read(&csv).unwrap().outputs.len(), 8);
}

#[test]
fn bad_input_is_a_clear_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.h5");
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "masses = [1.0]\n[[spring]]\ndofs = [1]\nstifness = 3.0\n",
    )
    .unwrap();
    for (args, needle) in [
        (
            vec![
                "simulate",
                "--model",
                bad.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            "stifness",
        ),
        (
            vec![
                "simulate",
                "--model",
                "data/lanl8dof.toml",
                "--sensors",
                "1,9",
                "-o",
                out.to_str().unwrap(),
            ],
            "DOF 9",
        ),
        (
            vec![
                "simulate",
                "--model",
                "missing.toml",
                "-o",
                out.to_str().unwrap(),
            ],
            "missing.toml",
        ),
        (
            vec![
                "simulate",
                "--model",
                "data/lanl8dof.toml",
                "--band",
                "5,400",
                "-o",
                out.to_str().unwrap(),
            ],
            "band",
        ),
        (
            vec![
                "diagnose",
                "--model",
                "data/lanl8dof.toml",
                "--record",
                "nope.h5",
                "-o",
                dir.path().join("d").to_str().unwrap(),
            ],
            "nope.h5",
        ),
    ] {
        let o = tacit(&args);
        assert!(!o.status.success(), "{args:?} succeeded");
        let t = text(&o);
        assert!(t.contains(needle), "{args:?}: {t}");
        assert!(!t.contains("panicked"), "{t}");
        assert!(!out.exists());
    }
}

#[test]
fn modal_prints_the_testbed_frequencies() {
    let o = tacit(&["modal", "--model", "data/lanl8dof.toml", "--json"]);
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let f = v["modes"][1]["frequency_hz"].as_f64().unwrap();
    assert!((f - 21.97).abs() < 0.02, "{f}");
}

#[test]
fn diagnose_writes_the_report_on_a_linear_record() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("lin.h5");
    let o = tacit(&[
        "simulate",
        "--model",
        "data/lanl8dof.toml",
        "--samples",
        "1024",
        "--sensors",
        "1,5,6",
        "--noise",
        "0.01",
        "--seed",
        "5",
        "-o",
        rec.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let out = dir.path().join("report");
    let o = tacit(&[
        "diagnose",
        "--model",
        "data/lanl8dof.toml",
        "--record",
        rec.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("no missing effect found"));
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    for key in ["before", "after", "effects", "verdict"] {
        assert!(j.get(key).is_some(), "report.json lacks {key}");
    }
    let before = j["before"]["relative_error"].as_f64().unwrap();
    assert!(before < 0.05, "linear record, linear model: {before}");
    assert_eq!(j["effects"].as_array().unwrap().len(), 0);
    // the exact model leaves white noise at about the 1 % simulated
    let left = &j["remaining"];
    assert_eq!(left["status"]["kind"], "white", "{left}");
    let level = left["level"].as_f64().unwrap();
    assert!((0.007..0.013).contains(&level), "{left}");
    assert!(out.join("report.md").exists() && out.join("residual.png").exists());
    // the figures, drawn (a blank 800×500 PNG is about 5 KB)
    for f in ["responses", "residual", "frf", "identified_force"] {
        for ext in ["png", "svg"] {
            let path = out.join(format!("{f}.{ext}"));
            let size = std::fs::metadata(&path).map_or(0, |m| m.len());
            assert!(size > 20_000, "{} is {size} bytes", path.display());
        }
    }
    // people's report: plain errors with a caption per figure, the
    // solver's words folded away
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let details = md.find("<details>").expect("an appendix");
    for plain in [
        "| before (declared model) |",
        "Segment error",
        "![frf.png](frf.png)",
    ] {
        assert!(md[..details].contains(plain), "{plain} missing: {md}");
    }
    for jargon in [
        "Riccati",
        "reweighting",
        "Gauss–Newton iterations",
        "BIC change",
    ] {
        assert!(
            !md[..details].contains(jargon),
            "{jargon} in the main text: {md}"
        );
    }
    assert!(md[details..].contains("Best candidates of the first trace round"));
}

/// report.json without its timings (the only field that may differ
/// between two runs of the same diagnosis).
fn report(dir: &std::path::Path) -> serde_json::Value {
    let mut j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    j.as_object_mut().unwrap().remove("timings");
    j
}

/// A settings file is read and written whole into report.json and
/// settings.toml; the diagnosis replayed from either gives the same
/// report, field for field (timings aside).
#[test]
fn a_settings_file_and_the_report_replay_the_diagnosis() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("contact.h5");
    let o = tacit(&[
        "simulate",
        "--model",
        "data/lanl8dof-contact.toml",
        "--samples",
        "2048",
        "--noise",
        "0.01",
        "--seed",
        "7",
        "-o",
        rec.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let file = dir.path().join("s.toml");
    std::fs::write(
        &file,
        "[screen]\nmax_effects = 2\n[segments]\nfit_segments = 12\n[fit]\nrace_iterations = 5\n",
    )
    .unwrap();
    let run = |settings: &std::path::Path, out: &str| {
        let out = dir.path().join(out);
        let o = tacit(&[
            "diagnose",
            "--model",
            "data/lanl8dof.toml",
            "--record",
            rec.to_str().unwrap(),
            "--settings",
            settings.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        out
    };
    let first = run(&file, "first");
    let j = report(&first);
    assert_eq!(j["settings"]["screen"]["max_effects"], 2);
    assert_eq!(j["settings"]["segments"]["fit_segments"], 12);
    assert_eq!(j["settings"]["fit"]["race_iterations"], 5);
    // the defaults of the fields the file left out
    assert_eq!(j["settings"]["noise"]["level"], 0.01);
    assert!(
        !j["effects"].as_array().unwrap().is_empty(),
        "{}",
        j["verdict"]
    );
    let from_json = run(&first.join("report.json"), "from_json");
    assert_eq!(report(&from_json), j);
    let from_toml = run(&first.join("settings.toml"), "from_toml");
    assert_eq!(report(&from_toml), j);
}

/// An invalid settings file is refused with the field and the rule, and
/// nothing is written.
#[test]
fn an_invalid_settings_file_names_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.toml");
    let out = dir.path().join("out");
    for (text_, field) in [
        ("[segments]\nfit_segments = 0\n", "segments.fit_segments"),
        ("[substeps]\nomega_h = 0.0\n", "substeps.omega_h"),
        ("[noise]\nlevel = -0.01\n", "noise.level"),
        ("[screen]\nmax_efects = 2\n", "max_efects"),
    ] {
        std::fs::write(&file, text_).unwrap();
        let o = tacit(&[
            "diagnose",
            "--model",
            "data/lanl8dof.toml",
            "--record",
            "data/lanl8dof-bumper.h5",
            "--settings",
            file.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(!o.status.success(), "{text_} accepted");
        let msg = text(&o);
        assert!(msg.contains(field) && msg.contains("bad.toml"), "{msg}");
        assert!(!out.exists(), "{text_}: output written");
    }
}
