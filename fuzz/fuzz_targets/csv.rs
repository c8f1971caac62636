//! The CSV record and truth readers on arbitrary bytes: an error or a
//! valid record, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.csv");
    std::fs::write(&path, data).unwrap();
    if let Ok(rec) = tacit::record::read(&path) {
        rec.validate(None).unwrap();
    }
    let _ = tacit::record::csvio::read_truth(&path);
});
