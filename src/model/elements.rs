//! Nonlinear elements and their internal forces and tangents.
//!
//! - Penalty contact between DOFs i→j: penetration `p = (u_i − u_j) − gap`;
//!   when `p > 0` the force `k_c p` pushes i and j apart
//!   (`f_int,i += k_c p`, `f_int,j −= k_c p`). With one DOF, a stop against
//!   ground: `p = u_i − gap`.
//! - Coulomb friction at a DOF against ground (the rod), regularised:
//!   `f_int = F tanh(v / v_r)`.
//! - Cubic spring between two DOFs or to ground: `f = k_3 δ³`, `δ = u_i − u_j`.
//! - Quadratic (asymmetric) spring between two DOFs or to ground:
//!   `f = k_2 δ²` (the even law: stiffer on one side of the rest position,
//!   softer on the other; `docs/formats.md` gives the reasons for this form).
//! - Nonlinear dampers in the relative velocity `ν = u̇_i − u̇_j` (or `u̇_i`):
//!   quadratic `f = c_2 ν|ν|`, cubic `f = c_3 ν³`.
//! - Two-sided clearance (dead zone) between two DOFs:
//!   `f = k_c (|δ| − gap) sign(δ)` when `|δ| > gap`, 0 inside. It is
//!   compiled as two penalty contacts (i→j and j→i, the same gap and
//!   stiffness), which is the same law, so the integrator's contact
//!   handling (side checks, batched open samples, sensitivities) applies.
//! - Coulomb friction between two DOFs (relative sliding), regularised as
//!   the friction against ground: `f = F tanh(ν / v_r)`.
//! - Jenkins element between two DOFs or to ground: a spring `k` in series
//!   with a Coulomb slider of slip force `F_s`, with an internal slip state
//!   `z` (the slider's displacement). Force `f = k (δ − z)`, `|f| ≤ F_s`:
//!   stuck (`ż = 0`, slope `k`) while the trial force `k (δ − z_n)` from
//!   the last committed slip stays within `±F_s`, slipping beyond it
//!   (`f = ±F_s`, slope 0, the slip moved so that `k (δ − z) = ±F_s`).
//!   This is the return mapping of rate-independent plasticity (Simo &
//!   Hughes, *Computational Inelasticity*, 1998, §1.4): the force is a
//!   function of `δ` given the committed slip, and the slip is committed
//!   once per accepted step ([`Element::committed_slip`]). Under an imposed
//!   `δ = X sin ωt` with `X > F_s / k` the loop is a parallelogram of
//!   area `4 F_s (X − F_s / k)` per cycle (Iwan 1966).
//! - Saturating spring between two DOFs or to ground: `f = k δ` while
//!   `|k δ| ≤ F`, `±F` beyond: an elastic (lossless, path-independent)
//!   softening law, the stiffness `k` lost once the force reaches `F` — a
//!   preloaded contact that separates when the load exceeds its preload.
//!   Under `δ = X sin θ` with `X > F/k` its first-harmonic stiffness is
//!   `(2k/π) (asin r + r √(1 − r²))`, `r = F / (k X)` (the saturation's
//!   describing function; Gelb & Vander Velde, *Multiple-Input Describing
//!   Functions and Nonlinear System Design*, 1968).

use serde::{Deserialize, Serialize};

fn default_vreg() -> f64 {
    1e-3
}

/// Penalty contact.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Contact {
    /// `[i, j]`: contact when `u_i − u_j > gap`; `[i]`: when `u_i > gap`.
    pub dofs: Vec<usize>,
    /// Gap, m (>= 0).
    pub gap: f64,
    /// Penalty stiffness, N/m (> 0).
    pub stiffness: f64,
}

/// Regularised Coulomb friction at one DOF.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Friction {
    /// DOF (from 1).
    pub dof: usize,
    /// Friction force level, N (>= 0).
    pub level: f64,
    /// Regularisation velocity, m/s (> 0; default 1e-3).
    #[serde(default = "default_vreg")]
    pub velocity: f64,
}

/// Cubic spring.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cubic {
    /// `[i, j]` or `[i]` (to ground).
    pub dofs: Vec<usize>,
    /// Cubic coefficient, N/m³.
    pub k3: f64,
}

/// Quadratic (asymmetric) spring: `f = k_2 δ²`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Quadratic {
    /// `[i, j]` or `[i]` (to ground).
    pub dofs: Vec<usize>,
    /// Quadratic coefficient, N/m² (any sign).
    pub k2: f64,
}

/// Quadratic damper: `f = c_2 ν|ν|` in the relative velocity ν.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuadraticDamper {
    /// `[i, j]` or `[i]` (to ground).
    pub dofs: Vec<usize>,
    /// Coefficient, N s²/m² (>= 0).
    pub c2: f64,
}

/// Cubic damper: `f = c_3 ν³` in the relative velocity ν.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CubicDamper {
    /// `[i, j]` or `[i]` (to ground).
    pub dofs: Vec<usize>,
    /// Coefficient, N s³/m³ (>= 0).
    pub c3: f64,
}

/// Two-sided clearance (dead zone): no force while `|δ| < gap`,
/// `k_c (|δ| − gap) sign(δ)` beyond.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Clearance {
    /// `[i, j]` (no clearance to ground).
    pub dofs: Vec<usize>,
    /// Half-width of the dead zone, m (>= 0).
    pub gap: f64,
    /// Penalty stiffness beyond the gap, N/m (> 0).
    pub stiffness: f64,
}

/// Regularised Coulomb friction between two DOFs (relative sliding).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RelativeFriction {
    /// `[i, j]`: the friction force opposes `u̇_i − u̇_j`.
    pub dofs: Vec<usize>,
    /// Friction force level, N (>= 0).
    pub level: f64,
    /// Regularisation velocity, m/s (> 0; default 1e-3).
    #[serde(default = "default_vreg")]
    pub velocity: f64,
}

/// Jenkins element: a spring in series with a Coulomb slider (stick–slip
/// friction with a finite stuck stiffness).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Jenkins {
    /// `[i, j]` or `[i]` (to ground).
    pub dofs: Vec<usize>,
    /// Stiffness of the spring while the slider sticks, N/m (> 0).
    pub stiffness: f64,
    /// Slip force of the slider, N (>= 0).
    pub slip_force: f64,
}

/// Saturating spring: an elastic softening law, `f = k δ` clipped at
/// `±F` (stiffness `k` below the bound, none beyond; no loss per cycle).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Saturating {
    /// `[i, j]` or `[i]` (to ground).
    pub dofs: Vec<usize>,
    /// Stiffness below the bound, N/m (> 0).
    pub stiffness: f64,
    /// Bound of the force, N (> 0).
    pub force: f64,
}

/// The force and slope of a saturating spring of stiffness `k` and bound
/// `fmax` at the relative displacement `delta`: `(k δ, k)` while
/// `|k δ| ≤ fmax`, `(±fmax, 0)` beyond.
pub fn saturation(k: f64, fmax: f64, delta: f64) -> (f64, f64) {
    let trial = k * delta;
    if trial.abs() <= fmax {
        (trial, k)
    } else {
        (fmax.copysign(trial), 0.0)
    }
}

/// One nonlinear element in compiled, 0-based form for the integrator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Element {
    /// Contact i→j (j = None: ground stop).
    Contact {
        /// First DOF.
        i: usize,
        /// Second DOF.
        j: Option<usize>,
        /// Gap, m.
        gap: f64,
        /// Stiffness, N/m.
        k: f64,
    },
    /// Friction at a DOF.
    Friction {
        /// DOF.
        d: usize,
        /// Level, N.
        level: f64,
        /// Regularisation velocity, m/s.
        vreg: f64,
    },
    /// Cubic spring.
    Cubic {
        /// First DOF.
        i: usize,
        /// Second DOF.
        j: Option<usize>,
        /// Coefficient, N/m³.
        k3: f64,
    },
    /// Quadratic spring `k_2 δ²`.
    Quadratic {
        /// First DOF.
        i: usize,
        /// Second DOF.
        j: Option<usize>,
        /// Coefficient, N/m².
        k2: f64,
    },
    /// Quadratic damper `c_2 ν|ν|`.
    QuadraticDamper {
        /// First DOF.
        i: usize,
        /// Second DOF.
        j: Option<usize>,
        /// Coefficient, N s²/m².
        c2: f64,
    },
    /// Cubic damper `c_3 ν³`.
    CubicDamper {
        /// First DOF.
        i: usize,
        /// Second DOF.
        j: Option<usize>,
        /// Coefficient, N s³/m³.
        c3: f64,
    },
    /// Friction between two DOFs, `F tanh((u̇_i − u̇_j)/v_r)`.
    RelativeFriction {
        /// First DOF.
        i: usize,
        /// Second DOF.
        j: usize,
        /// Level, N.
        level: f64,
        /// Regularisation velocity, m/s.
        vreg: f64,
    },
    /// Jenkins element (spring `k` in series with a slider `F_s`); its slip
    /// state is carried by the integrator.
    Jenkins {
        /// First DOF.
        i: usize,
        /// Second DOF.
        j: Option<usize>,
        /// Stuck stiffness, N/m.
        k: f64,
        /// Slip force, N.
        fs: f64,
    },
    /// Saturating spring `k δ` clipped at `±F`.
    Saturating {
        /// First DOF.
        i: usize,
        /// Second DOF.
        j: Option<usize>,
        /// Stiffness below the bound, N/m.
        k: f64,
        /// Bound of the force, N.
        fmax: f64,
    },
}

/// Gather the model's elements into compiled form.
pub fn compile(model: &super::Model) -> Vec<Element> {
    let mut out = Vec::new();
    for c in &model.contacts {
        out.push(Element::Contact {
            i: c.dofs[0] - 1,
            j: c.dofs.get(1).map(|j| j - 1),
            gap: c.gap,
            k: c.stiffness,
        });
    }
    for f in &model.frictions {
        out.push(Element::Friction {
            d: f.dof - 1,
            level: f.level,
            vreg: f.velocity,
        });
    }
    for c in &model.cubics {
        out.push(Element::Cubic {
            i: c.dofs[0] - 1,
            j: c.dofs.get(1).map(|j| j - 1),
            k3: c.k3,
        });
    }
    let ends = |dofs: &[usize]| (dofs[0] - 1, dofs.get(1).map(|j| j - 1));
    for q in &model.quadratics {
        let (i, j) = ends(&q.dofs);
        out.push(Element::Quadratic { i, j, k2: q.k2 });
    }
    for d in &model.quadratic_dampers {
        let (i, j) = ends(&d.dofs);
        out.push(Element::QuadraticDamper { i, j, c2: d.c2 });
    }
    for d in &model.cubic_dampers {
        let (i, j) = ends(&d.dofs);
        out.push(Element::CubicDamper { i, j, c3: d.c3 });
    }
    for f in &model.relative_frictions {
        out.push(Element::RelativeFriction {
            i: f.dofs[0] - 1,
            j: f.dofs[1] - 1,
            level: f.level,
            vreg: f.velocity,
        });
    }
    for c in &model.clearances {
        out.extend(clearance_contacts(c));
    }
    for e in &model.jenkins {
        let (i, j) = ends(&e.dofs);
        out.push(Element::Jenkins {
            i,
            j,
            k: e.stiffness,
            fs: e.slip_force,
        });
    }
    for e in &model.saturating {
        let (i, j) = ends(&e.dofs);
        out.push(Element::Saturating {
            i,
            j,
            k: e.stiffness,
            fmax: e.force,
        });
    }
    out
}

/// The two penalty contacts of a clearance between DOFs i and j: i→j and
/// j→i with the clearance's gap and stiffness.
fn clearance_contacts(c: &Clearance) -> [Element; 2] {
    let (i, j) = (c.dofs[0] - 1, c.dofs[1] - 1);
    let (gap, k) = (c.gap, c.stiffness);
    [
        Element::Contact {
            i,
            j: Some(j),
            gap,
            k,
        },
        Element::Contact {
            i: j,
            j: Some(i),
            gap,
            k,
        },
    ]
}

/// The lists of nonlinear elements of a model, in the order
/// [`compile`] takes them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ElementList {
    /// `model.contacts`.
    Contact,
    /// `model.frictions`.
    Friction,
    /// `model.cubics`.
    Cubic,
    /// `model.quadratics`.
    Quadratic,
    /// `model.quadratic_dampers`.
    QuadraticDamper,
    /// `model.cubic_dampers`.
    CubicDamper,
    /// `model.relative_frictions`.
    RelativeFriction,
    /// `model.clearances` (two compiled contacts each).
    Clearance,
    /// `model.jenkins`.
    Jenkins,
    /// `model.saturating`.
    Saturating,
}

/// Index in [`compile`]`(model)` of the (first) element compiled from entry
/// `index` of `list`; a clearance's two contacts are at this index and the
/// next.
pub fn compiled_index(model: &super::Model, list: ElementList, index: usize) -> usize {
    let sizes = [
        (ElementList::Contact, model.contacts.len()),
        (ElementList::Friction, model.frictions.len()),
        (ElementList::Cubic, model.cubics.len()),
        (ElementList::Quadratic, model.quadratics.len()),
        (ElementList::QuadraticDamper, model.quadratic_dampers.len()),
        (ElementList::CubicDamper, model.cubic_dampers.len()),
        (
            ElementList::RelativeFriction,
            model.relative_frictions.len(),
        ),
        (ElementList::Clearance, 2 * model.clearances.len()),
        (ElementList::Jenkins, model.jenkins.len()),
        (ElementList::Saturating, model.saturating.len()),
    ];
    let before: usize = sizes
        .iter()
        .take_while(|(l, _)| *l != list)
        .map(|(_, n)| n)
        .sum();
    let per = if list == ElementList::Clearance { 2 } else { 1 };
    before + per * index
}

/// tanh through one `exp_m1` (about 3× cheaper than libm's tanh here;
/// relative error ~1e-16 away from 0, absolute ~1e-17 near 0).
#[inline(always)]
fn fast_tanh(x: f64) -> f64 {
    if x.abs() > 20.0 {
        return x.signum();
    }
    let e = (2.0 * x).exp_m1();
    e / (e + 2.0)
}

#[inline]
fn rel(u: &[f64], i: usize, j: Option<usize>) -> f64 {
    match j {
        Some(j) => u[i] - u[j],
        None => u[i],
    }
}

/// Add a scalar pair force `s` (on i: +s, on j: −s) into `f`.
#[inline]
fn scatter(f: &mut [f64], i: usize, j: Option<usize>, s: f64) {
    f[i] += s;
    if let Some(j) = j {
        f[j] -= s;
    }
}

/// Add `c (e_i − e_j)(e_i − e_j)ᵀ` into a column-major n×n matrix.
#[inline]
fn scatter_tangent(t: &mut [f64], n: usize, i: usize, j: Option<usize>, c: f64) {
    t[i * n + i] += c;
    if let Some(j) = j {
        t[j * n + j] += c;
        t[i * n + j] -= c;
        t[j * n + i] -= c;
    }
}

impl Element {
    /// Add this element's internal force at (u, v) into `f`.
    #[inline]
    pub fn add_force(&self, u: &[f64], v: &[f64], f: &mut [f64]) {
        self.force_and_slope(u, v, f);
    }

    /// Add this element's internal force at (u, v) into `f` and return its
    /// scalar slope: `∂f/∂δ` for a contact or cubic spring (0 when a contact
    /// is open), `∂f/∂v` for friction. [`Element::add_slope`] scatters it
    /// into a tangent without evaluating the law again.
    #[inline(always)]
    pub fn force_and_slope(&self, u: &[f64], v: &[f64], f: &mut [f64]) -> f64 {
        self.force_and_slope_at(u, v, 0.0, f)
    }

    /// [`Element::force_and_slope`] with a Jenkins element's committed slip
    /// `slip` (m; ignored by the other elements, which have no state).
    #[inline(always)]
    pub fn force_and_slope_at(&self, u: &[f64], v: &[f64], slip: f64, f: &mut [f64]) -> f64 {
        match *self {
            Element::Contact { i, j, gap, k } => {
                let p = rel(u, i, j) - gap;
                if p > 0.0 {
                    scatter(f, i, j, k * p);
                    k
                } else {
                    0.0
                }
            }
            Element::Friction { d, level, vreg } => {
                let th = fast_tanh(v[d] / vreg);
                f[d] += level * th;
                level / vreg * (1.0 - th * th)
            }
            Element::Cubic { i, j, k3 } => {
                let x = rel(u, i, j);
                scatter(f, i, j, k3 * x * x * x);
                3.0 * k3 * x * x
            }
            Element::Quadratic { i, j, k2 } => {
                let x = rel(u, i, j);
                scatter(f, i, j, k2 * x * x);
                2.0 * k2 * x
            }
            Element::QuadraticDamper { i, j, c2 } => {
                let w = rel(v, i, j);
                scatter(f, i, j, c2 * w * w.abs());
                2.0 * c2 * w.abs()
            }
            Element::CubicDamper { i, j, c3 } => {
                let w = rel(v, i, j);
                scatter(f, i, j, c3 * w * w * w);
                3.0 * c3 * w * w
            }
            Element::RelativeFriction { i, j, level, vreg } => {
                let th = fast_tanh((v[i] - v[j]) / vreg);
                scatter(f, i, Some(j), level * th);
                level / vreg * (1.0 - th * th)
            }
            Element::Jenkins { i, j, k, fs } => {
                let (force, slope) = jenkins_law(k, fs, rel(u, i, j), slip);
                scatter(f, i, j, force);
                slope
            }
            Element::Saturating { i, j, k, fmax } => {
                let (force, slope) = saturation(k, fmax, rel(u, i, j));
                scatter(f, i, j, force);
                slope
            }
        }
    }

    /// The slip to commit after an accepted step that ends at `u`, from the
    /// slip `slip` committed before it (the return mapping: unchanged while
    /// stuck, moved to `δ ∓ F_s / k` while slipping); `slip` itself for the
    /// elements without state.
    #[inline]
    pub fn committed_slip(&self, u: &[f64], slip: f64) -> f64 {
        match *self {
            Element::Jenkins { i, j, k, fs } => {
                let d = rel(u, i, j);
                let (force, _) = jenkins_law(k, fs, d, slip);
                d - force / k
            }
            _ => slip,
        }
    }

    /// True for an element with an internal state the integrator carries
    /// (the Jenkins element's slip).
    pub fn has_state(&self) -> bool {
        matches!(self, Element::Jenkins { .. })
    }

    /// Add `c_u slope` (displacement laws) or `c_v slope` (velocity laws:
    /// friction, dampers) into the column-major n×n matrix `t`; returns
    /// false when nothing was added.
    #[inline]
    pub fn add_slope(&self, slope: f64, cu: f64, cv: f64, t: &mut [f64], n: usize) -> bool {
        if slope == 0.0 {
            return false;
        }
        match *self {
            Element::Contact { i, j, .. }
            | Element::Cubic { i, j, .. }
            | Element::Quadratic { i, j, .. }
            | Element::Jenkins { i, j, .. }
            | Element::Saturating { i, j, .. } => scatter_tangent(t, n, i, j, cu * slope),
            Element::Friction { d, .. } => t[d * n + d] += cv * slope,
            Element::QuadraticDamper { i, j, .. } | Element::CubicDamper { i, j, .. } => {
                scatter_tangent(t, n, i, j, cv * slope)
            }
            Element::RelativeFriction { i, j, .. } => scatter_tangent(t, n, i, Some(j), cv * slope),
        }
        true
    }

    /// True for a law of the velocity (friction, dampers), whose slope is
    /// `∂f/∂v`; false for a law of the displacement (`∂f/∂u`). The
    /// element's slope products ([`Element::add_slope_product`]) act on the
    /// relative value between its [`Element::ends`] of the one or the other.
    pub fn is_velocity_law(&self) -> bool {
        matches!(
            self,
            Element::Friction { .. }
                | Element::QuadraticDamper { .. }
                | Element::CubicDamper { .. }
                | Element::RelativeFriction { .. }
        )
    }

    /// The DOFs the element acts on: `(i, j)`, `j = None` for ground.
    pub fn ends(&self) -> (usize, Option<usize>) {
        match *self {
            Element::Contact { i, j, .. }
            | Element::Cubic { i, j, .. }
            | Element::Quadratic { i, j, .. }
            | Element::QuadraticDamper { i, j, .. }
            | Element::CubicDamper { i, j, .. }
            | Element::Jenkins { i, j, .. }
            | Element::Saturating { i, j, .. } => (i, j),
            Element::Friction { d, .. } => (d, None),
            Element::RelativeFriction { i, j, .. } => (i, Some(j)),
        }
    }

    /// The same element on DOFs renumbered by `map` (None when a DOF has
    /// no new number).
    pub fn renumbered(&self, map: impl Fn(usize) -> Option<usize>) -> Option<Element> {
        let (i2, j2) = match self.ends() {
            (i, Some(j)) => (map(i)?, Some(map(j)?)),
            (i, None) => (map(i)?, None),
        };
        let mut e = *self;
        match &mut e {
            Element::Contact { i, j, .. }
            | Element::Cubic { i, j, .. }
            | Element::Quadratic { i, j, .. }
            | Element::QuadraticDamper { i, j, .. }
            | Element::CubicDamper { i, j, .. }
            | Element::Jenkins { i, j, .. }
            | Element::Saturating { i, j, .. } => (*i, *j) = (i2, j2),
            Element::Friction { d, .. } => *d = i2,
            Element::RelativeFriction { i, j, .. } => (*i, *j) = (i2, j2?),
        }
        Some(e)
    }
}

/// A parameter of an element, for derivatives of the internal force
/// ([`Element::add_param_derivative`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ElementParam {
    /// Contact gap, m.
    Gap,
    /// Contact penalty stiffness, N/m.
    Stiffness,
    /// Friction force level, N.
    Level,
    /// Cubic coefficient, N/m³.
    K3,
    /// Quadratic spring coefficient, N/m².
    K2,
    /// Quadratic damper coefficient, N s²/m².
    C2,
    /// Cubic damper coefficient, N s³/m³.
    C3,
}

impl ElementParam {
    /// True when `element` has this parameter.
    pub fn belongs_to(&self, element: &Element) -> bool {
        matches!(
            (self, element),
            (
                ElementParam::Gap | ElementParam::Stiffness,
                Element::Contact { .. }
            ) | (
                ElementParam::Level,
                Element::Friction { .. } | Element::RelativeFriction { .. }
            ) | (ElementParam::K3, Element::Cubic { .. })
                | (ElementParam::K2, Element::Quadratic { .. })
                | (ElementParam::C2, Element::QuadraticDamper { .. })
                | (ElementParam::C3, Element::CubicDamper { .. })
        )
    }
}

impl Element {
    /// Add `s ∂f/∂q` at (u, v) into `f`, for the element's parameter `q`:
    ///
    /// - contact, `p = δ − gap > 0`: `∂f/∂gap = −k_c`, `∂f/∂k_c = p`
    ///   (both scattered `+` on i, `−` on j); 0 when open (at `p = 0` the law
    ///   has a kink and the open side's 0 is returned);
    /// - friction: `∂f/∂F = tanh(v/v_r)` (the same `tanh` as the force);
    /// - cubic: `∂f/∂k_3 = δ³`; quadratic: `∂f/∂k_2 = δ²`;
    /// - dampers: `∂f/∂c_2 = ν|ν|`, `∂f/∂c_3 = ν³`;
    /// - friction between two DOFs: `∂f/∂F = tanh(ν/v_r)`.
    ///
    /// Returns false (and adds nothing) when the element has no such
    /// parameter.
    #[inline]
    pub fn add_param_derivative(
        &self,
        q: ElementParam,
        s: f64,
        u: &[f64],
        v: &[f64],
        f: &mut [f64],
    ) -> bool {
        self.add_param_derivative_on(q, s, u, v, None, f)
    }

    /// [`Element::add_param_derivative`] with a contact's side of the
    /// switch given: `Some(true)` uses the closed law `k_c p` (its
    /// penetration `p` extended linearly, even if ≤ 0), `Some(false)` the
    /// open one (0); `None` takes the side from the sign of `p`. Ignored by
    /// the other elements. (A Newton iterate computed with one side's
    /// matrix may be accepted just across the switch; its derivative is
    /// that side's.)
    #[inline]
    pub fn add_param_derivative_on(
        &self,
        q: ElementParam,
        s: f64,
        u: &[f64],
        v: &[f64],
        closed: Option<bool>,
        f: &mut [f64],
    ) -> bool {
        match (*self, q) {
            (Element::Contact { i, j, gap, k }, ElementParam::Gap | ElementParam::Stiffness) => {
                let p = rel(u, i, j) - gap;
                if closed.unwrap_or(p > 0.0) {
                    let d = if q == ElementParam::Gap { -k } else { p };
                    scatter(f, i, j, s * d);
                }
            }
            (Element::Friction { d, vreg, .. }, ElementParam::Level) => {
                f[d] += s * fast_tanh(v[d] / vreg);
            }
            (Element::Cubic { i, j, .. }, ElementParam::K3) => {
                let x = rel(u, i, j);
                scatter(f, i, j, s * x * x * x);
            }
            (Element::Quadratic { i, j, .. }, ElementParam::K2) => {
                let x = rel(u, i, j);
                scatter(f, i, j, s * x * x);
            }
            (Element::QuadraticDamper { i, j, .. }, ElementParam::C2) => {
                let w = rel(v, i, j);
                scatter(f, i, j, s * w * w.abs());
            }
            (Element::CubicDamper { i, j, .. }, ElementParam::C3) => {
                let w = rel(v, i, j);
                scatter(f, i, j, s * w * w * w);
            }
            (Element::RelativeFriction { i, j, vreg, .. }, ElementParam::Level) => {
                scatter(f, i, Some(j), s * fast_tanh((v[i] - v[j]) / vreg));
            }
            _ => return false,
        }
        true
    }

    /// `y += c_u slope ∂f/∂u · x_u` (displacement laws) or
    /// `y += c_v slope ∂f/∂v · x_v` (velocity laws): the product of the tangent
    /// that [`Element::add_slope`] assembles with vectors, without the
    /// matrix.
    #[inline]
    pub fn add_slope_product(
        &self,
        slope: f64,
        (cu, xu): (f64, &[f64]),
        (cv, xv): (f64, &[f64]),
        y: &mut [f64],
    ) {
        if slope == 0.0 {
            return;
        }
        match *self {
            Element::Contact { i, j, .. }
            | Element::Cubic { i, j, .. }
            | Element::Quadratic { i, j, .. }
            | Element::Jenkins { i, j, .. }
            | Element::Saturating { i, j, .. } => scatter(y, i, j, cu * slope * rel(xu, i, j)),
            Element::Friction { d, .. } => y[d] += cv * slope * xv[d],
            Element::QuadraticDamper { i, j, .. } | Element::CubicDamper { i, j, .. } => {
                scatter(y, i, j, cv * slope * rel(xv, i, j))
            }
            Element::RelativeFriction { i, j, .. } => {
                scatter(y, i, Some(j), cv * slope * (xv[i] - xv[j]))
            }
        }
    }
}

/// The Jenkins law at relative displacement `d` from the committed slip
/// `slip`: (force, `∂f/∂δ`). Stuck, `k (d − slip)` with slope `k`, while
/// that trial force is within `±F_s` (the boundary included); `±F_s` with
/// slope 0 beyond.
#[inline(always)]
pub fn jenkins_law(k: f64, fs: f64, d: f64, slip: f64) -> (f64, f64) {
    let trial = k * (d - slip);
    if trial.abs() <= fs {
        (trial, k)
    } else {
        (fs.copysign(trial), 0.0)
    }
}

/// Total internal force of a set of elements with their states (`slips`,
/// one per element, as the integrator carries them).
pub fn internal_force_at(elements: &[Element], u: &[f64], v: &[f64], slips: &[f64], f: &mut [f64]) {
    f.iter_mut().for_each(|x| *x = 0.0);
    for (e, &z) in elements.iter().zip(slips) {
        e.force_and_slope_at(u, v, z, f);
    }
}

/// Total internal force of a set of elements (a Jenkins element at zero
/// slip; [`internal_force_at`] takes the slips the integrator carries).
pub fn internal_force(elements: &[Element], u: &[f64], v: &[f64], f: &mut [f64]) {
    f.iter_mut().for_each(|x| *x = 0.0);
    for e in elements {
        e.add_force(u, v, f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kind of element, active, at one state of a 3-DOF system.
    fn sample() -> (Vec<Element>, [f64; 3], [f64; 3]) {
        (
            vec![
                Element::Contact {
                    i: 0,
                    j: Some(1),
                    gap: 1e-3,
                    k: 2e6,
                },
                Element::Friction {
                    d: 1,
                    level: 0.3,
                    vreg: 1e-2,
                },
                Element::Cubic {
                    i: 2,
                    j: Some(1),
                    k3: 1e9,
                },
                Element::Cubic {
                    i: 0,
                    j: None,
                    k3: -3e8,
                },
                Element::Quadratic {
                    i: 1,
                    j: Some(2),
                    k2: -4e6,
                },
                Element::Quadratic {
                    i: 2,
                    j: None,
                    k2: 5e6,
                },
                Element::QuadraticDamper {
                    i: 0,
                    j: Some(2),
                    c2: 30.0,
                },
                Element::QuadraticDamper {
                    i: 1,
                    j: None,
                    c2: 20.0,
                },
                Element::CubicDamper {
                    i: 2,
                    j: Some(0),
                    c3: 70.0,
                },
                Element::CubicDamper {
                    i: 0,
                    j: None,
                    c3: 50.0,
                },
                Element::RelativeFriction {
                    i: 1,
                    j: 2,
                    level: 0.4,
                    vreg: 0.3,
                },
                // below its bound, and beyond it
                Element::Saturating {
                    i: 0,
                    j: Some(2),
                    k: 1e3,
                    fmax: 10.0,
                },
                Element::Saturating {
                    i: 1,
                    j: None,
                    k: 2e4,
                    fmax: 5.0,
                },
            ],
            [3e-3, 1e-3, -2e-3],
            [0.1, 4e-3, -0.2],
        )
    }

    /// Tangent `cu ∂f/∂u + cv ∂f/∂v` assembled from the slopes.
    fn tangent(els: &[Element], u: &[f64], v: &[f64], cu: f64, cv: f64, n: usize) -> Vec<f64> {
        let mut t = vec![0.0; n * n];
        let mut f = vec![0.0; n];
        for e in els {
            let s = e.force_and_slope(u, v, &mut f);
            e.add_slope(s, cu, cv, &mut t, n);
        }
        t
    }

    #[test]
    fn tangents_match_central_differences() {
        let (els, u, v) = sample();
        let n = 3;
        let t = tangent(&els, &u, &v, 1.0, 0.0, n);
        let h = 1e-8;
        for c in 0..n {
            let (mut up, mut um) = (u, u);
            up[c] += h;
            um[c] -= h;
            let (mut fp, mut fm) = (vec![0.0; n], vec![0.0; n]);
            internal_force(&els, &up, &v, &mut fp);
            internal_force(&els, &um, &v, &mut fm);
            for r in 0..n {
                let fd = (fp[r] - fm[r]) / (2.0 * h);
                approx::assert_relative_eq!(t[c * n + r], fd, max_relative = 1e-5, epsilon = 1e-3);
            }
        }
        let tv = tangent(&els, &u, &v, 0.0, 1.0, n);
        for c in 0..n {
            let (mut vp, mut vm) = (v, v);
            vp[c] += 1e-7;
            vm[c] -= 1e-7;
            let (mut fp, mut fm) = (vec![0.0; n], vec![0.0; n]);
            internal_force(&els, &u, &vp, &mut fp);
            internal_force(&els, &u, &vm, &mut fm);
            for r in 0..n {
                let fd = (fp[r] - fm[r]) / 2e-7;
                approx::assert_relative_eq!(tv[c * n + r], fd, max_relative = 1e-5, epsilon = 1e-6);
            }
        }
    }

    #[test]
    fn parameter_derivatives_match_central_differences() {
        let (els, u, v) = sample();
        let n = 3;
        let with = |e: Element, q: ElementParam, dq: f64| -> Element {
            match (e, q) {
                (Element::Contact { i, j, gap, k }, ElementParam::Gap) => Element::Contact {
                    i,
                    j,
                    gap: gap + dq,
                    k,
                },
                (Element::Contact { i, j, gap, k }, _) => Element::Contact {
                    i,
                    j,
                    gap,
                    k: k + dq,
                },
                (Element::Friction { d, level, vreg }, _) => Element::Friction {
                    d,
                    level: level + dq,
                    vreg,
                },
                (Element::Cubic { i, j, k3 }, _) => Element::Cubic { i, j, k3: k3 + dq },
                (Element::Quadratic { i, j, k2 }, _) => Element::Quadratic { i, j, k2: k2 + dq },
                (Element::QuadraticDamper { i, j, c2 }, _) => {
                    Element::QuadraticDamper { i, j, c2: c2 + dq }
                }
                (Element::CubicDamper { i, j, c3 }, _) => {
                    Element::CubicDamper { i, j, c3: c3 + dq }
                }
                (Element::RelativeFriction { i, j, level, vreg }, _) => Element::RelativeFriction {
                    i,
                    j,
                    level: level + dq,
                    vreg,
                },
                // no parameter derivatives (finite differences of the
                // simulation: its slip state has no recursion)
                (e @ Element::Jenkins { .. }, _) => e,
                // no parameter derivatives
                (e @ Element::Saturating { .. }, _) => e,
            }
        };
        let cases = [
            (0, ElementParam::Gap, 1e-3),
            (0, ElementParam::Stiffness, 2e6),
            (1, ElementParam::Level, 0.3),
            (2, ElementParam::K3, 1e9),
            (3, ElementParam::K3, 3e8),
            (4, ElementParam::K2, 4e6),
            (5, ElementParam::K2, 5e6),
            (6, ElementParam::C2, 30.0),
            (7, ElementParam::C2, 20.0),
            (8, ElementParam::C3, 70.0),
            (9, ElementParam::C3, 50.0),
            (10, ElementParam::Level, 0.4),
        ];
        for (e, q, size) in cases {
            let mut d = vec![0.0; n];
            assert!(els[e].add_param_derivative(q, 2.0, &u, &v, &mut d));
            assert!(d.iter().any(|&x| x != 0.0), "{q:?}");
            let h = 1e-6 * size;
            let (mut fp, mut fm) = (vec![0.0; n], vec![0.0; n]);
            with(els[e], q, h).add_force(&u, &v, &mut fp);
            with(els[e], q, -h).add_force(&u, &v, &mut fm);
            for r in 0..n {
                let fd = 2.0 * (fp[r] - fm[r]) / (2.0 * h);
                approx::assert_relative_eq!(d[r], fd, max_relative = 1e-7, epsilon = 1e-12);
            }
        }
        // a parameter of another kind adds nothing
        let mut d = vec![0.0; n];
        assert!(!els[1].add_param_derivative(ElementParam::Gap, 1.0, &u, &v, &mut d));
        assert!(!ElementParam::K3.belongs_to(&els[0]));
        assert_eq!(d, vec![0.0; n]);
    }

    #[test]
    fn slope_products_equal_the_assembled_tangent() {
        let (els, u, v) = sample();
        let n = 3;
        let (cu, cv) = (1.5, 0.25);
        let t = tangent(&els, &u, &v, cu, cv, n);
        let x = [0.3, -1.1, 0.7];
        let mut y = vec![0.0; n];
        let mut f = vec![0.0; n];
        for e in &els {
            let s = e.force_and_slope(&u, &v, &mut f);
            e.add_slope_product(s, (cu, &x), (cv, &x), &mut y);
        }
        for r in 0..n {
            let tx: f64 = (0..n).map(|c| t[c * n + r] * x[c]).sum();
            approx::assert_relative_eq!(y[r], tx, max_relative = 1e-14);
        }
    }

    #[test]
    fn contact_pushes_apart() {
        let e = Element::Contact {
            i: 4,
            j: Some(5),
            gap: 0.381e-3,
            k: 2e6,
        };
        let mut u = [0.0; 8];
        u[4] = 0.5e-3;
        let mut f = [0.0; 8];
        e.add_force(&u, &[0.0; 8], &mut f);
        approx::assert_relative_eq!(f[4], 2e6 * (0.5e-3 - 0.381e-3));
        approx::assert_relative_eq!(f[5], -f[4]);
        let mut f2 = [0.0; 8];
        u[4] = 0.3e-3;
        e.add_force(&u, &[0.0; 8], &mut f2);
        assert_eq!(f2, [0.0; 8]);
    }

    /// The force and loop area of a Jenkins element under an imposed
    /// relative displacement `X sin(2π t/T)`, over the second cycle (`steps`
    /// per cycle): (max |f|, ∮ f dδ by the trapezoidal rule).
    fn jenkins_loop(k: f64, fs: f64, x: f64, steps: usize) -> (f64, f64) {
        let e = Element::Jenkins {
            i: 0,
            j: Some(1),
            k,
            fs,
        };
        let (mut z, mut fmax, mut area) = (0.0, 0.0f64, 0.0);
        let (mut d_prev, mut f_prev) = (0.0, 0.0);
        for n in 1..=2 * steps {
            let d = x * (2.0 * std::f64::consts::PI * n as f64 / steps as f64).sin();
            let u = [d, 0.0];
            let mut f = [0.0; 2];
            let slope = e.force_and_slope_at(&u, &[0.0; 2], z, &mut f);
            assert!(slope == k || slope == 0.0);
            z = e.committed_slip(&u, z);
            if n > steps {
                fmax = fmax.max(f[0].abs());
                area += 0.5 * (f[0] + f_prev) * (d - d_prev);
            }
            assert_eq!(f[1], -f[0]);
            (d_prev, f_prev) = (d, f[0]);
        }
        (fmax, area)
    }

    #[test]
    fn jenkins_loop_saturates_at_the_slip_force_with_the_closed_form_area() {
        let (k, fs) = (2.0e4, 30.0);
        for x in [2.0e-3, 5.0e-3, 2.0e-2] {
            let (fmax, area) = jenkins_loop(k, fs, x, 20_000);
            assert_eq!(fmax, fs, "X {x}");
            // parallelogram: 4 F_s (X − F_s/k)
            let exact = 4.0 * fs * (x - fs / k);
            approx::assert_relative_eq!(area, exact, max_relative = 1e-3);
        }
        // below the slip displacement F_s/k it stays stuck: a line, no area
        let (fmax, area) = jenkins_loop(k, fs, 0.9 * fs / k, 20_000);
        approx::assert_relative_eq!(fmax, 0.9 * fs, max_relative = 1e-6);
        assert!(area.abs() < 1e-12 * fs * fs / k, "area {area}");
    }

    #[test]
    fn jenkins_law_sticks_then_slips_and_unloads_with_the_stuck_stiffness() {
        let (k, fs) = (1.0e3, 2.0);
        // loading from 0: stuck up to δ = 2 mm, then slipping at F_s
        assert_eq!(jenkins_law(k, fs, 1.5e-3, 0.0), (1.5, k));
        assert_eq!(jenkins_law(k, fs, 3.0e-3, 0.0), (2.0, 0.0));
        let e = Element::Jenkins {
            i: 0,
            j: None,
            k,
            fs,
        };
        let z = e.committed_slip(&[3.0e-3], 0.0);
        approx::assert_relative_eq!(z, 1.0e-3, max_relative = 1e-12);
        // unloading by 1 mm from there: stuck, f = F_s − k · 1 mm
        let (f, s) = jenkins_law(k, fs, 2.0e-3, z);
        approx::assert_relative_eq!(f, 1.0, max_relative = 1e-12);
        assert_eq!(s, k);
        // reversed slip at −F_s once δ < z − F_s/k = −1 mm
        assert_eq!(jenkins_law(k, fs, -1.5e-3, z), (-2.0, 0.0));
        assert_eq!(e.committed_slip(&[2.0e-3], z), z);
    }

    #[test]
    fn jenkins_in_the_integrator_dissipates_the_closed_form_energy() {
        // a mass on a spring k0 and a Jenkins element to ground under a
        // harmonic force: the simulated loop (u, f_int) saturates at ±F_s
        // and its area equals 4 F_s (X − F_s/k), X its half-excursion
        let (m, k0, k, fs) = (1.0, 4.0e3, 6.0e3, 3.0);
        let model = crate::model::Model {
            masses: vec![m],
            springs: vec![crate::model::Spring {
                dofs: vec![1],
                stiffness: k0,
                name: None,
            }],
            damping: crate::model::Damping::Rayleigh {
                alpha: 10.0,
                beta: 0.0,
            },
            jenkins: vec![Jenkins {
                dofs: vec![1],
                stiffness: k,
                slip_force: fs,
            }],
            ..Default::default()
        };
        let (rate, f0, hz) = (2000.0, 12.0, 8.0);
        let n = (24.0 * rate / hz) as usize;
        let force = nalgebra::DMatrix::from_fn(1, n, |_, s| {
            f0 * (2.0 * std::f64::consts::PI * hz * s as f64 / rate).sin()
        });
        let settings = crate::integrate::SimSettings {
            substeps: 4,
            ..Default::default()
        };
        let sim = crate::integrate::Integrator::new(&model, rate, settings)
            .unwrap()
            .run(force.as_view(), &[0.0], &[0.0]);
        assert!(sim.completed());
        // the last cycle
        let per = (rate / hz) as usize;
        let (a, b) = (n - per - 1, n - 1);
        let u: Vec<f64> = (a..=b).map(|s| sim.u[(0, s)]).collect();
        let f: Vec<f64> = (a..=b).map(|s| sim.fint[(0, s)]).collect();
        let fmax = f.iter().fold(0.0f64, |x, y| x.max(y.abs()));
        approx::assert_relative_eq!(fmax, fs, max_relative = 1e-9);
        let x = 0.5
            * (u.iter().cloned().fold(f64::MIN, f64::max)
                - u.iter().cloned().fold(f64::MAX, f64::min));
        assert!(x > 2.0 * fs / k, "excursion {x}: the slider must slip");
        let area: f64 = (1..u.len())
            .map(|s| 0.5 * (f[s] + f[s - 1]) * (u[s] - u[s - 1]))
            .sum();
        let exact = 4.0 * fs * (x - fs / k);
        approx::assert_relative_eq!(area, exact, max_relative = 2e-2);
    }

    /// The first-harmonic stiffness and the loop area of a saturating spring
    /// under an imposed `δ = X sin θ` (`steps` points per cycle).
    fn saturating_cycle(k: f64, fmax: f64, x: f64, steps: usize) -> (f64, f64) {
        let e = Element::Saturating {
            i: 0,
            j: Some(1),
            k,
            fmax,
        };
        let (mut b1, mut area, mut prev) = (0.0, 0.0, (0.0, 0.0));
        for n in 0..=steps {
            let th = 2.0 * std::f64::consts::PI * n as f64 / steps as f64;
            let u = [x * th.sin(), 0.0];
            let mut f = [0.0; 2];
            let slope = e.force_and_slope(&u, &[0.0; 2], &mut f);
            assert!(slope == k || slope == 0.0);
            assert!(f[0].abs() <= fmax && f[1] == -f[0]);
            if n > 0 {
                b1 += f[0] * th.sin() * 2.0 / steps as f64;
                area += 0.5 * (f[0] + prev.1) * (u[0] - prev.0);
            }
            prev = (u[0], f[0]);
        }
        (b1 / x, area)
    }

    #[test]
    fn saturating_spring_has_the_describing_function_of_a_saturation_and_no_loss() {
        let (k, fmax) = (6.0e3, 3.0);
        for x in [0.25e-3, 0.5e-3, 1.0e-3, 4.0e-3, 2.0e-2] {
            let (kx, area) = saturating_cycle(k, fmax, x, 200_000);
            let r: f64 = (fmax / (k * x)).min(1.0);
            let exact = 2.0 * k / std::f64::consts::PI * (r.asin() + r * (1.0 - r * r).sqrt());
            approx::assert_relative_eq!(kx, exact, max_relative = 1e-6);
            assert!(area.abs() < 1e-9 * fmax * x, "X {x}: loop area {area}");
        }
        // below the bound it is the linear spring
        let (kx, _) = saturating_cycle(k, fmax, 0.4 * fmax / k, 1000);
        approx::assert_relative_eq!(kx, k, max_relative = 1e-9);
    }

    #[test]
    fn saturating_spring_in_the_integrator_conserves_the_closed_form_energy() {
        // a mass on a spring k0 and a saturating spring (k, F) to ground,
        // undamped, released from x0 beyond F/k: the potential is
        // k0 x²/2 + k x²/2 (|x| ≤ F/k) or F |x| − F²/(2k) (beyond), so the
        // speed through 0 is √(2 V(x0) / m) and every turning point ±x0
        let text = "masses = [1.0]\n[[spring]]\ndofs = [1]\nstiffness = 4000.0\n\
                    [[saturating]]\ndofs = [1]\nstiffness = 6000.0\nforce = 3.0\n";
        let model = crate::model::Model::from_toml_str(text, "test").unwrap();
        assert_eq!(compile(&model).len(), 1);
        let (m, k0, k, fmax, x0): (f64, f64, f64, f64, f64) = (1.0, 4.0e3, 6.0e3, 3.0, 2.0e-3);
        let v_exact = (2.0 * (0.5 * k0 * x0 * x0 + fmax * x0 - fmax * fmax / (2.0 * k)) / m).sqrt();
        let (rate, n) = (2000.0, 4000);
        let force = nalgebra::DMatrix::zeros(1, n);
        let settings = crate::integrate::SimSettings {
            substeps: 8,
            ..Default::default()
        };
        let sim = crate::integrate::Integrator::new(&model, rate, settings)
            .unwrap()
            .run(force.as_view(), &[x0], &[0.0]);
        assert!(sim.completed(), "{:?}", sim.status);
        let vmax = (0..n).map(|s| sim.v[(0, s)].abs()).fold(0.0, f64::max);
        approx::assert_relative_eq!(vmax, v_exact, max_relative = 1e-3);
        // no loss: the last swing still reaches −x0 and +x0
        let last: Vec<f64> = (n - 200..n).map(|s| sim.u[(0, s)]).collect();
        let (lo, hi) = last
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &u| (a.min(u), b.max(u)));
        approx::assert_relative_eq!(hi, x0, max_relative = 2e-3);
        approx::assert_relative_eq!(lo, -x0, max_relative = 2e-3);
        // a bad bound is named
        let bad = text.replace("force = 3.0", "force = -1.0");
        let err = crate::model::Model::from_toml_str(&bad, "test").unwrap_err();
        assert!(err.to_string().contains("saturating[0].force"), "{err}");
    }
}
