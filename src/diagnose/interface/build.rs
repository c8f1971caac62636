//! The interface's models: a Jenkins element (a spring in series with a
//! Coulomb slider, [`crate::model::Jenkins`]) or an Iwan model (several in
//! parallel) added to a modal model ([`crate::model::modal`]) held as
//! identified, either between two points, taking its stiffness out of
//! their coupling spring ([`model_with`]), or on an unmeasured interface
//! coordinate ([`coordinate_model`]) whose displacement in each
//! non-residual mode is a parameter. Stuck, every such model *is* the
//! linear model.

use crate::error::{Result, TacitError};
use crate::model::{modal, Jenkins, Model};
use serde::Serialize;
use std::f64::consts::PI;
use std::sync::Arc;

/// A linear-part parameter fitted with the interface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ModeParam {
    /// The natural frequency of the (non-residual) mode nearest this
    /// frequency, Hz.
    Frequency(f64),
    /// The damping ratio of the mode nearest this frequency, Hz.
    Damping(f64),
}

/// Where the Jenkins element acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Between the two points of [`FitSpec::pair`], taking `k_J` out of
    /// their coupling spring ([`model_with`]); fitted: `k_J` and `F_s`.
    Points,
    /// From the interface coordinate to ground ([`coordinate_model`]): an
    /// unmeasured point whose modal displacements (the interface's
    /// participation in each non-residual mode) are fitted with `F_s`,
    /// starting from the relative displacement of [`FitSpec::pair`] in
    /// those modes.
    Coordinate,
}

/// An elastic softening beside the slider on the interface coordinate: a
/// saturating spring ([`crate::model::Saturating`], `k_e q` clipped at
/// `±F_e` in the coordinate's displacement `q`) whose stiffness `k_e` is
/// taken out of the coordinate's linear stiffness, so that below `F_e`
/// the model is still the linear model; once its force reaches `F_e` the
/// interface loses `k_e` without dissipating (a preloaded contact that
/// separates).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Softening {
    /// `k_e / k_J`: its stiffness as a share of the Jenkins elements'
    /// (> 0).
    pub share: f64,
    /// The bound of its force `F_e`, N (> 0).
    pub force: f64,
}

/// What [`super::fit::fit`] fits.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitSpec {
    /// Where the Jenkins element acts.
    pub direction: Direction,
    /// The two points the Jenkins element joins (DOFs from 1); with
    /// [`Direction::Coordinate`], the pair whose relative displacement
    /// the interface coordinate starts from and whose coupling sets `k_J`.
    pub pair: [usize; 2],
    /// Start of the share of the coupling spring taken by the Jenkins
    /// element, `k_J / k_coupling` (in (0, 1]).
    pub share: f64,
    /// Start of the slip force, N (with several elements, the largest).
    pub slip_force: f64,
    /// Jenkins elements in parallel (1: one Jenkins element; `n > 1`: an
    /// Iwan model, `n` elements of stiffness `k_J / n` each and slip forces
    /// `F_s i / n`, `i = 1..n`, a uniform density of slip forces up to
    /// `F_s`: the interface slips gradually, microslip before macroslip;
    /// [`FitSpec::spread`] shapes the density).
    pub elements: usize,
    /// With `n > 1` elements: the slip forces are `F_s (i/n)^p`, `p` this
    /// exponent (1: a uniform density of slip forces up to `F_s`; `p > 1`:
    /// more of the interface slips at low force). The start when
    /// [`FitSpec::fit_spread`].
    pub spread: f64,
    /// Fit the exponent [`FitSpec::spread`] (on its logarithm) with the
    /// slip force (only with `n > 1` elements).
    pub fit_spread: bool,
    /// With [`Direction::Coordinate`]: the start of the participations,
    /// one per non-residual mode (None: the relative displacement of
    /// [`FitSpec::pair`], [`pair_participations`]).
    pub participations: Option<Vec<f64>>,
    /// With [`Direction::Coordinate`]: hold the participations at
    /// [`FitSpec::participations`] (which must then be given) instead of
    /// fitting them.
    pub hold_participations: bool,
    /// With [`Direction::Coordinate`]: an elastic softening beside the
    /// slider, its share and force bound fitted (on their logarithms) from
    /// these starts (None: the slider alone).
    pub softening: Option<Softening>,
    /// Linear parameters fitted with the interface (empty: the identified
    /// linear part held).
    pub modes: Vec<ModeParam>,
    /// Factor on the frequency of the residual mode above the band, its
    /// shape scaled by the same factor so that its flexibility at the
    /// points (shape² / ω²) is unchanged (1: as identified).
    pub upper_residual_factor: f64,
    /// Damping ratio of the residual mode above the band (None: as
    /// identified). The residual mode stands for a quasi-static
    /// flexibility; its own resonance is not a mode of the structure.
    pub upper_residual_damping: Option<f64>,
    /// Step of the centered differences in the logarithm of a parameter.
    pub fd_step: f64,
    /// Limit on the simulations of the fit.
    pub max_simulations: usize,
    /// Sub-steps per sample of the simulations.
    pub substeps: usize,
    /// Samples not scored at the start of every record.
    pub warm_up: usize,
}

impl FitSpec {
    /// Check the settings.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(TacitError::Setting(format!("interface fit: {m}")));
        if !(self.share > 0.0 && self.share <= 1.0) {
            return bad(format!("share {} must be in (0, 1]", self.share));
        }
        if !(self.slip_force > 0.0 && self.slip_force.is_finite()) {
            return bad(format!("slip force {} must be > 0", self.slip_force));
        }
        if !(self.upper_residual_factor >= 1.0 && self.upper_residual_factor.is_finite()) {
            return bad(format!(
                "upper residual factor {} must be >= 1",
                self.upper_residual_factor
            ));
        }
        if !(self.fd_step > 0.0 && self.fd_step < 0.1) {
            return bad(format!("fd_step {} must be in (0, 0.1)", self.fd_step));
        }
        if !(self.spread > 0.0 && self.spread <= 20.0) {
            return bad(format!("spread {} must be in (0, 20]", self.spread));
        }
        if self.pair[0] == 0 || self.pair[1] == 0 || self.pair[0] == self.pair[1] {
            return bad(format!(
                "pair {:?}: two different points, numbered from 1",
                self.pair
            ));
        }
        if self.substeps == 0 || self.max_simulations == 0 || self.elements == 0 {
            return bad("substeps, elements and max_simulations must be > 0".into());
        }
        if self.hold_participations && self.participations.is_none() {
            return bad("held participations must be given".into());
        }
        if let Some(e) = &self.softening {
            if self.direction != Direction::Coordinate {
                return bad("a softening acts on the interface coordinate only".into());
            }
            if !(e.share > 0.0 && e.share.is_finite() && e.force > 0.0 && e.force.is_finite()) {
                return bad(format!(
                    "softening share {} and force {} must be > 0",
                    e.share, e.force
                ));
            }
        }
        Ok(())
    }
}

/// The model with the Jenkins element: `base`'s modal section with the
/// linear parameters `x_modes` applied (factors on the frequency or the
/// damping ratio of the chosen modes), the damping matrix of that linear
/// model held, and the Jenkins element `(k_J, F_s)` taking `k_J` out of
/// the coupling spring of `pair`.
pub fn model_with(
    base: &modal::ModalSection,
    spec: &FitSpec,
    factors: &[f64],
    k_j_share: f64,
    slip_force: f64,
) -> Result<Model> {
    let section = linear_section(base, spec, factors)?;
    let mut m = held_model(&section)?;
    let pair = spec.pair;
    let s = coupling_index(&m, pair)?;
    let k_c = m.springs[s].stiffness;
    let k_j = k_j_share * k_c;
    m.springs[s].stiffness = k_c - k_j;
    push_jenkins(&mut m, spec, pair.to_vec(), k_j, slip_force);
    Ok(m)
}

/// `n` Jenkins elements of stiffness `k_j / n` and slip forces
/// `F_s (i/n)^p` on `dofs` (one: a single Jenkins element).
fn push_jenkins(m: &mut Model, spec: &FitSpec, dofs: Vec<usize>, k_j: f64, slip_force: f64) {
    let n = spec.elements.max(1);
    for i in 1..=n {
        m.jenkins.push(Jenkins {
            dofs: dofs.clone(),
            stiffness: k_j / n as f64,
            slip_force: element_slip_force(i, n, spec.spread, slip_force),
        });
    }
}

/// The slip force of element `i` (from 1) of `n` whose largest is
/// `slip_force`: `F_s (i / n)^p` (`p` the density's exponent,
/// [`FitSpec::spread`]).
pub(super) fn element_slip_force(i: usize, n: usize, spread: f64, slip_force: f64) -> f64 {
    slip_force * (i as f64 / n as f64).powf(spread)
}

/// `base` with the residual mode above the band and the factors of
/// `spec.modes` applied.
pub(super) fn linear_section(
    base: &modal::ModalSection,
    spec: &FitSpec,
    factors: &[f64],
) -> Result<modal::ModalSection> {
    let mut section = base.clone();
    let top = section
        .modes
        .iter()
        .map(|m| m.frequency_hz)
        .fold(0.0, f64::max);
    for m in section.modes.iter_mut() {
        if m.residual && m.frequency_hz == top {
            m.frequency_hz *= spec.upper_residual_factor;
            m.shape
                .iter_mut()
                .for_each(|v| *v *= spec.upper_residual_factor);
            if let Some(z) = spec.upper_residual_damping {
                m.damping = z;
            }
        }
    }
    for (p, &f) in spec.modes.iter().zip(factors) {
        let (hz, freq) = match *p {
            ModeParam::Frequency(hz) => (hz, true),
            ModeParam::Damping(hz) => (hz, false),
        };
        let r = nearest_mode(&section, hz)?;
        if freq {
            section.modes[r].frequency_hz *= f;
        } else {
            section.modes[r].damping *= f;
        }
    }
    Ok(section)
}

/// The dense model of `section` with its modal damping matrix held as a
/// matrix (so that splitting a stiffness does not change it).
pub(super) fn held_model(section: &modal::ModalSection) -> Result<Model> {
    let text = modal::to_toml_string("interface", "modal model with an interface", section);
    let mut m = modal::from_toml_str(&text, "interface")?;
    let c = m.damping_matrix()?;
    let mut lin = m
        .matrices
        .as_deref()
        .cloned()
        .ok_or_else(|| TacitError::Numerical("the modal model has no matrices".into()))?;
    lin.c = Some(c);
    m.matrices = Some(Arc::new(lin));
    m.damping = crate::model::Damping::None;
    Ok(m)
}

/// Index in `m.springs` of the coupling spring between the two points.
pub(super) fn coupling_index(m: &Model, pair: [usize; 2]) -> Result<usize> {
    m.springs
        .iter()
        .position(|s| s.dofs.len() == 2 && s.dofs.contains(&pair[0]) && s.dofs.contains(&pair[1]))
        .ok_or_else(|| {
            TacitError::Numerical(format!(
                "the model has no coupling spring between {} and {}",
                m.dof_name(pair[0]),
                m.dof_name(pair[1])
            ))
        })
}

/// Label of the unmeasured point that is the interface's slip coordinate
/// ([`Direction::Coordinate`]).
pub const INTERFACE: &str = "interface";

/// The identified coupling spring between the points of `spec.pair` (N/m)
/// times `spec.share`: the stuck stiffness `k_J` of the Jenkins element on
/// the interface coordinate.
pub fn coordinate_stiffness(base: &modal::ModalSection, spec: &FitSpec) -> Result<f64> {
    let m = held_model(base)?;
    Ok(spec.share * m.springs[coupling_index(&m, spec.pair)?].stiffness)
}

/// The interface's participation `δ_r` in each non-residual mode of `base`
/// (in the section's order) when the interface coordinate is the relative
/// displacement of `spec.pair` restricted to those modes:
/// `δ_r = √k_J (φ_a,r − φ_b,r) / ω_r`.
pub fn pair_participations(base: &modal::ModalSection, spec: &FitSpec) -> Result<Vec<f64>> {
    let k_j = coordinate_stiffness(base, spec)?;
    let [a, b] = spec.pair.map(|d| d - 1);
    Ok(base
        .modes
        .iter()
        .filter(|m| !m.residual)
        .map(|m| k_j.sqrt() * (m.shape[a] - m.shape[b]) / (2.0 * PI * m.frequency_hz))
        .collect())
}

/// The model with the interface as a coordinate of its own: `base` (with
/// `factors`, [`linear_section`]) gains the unmeasured point
/// [`INTERFACE`] whose displacement in mode `r` is
/// `g_r = δ_r ω_r / √k_J` for the non-residual modes (`deltas`, in the
/// section's order) and 0 for the residual modes; a Jenkins element
/// `(k_J, F_s)` acts from it to ground, and `k_J` is taken out of the
/// linear stiffness of that coordinate, so that stuck the model is the
/// linear model and fully slipped the stiffness of the modes loses
/// `k_J g gᵀ` (mode `r` alone: `ω_r² (1 − δ_r²)`). `k_J` is
/// [`coordinate_stiffness`]; it only sets the coordinate's scale. With
/// [`FitSpec::softening`] a saturating spring `k_e = share · k_J` acts
/// beside it and `k_e` is taken out too (slipped and saturated, mode `r`
/// alone keeps `ω_r² (1 − δ_r² (1 + share))`).
pub fn coordinate_model(
    base: &modal::ModalSection,
    spec: &FitSpec,
    factors: &[f64],
    deltas: &[f64],
    slip_force: f64,
) -> Result<Model> {
    let k_j = coordinate_stiffness(base, spec)?;
    let mut section = linear_section(base, spec, factors)?;
    let free = section.modes.iter().filter(|m| !m.residual).count();
    if deltas.len() != free {
        return Err(TacitError::Setting(format!(
            "interface coordinate: {} participations for {free} modes",
            deltas.len()
        )));
    }
    section.points.push(INTERFACE.into());
    let mut d = deltas.iter();
    for m in section.modes.iter_mut() {
        let g = match m.residual {
            true => 0.0,
            false => d.next().copied().unwrap_or(0.0) * 2.0 * PI * m.frequency_hz / k_j.sqrt(),
        };
        m.shape.push(g);
    }
    if !section.dofs.is_empty() {
        let next = section.dofs.iter().max().copied().unwrap_or(0) + 1;
        section.dofs.push(next);
    }
    let mut m = held_model(&section)?;
    let s = m.points.len();
    let mut lin = m
        .matrices
        .as_deref()
        .cloned()
        .ok_or_else(|| TacitError::Numerical("the modal model has no matrices".into()))?;
    lin.k_rest[(s - 1, s - 1)] -= k_j;
    if let Some(e) = &spec.softening {
        lin.k_rest[(s - 1, s - 1)] -= e.share * k_j;
        m.saturating.push(crate::model::Saturating {
            dofs: vec![s],
            stiffness: e.share * k_j,
            force: e.force,
        });
    }
    m.matrices = Some(Arc::new(lin));
    push_jenkins(&mut m, spec, vec![s], k_j, slip_force);
    Ok(m)
}

/// Index of the non-residual mode nearest `hz`.
fn nearest_mode(section: &modal::ModalSection, hz: f64) -> Result<usize> {
    (0..section.modes.len())
        .filter(|&r| !section.modes[r].residual)
        .min_by(|&a, &b| {
            let d = |r: usize| (section.modes[r].frequency_hz - hz).abs();
            d(a).total_cmp(&d(b))
        })
        .ok_or_else(|| TacitError::Numerical("the modal model has no mode".into()))
}

impl Default for FitSpec {
    fn default() -> Self {
        FitSpec {
            direction: Direction::Points,
            pair: [2, 3],
            share: 0.5,
            slip_force: 50.0,
            elements: 1,
            spread: 1.0,
            fit_spread: false,
            participations: None,
            hold_participations: false,
            softening: None,
            upper_residual_factor: 1.0,
            upper_residual_damping: Some(0.3),
            modes: vec![],
            fd_step: 1e-3,
            max_simulations: 60,
            substeps: 10,
            warm_up: 8192,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::fit::describe;
    use super::*;

    fn section() -> modal::ModalSection {
        let text = r#"
[modal]
points = ["exc", "wing", "payload"]
driving_point = "exc"
[[modal.mode]]
frequency_hz = 3.0
damping = 0.02
shape = [0.4, 0.3, 0.25]
[[modal.mode]]
frequency_hz = 5.0
damping = 0.01
shape = [0.3, -0.1, -0.3]
[[modal.mode]]
frequency_hz = 7.0
damping = 0.01
shape = [0.1, -0.4, 0.4]
"#;
        let t: toml::Table = text.parse().unwrap();
        t["modal"].clone().try_into().unwrap()
    }

    #[test]
    fn stuck_jenkins_model_has_the_linear_models_matrices() {
        let s = section();
        let spec = FitSpec {
            direction: Direction::Points,
            pair: [2, 3],
            share: 0.5,
            slip_force: 1.0,
            upper_residual_damping: None,
            max_simulations: 10,
            substeps: 4,
            warm_up: 0,
            ..Default::default()
        };
        let text = modal::to_toml_string("x", "x", &s);
        let lin = modal::from_toml_str(&text, "x").unwrap();
        let m = model_with(&s, &spec, &[], 0.5, 1.0).unwrap();
        // the coupling spring split: linear rest + stuck Jenkins = L1's
        let mut k = m.stiffness_matrix();
        let j = &m.jenkins[0];
        crate::model::add_spring(&mut k, (1, Some(2)), j.stiffness);
        let k1 = lin.stiffness_matrix();
        assert!((k - &k1).abs().max() < 1e-9 * k1.abs().max());
        let c = m.damping_matrix().unwrap();
        let c1 = lin.damping_matrix().unwrap();
        assert!((c - &c1).abs().max() < 1e-9 * c1.abs().max());
        assert!(j.stiffness > 0.0);
    }

    /// [`section`] with a residual mode at 30 Hz, and the settings of an
    /// interface coordinate on a pair the linear model couples by a spring.
    fn coordinate_case() -> (modal::ModalSection, FitSpec) {
        let mut s = section();
        s.modes.push(modal::ModalMode {
            frequency_hz: 30.0,
            damping: 0.05,
            shape: vec![0.2, 0.1, -0.3],
            residual: true,
        });
        let d = &held_model(&s).unwrap().springs[0].dofs;
        let spec = FitSpec {
            direction: Direction::Coordinate,
            pair: [d[0], d[1]],
            upper_residual_damping: None,
            ..Default::default()
        };
        (s, spec)
    }

    #[test]
    fn interface_coordinate_softens_only_the_modes_it_strains() {
        let (s, spec) = coordinate_case();
        // the 7-Hz mode alone: fully slipped it keeps 1 − δ² of its ω²
        let m = coordinate_model(&s, &spec, &[], &[0.0, 0.0, 0.6], 1.0).unwrap();
        assert_eq!(m.points, ["exc", "wing", "payload", INTERFACE]);
        assert_eq!(m.jenkins[0].dofs, [4]);
        let f = describe(&m, &s, &spec, &[0.0, 0.0, 0.6, 0.0]).unwrap();
        let want = [3.0, 5.0, 7.0, 30.0];
        for (got, w) in f.stuck_hz.iter().zip(want) {
            assert!((got - w).abs() < 1e-7 * w, "stuck {:?}", f.stuck_hz);
        }
        let slipped = [3.0, 5.0, 7.0 * 0.8, 30.0];
        let mut got = f.slipped_hz.clone();
        got.sort_by(f64::total_cmp);
        for (g, w) in got.iter().zip(slipped) {
            assert!((g - w).abs() < 1e-7 * w, "slipped {:?}", f.slipped_hz);
        }
        // the stuck model's damping is modal with the section's ratios
        let mut k = m.stiffness_matrix();
        crate::model::add_spring(&mut k, (3, None), m.jenkins[0].stiffness);
        let modes = crate::modal::solve(&m.mass_matrix(), &k).unwrap();
        let c = m.damping_matrix().unwrap();
        let mc = modes.shapes.transpose() * c * &modes.shapes;
        for (r, z) in [0.02, 0.01, 0.01, 0.05].iter().enumerate() {
            let w = modes.omega[r];
            assert!(
                (mc[(r, r)] - 2.0 * z * w).abs() < 1e-7 * w,
                "mode {r}: {}",
                mc[(r, r)]
            );
        }
        // participations of the pair's relative displacement: all modes
        let d = pair_participations(&s, &spec).unwrap();
        assert_eq!(d.len(), 3);
        assert!(d.iter().all(|v| v.abs() > 0.0));
    }

    #[test]
    fn elastic_softening_keeps_the_linear_model_below_its_bound_and_adds_its_share_saturated() {
        let (s, coordinate) = coordinate_case();
        let spec = FitSpec {
            participations: Some(vec![0.0, 0.0, 0.6]),
            hold_participations: true,
            softening: Some(Softening {
                share: 0.5,
                force: 3.0,
            }),
            ..coordinate
        };
        spec.validate().unwrap();
        let m = coordinate_model(&s, &spec, &[], &[0.0, 0.0, 0.6], 1.0).unwrap();
        assert_eq!(m.saturating.len(), 1);
        assert_eq!(m.saturating[0].dofs, [4]);
        let k_j = coordinate_stiffness(&s, &spec).unwrap();
        approx::assert_relative_eq!(m.saturating[0].stiffness, 0.5 * k_j, max_relative = 1e-12);
        // the parameter vector with held participations: (ln share_e,
        // ln F_e, ln F_s); the model at it is the one above
        let x = [0.5f64.ln(), 3.0f64.ln(), 1.0f64.ln()];
        let p = super::super::fit::unpack(&spec, &x);
        assert_eq!(p.middle, vec![0.0, 0.0, 0.6]);
        approx::assert_relative_eq!(p.softening.unwrap().force, 3.0, max_relative = 1e-12);
        let f = describe(&m, &s, &spec, &x).unwrap();
        approx::assert_relative_eq!(f.softening_stiffness, 0.5 * k_j, max_relative = 1e-12);
        // below every bound: the linear model's modes; slipped and
        // saturated the 7-Hz mode keeps 1 − δ² (1 + share) of its ω²
        for (got, w) in f.stuck_hz.iter().zip([3.0, 5.0, 7.0, 30.0]) {
            assert!((got - w).abs() < 1e-7 * w, "stuck {:?}", f.stuck_hz);
        }
        let mut got = f.slipped_hz.clone();
        got.sort_by(f64::total_cmp);
        let soft = 7.0 * (1.0 - 0.36 * 1.5f64).sqrt();
        for (g, w) in got.iter().zip([3.0, soft, 5.0, 30.0]) {
            assert!((g - w).abs() < 1e-7 * w, "slipped {:?}", f.slipped_hz);
        }
        // a softening between two points is refused
        let bad = FitSpec {
            direction: Direction::Points,
            ..spec.clone()
        };
        assert!(bad.validate().is_err());
    }
}
