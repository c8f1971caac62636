//! Arrival starts: a segment's start state found from the refined start
//! of the segment after it.
//!
//! A segment whose refined start stays in a wrong basin, and that has no
//! well-fitted segment before it (the first segment of a record cut from
//! a running test), is given the state `x₀` from which the model arrives,
//! one segment later, at the refined start `x₁` of the next segment:
//!
//! $$ \min_{x_0} \| S^{-1} (x_1 - \Phi_L(x_0)) \|^2 , $$
//!
//! `Φ_L` the model's flow over the segment's `L` samples and `S` the state
//! scale ([`SampledModel::state_scale`]). Its Jacobian is the flow's
//! state sensitivity (`2n × 2n`, from the tape of the evaluation), well
//! conditioned over a segment of a damped structure: unlike the output
//! error it sees every state direction, a start on the wrong side of an
//! impact included. The state found is then refined on the segment's data
//! as every start is.

use super::Comparison;
use crate::integrate::{Integrator, Seeds, Tape};
use crate::update::shooting::Segment;
use nalgebra::{DMatrix, DVector};

/// The arrival problem of one segment for the least-squares driver: the
/// point is the segment's start (its `len` the segment's), the residual
/// the scaled defect at the next segment's start.
pub(super) struct Arrival<'a> {
    pub cmp: &'a Comparison,
    pub integ: &'a Integrator,
    /// The next segment's start state `(u; v)`.
    pub target: DVector<f64>,
    /// State scale (displacements × ω, velocities).
    pub scale: &'a DVector<f64>,
    /// Simulations run.
    pub sims: usize,
}

/// The defect, its squared norm and the tape of the run.
type ArrivalEval = (DVector<f64>, f64, Tape);

impl crate::lsq::Problem for Arrival<'_> {
    type Point = Segment;
    type Eval = ArrivalEval;
    type Lin = DVector<f64>;
    type Step = DVector<f64>;

    fn evaluate(&mut self, s: &Segment) -> Option<ArrivalEval> {
        self.sims += 1;
        let force = self.cmp.force.columns(s.start, s.len + 1);
        let (run, tape) = self.integ.run_taped(force, &s.u0, &s.v0, false);
        if !run.completed() || run.len() != s.len + 1 {
            return None;
        }
        let n = s.u0.len();
        let r = DVector::from_fn(2 * n, |q, _| {
            let x = if q < n {
                run.u[(q, s.len)]
            } else {
                run.v[(q - n, s.len)]
            };
            (self.target[q] - x) / self.scale[q]
        });
        let c = r.norm_squared();
        c.is_finite().then_some((r, c, tape))
    }

    fn cost(&self, e: &ArrivalEval) -> f64 {
        e.1
    }

    fn linearize(&mut self, s: &Segment, e: &ArrivalEval) -> Result<DVector<f64>, String> {
        let n = s.u0.len();
        let force = self.cmp.force.columns(s.start, s.len + 1);
        let d = self
            .integ
            .sensitivities_from_tape(force, &s.u0, &s.v0, &e.2, &Seeds::initial_state(n))
            .map_err(|e| e.to_string())?;
        if d.singular_tangent.is_some() {
            return Err("singular tangent".into());
        }
        let j = DMatrix::from_fn(2 * n, 2 * n, |r, q| {
            let x = if r < n {
                d.du[q][(r, s.len)]
            } else {
                d.dv[q][(r - n, s.len)]
            };
            x * self.scale[q] / self.scale[r]
        });
        if j.iter().any(|v| !v.is_finite()) {
            return Err("derivatives not finite".into());
        }
        let svd = j.svd(true, true);
        let tol = 1e-10 * svd.singular_values.max();
        let dz = svd.solve(&e.0, tol)?;
        Ok(dz.component_mul(self.scale))
    }

    fn step(&mut self, lin: &DVector<f64>, _lambda: f64) -> Result<DVector<f64>, String> {
        Ok(lin.clone())
    }

    fn trial(&self, s: &Segment, d: &DVector<f64>, t: f64) -> Segment {
        let n = s.u0.len();
        Segment {
            start: s.start,
            len: s.len,
            u0: (0..n).map(|q| s.u0[q] + t * d[q]).collect(),
            v0: (0..n).map(|q| s.v0[q] + t * d[n + q]).collect(),
        }
    }
}

/// The start of `seg` from which the model arrives at the start of
/// `next` (which must follow it directly), found from `seg`'s start by
/// Gauss–Newton on the arrival defect; None when `next` does not follow
/// or the runs fail.
pub(super) fn arrive(
    cmp: &Comparison,
    integ: &Integrator,
    scale: &DVector<f64>,
    seg: &Segment,
    next: &Segment,
    sims: &mut usize,
) -> Option<Segment> {
    if seg.start + seg.len != next.start || next.start >= cmp.force.ncols() {
        return None;
    }
    let target = DVector::from_iterator(
        2 * seg.u0.len(),
        next.u0.iter().chain(next.v0.iter()).copied(),
    );
    let mut q = Arrival {
        cmp,
        integ,
        target,
        scale,
        sims: 0,
    };
    let stop = crate::lsq::Stopping {
        max_iterations: 12,
        x_tol: None,
        cost: crate::lsq::CostTest::Gain(1e-4),
        light: 0.0,
        stall: None,
        count_failed_attempt: true,
    };
    let method = crate::lsq::Method::LineSearch { min_t: 1.0 / 64.0 };
    let out = crate::lsq::minimize(&mut q, seg.clone(), method, &stop);
    *sims += q.sims;
    out.eval.is_some().then_some(out.point)
}
