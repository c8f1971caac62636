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
