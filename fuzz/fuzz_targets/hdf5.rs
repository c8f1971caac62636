//! The HDF5 record reader (layout checks) on arbitrary bytes, and on a
//! valid record with some bytes changed: an error or a valid record, never
//! a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.h5");
    // a valid record from the repository with the input's bytes written
    // over it from an offset the input chooses, so the fuzzer reaches the
    // layout checks and not only the file signature
    let base = include_bytes!("../../data/lanl8dof-bumper-validation.h5");
    let mut bytes = base.to_vec();
    if data.len() >= 4 {
        let at = u32::from_le_bytes([data[0], data[1], data[2], data[3]]) as usize % bytes.len();
        for (i, b) in data[4..].iter().enumerate() {
            if let Some(x) = bytes.get_mut(at + i) {
                *x = *b;
            }
        }
    }
    std::fs::write(&path, &bytes).unwrap();
    if let Ok(rec) = tacit::record::read(&path) {
        rec.validate(None).unwrap();
    }
});
