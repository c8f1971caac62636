//! Shared by the diagnosis tables `close_the_loop_matrix` and
//! `imperfect_matrix`: the declared model and the table's cells.

use tacit::diagnose::EffectReport;
use tacit::model::Model;

/// The declared model, `data/lanl8dof.toml`.
pub fn lanl() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    Model::from_file(std::path::Path::new(p)).unwrap()
}

/// The effects found, with their parameters: `kind [dofs]: name value, ...; ...`.
pub fn effects_cell(effects: &[EffectReport]) -> String {
    let params: Vec<String> = effects
        .iter()
        .map(|e| {
            let p: Vec<String> = e
                .parameters
                .iter()
                .map(|(k, v)| match e.std_errors.get(k).copied().flatten() {
                    Some(se) => format!("{k} {v:.4e} ± {se:.1e}"),
                    None => format!("{k} {v:.4e}"),
                })
                .collect();
            format!("{} {:?}: {}", e.kind.name(), e.dofs, p.join(", "))
        })
        .collect();
    params.join("; ")
}

/// The sensor set: `1–8` (all eight masses) or the list (`1, 5, 6`).
pub fn sensors_cell(sensors: &[usize]) -> String {
    if sensors.len() == 8 {
        "1–8".into()
    } else {
        let s: Vec<String> = sensors.iter().map(|d| d.to_string()).collect();
        s.join(", ")
    }
}
