//! `tacit identify`'s default, the located, lifted smoother, on the bumper
//! record shipped in data/ (accelerations at 1, 5, 6; the record carries
//! the true internal force): the force comes back at the contact DOFs and
//! nowhere else.

mod common;

use common::{tacit, text};
use tacit::identify::{identify_located, LocatedSettings, Problem};
use tacit::model::Model;

fn data(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(name)
}

#[test]
fn lifted_default_finds_the_contact_force_on_the_shipped_record() {
    let model = Model::from_file(&data("lanl8dof.toml")).unwrap();
    let rec = tacit::record::read(&data("lanl8dof-bumper.h5")).unwrap();
    let prob = Problem::new(&model.linear_part(), &rec, &[1, 5, 6]).unwrap();
    let est = identify_located(&model, &prob, &LocatedSettings::default()).unwrap();
    let truth = est
        .truth
        .as_ref()
        .expect("the shipped record carries its truth");
    let (rms_true, rms_id, corr) = (&truth.rms_true, &truth.rms_identified, &truth.correlation);
    for d in [4, 5] {
        assert!(
            corr[d] >= 0.9,
            "DOF {}: correlation {} with the true contact force",
            d + 1,
            corr[d]
        );
        let ratio = rms_id[d] / rms_true[d];
        assert!(
            (0.7..1.3).contains(&ratio),
            "DOF {}: RMS {} N against a true {} N",
            d + 1,
            rms_id[d],
            rms_true[d]
        );
    }
    for d in (0..8).filter(|d| ![4, 5].contains(d)) {
        assert!(
            rms_id[d] < 0.05 * rms_true[4],
            "DOF {}: RMS {} N where no force acts",
            d + 1,
            rms_id[d]
        );
    }
    let (before, after, _) = est.overall_errors();
    assert!(before > 0.5 && after < 0.05, "{before} -> {after}");
    let note = &est.diagnostics.identifiability.as_ref().unwrap().note;
    assert!(note.contains("pair 5–6"), "{note}");
}

#[test]
fn the_cli_default_is_the_lifted_method() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("id");
    let o = tacit(&[
        "identify",
        "--model",
        "data/lanl8dof.toml",
        "--record",
        "data/lanl8dof-bumper.h5",
        "--sensors",
        "1,5,6",
        "--no-figures",
        "-o",
        out.to_str().unwrap(),
    ]);
    let text = text(&o);
    assert!(o.status.success(), "{text}");
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["method"], "lifted", "{text}");
    let c5 = s["truth"]["correlation"][4].as_f64().unwrap();
    assert!(c5 >= 0.9, "correlation at DOF 5: {c5}");
    // a reduction is refused with the option named
    let o = tacit(&[
        "identify",
        "--model",
        "data/lanl8dof.toml",
        "--record",
        "data/lanl8dof-bumper.h5",
        "--sensors",
        "1,5,6",
        "--reduce",
        "serep",
        "-o",
        dir.path().join("bad").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--reduce"));
    assert!(!dir.path().join("bad").exists());
}
