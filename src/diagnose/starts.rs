//! Segment start states fitted to the record.
//!
//! The multiple-shooting error simulates each segment from a start state.
//! The reconstruction gives one, but from a few accelerometers its error is
//! large enough to dominate the segment error of an otherwise exact model
//! (an impacting structure amplifies it). So each start state is refined,
//! for the model being scored, by minimising the segment's weighted output
//! error
//!
//! $$ J_s(x_0) = \sum_{c,k} w_c^2 \, (y_{c,k} - \hat y_{c,k}(x_0))^2 $$
//!
//! with Gauss–Newton steps `δ = J⁺ r` from the reconstructed state. For a
//! linear model the Jacobian is exact, `∂ŷ_k/∂x_0 = C_y A^k`, and one step
//! solves the problem (the only one taken). For a nonlinear model it is the
//! forward sensitivity of the nonlinear simulation
//! ([`Integrator::run_sensitivities`], the exact derivative of the discrete
//! solution, with 2n seeds), and the iterations go on; a segment's
//! evaluation keeps its simulation's tape ([`Tape`]), so the sensitivities
//! at an accepted point are the derivative steps alone, without simulating
//! the segment again; a step that does not lower `J_s` is halved, up
//! to four times, else the segment keeps its state. Each segment is a
//! problem of the least-squares driver ([`crate::lsq`], Gauss–Newton with
//! its halving line search), the segments in parallel. `J⁺` is the
//! pseudo-inverse in states scaled to a common unit (displacements × ω,
//! [`SampledModel::state_scale`]), singular values below 1e-8 of the
//! largest dropped: directions the outputs never see (a free-free model's
//! rigid-body displacement under acceleration data) keep the reconstructed
//! value. Every model — the declared one before, the fitted one after — is
//! scored the same way.
//!
//! For a nonlinear model a segment may start in the wrong basin (the wrong
//! side of an impact; the cost is rough in a contact, docs/updating.md).
//! From the second iteration a segment may take the state where the
//! segment before ends (continuity), the segments taken in order so that a
//! run of them in a wrong basin takes the model's simulation from the last
//! good one; a segment left above 8× the median cost is run in from the
//! refined segment before; one still there is given a long run-in from 2,
//! 4, 8 or 16 segments back, or the state from which the model arrives at
//! the next segment's refined start ([`rescue`]); and one still there is
//! refined over a growing horizon (the first quarter of the segment, then
//! half, then all; and from an eighth), from the reconstructed start and
//! from the end of the segment before, the best kept ([`grow`]). Segments
//! left above 8× the median are reported ([`StartFit::stuck`]) with their
//! costs, which stay in the error.

mod arrival;
mod rescue;

use super::comparison::{segment_residual, Comparison};
use crate::integrate::{Integrator, Seeds, SimSettings, Tape};
use crate::linear::SampledModel;
use crate::model::Model;
use crate::record::Quantity;
use crate::update::shooting::Segment;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;

/// What the refinement did.
#[derive(Debug, Clone, Serialize)]
pub struct StartFit {
    /// Gauss–Newton iterations run.
    pub iterations: usize,
    /// Segments that took the previous segment's end state as their start.
    pub continued: usize,
    /// Segments whose start came from a growing horizon ([`grow`]).
    pub grown: usize,
    /// Segments whose start came from a long run-in or an arrival
    /// ([`rescue`]).
    pub rescued: usize,
    /// Segments left above [`super::settings::StartSettings::outlier`] ×
    /// the median cost after every start tried (in a wrong basin, or not
    /// predicted by the model), each with its cost; their costs stay in
    /// the error.
    pub stuck: Vec<StuckSegment>,
    /// Segment simulations run.
    pub simulations: usize,
    /// Weighted squared error summed over segments, before and after.
    pub cost: (f64, f64),
    /// Segments whose state could not be improved in the last iteration.
    pub stalled: usize,
    /// What went wrong, if anything.
    pub note: String,
}

/// A segment left far above the others ([`StartFit::stuck`]).
#[derive(Debug, Clone, Serialize)]
pub struct StuckSegment {
    /// Index of the segment.
    pub segment: usize,
    /// Its first sample.
    pub start: usize,
    /// Its weighted squared error.
    pub cost: f64,
    /// The median over the segments.
    pub median: f64,
}

/// Pseudo-inverses of the start-state Jacobian of the linear part, one per
/// segment length (in unscaled states; singular values below 1e-8 of the
/// largest, in scaled states, dropped).
struct Jacobians {
    a: DMatrix<f64>,
    cy: DMatrix<f64>,
    w: Vec<f64>,
    scale: DVector<f64>,
    pinv: BTreeMap<usize, DMatrix<f64>>,
}

impl Jacobians {
    fn new(sm: &SampledModel, cmp: &Comparison) -> Option<Jacobians> {
        let channels: Vec<_> = cmp
            .observations
            .iter()
            .map(|o| (o.quantity, o.dof - 1))
            .collect();
        let (cy, _) = sm.outputs(&channels).ok()?;
        Some(Jacobians {
            a: sm.a.clone(),
            cy,
            w: cmp.observations.iter().map(|o| o.weight).collect(),
            scale: sm.state_scale(),
            pinv: BTreeMap::new(),
        })
    }

    fn pinv(&mut self, len: usize) -> Option<&DMatrix<f64>> {
        let (a, cy, w, scale) = (&self.a, &self.cy, &self.w, &self.scale);
        if let std::collections::btree_map::Entry::Vacant(slot) = self.pinv.entry(len) {
            let (p, nx) = (cy.nrows(), cy.ncols());
            let mut j = DMatrix::zeros(len * p, nx);
            let mut blk = cy.clone();
            for k in 0..len {
                for r in 0..p {
                    for c in 0..nx {
                        j[(k * p + r, c)] = w[r] * blk[(r, c)] * scale[c];
                    }
                }
                blk = &blk * a;
            }
            let svd = j.svd(true, true);
            let tol = 1e-8 * svd.singular_values.max();
            let mut out = svd.pseudo_inverse(tol).ok()?;
            // back to unscaled states
            for r in 0..nx {
                out.row_mut(r).scale_mut(scale[r]);
            }
            slot.insert(out);
        }
        self.pinv.get(&len)
    }
}

/// Weighted residual of a segment (rows sample-major: `k p + c`) and its
/// squared norm; `None` when the prediction is not finite.
fn residual(cmp: &Comparison, seg: &Segment, y: &DMatrix<f64>) -> Option<(DVector<f64>, f64)> {
    let r = segment_residual(&cmp.observations, seg, y.columns(seg.start, seg.len))?;
    let s = r.norm_squared();
    Some((r, s))
}

/// The observed channels of a segment's simulation (p × len), as
/// [`Comparison::predict`] extracts them.
fn observed(cmp: &Comparison, run: &crate::integrate::Simulation) -> DMatrix<f64> {
    let mut y = DMatrix::zeros(cmp.observations.len(), run.len());
    for (c, o) in cmp.observations.iter().enumerate() {
        let src = match o.quantity {
            Quantity::Disp => &run.u,
            Quantity::Vel => &run.v,
            _ => &run.a,
        };
        y.row_mut(c).copy_from(&src.row(o.dof - 1));
    }
    y
}

/// Copy the columns of segment `s` from `src` into `dst`.
fn copy_segment(dst: &mut DMatrix<f64>, src: &DMatrix<f64>, s: &Segment) {
    dst.columns_mut(s.start, s.len)
        .copy_from(&src.columns(s.start, s.len));
}

/// Predict the segments one call at a time when a joint call fails (a
/// failing segment stays NaN).
fn predict_each(
    cmp: &Comparison,
    model: &Model,
    segs: &[Segment],
    sim: SimSettings,
    count: &mut usize,
) -> DMatrix<f64> {
    *count += segs.len();
    if let Ok(y) = cmp.predict(model, segs, sim) {
        return y;
    }
    let mut out = DMatrix::from_element(cmp.observations.len(), cmp.force.ncols(), f64::NAN);
    for s in segs {
        if let Ok(y) = cmp.predict(model, std::slice::from_ref(s), sim) {
            copy_segment(&mut out, &y, s);
        }
    }
    out
}

/// The Gauss–Newton step of segment `s` (weighted residual `r`) from the
/// forward sensitivities of the nonlinear simulation
/// ([`Integrator::run_sensitivities`]) with the `2n` initial-state seeds:
/// from the tape of the segment's evaluation when there is one (the
/// derivative steps alone, [`Integrator::sensitivities_from_tape`]: the
/// same numbers without simulating the segment again), else from one
/// simulation; None when the simulation or its derivatives fail.
fn sens_step(
    integ: &Integrator,
    cmp: &Comparison,
    s: &Segment,
    (r, tape): (&DVector<f64>, Option<&Tape>),
    scale: &DVector<f64>,
) -> Option<DVector<f64>> {
    let n = integ.ndof();
    let nx = 2 * n;
    let p = cmp.observations.len();
    let seeds = Seeds::initial_state(n);
    let force = cmp.force.columns(s.start, s.len);
    let d = match tape {
        Some(t) if t.samples() == s.len => integ
            .sensitivities_from_tape(force, &s.u0, &s.v0, t, &seeds)
            .ok()?,
        _ => {
            let (run, d) = integ.run_sensitivities(force, &s.u0, &s.v0, &seeds).ok()?;
            if !run.completed() {
                return None;
            }
            d
        }
    };
    if d.singular_tangent.is_some() {
        return None;
    }
    let mut j = DMatrix::zeros(s.len * p, nx);
    for q in 0..nx {
        for (c, o) in cmp.observations.iter().enumerate() {
            let src = match o.quantity {
                Quantity::Disp => &d.du[q],
                Quantity::Vel => &d.dv[q],
                _ => &d.da[q],
            };
            for k in 0..s.len {
                j[(k * p + c, q)] = o.weight * src[(o.dof - 1, k)] * scale[q];
            }
        }
    }
    if j.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let svd = j.svd(true, true);
    let smax = svd.singular_values.max();
    let d = svd.solve(r, 1e-8 * smax).ok()?;
    Some(d.component_mul(scale))
}

/// Continuity starts: every segment that directly follows another is tried
/// from the state where the previous one ends (its simulation carried one
/// sample further); the trial is kept when it lowers the segment's error.
/// The segments are taken in order, each from its predecessor as it is
/// then: when the predecessor has just taken its own trial, the trial is
/// simulated again from there, so a run of segments in a wrong basin is
/// replaced by the model's simulation from the last good one (a state the
/// segments do not see, such as a free-free structure's rigid-body
/// displacement under a stop or a spring to ground, is carried along);
/// the other trials are simulated beforehand in parallel. Returns the
/// segments changed.
fn continuity(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segs: &mut [Segment],
    y: &mut DMatrix<f64>,
    res: &mut [Option<(DVector<f64>, f64)>],
    count: &mut usize,
) -> Vec<usize> {
    let Ok(integ) = Integrator::new(model, cmp.fs, sim) else {
        return vec![];
    };
    let n = model.ndof();
    let ns = cmp.force.ncols();
    let follows = |i: usize| i > 0 && segs[i - 1].start + segs[i - 1].len == segs[i].start;
    let idx: Vec<usize> = (1..segs.len())
        .filter(|&i| follows(i) && segs[i].start < ns)
        .collect();
    *count += idx.len();
    let trials: Vec<Option<Segment>> = idx
        .par_iter()
        .map(|&i| carried(&integ, cmp, &segs[i - 1], &segs[i], n))
        .collect();
    let ok: Vec<(usize, Segment)> = idx
        .into_iter()
        .zip(trials)
        .filter_map(|(i, t)| Some((i, t?)))
        .collect();
    let trial_segs: Vec<Segment> = ok.iter().map(|(_, t)| t.clone()).collect();
    let yt = predict_each(cmp, model, &trial_segs, sim, count);
    let mut changed: Vec<usize> = vec![];
    for (i, t) in &ok {
        let i = *i;
        let old = res[i].as_ref().map_or(f64::INFINITY, |r| r.1);
        let kept = if changed.last() == Some(&(i - 1)) {
            // the predecessor has just moved: its end again, simulated alone
            *count += 2;
            carried(&integ, cmp, &segs[i - 1], &segs[i], n)
                .and_then(|t| {
                    let yi = cmp.predict(model, std::slice::from_ref(&t), sim).ok()?;
                    let r = residual(cmp, &t, &yi)?;
                    Some((t, r, Some(yi)))
                })
                .filter(|a| a.1 .1 < old)
        } else {
            residual(cmp, t, &yt)
                .filter(|r| r.1 < old)
                .map(|r| (t.clone(), r, None))
        };
        if let Some((t, r, yi)) = kept {
            copy_segment(y, yi.as_ref().unwrap_or(&yt), &t);
            segs[i] = t;
            res[i] = Some(r);
            changed.push(i);
        }
    }
    changed
}

/// Segment `s` started from where its predecessor `p` ends (`p`
/// simulated one sample past its end); `None` when `p` does not end where
/// `s` starts or its simulation fails.
fn carried(
    integ: &Integrator,
    cmp: &Comparison,
    p: &Segment,
    s: &Segment,
    n: usize,
) -> Option<Segment> {
    if p.start + p.len != s.start {
        return None;
    }
    let run = integ.run(cmp.force.columns(p.start, p.len + 1), &p.u0, &p.v0);
    if !run.completed() || run.len() != p.len + 1 {
        return None;
    }
    Some(Segment {
        start: s.start,
        len: s.len,
        u0: (0..n).map(|q| run.u[(q, p.len)]).collect(),
        v0: (0..n).map(|q| run.v[(q, p.len)]).collect(),
    })
}

/// Refine the start states of `segments` for `model` (module docs).
/// Returns the refined segments, their predictions (p × N, NaN outside the
/// segments and where a simulation failed) and what was done.
pub fn refine(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segments: &[Segment],
    iterations: usize,
) -> (Vec<Segment>, DMatrix<f64>, StartFit) {
    refine_with(cmp, model, sim, segments, (iterations, true))
}

/// [`refine`] without the long run-ins and arrivals ([`rescue`]): the
/// starts of the segments a joint fit steps (a trial model's segment far
/// above the others is left to the fit, which moves the model).
pub fn refine_for_fit(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segments: &[Segment],
    iterations: usize,
) -> (Vec<Segment>, DMatrix<f64>, StartFit) {
    refine_with(cmp, model, sim, segments, (iterations, false))
}

/// [`refine`], with the rescue of stuck segments or without.
fn refine_with(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segments: &[Segment],
    (iterations, with_rescue): (usize, bool),
) -> (Vec<Segment>, DMatrix<f64>, StartFit) {
    let (mut segs, mut y, mut fit) = refine_local(cmp, model, sim, segments, iterations, true);
    if !model.is_nonlinear() || iterations == 0 {
        return (segs, y, fit);
    }
    // segments left far above the others: run in again from where the
    // (now refined) segment before ends, then refine those alone
    let mut res: Vec<Option<(DVector<f64>, f64)>> =
        segs.iter().map(|s| residual(cmp, s, &y)).collect();
    let mut tried = vec![false; segs.len()];
    for _ in 0..cmp.starts.run_in_passes {
        let costs = segment_costs(&res);
        let picks: Vec<Pick> = outliers(&costs, &tried, cmp.starts.outlier)
            .into_iter()
            .filter(|&i| i > 0 && segs[i - 1].start + segs[i - 1].len == segs[i].start)
            .map(|i| {
                tried[i] = true;
                (i, segs[i - 1].clone(), costs[i])
            })
            .collect();
        if picks.is_empty() {
            break;
        }
        let (changed, yt, n) = run_in_refined(cmp, model, sim, &mut segs, &picks, iterations);
        fit.simulations += n;
        fit.continued += changed.len();
        if changed.is_empty() {
            break;
        }
        for &i in &changed {
            copy_segment(&mut y, &yt, &segs[i]);
            res[i] = residual(cmp, &segs[i], &y);
        }
    }
    // segments still far above the others: a long run-in from earlier
    // segments or the arrival at the next one's start ([`rescue`]), then a
    // growing horizon
    let costs = segment_costs(&res);
    let picks = outliers(&costs, &vec![false; segs.len()], cmp.starts.outlier);
    if with_rescue && !picks.is_empty() {
        let (changed, yt, n) =
            rescue::rescue(cmp, model, sim, &mut segs, (&picks, &costs), iterations);
        fit.simulations += n;
        fit.rescued += changed.len();
        for &i in &changed {
            copy_segment(&mut y, &yt, &segs[i]);
            res[i] = residual(cmp, &segs[i], &y);
        }
    }
    let costs = segment_costs(&res);
    let picks: Vec<(usize, f64)> = outliers(&costs, &vec![false; segs.len()], cmp.starts.outlier)
        .into_iter()
        .map(|i| (i, costs[i]))
        .collect();
    if !picks.is_empty() {
        let (changed, yt, n) = grow(cmp, model, sim, segments, &mut segs, &picks, iterations);
        fit.simulations += n;
        fit.grown += changed.len();
        for &i in &changed {
            copy_segment(&mut y, &yt, &segs[i]);
            res[i] = residual(cmp, &segs[i], &y);
        }
    }
    fit.stuck = stuck(&segs, &segment_costs(&res), cmp.starts.outlier);
    fit.cost.1 = res.iter().flatten().map(|r| r.1).sum();
    (segs, y, fit)
}

/// Each segment's cost (infinite where its prediction failed).
fn segment_costs(res: &[Option<(DVector<f64>, f64)>]) -> Vec<f64> {
    res.iter()
        .map(|r| r.as_ref().map_or(f64::INFINITY, |r| r.1))
        .collect()
}

/// The segments whose cost exceeds `factor` × the median.
fn stuck(segs: &[Segment], costs: &[f64], factor: f64) -> Vec<StuckSegment> {
    let mut sorted = costs.to_vec();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
    outliers(costs, &vec![false; costs.len()], factor)
        .into_iter()
        .map(|i| StuckSegment {
            segment: i,
            start: segs[i].start,
            cost: costs[i],
            median,
        })
        .collect()
}

/// Horizon schedules of [`grow`]: the fractions of a segment over which
/// the start state is refined before the whole segment.
const GROW: [&[usize]; 2] = [&[4, 2], &[8, 4, 2]];

/// Growing-horizon starts for chosen segments (index, cost now): from the
/// start state in `original`, refined ([`refine_local`]) on the first
/// quarter of the segment, then on the first half, then on all of it, each
/// stage from the one before (and again from an eighth); the best is kept
/// when it predicts the segment better than its cost now. An impact late
/// in a segment makes its cost in the start state rough (docs/updating.md, rough costs);
/// over the first part, before the impact, it is nearly quadratic, and
/// each longer stage starts close to its minimum. Returns the indices
/// changed, their predictions (p × N) and the simulations run.
fn grow(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    original: &[Segment],
    segs: &mut [Segment],
    picks: &[(usize, f64)],
    iterations: usize,
) -> (Vec<usize>, DMatrix<f64>, usize) {
    let mut sims = 0;
    let mut best: Vec<(f64, Option<Segment>)> = picks.iter().map(|&(_, c)| (c, None)).collect();
    let mut y = DMatrix::zeros(cmp.observations.len(), cmp.force.ncols());
    // origins: the reconstructed start, and the end of the refined
    // segment before (when it ends where this one starts)
    let n = model.ndof();
    let Ok(integ) = Integrator::new(model, cmp.fs, sim) else {
        return (vec![], y, sims);
    };
    let before: Vec<Segment> = picks
        .iter()
        .map(|&(i, _)| {
            let p = i.checked_sub(1).map(|j| &segs[j]);
            p.and_then(|p| carried(&integ, cmp, p, &segs[i], n))
                .unwrap_or_else(|| original[i].clone())
        })
        .collect();
    sims += picks.len();
    let origins: [&[Segment]; 2] = [
        &picks
            .iter()
            .map(|&(i, _)| original[i].clone())
            .collect::<Vec<_>>(),
        &before,
    ];
    // the four (origin, schedule) chains are independent: in parallel
    // (a few picks leave the segment-parallel refinement a core idle),
    // taken in order
    let chains: Vec<(&[Segment], &[usize])> = origins
        .iter()
        .flat_map(|o| GROW.iter().map(move |s| (*o, *s)))
        .collect();
    let grown: Vec<(Vec<Segment>, DMatrix<f64>, usize)> = chains
        .par_iter()
        .map(|&(origin, schedule)| {
            let mut sims = 0;
            let mut trial: Vec<Segment> = origin.to_vec();
            for &frac in schedule {
                let short: Vec<Segment> = trial
                    .iter()
                    .map(|s| Segment {
                        len: (s.len / frac).max(2),
                        ..s.clone()
                    })
                    .collect();
                let (refined, _, f) = refine_local(cmp, model, sim, &short, iterations, false);
                sims += f.simulations;
                for (t, r) in trial.iter_mut().zip(refined) {
                    t.u0 = r.u0;
                    t.v0 = r.v0;
                }
            }
            let (trial, y_new, f) = refine_local(cmp, model, sim, &trial, iterations, false);
            (trial, y_new, sims + f.simulations)
        })
        .collect();
    for (trial, y_new, n) in grown {
        sims += n;
        for (b, t) in best.iter_mut().zip(trial) {
            if let Some(r) = residual(cmp, &t, &y_new).filter(|r| r.1 < b.0) {
                copy_segment(&mut y, &y_new, &t);
                *b = (r.1, Some(t));
            }
        }
    }
    let mut changed = vec![];
    for (&(i, _), (_, t)) in picks.iter().zip(best) {
        if let Some(t) = t {
            segs[i] = t;
            changed.push(i);
        }
    }
    (changed, y, sims)
}

/// Segments whose cost exceeds `factor` times the median (taken to be
/// started in a wrong basin; [`super::settings::StartSettings::outlier`]), not tried yet.
pub fn outliers(costs: &[f64], tried: &[bool], factor: f64) -> Vec<usize> {
    let mut sorted: Vec<f64> = costs.to_vec();
    sorted.sort_by(f64::total_cmp);
    let Some(&median) = sorted.get(sorted.len() / 2) else {
        return vec![];
    };
    (0..costs.len())
        .filter(|&i| !tried[i] && costs[i] > factor * median)
        .collect()
}

/// A segment to run in: its index, the segment before it, and its cost
/// now.
pub type Pick = (usize, Segment, f64);

/// One segment's start state as a problem of the least-squares driver
/// ([`crate::lsq`], Gauss–Newton with its halving line search): the point
/// is the segment, its evaluation the weighted residual, the cost and the
/// prediction (p × len), its linearization the Gauss–Newton step — the
/// exact one of the linear part (`exact`: the pseudo-inverse for the
/// segment's length) or the sensitivities' ([`sens_step`]).
struct StartProblem<'a> {
    cmp: &'a Comparison,
    model: &'a Model,
    sim: SimSettings,
    exact: Option<&'a DMatrix<f64>>,
    /// The model's integrator (the one [`Comparison::predict`] builds).
    integ: Option<&'a Integrator>,
    /// Linearized by the sensitivities (a nonlinear model).
    sensitivities: bool,
    scale: &'a DVector<f64>,
    sims: usize,
}

/// A segment's evaluation: weighted residual, its squared norm, the
/// prediction of the segment's samples (p × len) and, for a nonlinear
/// model, the simulation's tape (for the sensitivities at the point,
/// [`sens_step`]).
type SegEval = (DVector<f64>, f64, DMatrix<f64>, Option<Tape>);

impl crate::lsq::Problem for StartProblem<'_> {
    type Point = Segment;
    type Eval = SegEval;
    type Lin = DVector<f64>;
    type Step = DVector<f64>;

    fn evaluate(&mut self, s: &Segment) -> Option<SegEval> {
        if let Some(integ) = self.integ {
            // the simulation [`Comparison::predict`] runs, with its tape
            // when the sensitivities will need it
            self.sims += 1;
            let force = self.cmp.force.columns(s.start, s.len);
            let (run, tape) = if self.sensitivities {
                let (run, tape) = integ.run_taped(force, &s.u0, &s.v0, false);
                (run, Some(tape))
            } else {
                (integ.run(force, &s.u0, &s.v0), None)
            };
            if !run.completed() {
                return None;
            }
            let y = observed(self.cmp, &run);
            let r = segment_residual(&self.cmp.observations, s, y.as_view())?;
            let c = r.norm_squared();
            return Some((r, c, y, tape));
        }
        let y = predict_each(
            self.cmp,
            self.model,
            std::slice::from_ref(s),
            self.sim,
            &mut self.sims,
        );
        let (r, c) = residual(self.cmp, s, &y)?;
        Some((r, c, y.columns(s.start, s.len).into_owned(), None))
    }

    fn cost(&self, e: &SegEval) -> f64 {
        e.1
    }

    fn linearize(&mut self, s: &Segment, e: &SegEval) -> Result<DVector<f64>, String> {
        match (self.exact, self.integ) {
            (Some(pinv), _) => Ok(pinv * &e.0),
            (None, Some(integ)) if self.sensitivities => {
                self.sims += 1;
                sens_step(integ, self.cmp, s, (&e.0, e.3.as_ref()), self.scale)
                    .ok_or_else(|| "the sensitivities failed".into())
            }
            (None, _) => Err("no integrator".into()),
        }
    }

    fn step(&mut self, lin: &DVector<f64>, _lambda: f64) -> Result<DVector<f64>, String> {
        Ok(lin.clone())
    }

    fn trial(&self, s: &Segment, d: &DVector<f64>, t: f64) -> Segment {
        let n = self.model.ndof();
        Segment {
            start: s.start,
            len: s.len,
            u0: (0..n).map(|q| s.u0[q] + t * d[q]).collect(),
            v0: (0..n).map(|q| s.v0[q] + t * d[n + q]).collect(),
        }
    }
}

/// A segment's refined start, its residual, cost and prediction, when it
/// improved.
type Improved = Option<(Segment, (DVector<f64>, f64, DMatrix<f64>))>;

/// How one segment's refinement went: iterations in which it took part,
/// whether the last of them failed to lower its cost, whether it is still
/// worth a step.
struct SegmentRun {
    attempts: usize,
    last_failed: bool,
    active: bool,
}

/// The segments being refined, their predictions and residuals, and what
/// the driver's problems share.
struct Refining<'a> {
    cmp: &'a Comparison,
    model: &'a Model,
    sim: SimSettings,
    pinv: BTreeMap<usize, DMatrix<f64>>,
    linear: bool,
    integ: Option<Integrator>,
    scale: DVector<f64>,
    segs: Vec<Segment>,
    y: DMatrix<f64>,
    res: Vec<Option<(DVector<f64>, f64)>>,
    sims: usize,
}

impl Refining<'_> {
    /// Up to `iterations` Gauss–Newton iterations of every segment marked
    /// in `active` (each its own problem of the least-squares driver, in
    /// parallel): a step that does not lower the segment's cost is halved
    /// down to 1/16, and a segment stops when no step lowers its cost or a
    /// step gains less than [`super::settings::StartSettings::settled`] of
    /// it. Updates `active`; returns the iterations run (the most any
    /// segment took part in) and the segments whose last iteration, at that
    /// count, failed.
    fn run(&mut self, iterations: usize, active: &mut [bool]) -> (usize, usize) {
        use crate::lsq;
        let stop = lsq::Stopping {
            max_iterations: iterations,
            x_tol: None,
            cost: lsq::CostTest::Gain(self.cmp.starts.settled),
            light: 0.0,
            stall: None,
            count_failed_attempt: true,
        };
        let method = lsq::Method::LineSearch { min_t: 1.0 / 16.0 };
        let idx: Vec<usize> = (0..self.segs.len()).filter(|&i| active[i]).collect();
        let this = &*self;
        let runs: Vec<(SegmentRun, Improved, usize)> = idx
            .par_iter()
            .map(|&i| {
                let Some((r, c)) = this.res[i].clone() else {
                    let failed = SegmentRun {
                        attempts: usize::from(iterations > 0),
                        last_failed: true,
                        active: false,
                    };
                    return (failed, None, 0);
                };
                let seg = &this.segs[i];
                let mut q = StartProblem {
                    cmp: this.cmp,
                    model: this.model,
                    sim: this.sim,
                    exact: this.pinv.get(&seg.len).filter(|_| this.linear),
                    integ: this.integ.as_ref(),
                    sensitivities: !this.linear,
                    scale: &this.scale,
                    sims: 0,
                };
                let y0 = this.y.columns(seg.start, seg.len).into_owned();
                let out = lsq::minimize_from(&mut q, seg.clone(), (r, c, y0, None), method, &stop);
                let run = segment_run(&out.termination, out.iterations);
                let improved = out.history.len() > 1;
                // the tape is dropped here: one per segment at a time
                let kept = improved.then(|| {
                    let (r, c, y, _) = out.eval.expect("evaluated");
                    (out.point, (r, c, y))
                });
                (run, kept, q.sims)
            })
            .collect();
        let done = runs.iter().map(|r| r.0.attempts).max().unwrap_or(0);
        let mut stalled = 0;
        for (&i, (run, kept, sims)) in idx.iter().zip(runs) {
            self.sims += sims;
            stalled += usize::from(run.attempts == done && run.last_failed);
            active[i] = run.active;
            if let Some((seg, (r, c, y))) = kept {
                self.y.columns_mut(seg.start, seg.len).copy_from(&y);
                self.res[i] = Some((r, c));
                self.segs[i] = seg;
            }
        }
        (done, stalled)
    }
}

/// A segment's [`SegmentRun`] from how its driver stopped after
/// `iterations` (failed attempts counted).
fn segment_run(t: &crate::lsq::Termination, iterations: usize) -> SegmentRun {
    use crate::lsq::Termination as T;
    match t {
        // the last step gained enough: worth another
        T::IterationLimit => SegmentRun {
            attempts: iterations,
            last_failed: false,
            active: true,
        },
        T::Converged(_) => SegmentRun {
            attempts: iterations,
            last_failed: false,
            active: false,
        },
        // no step could be taken: an attempt that failed
        T::LinearizationFailed(_) | T::SolveFailed(_) => SegmentRun {
            attempts: iterations + 1,
            last_failed: true,
            active: false,
        },
        _ => SegmentRun {
            attempts: iterations,
            last_failed: true,
            active: false,
        },
    }
}

/// [`refine`] without the run-in passes (and without continuity starts
/// when `continue_from` is false).
fn refine_local(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segments: &[Segment],
    iterations: usize,
    continue_from: bool,
) -> (Vec<Segment>, DMatrix<f64>, StartFit) {
    let mut sims = 0;
    let segs = segments.to_vec();
    let y = predict_each(cmp, model, &segs, sim, &mut sims);
    let res: Vec<Option<(DVector<f64>, f64)>> = segs.iter().map(|s| residual(cmp, s, &y)).collect();
    let cost0: f64 = res.iter().flatten().map(|r| r.1).sum();
    let sampled = SampledModel::from_model(&model.linear_part(), cmp.fs, sim.substeps).ok();
    let Some(sm) = sampled else {
        let fit = StartFit {
            iterations: 0,
            simulations: sims,
            cost: (cost0, cost0),
            continued: 0,
            grown: 0,
            rescued: 0,
            stuck: vec![],
            stalled: segs.len(),
            note: "the linear part of the model could not be sampled; start states kept".into(),
        };
        return (segs, y, fit);
    };
    // a linear model: the Jacobian is exact and one step solves the problem
    let jac = if model.is_nonlinear() {
        None
    } else {
        Jacobians::new(&sm, cmp)
    };
    let exact = jac.is_some();
    let mut pinv = BTreeMap::new();
    if let Some(mut jac) = jac {
        for s in &segs {
            if let Some(p) = jac.pinv(s.len) {
                pinv.entry(s.len).or_insert_with(|| p.clone());
            }
        }
    }
    let iterations = if exact { iterations.min(1) } else { iterations };
    let mut run = Refining {
        cmp,
        model,
        sim,
        pinv,
        linear: exact,
        integ: Integrator::new(model, cmp.fs, sim).ok(),
        scale: sm.state_scale(),
        segs,
        y,
        res,
        sims,
    };
    // segments still worth a step: one whose last step failed would take
    // the same step again, and one whose last step gained less than
    // [`super::settings::StartSettings::settled`] of its cost has settled
    let mut active = vec![true; run.segs.len()];
    // from the second iteration of a nonlinear model: a segment may start
    // instead from where the previous one ends (continuity), when that
    // predicts it better (a refinement stuck in a local minimum; the cost
    // is rough in a contact, docs/updating.md)
    let with_continuity = continue_from && !exact && iterations >= 2;
    let first = if with_continuity { 1 } else { iterations };
    let (mut done, mut stalled) = run.run(first, &mut active);
    let mut continued = 0;
    if with_continuity {
        let Refining {
            segs, y, res, sims, ..
        } = &mut run;
        let changed = continuity(cmp, model, sim, segs, y, res, sims);
        continued = changed.len();
        for i in changed {
            active[i] = true;
        }
        let (more, st) = run.run(iterations - 1, &mut active);
        if more > 0 {
            done += more;
            stalled = st;
        }
    }
    let cost1: f64 = run.res.iter().flatten().map(|r| r.1).sum();
    let fit = StartFit {
        iterations: done,
        continued,
        grown: 0,
        rescued: 0,
        stuck: vec![],
        simulations: run.sims,
        cost: (cost0, cost1),
        stalled,
        note: String::new(),
    };
    (run.segs, run.y, fit)
}

/// Run-in starts for chosen segments, given as [`Pick`]s with the
/// predecessor's reconstructed start state: the predecessors are refined
/// for `model` ([`refine`]) and simulated one sample past their end; the
/// state there, refined in turn, replaces the segment's start when it
/// predicts the segment better than its cost now (a start state stuck in
/// a wrong basin — the wrong side of an impact — that the local refinement
/// cannot leave; the cost is rough in a contact, docs/updating.md). Returns the indices changed and the
/// simulations run.
pub fn run_in(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segs: &mut [Segment],
    picks: &[Pick],
    iterations: usize,
) -> (Vec<usize>, usize) {
    let preds: Vec<Segment> = picks.iter().map(|p| p.1.clone()).collect();
    let (preds, _, f) = refine_local(cmp, model, sim, &preds, iterations, false);
    let picks: Vec<Pick> = picks
        .iter()
        .zip(preds)
        .map(|(p, pred)| (p.0, pred, p.2))
        .collect();
    let (changed, _, n) = run_in_refined(cmp, model, sim, segs, &picks, iterations);
    (changed, f.simulations + n)
}

/// [`run_in`] from predecessors already refined; also returns the
/// predictions of the segments changed (p × N).
fn run_in_refined(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segs: &mut [Segment],
    picks: &[Pick],
    iterations: usize,
) -> (Vec<usize>, DMatrix<f64>, usize) {
    let empty = || DMatrix::zeros(0, 0);
    let Ok(integ) = Integrator::new(model, cmp.fs, sim) else {
        return (vec![], empty(), 0);
    };
    let n = model.ndof();
    let mut sims = picks.len();
    let cands: Vec<Option<(usize, Segment, f64)>> = picks
        .par_iter()
        .map(|(i, p, cost)| Some((*i, carried(&integ, cmp, p, &segs[*i], n)?, *cost)))
        .collect();
    let cands: Vec<(usize, Segment, f64)> = cands.into_iter().flatten().collect();
    if cands.is_empty() {
        return (vec![], empty(), sims);
    }
    let trial: Vec<Segment> = cands.iter().map(|c| c.1.clone()).collect();
    let (trial, y_new, f) = refine_local(cmp, model, sim, &trial, iterations, false);
    sims += f.simulations;
    let mut changed = vec![];
    for ((i, _, before), t) in cands.iter().zip(&trial) {
        if residual(cmp, t, &y_new).is_some_and(|r| r.1 < *before) {
            segs[*i] = t.clone();
            changed.push(*i);
        }
    }
    (changed, y_new, sims)
}
