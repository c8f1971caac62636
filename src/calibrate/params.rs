//! The numbers of a model's linear part that a calibration may correct.
//!
//! Every parameter is moved on a logarithmic scale, `p = p_0 e^{q}`, so a
//! stiffness, a mass or a damping ratio stays positive and `q` is the
//! relative change to first order.

use crate::error::Result;
use crate::model::{Damping, Model};
use serde::{Deserialize, Serialize};

/// One number of the linear part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "index", rename_all = "snake_case")]
pub enum LinearParam {
    /// Stiffness of `model.springs[i]` (0-based), N/m.
    Spring(usize),
    /// Mass of DOF `i` (0-based), kg.
    Mass(usize),
    /// Modal damping ratio of flexible mode `r` (0-based, ascending
    /// frequency), dimensionless.
    ModalRatio(usize),
    /// Rayleigh mass-proportional coefficient α, 1/s.
    RayleighAlpha,
    /// Rayleigh stiffness-proportional coefficient β, s.
    RayleighBeta,
    /// The one modal damping ratio of every flexible mode, dimensionless.
    DampingRatio,
    /// Multiplier of the whole stiffness of a model from matrices (as a
    /// Young's modulus scales it), dimensionless.
    StiffnessScale,
    /// Multiplier of the whole mass of a model from matrices (as a density
    /// scales it), dimensionless.
    MassScale,
}

impl LinearParam {
    /// A name for reports: `k5` (the spring's label), `m3`, `zeta2`,
    /// `alpha`, `beta` (indices from 1), `stiffness_scale`, `mass_scale`.
    pub fn label(&self, model: &Model) -> String {
        match *self {
            LinearParam::Spring(i) => model.springs[i].label(i),
            LinearParam::Mass(i) => format!("m{}", i + 1),
            LinearParam::ModalRatio(r) => format!("zeta{}", r + 1),
            LinearParam::RayleighAlpha => "alpha".into(),
            LinearParam::RayleighBeta => "beta".into(),
            LinearParam::DampingRatio => "zeta".into(),
            LinearParam::StiffnessScale => "stiffness_scale".into(),
            LinearParam::MassScale => "mass_scale".into(),
        }
    }

    /// Unit of the parameter.
    pub fn unit(&self) -> &'static str {
        match self {
            LinearParam::Spring(_) => "N/m",
            LinearParam::Mass(_) => "kg",
            LinearParam::ModalRatio(_) | LinearParam::DampingRatio => "",
            LinearParam::RayleighAlpha => "1/s",
            LinearParam::RayleighBeta => "s",
            LinearParam::StiffnessScale | LinearParam::MassScale => "",
        }
    }

    /// The same number as a target of the time-domain updating.
    pub fn target(&self) -> crate::update::Target {
        use crate::update::Target;
        match *self {
            LinearParam::Spring(i) => Target::SpringStiffness(i),
            LinearParam::Mass(i) => Target::Mass(i),
            LinearParam::ModalRatio(r) => Target::ModalRatio(r),
            LinearParam::RayleighAlpha => Target::RayleighAlpha,
            LinearParam::RayleighBeta => Target::RayleighBeta,
            LinearParam::DampingRatio => Target::DampingRatio,
            LinearParam::StiffnessScale => Target::StiffnessScale,
            LinearParam::MassScale => Target::MassScale,
        }
    }

    /// Value in `model` (damping ratios after [`per_mode`]); an error
    /// when the model has no such number.
    pub fn get(&self, model: &Model) -> Result<f64> {
        self.target().get(model)
    }

    /// Set the value in `model` (which must have been through [`per_mode`]).
    pub fn set(&self, model: &mut Model, value: f64) {
        self.target().set(model, value)
    }
}

/// Number of flexible modes of the model's linear part.
pub fn flexible_modes(model: &Model) -> Result<usize> {
    Ok(crate::model::flexible_frequencies(model)?.len())
}

/// The model with modal damping written as one ratio per flexible mode
/// (`ratio = z` becomes `ratios = [z; modes]`), so that each can be
/// corrected on its own; other damping kinds, and a model from matrices
/// calibrated by scales ([`Freedom`]: its one declared ratio is corrected
/// as one number), are returned as they are.
pub fn per_mode(model: &Model) -> Result<Model> {
    let mut m = model.clone();
    if model.calibrated_by_scales() {
        return Ok(m);
    }
    if let Damping::Modal { ratio, ratios } = &model.damping {
        let nf = flexible_modes(model)?;
        let all = (0..nf)
            .map(|r| {
                ratio
                    .or_else(|| crate::model::modal_ratio_index(r, ratios.len()).map(|i| ratios[i]))
                    .unwrap_or(0.0)
            })
            .collect();
        m.damping = Damping::Modal {
            ratio: None,
            ratios: all,
        };
    }
    Ok(m)
}

/// What a calibration may correct (also the `[free]` table of a model
/// file, where a missing key takes its default). On a model from matrices (unless its
/// stiffness is all in point-to-point springs: a lumped model written as
/// matrices) the springs are the couplings a reduction left between the
/// kept points, not numbers of the structure: `springs` opens the scale of
/// the whole stiffness instead, `masses` the scale of the whole mass, and
/// `damping` the declared damping's own numbers (one modal ratio for every
/// mode when one is declared; a ratio per mode can absorb a local effect
/// on the mode it drives).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Freedom {
    /// Every spring's stiffness (default true).
    pub springs: bool,
    /// The damping: every modal ratio, or both Rayleigh coefficients
    /// (default true; a model without damping is given none).
    pub damping: bool,
    /// Every mass (default false: with one force gauge and accelerations
    /// the masses and stiffnesses are only fixed together through the
    /// driving point, and the declared masses are usually weighed).
    pub masses: bool,
}

impl Default for Freedom {
    fn default() -> Self {
        Freedom {
            springs: true,
            damping: true,
            masses: false,
        }
    }
}

/// The parameters `freedom` opens on `model` (after [`per_mode`]).
pub fn select(model: &Model, freedom: &Freedom) -> Vec<LinearParam> {
    let mut out = vec![];
    let scales = model.calibrated_by_scales();
    if freedom.springs && scales {
        out.push(LinearParam::StiffnessScale);
    } else if freedom.springs {
        out.extend((0..model.springs.len()).map(LinearParam::Spring));
    }
    if freedom.masses && scales {
        out.push(LinearParam::MassScale);
    } else if freedom.masses {
        out.extend((0..model.ndof()).map(LinearParam::Mass));
    }
    if freedom.damping {
        match &model.damping {
            Damping::Modal { ratio: Some(_), .. } => out.push(LinearParam::DampingRatio),
            Damping::Modal { ratios, .. } => {
                out.extend((0..ratios.len()).map(LinearParam::ModalRatio));
            }
            Damping::Rayleigh { alpha, beta } => {
                if *alpha > 0.0 {
                    out.push(LinearParam::RayleighAlpha);
                }
                if *beta > 0.0 {
                    out.push(LinearParam::RayleighBeta);
                }
            }
            Damping::None => {}
        }
    }
    out
}

/// `model` with every parameter at `p_0 e^{q}` (a damping ratio at most
/// its ceiling, as [`crate::update::Target::set`] keeps it: the log parameter is
/// unbounded above).
pub fn apply(model: &Model, params: &[LinearParam], p0: &[f64], q: &[f64]) -> Model {
    let mut m = model.clone();
    for ((p, v0), qi) in params.iter().zip(p0).zip(q) {
        p.set(&mut m, v0 * qi.exp());
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain() -> Model {
        Model::from_toml_str(
            r#"
name = "chain"
masses = [1.0, 1.0, 1.0]
[[spring]]
dofs = [1, 2]
stiffness = 1000.0
[[spring]]
dofs = [2, 3]
stiffness = 2000.0
[damping]
kind = "modal"
ratio = 0.02
"#,
            "chain",
        )
        .unwrap()
    }

    #[test]
    fn modal_damping_is_opened_per_flexible_mode() {
        let m = per_mode(&chain()).unwrap();
        let p = select(&m, &Freedom::default());
        // two springs, two flexible modes (one rigid-body mode)
        assert_eq!(p.len(), 4);
        assert_eq!(p[3], LinearParam::ModalRatio(1));
        let moved = apply(&m, &p, &[1000.0, 2000.0, 0.02, 0.02], &[0.1, 0.0, 0.0, 0.5]);
        assert!((moved.springs[0].stiffness - 1000.0 * 0.1f64.exp()).abs() < 1e-9);
        assert!(
            (LinearParam::ModalRatio(1).get(&moved).unwrap() - 0.02 * 0.5f64.exp()).abs() < 1e-12
        );
        assert!((LinearParam::ModalRatio(0).get(&moved).unwrap() - 0.02).abs() < 1e-15);
    }
}
