//! The writers: every file is there, the HDF5 layout is as documented, the
//! summary parses, and a failed write leaves nothing behind.

use tacit::identify::{identify, output, IdentifySettings, Problem, Reduce};
use tacit::model::Model;
use tacit::simulate::{simulate_record, RecordSpec};

#[test]
fn write_all_produces_the_documented_files() {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof-contact.toml");
    let model = Model::from_file(p.as_ref()).unwrap();
    let spec = RecordSpec {
        samples: 200,
        sensors: vec![1, 5, 6],
        ..Default::default()
    };
    let (rec, _) = simulate_record(&model, &spec).unwrap();
    let prob = Problem::new(&model.linear_part(), &rec, &[1, 5, 6]).unwrap();
    let est = identify(&prob, &IdentifySettings::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let files = output::write_all(&est, dir.path(), true).unwrap();
    for name in [
        "forces.h5",
        "forces.csv",
        "channels.csv",
        "summary.json",
        "before.png",
        "forces.svg",
        "after.png",
    ] {
        assert!(dir.path().join(name).is_file(), "{name} missing: {files:?}");
    }
    let h5 = hdf5::File::open(dir.path().join("forces.h5")).unwrap();
    let f = h5.dataset("force").unwrap().read_2d::<f64>().unwrap();
    assert_eq!(f.shape(), &[8, 200]);
    let g = h5
        .dataset("generalized/force")
        .unwrap()
        .read_2d::<f64>()
        .unwrap();
    assert_eq!(g.shape(), &[3, 200]);
    let u = h5.dataset("states/u").unwrap().read_2d::<f64>().unwrap();
    assert_eq!(u.shape(), &[8, 200]);
    let m = h5
        .dataset("channels/measured")
        .unwrap()
        .read_2d::<f64>()
        .unwrap();
    assert_eq!(m.shape(), &[3, 200]);
    assert!(h5.dataset("truth/fint").is_ok());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["method"], "mhe");
    assert!(summary["diagnostics"]["spectral_radius"].as_f64().unwrap() < 1.0);
    assert!(
        summary["diagnostics"]["identifiability"]["window"]["rank"]
            .as_u64()
            .unwrap()
            <= 3
    );
    let csv = std::fs::read_to_string(dir.path().join("forces.csv")).unwrap();
    assert!(csv.starts_with("time,f_1,"), "{}", &csv[..40]);
    assert_eq!(csv.lines().count(), 201);
    // a directory that cannot be created: an error, no partial files
    let bad = dir.path().join("forces.csv").join("sub");
    assert!(output::write_all(&est, &bad, false).is_err());
    // the full-order estimate carries no generalized force
    let s = IdentifySettings {
        reduce: Reduce::None,
        ..Default::default()
    };
    let est = identify(&prob, &s).unwrap();
    assert!(est.generalized.is_none());
    assert_eq!(est.states.a.shape(), (8, 200));
}
