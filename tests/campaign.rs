//! `tacit campaign` end to end: the bumper simulated at three force
//! levels, diagnosed from a manifest, summarized, the contact's gap and
//! stiffness fitted to the three records at once; a second run keeps the
//! records done; bad manifests are refused with the key named.

mod common;

use common::{tacit, text};
use std::path::Path;
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::simulate::{simulate_record, InputSpec, RecordSpec};

fn data(name: &str) -> String {
    format!("{}/data/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// The bumper at `rms` N, accelerations at 1, 5, 6, 1 % noise.
fn record(dir: &Path, rms: f64) {
    let model = Model::from_file(Path::new(&data("lanl8dof-contact.toml"))).unwrap();
    let spec = RecordSpec {
        input: InputSpec::Random {
            band: (5.0, 200.0),
            rms,
        },
        sensors: vec![1, 5, 6],
        noise: 0.01,
        seed: 11,
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    let rec = simulate_record(&model, &spec).unwrap().0;
    tacit::record::write(&rec, &dir.join(format!("bumper-{rms}N.h5"))).unwrap();
}

#[test]
fn three_levels_are_diagnosed_and_share_one_contact() {
    let d = tempfile::tempdir().unwrap();
    for rms in [10.0, 20.0, 40.0] {
        record(d.path(), rms);
    }
    let manifest = d.path().join("campaign.toml");
    let mut text_m = format!(
        "model = \"{}\"\nsensors = [1, 5, 6]\n",
        data("lanl8dof.toml")
    );
    for (rms, name) in [(10, "low"), (20, "mid"), (40, "high")] {
        text_m.push_str(&format!(
            "\n[[record]]\npath = \"bumper-{rms}N.h5\"\nname = \"{name}\"\ngroup = \"{rms} N\"\n"
        ));
    }
    std::fs::write(&manifest, text_m).unwrap();
    let out = d.path().join("out");
    let args = [
        "campaign",
        manifest.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    let o = tacit(&args);
    assert!(o.status.success(), "{}", text(&o));
    // piped: no progress bar on stderr
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("records"),
        "{}",
        text(&o)
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("campaign.json")).unwrap()).unwrap();
    let rows = s["records"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    for r in rows {
        assert_eq!(r["effects"][0], "contact 5→6", "{r}");
        assert!(r["error_after"].as_f64().unwrap() < 0.05, "{r}");
    }
    assert_eq!(rows[2]["group"], "40 N");
    let gap = &s["spreads"][0];
    assert_eq!(gap["key"], "contact 5→6 gap");
    assert_eq!(gap["records"], 3);
    // the shared contact: the simulated 0.381 mm and 2e6 N/m
    let j = &s["joint"];
    assert_eq!(j["effect"], "contact 5→6", "{j}");
    let g = j["parameters"][0]["value"].as_f64().unwrap();
    let k = j["parameters"][1]["value"].as_f64().unwrap();
    assert!((g / 0.381e-3 - 1.0).abs() < 0.01, "shared gap {g}");
    assert!((k / 2e6 - 1.0).abs() < 0.05, "shared stiffness {k}");
    // one parameter set explains every level about as well as its own fit
    for r in j["records"].as_array().unwrap() {
        let (own, joint) = (r["own"].as_f64().unwrap(), r["joint"].as_f64().unwrap());
        assert!(joint < 0.03 && joint < 1.5 * own, "{r}");
    }
    let md = std::fs::read_to_string(out.join("campaign.md")).unwrap();
    assert!(md.contains("| mid | 20 N | contact 5→6 |"), "{md}");
    assert!(out.join("model-joint.toml").exists());
    let csv = std::fs::read_to_string(out.join("campaign.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 * 2, "{csv}");
    // resumed: the reports are kept, not rewritten
    let report = out.join("records/low/report.json");
    let before = std::fs::metadata(&report).unwrap().modified().unwrap();
    let mut again = args.to_vec();
    again.push("--no-joint");
    let o = tacit(&again);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("3 record(s) already diagnosed"),
        "{}",
        text(&o)
    );
    assert_eq!(
        std::fs::metadata(&report).unwrap().modified().unwrap(),
        before
    );
}

#[test]
fn bad_manifests_and_outputs_are_refused_naming_the_fault() {
    let d = tempfile::tempdir().unwrap();
    let m = d.path().join("c.toml");
    let out = d.path().join("out");
    let run = |body: &str| {
        std::fs::write(&m, body).unwrap();
        tacit(&["campaign", m.to_str().unwrap(), "-o", out.to_str().unwrap()])
    };
    let model = data("lanl8dof.toml");
    let o = run(&format!("model = \"{model}\"\n[[record]]\npath = \"a.h5\"\nname = \"x\"\n[[record]]\npath = \"b.h5\"\nname = \"x\"\n"));
    assert!(!o.status.success());
    assert!(text(&o).contains("\"x\" is used twice"), "{}", text(&o));
    let o = run(&format!(
        "model = \"{model}\"\n[[record]]\npath = \"a.h5\"\nname = \"../x\"\n"
    ));
    assert!(text(&o).contains("record[0].name"), "{}", text(&o));
    let o = run(&format!("model = \"{model}\"\nrecords = 3\n"));
    assert!(!o.status.success());
    assert!(text(&o).contains("records"), "{}", text(&o));
    // a directory of something else is not a campaign's output
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let o = run(&format!(
        "model = \"{model}\"\n[[record]]\npath = \"{}\"\n",
        data("lanl8dof-bumper.h5")
    ));
    assert!(text(&o).contains("not a campaign's output"), "{}", text(&o));
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
}

/// The record checks against the model run in a campaign as in
/// `tacit diagnose`: accelerations in g are a warning in the record's
/// report; a dead channel that is used fails that record, by name.
#[test]
fn record_checks_against_the_model_run_in_a_campaign() {
    let d = tempfile::tempdir().unwrap();
    let mut rec = tacit::record::read(Path::new(&data("lanl8dof-bumper.h5"))).unwrap();
    rec = rec.slice(0, 2048).unwrap();
    let mut g = rec.clone();
    for c in &mut g.outputs {
        c.data.iter_mut().for_each(|x| *x /= 9.80665);
    }
    tacit::record::write(&g, &d.path().join("g.h5")).unwrap();
    let dead = rec.outputs.iter_mut().find(|c| c.dof == 6).unwrap();
    dead.data.fill(0.0);
    tacit::record::write(&rec, &d.path().join("dead.h5")).unwrap();
    let manifest = d.path().join("c.toml");
    let body = format!(
        "model = \"{}\"\ntrust_linear = true\n[joint]\noff = true\n\n[[record]]\npath = \"g.h5\"\n\n[[record]]\npath = \"dead.h5\"\n",
        data("lanl8dof.toml")
    );
    std::fs::write(&manifest, body).unwrap();
    let out = d.path().join("out");
    let o = tacit(&[
        "campaign",
        manifest.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("record dead: record ")
            && text(&o).contains("dead.h5: cannot be used as it is: channel accel_6 is dead"),
        "{}",
        text(&o)
    );
    let report = out.join("records/g/report.json");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    let w: Vec<&str> = json["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|w| w.as_str())
        .collect();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("g.h5: the measured responses") && w[0].contains("look like they are in g"),
        "{w:?}"
    );
}
