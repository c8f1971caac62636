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
//! solution: one simulation of every segment per iteration, with 2n seeds),
//! and the iterations go on; a step that does not lower `J_s` is halved, up
//! to four times (the halving schedule of the least-squares driver,
//! [`crate::lsq::halving`], every segment still pending at one step
//! fraction so that their simulations run together), else the segment
//! keeps its state. `J⁺` is the
//! pseudo-inverse in states scaled to a common unit (displacements × ω,
//! [`SampledModel::state_scale`]), singular values below 1e-8 of the
//! largest dropped: directions the outputs never see (a free-free model's
//! rigid-body displacement under acceleration data) keep the reconstructed
//! value. Every model — the declared one before, the fitted one after — is
//! scored the same way.
//!
//! For a nonlinear model a segment may start in the wrong basin (the wrong
//! side of an impact; the cost is rough in a contact, docs/updating.md). From the second iteration a segment
//! may take the state where the segment before ends (continuity); a
//! segment left above 8× the median cost is run in from the refined
//! segment before; and one still there is refined over a growing horizon
//! (the first quarter of the segment, then half, then all; and from an
//! eighth), from the reconstructed start and from the end of the segment
//! before, the best kept ([`grow`]). On a 0.203 mm bumper seen by three
//! sensors this brought the exact model's error from 14 % to 1.3 % (the
//! noise), and the fitted model's from 26 % to 1.3 %.

use super::comparison::{segment_residual, Comparison};
use crate::integrate::{Integrator, Seeds, SimSettings};
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
    /// Segment simulations run.
    pub simulations: usize,
    /// Weighted squared error summed over segments, before and after.
    pub cost: (f64, f64),
    /// Segments whose state could not be improved in the last iteration.
    pub stalled: usize,
    /// What went wrong, if anything.
    pub note: String,
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

/// Gauss–Newton steps from the forward sensitivities of the nonlinear
/// simulation ([`Integrator::run_sensitivities`]): one simulation of every
/// segment with the `2n` initial-state seeds. A segment whose simulation or
/// derivatives fail gets no step.
fn sens_steps(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segs: &[Segment],
    res: &[Option<(DVector<f64>, f64)>],
    scale: &DVector<f64>,
    count: &mut usize,
) -> Vec<Option<DVector<f64>>> {
    let n = model.ndof();
    let nx = 2 * n;
    let p = cmp.observations.len();
    let Ok(integ) = Integrator::new(model, cmp.fs, sim) else {
        return vec![None; segs.len()];
    };
    let seeds = Seeds::initial_state(n);
    *count += res.iter().filter(|r| r.is_some()).count();
    // segments are independent: in parallel, collected in order (the same
    // numbers whatever the thread count)
    segs.par_iter()
        .zip(res)
        .map(|(s, r)| {
            let (r, _) = r.as_ref()?;
            let force = cmp.force.columns(s.start, s.len);
            let (run, d) = integ.run_sensitivities(force, &s.u0, &s.v0, &seeds).ok()?;
            if !run.completed() || d.singular_tangent.is_some() {
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
        })
        .collect()
}

/// Continuity starts: every segment that directly follows another is tried
/// from the state where the previous one ends (its simulation carried one
/// sample further); the trial is kept when it lowers the segment's error.
/// Returns the segments changed.
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
    let mut changed = vec![];
    for (i, t) in &ok {
        let old = res[*i].as_ref().map_or(f64::INFINITY, |r| r.1);
        if let Some(r) = residual(cmp, t, &yt) {
            if r.1 < old {
                copy_segment(y, &yt, t);
                segs[*i] = t.clone();
                res[*i] = Some(r);
                changed.push(*i);
            }
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
        let costs: Vec<f64> = res
            .iter()
            .map(|r| r.as_ref().map_or(f64::INFINITY, |r| r.1))
            .collect();
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
    // segments still far above the others: a growing horizon from the
    // reconstructed start
    let costs: Vec<f64> = res
        .iter()
        .map(|r| r.as_ref().map_or(f64::INFINITY, |r| r.1))
        .collect();
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
    fit.cost.1 = res.iter().flatten().map(|r| r.1).sum();
    (segs, y, fit)
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

/// The segments being refined, their predictions and residuals.
struct Stepping<'a> {
    cmp: &'a Comparison,
    model: &'a Model,
    sim: SimSettings,
    segs: &'a mut Vec<Segment>,
    y: &'a mut DMatrix<f64>,
    res: &'a mut Vec<Option<(DVector<f64>, f64)>>,
    sims: &'a mut usize,
}

impl Stepping<'_> {
    /// Take the Gauss–Newton `steps` of segments `idx` (in that order),
    /// halved up to four times while a step does not lower the segment's
    /// cost; returns which segments improved (indexed by segment).
    fn line_search(&mut self, idx: &[usize], steps: Vec<Option<DVector<f64>>>) -> Vec<bool> {
        let n = self.model.ndof();
        let mut step_of: Vec<Option<DVector<f64>>> = vec![None; self.segs.len()];
        for (&i, d) in idx.iter().zip(steps) {
            step_of[i] = d;
        }
        let mut pending: Vec<usize> = idx
            .iter()
            .copied()
            .filter(|&i| step_of[i].is_some())
            .collect();
        let mut improved = vec![false; self.segs.len()];
        // the driver's halving schedule, all pending segments at one t:
        // 1, 1/2, …, 1/16
        crate::lsq::halving(1.0, 1.0 / 16.0, |t| {
            if pending.is_empty() {
                return crate::lsq::Halve::Stop;
            }
            let trial: Vec<Segment> = pending
                .iter()
                .map(|&i| {
                    let d = step_of[i].as_ref().expect("pending segments have a step");
                    let s = &self.segs[i];
                    Segment {
                        start: s.start,
                        len: s.len,
                        u0: (0..n).map(|q| s.u0[q] + t * d[q]).collect(),
                        v0: (0..n).map(|q| s.v0[q] + t * d[n + q]).collect(),
                    }
                })
                .collect();
            let yt = predict_each(self.cmp, self.model, &trial, self.sim, self.sims);
            let mut still = vec![];
            for (ti, &i) in pending.iter().enumerate() {
                let old = self.res[i].as_ref().map_or(f64::INFINITY, |r| r.1);
                match residual(self.cmp, &trial[ti], &yt) {
                    Some(r) if r.1 < old => {
                        copy_segment(self.y, &yt, &trial[ti]);
                        self.segs[i] = trial[ti].clone();
                        self.res[i] = Some(r);
                        improved[i] = true;
                    }
                    _ => still.push(i),
                }
            }
            pending = std::mem::take(&mut still);
            crate::lsq::Halve::Again
        });
        improved
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
    let mut segs = segments.to_vec();
    let mut y = predict_each(cmp, model, &segs, sim, &mut sims);
    let mut res: Vec<Option<(DVector<f64>, f64)>> =
        segs.iter().map(|s| residual(cmp, s, &y)).collect();
    let cost0: f64 = res.iter().flatten().map(|r| r.1).sum();
    let sampled = SampledModel::from_model(&model.linear_part(), cmp.fs, sim.substeps).ok();
    let Some(sm) = sampled else {
        let fit = StartFit {
            iterations: 0,
            simulations: sims,
            cost: (cost0, cost0),
            continued: 0,
            grown: 0,
            stalled: segs.len(),
            note: "the linear part of the model could not be sampled; start states kept".into(),
        };
        return (segs, y, fit);
    };
    // a linear model: the Jacobian is exact and one step solves the problem
    let mut exact = if model.is_nonlinear() {
        None
    } else {
        Jacobians::new(&sm, cmp)
    };
    let scale = sm.state_scale();
    let iterations = if exact.is_some() {
        iterations.min(1)
    } else {
        iterations
    };
    let mut stalled = 0;
    let mut done = 0;
    let mut continued = 0;
    // segments still worth a step: one whose last step failed would take
    // the same step again, and one whose last step gained less than
    // [`super::settings::StartSettings::settled`] of its cost has settled
    let mut active = vec![true; segs.len()];
    for it in 0..iterations {
        done += 1;
        // from the second iteration of a nonlinear model: a segment may
        // start instead from where the previous one ends (continuity),
        // when that predicts it better (a refinement stuck in a local
        // minimum; the cost is rough in a contact, docs/updating.md)
        if continue_from && exact.is_none() && it == 1 {
            let changed = continuity(cmp, model, sim, &mut segs, &mut y, &mut res, &mut sims);
            continued = changed.len();
            for i in changed {
                active[i] = true;
            }
        }
        let idx: Vec<usize> = (0..segs.len()).filter(|&i| active[i]).collect();
        if idx.is_empty() {
            done -= 1;
            break;
        }
        let steps = match exact.as_mut() {
            Some(jac) => idx
                .iter()
                .map(|&i| {
                    let r = res[i].as_ref().map(|r| &r.0);
                    r.and_then(|r| Some(jac.pinv(segs[i].len)? * r))
                })
                .collect(),
            None => {
                let sub: Vec<Segment> = idx.iter().map(|&i| segs[i].clone()).collect();
                let sub_res: Vec<_> = idx.iter().map(|&i| res[i].clone()).collect();
                sens_steps(cmp, model, sim, &sub, &sub_res, &scale, &mut sims)
            }
        };
        let before: Vec<f64> = res
            .iter()
            .map(|r| r.as_ref().map_or(f64::INFINITY, |r| r.1))
            .collect();
        let mut run = Stepping {
            cmp,
            model,
            sim,
            segs: &mut segs,
            y: &mut y,
            res: &mut res,
            sims: &mut sims,
        };
        let improved = run.line_search(&idx, steps);
        stalled = idx.iter().filter(|&&i| !improved[i]).count();
        for &i in &idx {
            let after = res[i].as_ref().map_or(f64::INFINITY, |r| r.1);
            active[i] = improved[i] && after < (1.0 - cmp.starts.settled) * before[i];
        }
    }
    let cost1: f64 = res.iter().flatten().map(|r| r.1).sum();
    let fit = StartFit {
        iterations: done,
        continued,
        grown: 0,
        simulations: sims,
        cost: (cost0, cost1),
        stalled,
        note: String::new(),
    };
    (segs, y, fit)
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
