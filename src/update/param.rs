//! Parameters of a model that an update may change.
//!
//! A [`Parameter`] names one number of a [`Model`] (a spring stiffness, a
//! mass, the modal damping ratio, a contact gap, …), its nominal value `p0`,
//! its bounds and its scaling. The optimizers work on dimensionless
//! variables
//!
//! $$ x_i = (p_i - p_{0,i}) / s_i $$
//!
//! with `s_i = |p_{0,i}|` for [`Scaling::Relative`] (so `x_i` is the
//! fractional change, the paper's percentage / 100) and a typical size given
//! by the caller for [`Scaling::Absolute`] (for parameters whose nominal
//! value may be zero, e.g. a cubic coefficient not yet in the model).

use crate::error::{Result, TacitError};
use crate::model::{Damping, Model};
use serde::Serialize;

/// Which number of the model a parameter is. Indices are 0-based positions
/// in the model's lists (`model.springs`, `model.masses`, …).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", content = "index", rename_all = "snake_case")]
pub enum Target {
    /// Stiffness of `model.springs[i]`, N/m.
    SpringStiffness(usize),
    /// Mass of DOF `i` (0-based), kg.
    Mass(usize),
    /// The modal damping ratio (`damping.kind = "modal"`), dimensionless:
    /// the single `ratio`, or with one ratio per mode their mean, every
    /// ratio moved in proportion.
    DampingRatio,
    /// The damping ratio of flexible mode `r` (0-based, ascending
    /// frequency) of a model with one ratio per mode, dimensionless.
    ModalRatio(usize),
    /// Rayleigh mass-proportional coefficient α, 1/s.
    RayleighAlpha,
    /// Rayleigh stiffness-proportional coefficient β, s.
    RayleighBeta,
    /// Gap of `model.contacts[i]`, m.
    ContactGap(usize),
    /// Penalty stiffness of `model.contacts[i]`, N/m.
    ContactStiffness(usize),
    /// Force level of `model.frictions[i]`, N.
    FrictionLevel(usize),
    /// Coefficient of `model.cubics[i]`, N/m³.
    CubicK3(usize),
    /// Coefficient of `model.quadratics[i]`, N/m².
    QuadraticK2(usize),
    /// Coefficient of `model.quadratic_dampers[i]`, N s²/m².
    DamperC2(usize),
    /// Coefficient of `model.cubic_dampers[i]`, N s³/m³.
    DamperC3(usize),
    /// Gap of `model.clearances[i]`, m.
    ClearanceGap(usize),
    /// Penalty stiffness of `model.clearances[i]`, N/m.
    ClearanceStiffness(usize),
    /// Force level of `model.relative_frictions[i]`, N.
    RelativeFrictionLevel(usize),
    /// Multiplier of the stiffness of a model from matrices (the whole
    /// stiffness read from the matrices, as a Young's modulus scales it;
    /// 1 as read), dimensionless.
    StiffnessScale,
    /// Multiplier of the mass of a model from matrices (as a density
    /// scales it; 1 as read), dimensionless.
    MassScale,
}

/// The mean of per-mode damping ratios: the value of
/// [`Target::DampingRatio`] on a model with one ratio per mode.
pub(super) fn mean_ratio(ratios: &[f64]) -> f64 {
    ratios.iter().sum::<f64>() / ratios.len() as f64
}

impl Target {
    /// Value of this target in `model`; an error names the missing entry.
    pub fn get(&self, model: &Model) -> Result<f64> {
        let missing = |what: &str, i: usize, n: usize| {
            TacitError::Setting(format!(
                "parameter {what}[{i}]: the model has {n} {what} entries"
            ))
        };
        Ok(match *self {
            Target::SpringStiffness(i) => {
                model
                    .springs
                    .get(i)
                    .ok_or_else(|| missing("spring", i, model.springs.len()))?
                    .stiffness
            }
            Target::Mass(i) => *model
                .masses
                .get(i)
                .ok_or_else(|| missing("masses", i, model.masses.len()))?,
            Target::DampingRatio => match &model.damping {
                Damping::Modal { ratio: Some(z), .. } => *z,
                Damping::Modal {
                    ratio: None,
                    ratios,
                } if !ratios.is_empty() => mean_ratio(ratios),
                _ => {
                    return Err(TacitError::Setting(
                        "parameter zeta: the model's damping is not modal".into(),
                    ))
                }
            },
            Target::ModalRatio(r) => match &model.damping {
                Damping::Modal {
                    ratio: None,
                    ratios,
                } if r < ratios.len() => ratios[r],
                _ => return Err(missing("damping.ratios", r, 0)),
            },
            Target::RayleighAlpha | Target::RayleighBeta => match (&model.damping, self) {
                (Damping::Rayleigh { alpha, .. }, Target::RayleighAlpha) => *alpha,
                (Damping::Rayleigh { beta, .. }, _) => *beta,
                _ => {
                    return Err(TacitError::Setting(
                        "parameter alpha/beta: the model's damping is not Rayleigh".into(),
                    ))
                }
            },
            Target::ContactGap(i) => {
                model
                    .contacts
                    .get(i)
                    .ok_or_else(|| missing("contact", i, model.contacts.len()))?
                    .gap
            }
            Target::ContactStiffness(i) => {
                model
                    .contacts
                    .get(i)
                    .ok_or_else(|| missing("contact", i, model.contacts.len()))?
                    .stiffness
            }
            Target::FrictionLevel(i) => {
                model
                    .frictions
                    .get(i)
                    .ok_or_else(|| missing("friction", i, model.frictions.len()))?
                    .level
            }
            Target::CubicK3(i) => {
                model
                    .cubics
                    .get(i)
                    .ok_or_else(|| missing("cubic", i, model.cubics.len()))?
                    .k3
            }
            Target::StiffnessScale | Target::MassScale => model
                .matrix_scale(*self == Target::StiffnessScale)
                .ok_or_else(|| {
                    TacitError::Setting(format!(
                        "parameter {}: the model is not given by matrices",
                        self.default_name(model)
                    ))
                })?,
            _ => return self.get_added(model),
        })
    }

    /// [`Target::get`] for the quadratic springs, nonlinear dampers,
    /// clearances and friction between DOFs.
    fn get_added(&self, model: &Model) -> Result<f64> {
        fn at<'a, T>(list: &'a [T], what: &str, i: usize) -> Result<&'a T> {
            list.get(i).ok_or_else(|| {
                TacitError::Setting(format!(
                    "parameter {what}[{i}]: the model has {} {what} entries",
                    list.len()
                ))
            })
        }
        Ok(match *self {
            Target::QuadraticK2(i) => at(&model.quadratics, "quadratic", i)?.k2,
            Target::DamperC2(i) => at(&model.quadratic_dampers, "quadratic_damper", i)?.c2,
            Target::DamperC3(i) => at(&model.cubic_dampers, "cubic_damper", i)?.c3,
            Target::ClearanceGap(i) => at(&model.clearances, "clearance", i)?.gap,
            Target::ClearanceStiffness(i) => at(&model.clearances, "clearance", i)?.stiffness,
            Target::RelativeFrictionLevel(i) => {
                at(&model.relative_frictions, "relative_friction", i)?.level
            }
            _ => unreachable!("get_added is called for the added element targets only"),
        })
    }

    /// Write `value` into `model` (the target must exist: checked by
    /// [`Target::get`] when the problem is built).
    pub fn set(&self, model: &mut Model, value: f64) {
        match *self {
            Target::SpringStiffness(i) => model.springs[i].stiffness = value,
            Target::Mass(i) => model.masses[i] = value,
            // every ratio below critical (RATIO_CEILING): a mean within
            // its bounds may scale the largest of several past it
            Target::DampingRatio => match &mut model.damping {
                Damping::Modal { ratio: Some(z), .. } => *z = value.min(RATIO_CEILING),
                Damping::Modal {
                    ratio: None,
                    ratios,
                } if !ratios.is_empty() => {
                    let mean = mean_ratio(ratios);
                    let f = if mean > 0.0 { value / mean } else { 0.0 };
                    ratios.iter_mut().for_each(|z| {
                        *z = if mean > 0.0 { *z * f } else { value }.min(RATIO_CEILING)
                    });
                }
                _ => {}
            },
            Target::ModalRatio(r) => {
                if let Damping::Modal { ratios, .. } = &mut model.damping {
                    if let Some(z) = ratios.get_mut(r) {
                        *z = value.min(RATIO_CEILING);
                    }
                }
            }
            Target::RayleighAlpha => {
                if let Damping::Rayleigh { alpha, .. } = &mut model.damping {
                    *alpha = value;
                }
            }
            Target::RayleighBeta => {
                if let Damping::Rayleigh { beta, .. } = &mut model.damping {
                    *beta = value;
                }
            }
            Target::ContactGap(i) => model.contacts[i].gap = value,
            Target::ContactStiffness(i) => model.contacts[i].stiffness = value,
            Target::FrictionLevel(i) => model.frictions[i].level = value,
            Target::CubicK3(i) => model.cubics[i].k3 = value,
            Target::QuadraticK2(i) => model.quadratics[i].k2 = value,
            Target::DamperC2(i) => model.quadratic_dampers[i].c2 = value,
            Target::DamperC3(i) => model.cubic_dampers[i].c3 = value,
            Target::ClearanceGap(i) => model.clearances[i].gap = value,
            Target::ClearanceStiffness(i) => model.clearances[i].stiffness = value,
            Target::RelativeFrictionLevel(i) => model.relative_frictions[i].level = value,
            Target::StiffnessScale => model.set_matrix_scale(true, value),
            Target::MassScale => model.set_matrix_scale(false, value),
        }
    }

    /// Physical lower limit of the quantity (a stiffness or mass must stay
    /// positive, a gap, level, damper coefficient or damping ratio
    /// non-negative); `None` for a cubic or quadratic spring coefficient,
    /// which may take either sign.
    pub fn physical_floor(&self) -> Option<f64> {
        match self {
            Target::SpringStiffness(_)
            | Target::Mass(_)
            | Target::StiffnessScale
            | Target::MassScale
            | Target::ContactStiffness(_)
            | Target::ClearanceStiffness(_) => Some(0.0),
            Target::DampingRatio
            | Target::ModalRatio(_)
            | Target::RayleighAlpha
            | Target::RayleighBeta
            | Target::ContactGap(_)
            | Target::FrictionLevel(_)
            | Target::ClearanceGap(_)
            | Target::RelativeFrictionLevel(_)
            | Target::DamperC2(_)
            | Target::DamperC3(_) => Some(0.0),
            Target::CubicK3(_) | Target::QuadraticK2(_) => None,
        }
    }

    /// Physical upper limit of the quantity: a damping ratio stays below
    /// critical damping ([`RATIO_CEILING`]; the model accepts ratios in
    /// [0, 1)); `None` for every other quantity.
    pub fn physical_ceiling(&self) -> Option<f64> {
        match self {
            Target::DampingRatio | Target::ModalRatio(_) => Some(RATIO_CEILING),
            _ => None,
        }
    }

    /// True when the value must be strictly positive.
    fn strictly_positive(&self) -> bool {
        matches!(
            self,
            Target::SpringStiffness(_)
                | Target::Mass(_)
                | Target::StiffnessScale
                | Target::MassScale
                | Target::ContactStiffness(_)
                | Target::ClearanceStiffness(_)
        )
    }

    /// Default short name: `k3` (or the spring's label), `m2`, `zeta`,
    /// `gap1`, `kc1`, `friction1`, `cubic1`, `quadratic1`, `qdamper1`,
    /// `cdamper1`, `cgap1`, `kcl1`, `rfriction1` (numbers from 1),
    /// `stiffness_scale`, `mass_scale`.
    pub fn default_name(&self, model: &Model) -> String {
        match *self {
            Target::SpringStiffness(i) => model
                .springs
                .get(i)
                .map(|s| s.label(i))
                .unwrap_or_else(|| format!("k{}", i + 1)),
            Target::Mass(i) => format!("m{}", i + 1),
            Target::DampingRatio => "zeta".into(),
            Target::ModalRatio(r) => format!("zeta{}", r + 1),
            Target::RayleighAlpha => "alpha".into(),
            Target::RayleighBeta => "beta".into(),
            Target::ContactGap(i) => format!("gap{}", i + 1),
            Target::ContactStiffness(i) => format!("kc{}", i + 1),
            Target::FrictionLevel(i) => format!("friction{}", i + 1),
            Target::CubicK3(i) => format!("cubic{}", i + 1),
            Target::QuadraticK2(i) => format!("quadratic{}", i + 1),
            Target::DamperC2(i) => format!("qdamper{}", i + 1),
            Target::DamperC3(i) => format!("cdamper{}", i + 1),
            Target::ClearanceGap(i) => format!("cgap{}", i + 1),
            Target::ClearanceStiffness(i) => format!("kcl{}", i + 1),
            Target::RelativeFrictionLevel(i) => format!("rfriction{}", i + 1),
            Target::StiffnessScale => "stiffness_scale".into(),
            Target::MassScale => "mass_scale".into(),
        }
    }
}

/// How a parameter is scaled into the optimizer's variable.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Scaling {
    /// `x = (p − p0) / |p0|`: the fractional change (p0 must be non-zero).
    Relative,
    /// `x = (p − p0) / size`, `size` > 0 in the parameter's unit.
    Absolute {
        /// Typical size of the parameter, in its unit.
        size: f64,
    },
}

/// One free parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Parameter {
    /// What it changes.
    pub target: Target,
    /// Name used in reports and errors.
    pub name: String,
    /// Nominal value p0 (the minimum-change term pulls toward it and
    /// percentages are relative to it), in the parameter's unit.
    pub nominal: f64,
    /// Starting value of the search, in the parameter's unit.
    pub start: f64,
    /// Lower bound, in the parameter's unit.
    pub lower: f64,
    /// Upper bound, in the parameter's unit.
    pub upper: f64,
    /// Scaling of the optimizer's variable.
    pub scaling: Scaling,
}

/// The largest damping ratio a fit may reach ([`Target::physical_ceiling`]).
pub const RATIO_CEILING: f64 = 0.999;

/// Default relative bounds: the parameter may move from −95 % to +900 % of
/// its nominal value (and never below its physical floor).
pub const DEFAULT_RELATIVE_BOUNDS: (f64, f64) = (-0.95, 9.0);

impl Parameter {
    /// A parameter at the model's current value with relative scaling and
    /// the default bounds ([`DEFAULT_RELATIVE_BOUNDS`]); the error names the
    /// target when the model lacks it or its value is zero.
    pub fn relative(model: &Model, target: Target) -> Result<Parameter> {
        let p0 = target.get(model)?;
        let name = target.default_name(model);
        if p0 == 0.0 || !p0.is_finite() {
            return Err(TacitError::Setting(format!(
                "parameter {name}: nominal value {p0} cannot be scaled relatively; use Scaling::Absolute"
            )));
        }
        let (lo, hi) = DEFAULT_RELATIVE_BOUNDS;
        let (a, b) = (p0 + lo * p0.abs(), p0 + hi * p0.abs());
        let mut lower = a.min(b);
        if let Some(f) = target.physical_floor() {
            lower = lower.max(f);
        }
        let upper = target
            .physical_ceiling()
            .map_or(a.max(b), |c| a.max(b).min(c));
        Ok(Parameter {
            target,
            name,
            nominal: p0,
            start: p0,
            lower,
            upper,
            scaling: Scaling::Relative,
        })
    }

    /// A parameter with absolute scaling of typical `size`, nominal value
    /// from the model and bounds `[lower, upper]`.
    pub fn absolute(
        model: &Model,
        target: Target,
        size: f64,
        lower: f64,
        upper: f64,
    ) -> Result<Parameter> {
        let p0 = target.get(model)?;
        Ok(Parameter {
            target,
            name: target.default_name(model),
            nominal: p0,
            start: p0,
            lower,
            upper,
            scaling: Scaling::Absolute { size },
        })
    }

    /// The same parameter with relative bounds `[p0 (1 + lo), p0 (1 + hi)]`
    /// (e.g. `(-0.5, 0.5)` for ±50 %), clipped at the physical floor.
    pub fn with_relative_bounds(mut self, lo: f64, hi: f64) -> Parameter {
        let p0 = self.nominal;
        let (a, b) = (p0 + lo * p0.abs(), p0 + hi * p0.abs());
        self.lower = a.min(b);
        self.upper = a.max(b);
        if let Some(f) = self.target.physical_floor() {
            self.lower = self.lower.max(f);
        }
        if let Some(c) = self.target.physical_ceiling() {
            self.upper = self.upper.min(c);
        }
        self
    }

    /// The same parameter started at `value` (parameter's unit).
    pub fn with_start(mut self, value: f64) -> Parameter {
        self.start = value;
        self
    }

    /// The same parameter started at `p0 (1 + change)`.
    pub fn with_relative_start(mut self, change: f64) -> Parameter {
        self.start = self.nominal + change * self.nominal.abs();
        self
    }

    /// Scale `s` of the optimizer's variable.
    pub fn scale(&self) -> f64 {
        match self.scaling {
            Scaling::Relative => self.nominal.abs(),
            Scaling::Absolute { size } => size,
        }
    }

    /// Optimizer variable of a value.
    pub fn to_x(&self, value: f64) -> f64 {
        (value - self.nominal) / self.scale()
    }

    /// Value of an optimizer variable.
    pub fn from_x(&self, x: f64) -> f64 {
        self.nominal + x * self.scale()
    }

    /// Change from nominal in percent (NaN when the nominal value is 0).
    pub fn percent(&self, value: f64) -> f64 {
        if self.nominal == 0.0 {
            f64::NAN
        } else {
            100.0 * (value - self.nominal) / self.nominal.abs()
        }
    }

    /// Check the parameter against the model: the target exists, scale,
    /// bounds and start are finite and consistent, and the bounds respect
    /// the physical floor (a stiffness or mass > 0, a gap ≥ 0, …). Errors
    /// name the parameter.
    pub fn validate(&self, model: &Model) -> Result<()> {
        let name = &self.name;
        let err = |m: String| Err(TacitError::Setting(format!("parameter {name}: {m}")));
        self.target.get(model)?;
        let s = self.scale();
        if !(s.is_finite() && s > 0.0) {
            return err(format!("scale {s} must be finite and > 0"));
        }
        for (what, v) in [
            ("nominal", self.nominal),
            ("start", self.start),
            ("lower bound", self.lower),
            ("upper bound", self.upper),
        ] {
            if !v.is_finite() {
                return err(format!("{what} {v} is not finite"));
            }
        }
        if self.lower >= self.upper {
            return err(format!(
                "lower bound {} must be below the upper bound {}",
                self.lower, self.upper
            ));
        }
        if let Some(f) = self.target.physical_floor() {
            let bad = if self.target.strictly_positive() {
                self.lower < f || self.nominal <= f
            } else {
                self.lower < f || self.nominal < f
            };
            if bad {
                let rule = if self.target.strictly_positive() {
                    "> 0"
                } else {
                    ">= 0"
                };
                return err(format!(
                    "nominal {} / lower bound {}: the value must stay {rule}",
                    self.nominal, self.lower
                ));
            }
        }
        if let Some(c) = self.target.physical_ceiling() {
            if self.upper > c {
                return err(format!(
                    "upper bound {}: a damping ratio must stay at most {c}",
                    self.upper
                ));
            }
        }
        if !(self.lower..=self.upper).contains(&self.start) {
            return err(format!(
                "start {} is outside the bounds [{}, {}]",
                self.start, self.lower, self.upper
            ));
        }
        Ok(())
    }
}

/// Parse a comma-separated list of parameter names against a model:
///
/// - `k3` (or a spring's own `name`), `k1..k4` (a range of spring labels
///   `k<i>`), `springs` (every spring);
/// - `m2` (mass of DOF 2), `masses`;
/// - `zeta` (the modal damping ratio);
/// - `gap1`, `kc1` (gap and stiffness of contact 1), `friction1`;
/// - `cubic1`, or `cubic` (every cubic element).
///
/// Every parameter gets relative scaling and the default bounds. Unknown
/// names, names absent from the model, duplicates and an empty list are
/// errors naming the offending entry.
pub fn parse_free(spec: &str, model: &Model) -> Result<Vec<Parameter>> {
    let mut targets: Vec<Target> = Vec::new();
    for raw in spec.split(',').map(str::trim) {
        if raw.is_empty() {
            continue;
        }
        for t in parse_one(raw, model)? {
            if targets.contains(&t) {
                return Err(TacitError::Setting(format!(
                    "free parameters: '{raw}' repeats {}",
                    t.default_name(model)
                )));
            }
            targets.push(t);
        }
    }
    if targets.is_empty() {
        return Err(TacitError::Setting(
            "free parameters: the list is empty (e.g. --free k1..k4,cubic)".into(),
        ));
    }
    targets
        .into_iter()
        .map(|t| Parameter::relative(model, t))
        .collect()
}

/// (name prefix, number of entries, target constructor, entries' noun).
type Numbered = (&'static str, usize, fn(usize) -> Target, &'static str);

fn parse_one(raw: &str, model: &Model) -> Result<Vec<Target>> {
    let unknown = |why: String| TacitError::Setting(format!("free parameter '{raw}': {why}"));
    let lower = raw.to_ascii_lowercase();
    if let Some((a, b)) = lower.split_once("..") {
        let (ia, ib) = (spring_index(a, model), spring_index(b, model));
        return match (ia, ib) {
            (Some(a), Some(b)) if a <= b => Ok((a..=b).map(Target::SpringStiffness).collect()),
            _ => Err(unknown(format!(
                "a range needs two spring names in order, e.g. k1..k4 (the model has {} springs)",
                model.springs.len()
            ))),
        };
    }
    match lower.as_str() {
        "springs" => {
            return Ok((0..model.springs.len())
                .map(Target::SpringStiffness)
                .collect())
        }
        "masses" => return Ok((0..model.ndof()).map(Target::Mass).collect()),
        "zeta" | "damping" => return Ok(vec![Target::DampingRatio]),
        "stiffness_scale" | "mass_scale"
            if !model.matrices.as_ref().is_some_and(|l| l.by_scales) =>
        {
            return Err(unknown(format!(
                "only a model from matrices has a {lower} (model {} is not one)",
                model.name
            )))
        }
        "stiffness_scale" => return Ok(vec![Target::StiffnessScale]),
        "mass_scale" => return Ok(vec![Target::MassScale]),
        "cubic" | "cubics" => {
            if model.cubics.is_empty() {
                return Err(unknown("the model has no cubic element".into()));
            }
            return Ok((0..model.cubics.len()).map(Target::CubicK3).collect());
        }
        _ => {}
    }
    if let Some(i) = spring_index(&lower, model) {
        return Ok(vec![Target::SpringStiffness(i)]);
    }
    let numbered = |prefix: &str| -> Option<usize> {
        lower
            .strip_prefix(prefix)
            .and_then(|s| s.parse::<usize>().ok())
            .filter(|&i| i >= 1)
            .map(|i| i - 1)
    };
    let checks: [Numbered; 8] = [
        ("m", model.ndof(), Target::Mass, "DOFs"),
        ("gap", model.contacts.len(), Target::ContactGap, "contacts"),
        (
            "kc",
            model.contacts.len(),
            Target::ContactStiffness,
            "contacts",
        ),
        (
            "friction",
            model.frictions.len(),
            Target::FrictionLevel,
            "friction elements",
        ),
        (
            "cubic",
            model.cubics.len(),
            Target::CubicK3,
            "cubic elements",
        ),
        (
            "cgap",
            model.clearances.len(),
            Target::ClearanceGap,
            "clearances",
        ),
        (
            "kcl",
            model.clearances.len(),
            Target::ClearanceStiffness,
            "clearances",
        ),
        (
            "rfriction",
            model.relative_frictions.len(),
            Target::RelativeFrictionLevel,
            "relative friction elements",
        ),
    ];
    for (prefix, count, make, what) in checks {
        if let Some(i) = numbered(prefix) {
            if i >= count {
                return Err(unknown(format!("the model has {count} {what}")));
            }
            return Ok(vec![make(i)]);
        }
    }
    let labels: Vec<String> = model
        .springs
        .iter()
        .enumerate()
        .map(|(i, s)| s.label(i))
        .collect();
    Err(unknown(format!(
        "not a parameter name; use a spring label ({}), a range k1..k4, m<i>, zeta, gap<i>, kc<i>, friction<i>, cubic<i>, cubic, cgap<i>, kcl<i>, rfriction<i>, stiffness_scale or mass_scale",
        labels.join(", ")
    )))
}

/// Index of a spring from its label (`name` or `k<i>`), case-insensitive.
fn spring_index(label: &str, model: &Model) -> Option<usize> {
    model
        .springs
        .iter()
        .enumerate()
        .position(|(i, s)| s.label(i).eq_ignore_ascii_case(label))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain() -> Model {
        Model::from_toml_str(
            r#"
masses = [1.0, 1.0]
[[spring]]
dofs = [1]
stiffness = 100.0
[[spring]]
dofs = [1, 2]
stiffness = 50.0
[[cubic]]
dofs = [2]
k3 = 1e6
"#,
            "t",
        )
        .unwrap()
    }

    #[test]
    fn parses_names_and_ranges() {
        let m = chain();
        let p = parse_free("k1..k2,cubic", &m).unwrap();
        let names: Vec<_> = p.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["k1", "k2", "cubic1"]);
        assert!(parse_free("k3", &m)
            .unwrap_err()
            .to_string()
            .contains("'k3'"));
        assert!(parse_free("k1,k1", &m)
            .unwrap_err()
            .to_string()
            .contains("repeats"));
        assert!(parse_free(" , ", &m)
            .unwrap_err()
            .to_string()
            .contains("empty"));
        assert!(parse_free("gap1", &m)
            .unwrap_err()
            .to_string()
            .contains("0 contacts"));
        assert!(parse_free("zeta", &m).is_err());
    }

    #[test]
    fn a_damping_ratio_stays_below_critical() {
        let mut m = chain();
        m.damping = Damping::Modal {
            ratio: None,
            ratios: vec![0.3, 0.02],
        };
        let p = Parameter::relative(&m, Target::ModalRatio(0)).unwrap();
        approx::assert_relative_eq!(p.lower, 0.015, epsilon = 1e-15);
        assert_eq!(p.upper, RATIO_CEILING);
        let wide = p.clone().with_relative_bounds(-0.99, 20.0);
        assert_eq!(wide.upper, RATIO_CEILING);
        let q = Parameter::relative(&m, Target::ModalRatio(1)).unwrap();
        approx::assert_relative_eq!(q.upper, 0.2);
        // a mean within its bounds scales the largest ratio no further
        // than critical
        let mut all = m.clone();
        Target::DampingRatio.set(&mut all, 0.6);
        let Damping::Modal { ratios, .. } = &all.damping else {
            panic!("modal")
        };
        assert_eq!(ratios[0], RATIO_CEILING);
        approx::assert_relative_eq!(ratios[1], 0.02 * 0.6 / 0.16, epsilon = 1e-15);
        let mut over = p;
        over.upper = 1.5;
        assert!(over
            .validate(&m)
            .unwrap_err()
            .to_string()
            .contains("at most 0.999"));
    }

    #[test]
    fn scaling_round_trip() {
        let m = chain();
        let p = Parameter::relative(&m, Target::SpringStiffness(0)).unwrap();
        approx::assert_relative_eq!(p.from_x(-0.15), 85.0);
        approx::assert_relative_eq!(p.to_x(125.0), 0.25);
        approx::assert_relative_eq!(p.percent(85.0), -15.0);
        assert_eq!(p.lower, 5.0);
    }
}
