//! A universal file (datasets 58) written by pyuff
//! (`scripts/uff_fixture.py`: the first 512 samples of the shipped bumper
//! record, force in N as real double, accelerations in g as real single,
//! DOF 6 along −X) read back against the HDF5 record it was made from,
//! through the CLI too.

mod common;

use common::{tacit, text};
use std::path::Path;

fn root(rel: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

#[test]
fn pyuff_file_reads_as_the_hdf5_record() {
    let uff = tacit::record::read(&root("tests/data/bumper-512.uff")).unwrap();
    let h5 = tacit::record::read(&root("data/lanl8dof-bumper.h5")).unwrap();
    assert_eq!(uff.fs, 512.0);
    assert_eq!(uff.len(), 512);
    assert_eq!(uff.inputs.len(), 1);
    let (f, g) = (&uff.inputs[0], &h5.inputs[0]);
    assert_eq!((f.dof, f.unit.as_str()), (1, "N"));
    for (a, b) in f.data.iter().zip(&g.data) {
        assert!((a - b).abs() <= 1e-10 * b.abs().max(1.0), "{a} {b}");
    }
    let dofs: Vec<usize> = uff.outputs.iter().map(|c| c.dof).collect();
    assert_eq!(dofs, vec![1, 5, 6]);
    for c in &uff.outputs {
        // converted from g to m/s²; the −X channel negated back
        assert_eq!(c.unit, "m/s^2");
        let h = h5.output(c.quantity, c.dof).unwrap();
        let scale = h.data[..512].iter().map(|x| x.abs()).fold(0.0, f64::max);
        for (a, b) in c.data.iter().zip(&h.data) {
            assert!((a - b).abs() <= 1e-5 * scale, "{}: {a} {b}", c.name());
        }
    }
}

#[test]
fn identify_reads_a_universal_file() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("id");
    let o = tacit(&[
        "identify",
        "--model",
        "data/lanl8dof.toml",
        "--record",
        "tests/data/bumper-512.uff",
        "--sensors",
        "1,5,6",
        "--no-figures",
        "-o",
        out.to_str().unwrap(),
    ]);
    let text = text(&o);
    assert!(o.status.success(), "{text}");
    assert!(text.contains("force located at pair 5–6"), "{text}");
}

/// A dataset 58 written by hand (`4E20.12`, real double, 1024 Hz) at a
/// node and direction.
fn dataset58(node: i64, dir: i64, force: bool, data: &[f64]) -> String {
    let mut s = String::from("    -1\n    58\nhand\nwritten\n26-Nov-26 05:00:00\nNONE\nNONE\n");
    s += &format!(
        "{:5}{:10}{:5}{:10} {:<10}{:10}{:4} {:<10}{:10}{:4}\n",
        1, 1, 0, 0, "NONE", node, dir, "NONE", 1, 1
    );
    s += &format!(
        "{:10}{:10}{:10}{:13.5E}{:13.5E}{:13.5E}\n",
        4,
        data.len(),
        1,
        0.0,
        1.0 / 1024.0,
        0.0
    );
    let (spec, label, unit) = if force {
        (13, "Force", "N")
    } else {
        (12, "Acceleration", "m/s^2")
    };
    s += &format!(
        "{:10}{:5}{:5}{:5} {:<20} {:<20}\n",
        17, 0, 0, 0, "Time", "s"
    );
    s += &format!(
        "{:10}{:5}{:5}{:5} {:<20} {:<20}\n",
        spec, 1, 0, 0, label, unit
    );
    for _ in 0..2 {
        s += &format!(
            "{:10}{:5}{:5}{:5} {:<20} {:<20}\n",
            0, 0, 0, 0, "NONE", "NONE"
        );
    }
    for chunk in data.chunks(4) {
        for v in chunk {
            s += &format!("{v:20.12E}");
        }
        s += "\n";
    }
    s + "    -1\n"
}

/// A universal file written by hand from the beam with a stop at its tip
/// (a model from Matrix Market matrices with labels `n<node>:uy`): the
/// channels named by node and direction (`n100`, +Y; `n60` written along
/// −Y, its data negated) are the model's points `n100:uy`, `n60:uy`, ...;
/// read as the HDF5 record they came from, and diagnosed by label through
/// the CLI (the stop found at `n100:uy`).
#[test]
fn universal_file_channels_are_the_points_of_a_matrix_model() {
    let d = tempfile::tempdir().unwrap();
    let h5 = d.path().join("beam.h5");
    let o = tacit(&[
        "simulate",
        "--model",
        "data/beam100-stop/model.toml",
        "--points",
        "n20:uy,n40:uy,n60:uy,n80:uy,n100:uy",
        "--input-point",
        "n20:uy",
        "--band",
        "5,200",
        "--rms",
        "5",
        "--fs",
        "1024",
        "--noise",
        "0.01",
        "--substeps",
        "20",
        "--seed",
        "7",
        "-o",
        h5.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rec = tacit::record::read(&h5).unwrap();
    let node = |c: &tacit::record::Channel| -> i64 {
        let p = c.point.as_deref().unwrap();
        p[1..p.find(':').unwrap()].parse().unwrap()
    };
    let mut uff = String::new();
    for c in &rec.inputs {
        uff += &dataset58(node(c), 2, true, &c.data);
    }
    for c in &rec.outputs {
        let dir = if node(c) == 60 { -2 } else { 2 };
        let data: Vec<f64> = c
            .data
            .iter()
            .map(|x| if dir < 0 { -x } else { *x })
            .collect();
        uff += &dataset58(node(c), dir, false, &data);
    }
    let path = d.path().join("beam.uff");
    std::fs::write(&path, uff).unwrap();
    // read: each channel carries its node and its point
    let mut u = tacit::record::read(&path).unwrap();
    assert_eq!(u.fs, 1024.0);
    let points: Vec<&str> = u
        .outputs
        .iter()
        .map(|c| c.point.as_deref().unwrap())
        .collect();
    assert_eq!(points, ["n20:uy", "n40:uy", "n60:uy", "n80:uy", "n100:uy"]);
    assert_eq!(u.inputs[0].point.as_deref(), Some("n20:uy"));
    // resolved against the matrix model as the labelled HDF5 channels are
    let mut h = rec.clone();
    let model = root("data/beam100/model.toml");
    let m = tacit::model::Model::load(&model, &mut [&mut u, &mut h]).unwrap();
    assert_eq!(m.points.len(), 5, "{:?}", m.points);
    for (a, b) in u.outputs.iter().zip(&h.outputs) {
        assert_eq!((a.name(), a.dof), (b.name(), b.dof));
        assert!(a.dof >= 1, "{}", a.name());
        for (x, y) in a.data.iter().zip(&b.data) {
            assert!(
                (x - y).abs() <= 1e-11 * y.abs().max(1e-3),
                "{}: {x} {y}",
                a.name()
            );
        }
    }
    assert_eq!(u.outputs[2].name(), "accel:n60:uy");
    // the CLI: the stop at the tip found by its label
    let out = d.path().join("diag");
    let o = tacit(&[
        "diagnose",
        "--model",
        model.to_str().unwrap(),
        "--record",
        path.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("**contact @5 (n100:uy)**"), "{md}");
    assert!(md.contains("| accel:n60:uy |"), "{md}");
}
