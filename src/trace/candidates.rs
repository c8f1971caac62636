//! The candidate effects and their unit-strength internal forces.

use crate::model::Model;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Kind of effect (the names used in `report.json`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
pub enum EffectKind {
    /// Penalty contact i→j with a gap: force `k_c (u_i − u_j − g)` when positive.
    Contact,
    /// Coulomb friction to ground at one DOF (or the same level at several).
    Friction,
    /// Cubic spring between two DOFs or to ground.
    Cubic,
    /// Stiffness change of an existing spring.
    Stiffness,
    /// A linear spring from a DOF to ground.
    GroundSpring,
    /// A change of the model's viscous damping (`δ C v`).
    Damping,
    /// Quadratic (asymmetric) spring between two DOFs or to ground:
    /// `k_2 δ²`.
    Quadratic,
    /// Quadratic damper in the relative velocity: `c_2 ν|ν|`.
    QuadraticDamping,
    /// Cubic damper in the relative velocity: `c_3 ν³`.
    CubicDamping,
    /// Two-sided clearance between two DOFs: `k_c (|δ| − g) sign(δ)` beyond
    /// the gap.
    Clearance,
    /// Coulomb friction between two DOFs (relative sliding).
    RelativeFriction,
}

impl EffectKind {
    /// The internal force is linear in the state (a stiffness change, a
    /// spring to ground, a damping change).
    pub fn linear_in_state(self) -> bool {
        matches!(
            self,
            EffectKind::Stiffness | EffectKind::GroundSpring | EffectKind::Damping
        )
    }

    /// A change of a parameter the declared linear part already has (a
    /// stiffness or damping change), not an element of its own.
    pub fn changes_linear_part(self) -> bool {
        matches!(self, EffectKind::Stiffness | EffectKind::Damping)
    }

    /// The effect dissipates energy along a law other than the viscous
    /// damping's (friction to ground or between DOFs, a nonlinear damper):
    /// it is fitted with the model's damping free beside it
    /// ([`crate::diagnose::effects::damping_targets`]).
    pub fn dissipative(self) -> bool {
        matches!(
            self,
            EffectKind::Friction
                | EffectKind::RelativeFriction
                | EffectKind::QuadraticDamping
                | EffectKind::CubicDamping
        )
    }

    /// Name as in reports.
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::Contact => "contact",
            EffectKind::Friction => "friction",
            EffectKind::Cubic => "cubic",
            EffectKind::Stiffness => "stiffness",
            EffectKind::GroundSpring => "ground_spring",
            EffectKind::Damping => "damping",
            EffectKind::Quadratic => "quadratic",
            EffectKind::QuadraticDamping => "quadratic_damping",
            EffectKind::CubicDamping => "cubic_damping",
            EffectKind::Clearance => "clearance",
            EffectKind::RelativeFriction => "relative_friction",
        }
    }

    /// The best paying candidate acting along the located force
    /// directions is moved ahead of better-scoring ones ([`super::trace`])
    /// when it is of this kind: the contact, friction, cubic, stiffness,
    /// ground-spring and damping kinds. A quadratic spring, damper,
    /// clearance or friction between DOFs that is the best along them
    /// stays where its score puts it (and so does the rest): with the
    /// preference, a friction of 9 mN between DOFs 1 and 2 was taken
    /// ahead of the 0.5 N friction on every mass, and a quadratic damper
    /// to ground at 3 ahead of the damper 2–3 it lay on.
    pub fn preferred_when_located(self) -> bool {
        matches!(
            self,
            EffectKind::Contact
                | EffectKind::Friction
                | EffectKind::Cubic
                | EffectKind::Stiffness
                | EffectKind::GroundSpring
                | EffectKind::Damping
        )
    }

    /// The strength multiplies a law with a gap (contact, clearance): the
    /// gap is scanned and reported first.
    pub fn has_gap(self) -> bool {
        matches!(self, EffectKind::Contact | EffectKind::Clearance)
    }
}

/// One candidate effect. DOFs are 0-based here.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Candidate {
    /// Kind.
    pub kind: EffectKind,
    /// DOFs (0-based): `[i, j]` for a pair (contact: on when `u_i − u_j > gap`),
    /// `[i]` for a DOF to ground; friction may list several DOFs sharing a level.
    pub dofs: Vec<usize>,
    /// Index of the spring for [`EffectKind::Stiffness`].
    pub spring: Option<usize>,
    /// Gap for a contact or clearance (m), fixed during the regression.
    pub gap: Option<f64>,
    /// Regularisation velocity of friction (m/s).
    pub vreg: f64,
    /// Nominal stiffness of the spring for [`EffectKind::Stiffness`] (N/m),
    /// so the strength is reported as a relative change.
    pub nominal: f64,
}

impl Candidate {
    /// A candidate with default settings.
    pub fn new(kind: EffectKind, dofs: Vec<usize>) -> Candidate {
        Candidate {
            kind,
            dofs,
            spring: None,
            gap: None,
            vreg: 1e-3,
            nominal: 1.0,
        }
    }

    /// Short label with DOFs from 1, e.g. `contact 5→6`, `friction @3`.
    pub fn label(&self) -> String {
        let d: Vec<String> = self.dofs.iter().map(|d| (d + 1).to_string()).collect();
        match (self.kind, self.dofs.len()) {
            (EffectKind::Contact, 2) => format!("contact {}→{}", d[0], d[1]),
            (EffectKind::Damping, _) => "damping (all modes)".into(),
            (_, 1) => format!("{} @{}", self.kind.name(), d[0]),
            (EffectKind::Friction, _) => format!("friction @{}", d.join(",")),
            _ => format!("{} {}", self.kind.name(), d.join("–")),
        }
    }

    /// Number of parameters (for the information criterion).
    pub fn nparams(&self) -> usize {
        if self.kind.has_gap() {
            2
        } else {
            1
        }
    }

    /// Force direction for pair/ground effects: `e_i − e_j` or `e_i`; `None`
    /// for effects with a force at several DOFs.
    pub fn direction(&self, n: usize) -> Option<DVector<f64>> {
        match self.kind {
            EffectKind::Damping => None,
            EffectKind::Friction if self.dofs.len() > 1 => None,
            _ => {
                let mut d = DVector::zeros(n);
                d[self.dofs[0]] = 1.0;
                if self.dofs.len() == 2 {
                    d[self.dofs[1]] = -1.0;
                }
                Some(d)
            }
        }
    }

    /// Relative displacement (pair) or displacement (ground) at sample k.
    pub fn delta(&self, states: &DMatrix<f64>, k: usize) -> f64 {
        let i = self.dofs[0];
        match self.dofs.get(1) {
            Some(&j) if self.dofs.len() == 2 => states[(i, k)] - states[(j, k)],
            _ => states[(i, k)],
        }
    }

    /// Relative velocity (pair) or velocity (ground) at sample k.
    pub fn delta_rate(&self, states: &DMatrix<f64>, n: usize, k: usize) -> f64 {
        let i = self.dofs[0];
        match self.dofs.get(1) {
            Some(&j) if self.dofs.len() == 2 => states[(n + i, k)] - states[(n + j, k)],
            _ => states[(n + i, k)],
        }
    }

    /// Scalar shape history `φ(t)` (unit strength) for effects with one
    /// direction: contact `max(δ − g, 0)`, friction `tanh(v/v_r)` (also
    /// between two DOFs, on the relative velocity), cubic `δ³`, quadratic
    /// `δ²`, dampers `ν|ν|` and `ν³`, clearance `max(|δ| − g, 0) sign(δ)`,
    /// stiffness `k_nominal δ` (strength = relative change) and ground
    /// spring `δ`.
    pub fn shape(&self, states: &DMatrix<f64>, n: usize) -> Vec<f64> {
        let ns = states.ncols();
        (0..ns)
            .map(|k| {
                let d = self.delta(states, k);
                match self.kind {
                    EffectKind::Contact | EffectKind::Clearance => self.gap_law(d),
                    EffectKind::Friction | EffectKind::RelativeFriction => {
                        (self.delta_rate(states, n, k) / self.vreg).tanh()
                    }
                    EffectKind::Cubic => d * d * d,
                    EffectKind::Stiffness => d * self.nominal,
                    EffectKind::GroundSpring => d,
                    EffectKind::Damping => 0.0,
                    EffectKind::Quadratic => d * d,
                    EffectKind::QuadraticDamping => {
                        let w = self.delta_rate(states, n, k);
                        w * w.abs()
                    }
                    EffectKind::CubicDamping => self.delta_rate(states, n, k).powi(3),
                }
            })
            .collect()
    }

    /// Unit-stiffness law of a contact (`max(δ − g, 0)`) or clearance
    /// (`max(|δ| − g, 0) sign(δ)`) at relative displacement `d` (0 for
    /// the other kinds).
    pub fn gap_law(&self, d: f64) -> f64 {
        let g = self.gap.unwrap_or(0.0);
        match self.kind {
            EffectKind::Contact => (d - g).max(0.0),
            EffectKind::Clearance => (d.abs() - g).max(0.0) * d.signum(),
            _ => 0.0,
        }
    }

    /// Full internal-force history (n × N) at unit strength, for any kind;
    /// `c` is the model's damping matrix (for [`EffectKind::Damping`]).
    pub fn force(&self, states: &DMatrix<f64>, c: &DMatrix<f64>) -> DMatrix<f64> {
        let n = states.nrows() / 2;
        let ns = states.ncols();
        match self.kind {
            EffectKind::Damping => c * states.rows(n, n),
            EffectKind::Friction if self.dofs.len() > 1 => {
                let mut f = DMatrix::zeros(n, ns);
                for &d in &self.dofs {
                    for k in 0..ns {
                        f[(d, k)] = (states[(n + d, k)] / self.vreg).tanh();
                    }
                }
                f
            }
            _ => {
                let mut f = DMatrix::zeros(n, ns);
                let phi = self.shape(states, n);
                for (k, p) in phi.iter().enumerate() {
                    f[(self.dofs[0], k)] = *p;
                    if self.dofs.len() == 2 {
                        f[(self.dofs[1], k)] = -*p;
                    }
                }
                f
            }
        }
    }
}

/// Pairs of DOFs joined by a spring of the model (0-based, i < j), and the
/// spring index; then the model's interface pairs not joined by a spring
/// (index `usize::MAX`).
pub fn spring_pairs(model: &Model) -> Vec<(usize, usize, usize)> {
    let mut out = Vec::new();
    for (s, sp) in model.springs.iter().enumerate() {
        if let (i, Some(j)) = sp.ends() {
            out.push((i.min(j), i.max(j), s));
        }
    }
    for &[i, j] in &model.interface_pairs {
        let (a, b) = ((i - 1).min(j - 1), (i - 1).max(j - 1));
        if !out.iter().any(|p| (p.0, p.1) == (a, b)) {
            out.push((a, b, usize::MAX));
        }
    }
    out
}

/// The candidate library for a model: contact on each spring-joined pair in
/// both directions (and, for a model from matrices or one with a spring to
/// ground, a stop against ground at each DOF), friction at each DOF and at
/// all DOFs with one level, a cubic spring on each spring-joined pair and
/// from each DOF to ground, a
/// stiffness change of each spring, a spring to ground at each DOF, a
/// change of the viscous damping (when the model has damping); then a
/// quadratic spring, a quadratic and a cubic damper on each spring-joined
/// pair and from each DOF to ground, and a clearance and friction on each
/// spring-joined pair.
pub fn library(model: &Model, has_damping: bool, vreg: f64) -> Vec<Candidate> {
    let n = model.physical_ndof();
    let pairs = spring_pairs(model);
    let mut out = Vec::new();
    for &(i, j, _) in &pairs {
        out.push(Candidate::new(EffectKind::Contact, vec![i, j]));
        out.push(Candidate::new(EffectKind::Contact, vec![j, i]));
    }
    // a model from matrices or one held to ground by a spring: a stop
    // against ground at each DOF too (a free-free lumped model's absolute
    // displacement drifts: its ground laws are screened apart,
    // `diagnose::ground`)
    if !model.points.is_empty() || model.has_ground_spring() {
        for d in 0..n {
            out.push(Candidate::new(EffectKind::Contact, vec![d]));
        }
    }
    for d in 0..n {
        out.push(Candidate {
            vreg,
            ..Candidate::new(EffectKind::Friction, vec![d])
        });
    }
    if n > 1 {
        out.push(Candidate {
            vreg,
            ..Candidate::new(EffectKind::Friction, (0..n).collect())
        });
    }
    for &(i, j, _) in &pairs {
        out.push(Candidate::new(EffectKind::Cubic, vec![i, j]));
    }
    for d in 0..n {
        out.push(Candidate::new(EffectKind::Cubic, vec![d]));
    }
    for (s, sp) in model.springs.iter().enumerate() {
        let (i, j) = sp.ends();
        let dofs = match j {
            Some(j) => vec![i, j],
            None => vec![i],
        };
        out.push(Candidate {
            spring: Some(s),
            nominal: sp.stiffness,
            ..Candidate::new(EffectKind::Stiffness, dofs)
        });
    }
    for d in 0..n {
        out.push(Candidate::new(EffectKind::GroundSpring, vec![d]));
    }
    if has_damping {
        out.push(Candidate::new(EffectKind::Damping, (0..n).collect()));
    }
    for kind in [
        EffectKind::Quadratic,
        EffectKind::QuadraticDamping,
        EffectKind::CubicDamping,
    ] {
        for &(i, j, _) in &pairs {
            out.push(Candidate::new(kind, vec![i, j]));
        }
        for d in 0..n {
            out.push(Candidate::new(kind, vec![d]));
        }
    }
    for &(i, j, _) in &pairs {
        out.push(Candidate::new(EffectKind::Clearance, vec![i, j]));
        out.push(Candidate {
            vreg,
            ..Candidate::new(EffectKind::RelativeFriction, vec![i, j])
        });
    }
    out
}

/// The model's viscous damping matrix split into the parts its damping
/// parameters scale, each at the parameter's value (so a part is the
/// derivative of `C` along a relative change of that parameter): one per
/// flexible mode with its own ratio, the whole `C` for one ratio of every
/// mode, `α M` and `β K` for Rayleigh damping; parts that are zero are
/// left out, and so is everything when the modes cannot be solved.
pub fn damping_parts(model: &Model) -> Vec<DMatrix<f64>> {
    use crate::model::Damping;
    let (m, k) = (model.mass_matrix(), model.stiffness_matrix());
    let parts = match &model.damping {
        Damping::None => vec![],
        Damping::Rayleigh { alpha, beta } => vec![&m * *alpha, &k * *beta],
        Damping::Modal { ratio: Some(_), .. } => {
            crate::model::damping_matrix(&model.damping, &m, &k)
                .ok()
                .into_iter()
                .collect()
        }
        Damping::Modal {
            ratio: None,
            ratios,
        } => modal_parts(&m, &k, ratios),
    };
    parts.into_iter().filter(|p| p.amax() > 0.0).collect()
}

/// [`damping_parts`] of per-mode ratios: the flexible modes beyond the
/// last ratio take it (as [`crate::model::damping_matrix`] does).
fn modal_parts(m: &DMatrix<f64>, k: &DMatrix<f64>, ratios: &[f64]) -> Vec<DMatrix<f64>> {
    let Ok(modes) = crate::modal::solve(m, k) else {
        return vec![];
    };
    let n = m.nrows();
    let mphi = m * &modes.shapes;
    let mut parts = vec![DMatrix::zeros(n, n); ratios.len()];
    let flexible = (0..modes.omega.len()).filter(|&r| !modes.rigid[r]);
    for (flex, r) in flexible.enumerate() {
        let Some(i) = crate::model::modal_ratio_index(flex, ratios.len()) else {
            break;
        };
        let v = mphi.column(r);
        parts[i] += v * v.transpose() * (2.0 * ratios[i] * modes.omega[r]);
    }
    parts
}
