//! The MATLAB v5 reader on arbitrary bytes with a fixed mapping: an error
//! or a valid record, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tacit::record::{MatChannel, MatMapping, Quantity};

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.mat");
    std::fs::write(&path, data).unwrap();
    let map = MatMapping {
        channels: vec![
            MatChannel::at_dof("V1", Quantity::Force, 1),
            MatChannel::at_dof("V2", Quantity::Disp, 1),
        ],
        fs: 100.0.into(),
        remove_mean: true,
    };
    if let Ok(rec) = tacit::record::read_mat(&path, &map) {
        rec.validate(None).unwrap();
    }
});
