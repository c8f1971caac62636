//! The model reader on arbitrary text: an error or a model whose matrices
//! can be built, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(model) = tacit::model::Model::from_toml_str(text, "fuzz") {
        let _ = model.mass_matrix();
        let _ = model.stiffness_matrix();
        let _ = model.damping_matrix();
        let _ = model.to_toml_string();
    }
});
