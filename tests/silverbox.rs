//! End-to-end: the Silverbox benchmark (real measurements, Wigren &
//! Schoukens, ECC 2013, read from the shared data set beside the checkout)
//! through the close-the-loop diagnosis.

use tacit::cases::silverbox::{self, Settings};

#[test]
fn silverbox_loop_finds_the_cubic_and_beats_the_reference_fit() {
    let Some(path) = tacit::record::shared_data("silverbox/SNLS80mV.mat") else {
        return;
    };
    let path = path.as_path();
    let r = silverbox::run(path, &Settings::default(), None).unwrap();
    eprintln!("{}", r.summary());
    // the loop names a cubic spring to ground at the only DOF
    assert_eq!(r.effects.first().map(|e| e.0.as_str()), Some("cubic @1"));
    // hardening, as the circuit is built
    assert!(r.parameters.3 > 0.0);
    // linear: the NumPy output-error fit gets 14.2 mV; with the cubic 0.95 mV
    assert!(
        (r.rms_linear - 14.2e-3).abs() < 0.5e-3,
        "linear {}",
        r.rms_linear
    );
    assert!(r.rms_final <= 0.95e-3, "final {}", r.rms_final);
}

#[test]
fn silverbox_bad_mapping_is_a_clear_error() {
    let Some(path) = tacit::record::shared_data("silverbox/SNLS80mV.mat") else {
        return;
    };
    let path = path.as_path();
    let e = tacit::record::read_mat(
        path,
        &tacit::record::MatMapping {
            channels: vec![tacit::record::MatChannel::at_dof(
                "V9",
                tacit::record::Quantity::Force,
                1,
            )],
            fs: 610.35.into(),
            remove_mean: true,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("V9") && e.contains("V1"), "{e}");
}
