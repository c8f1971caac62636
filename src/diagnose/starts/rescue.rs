//! Starts for segments the local refinement leaves far above the others.
//!
//! Two causes leave a segment's refined start in a wrong basin with an
//! exact model, each with its remedy:
//!
//! - **State directions the segment does not see.** A free-free structure
//!   measured by accelerometers gives no information on its rigid-body
//!   displacement and velocity, except through elements that act on the
//!   absolute motion (a stop against ground, friction). A segment without
//!   an impact on the stop keeps the reconstruction's values there, which
//!   drift by millimetres; the next segment whose impact is then missed
//!   has no sensitivity to them. They are set by the segments before, where
//!   the stop was hit, and carried by the model's own dynamics: the segment
//!   is started where the model arrives from the refined start of an
//!   earlier segment, simulated over every sample in between (a *long
//!   run-in*, from 2, 4, 8 and 16 segments back).
//! - **A start inside an impact with no segment before it** (the first
//!   segment of a record cut from a running test). With 1 % noise the
//!   output error over the segment has a local minimum with the wrong
//!   relative velocity in the contact; the state from which the model
//!   arrives at the next segment's refined start ([`super::arrival`]) lies
//!   in the right basin.
//!
//! Each candidate is refined on the segment's own data as every start is
//! and kept when it predicts the segment better; the first that brings the
//! segment back among the others ends the search. Nothing is dropped from
//! the error: a segment still far above the others is reported
//! ([`super::StartFit::stuck`]).

use super::{arrival, refine_local, residual, Comparison};
use crate::integrate::{Integrator, SimSettings};
use crate::linear::SampledModel;
use crate::model::Model;
use crate::update::shooting::Segment;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// How far back the long run-ins start, in segments.
const BACK: [usize; 4] = [2, 4, 8, 16];

/// What the search for one segment found: its best start, that start's
/// prediction of the segment (p × len) and cost, and the simulations run.
type Found = (Option<(Segment, DMatrix<f64>, f64)>, usize);

/// The model's integrator and state scale, and the segments' refined
/// starts and costs, shared by the searches.
struct Context<'a> {
    cmp: &'a Comparison,
    model: &'a Model,
    sim: SimSettings,
    iterations: usize,
    integ: Integrator,
    scale: DVector<f64>,
    segs: &'a [Segment],
    costs: &'a [f64],
    /// Cost at or below which a segment is back among the others.
    good: f64,
    /// Candidates of one search tried side by side: the threads the
    /// searches of the picks leave idle, at least one.
    side_by_side: usize,
}

/// New starts for the segments `picks` (indices into `segs`, whose costs
/// are `costs`; module docs): returns the indices changed, the
/// predictions of their segments (p × N) and the simulations run.
pub(super) fn rescue(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segs: &mut [Segment],
    (picks, costs): (&[usize], &[f64]),
    iterations: usize,
) -> (Vec<usize>, DMatrix<f64>, usize) {
    let mut y = DMatrix::zeros(cmp.observations.len(), cmp.force.ncols());
    let integ = Integrator::new(model, cmp.fs, sim).ok();
    let sm = SampledModel::from_model(&model.linear_part(), cmp.fs, sim.substeps).ok();
    let (Some(integ), Some(sm)) = (integ, sm) else {
        return (vec![], y, 0);
    };
    let ctx = Context {
        cmp,
        model,
        sim,
        iterations,
        integ,
        scale: sm.state_scale(),
        segs,
        costs,
        good: cmp.starts.outlier * median(costs),
        side_by_side: (rayon::current_num_threads() / picks.len().max(1)).max(1),
    };
    let found: Vec<Found> = picks.par_iter().map(|&i| ctx.search(i)).collect();
    let mut changed = vec![];
    let mut sims = 0;
    for (&i, (best, n)) in picks.iter().zip(found) {
        sims += n;
        if let Some((seg, yi, _)) = best {
            y.columns_mut(seg.start, seg.len).copy_from(&yi);
            segs[i] = seg;
            changed.push(i);
        }
    }
    (changed, y, sims)
}

/// The median of `costs` (infinite for none).
pub(super) fn median(costs: &[f64]) -> f64 {
    let mut sorted = costs.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted
        .get(sorted.len() / 2)
        .copied()
        .unwrap_or(f64::INFINITY)
}

impl Context<'_> {
    /// The candidates of segment `i` in turn — long run-ins from 2, 4, 8
    /// and 16 segments back, then the arrival at the next segment's
    /// start — until one brings it back among the others. With threads
    /// idle (fewer picks than threads), the next few candidates are tried
    /// side by side and taken in turn; the simulations counted are those
    /// of the candidates taken, as when tried one at a time.
    fn search(&self, i: usize) -> Found {
        let mut best: Option<(Segment, DMatrix<f64>, f64)> = None;
        let mut sims = 0;
        let mut bound = self.costs[i];
        let origins: Vec<Origin> = BACK
            .iter()
            .filter_map(|&b| i.checked_sub(b))
            .map(Origin::Before)
            .chain(std::iter::once(Origin::After))
            .collect();
        for chunk in origins.chunks(self.side_by_side) {
            let tried: Vec<Found> = match chunk {
                [one] => vec![self.try_origin(i, *one)],
                _ => chunk.par_iter().map(|&o| self.try_origin(i, o)).collect(),
            };
            for (c, n) in tried {
                if bound <= self.good {
                    break;
                }
                sims += n;
                if let Some(c) = c.filter(|c| c.2 < bound) {
                    bound = c.2;
                    best = Some(c);
                }
            }
            if bound <= self.good {
                break;
            }
        }
        (best, sims)
    }

    /// The start of segment `i` from `origin`, refined ([`Self::refined`]),
    /// and the simulations run.
    fn try_origin(&self, i: usize, origin: Origin) -> Found {
        let mut sims = 0;
        let c = self
            .candidate(i, origin, &mut sims)
            .and_then(|start| self.refined(start, &mut sims));
        (c, sims)
    }

    /// The start of segment `i` from `origin`, before refinement; None
    /// when the origin is itself far above the others, or a run fails.
    fn candidate(&self, i: usize, origin: Origin, sims: &mut usize) -> Option<Segment> {
        let seg = &self.segs[i];
        match origin {
            Origin::Before(j) => {
                (self.costs[j] <= self.good).then_some(())?;
                *sims += 1;
                run_in_from(&self.integ, self.cmp, &self.segs[j], seg)
            }
            Origin::After => {
                let next = self.segs.get(i + 1)?;
                (self.costs[i + 1] <= self.good).then_some(())?;
                arrival::arrive(self.cmp, &self.integ, &self.scale, seg, next, sims)
            }
        }
    }

    /// `start` refined on its segment's data: the segment, its prediction
    /// (p × len) and cost.
    fn refined(&self, start: Segment, sims: &mut usize) -> Option<(Segment, DMatrix<f64>, f64)> {
        let one = std::slice::from_ref(&start);
        let (t, y, f) = refine_local(self.cmp, self.model, self.sim, one, self.iterations, false);
        *sims += f.simulations;
        let t = t.into_iter().next()?;
        let (_, c) = residual(self.cmp, &t, &y)?;
        let yi = y.columns(t.start, t.len).into_owned();
        Some((t, yi, c))
    }
}

/// Where a candidate start comes from.
#[derive(Debug, Clone, Copy)]
enum Origin {
    /// A long run-in from the refined start of this earlier segment.
    Before(usize),
    /// The arrival at the next segment's refined start.
    After,
}

/// Segment `s` started where the model arrives from the start of the
/// earlier segment `p`, simulated over every sample between their starts;
/// None when `p` does not start before `s` or the run fails.
pub(super) fn run_in_from(
    integ: &Integrator,
    cmp: &Comparison,
    p: &Segment,
    s: &Segment,
) -> Option<Segment> {
    let span = s.start.checked_sub(p.start).filter(|&d| d > 0)?;
    if s.start >= cmp.force.ncols() {
        return None;
    }
    let run = integ.run(cmp.force.columns(p.start, span + 1), &p.u0, &p.v0);
    if !run.completed() || run.len() != span + 1 {
        return None;
    }
    let n = p.u0.len();
    Some(Segment {
        start: s.start,
        len: s.len,
        u0: (0..n).map(|q| run.u[(q, span)]).collect(),
        v0: (0..n).map(|q| run.v[(q, span)]).collect(),
    })
}
