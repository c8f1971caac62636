//! Carried starts after the refinement: a forward sweep of the model's
//! own simulation from the segments that fit to the noise into the
//! segments after them that do not.
//!
//! An exact model's segments all cost about the same (the noise over a
//! segment's samples, the channels weighted alike), so the lowest costs
//! give the floor the others should reach. From a few accelerometers a
//! segment may fit its outputs while its start is wrong in directions
//! they hardly see (the states of the unmeasured masses); with a stiff
//! element that grazes its threshold the cost from there is rough and the
//! refinement stalls at tens to hundreds of times the floor. When most
//! segments are in that state the median is too, and the rescues, which
//! act on segments above [`crate::diagnose::settings::StartSettings::outlier`]
//! × the median, see none of them. The continuity starts inside the
//! refinement are tried once, after its first iteration, before the
//! segment before has reached its own start. Here, once every segment is
//! refined, each segment above [`ABOVE`] × the floor (the [`FLOOR`]
//! quantile of the costs) that directly follows another is started where
//! the model arrives from the refined start of the segment before, and
//! refined ([`super::refine_local`]); when that start stays above the
//! floor's bound, the segment before is also refined over both segments
//! (a window that sees the directions the later segment needs) and the
//! segment started where the model arrives from there. The best start is
//! kept when it predicts the segment better than its start now. The sweep
//! goes on in waves, each over the segments whose predecessor has just
//! changed, so a run of segments takes the model's simulation from the
//! last one that fits.

use super::{carried, copy_segment, refine_local, residual, segment_costs, Comparison};
use crate::integrate::{Integrator, SimSettings};
use crate::model::Model;
use crate::update::shooting::Segment;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// The quantile of the segment costs taken as the floor.
const FLOOR: f64 = 0.125;

/// A segment above this multiple of the floor is swept.
const ABOVE: f64 = 2.0;

/// The floor of `costs` ([`FLOOR`]; infinite for none).
fn floor(costs: &[f64]) -> f64 {
    let mut sorted = costs.to_vec();
    sorted.sort_by(f64::total_cmp);
    let k = (FLOOR * sorted.len() as f64) as usize;
    sorted.get(k).copied().unwrap_or(f64::INFINITY)
}

/// The forward sweep (module docs) over `segs`, with their predictions
/// `y` (p × N) and evaluations `res`, all updated where a segment takes a
/// new start: returns the number of segments changed and the simulations
/// run.
pub(super) fn sweep(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    (segs, y, res): (&mut [Segment], &mut DMatrix<f64>, &mut [Evaluation]),
    iterations: usize,
) -> (usize, usize) {
    let (changed, yt, n) = waves(cmp, model, sim, segs, res, iterations);
    for &i in &changed {
        copy_segment(y, &yt, &segs[i]);
        res[i] = residual(cmp, &segs[i], y);
    }
    (changed.len(), n)
}

/// A segment's weighted residual and cost (None where its prediction
/// failed).
type Evaluation = Option<(DVector<f64>, f64)>;

/// The waves of the sweep: the indices changed, their predictions (p × N)
/// and the simulations run.
fn waves(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    segs: &mut [Segment],
    res: &[Evaluation],
    iterations: usize,
) -> (Vec<usize>, DMatrix<f64>, usize) {
    let mut y = DMatrix::zeros(cmp.observations.len(), cmp.force.ncols());
    let Ok(integ) = Integrator::new(model, cmp.fs, sim) else {
        return (vec![], y, 0);
    };
    let (n, mut sims) = (model.ndof(), 0);
    let mut costs = segment_costs(res);
    let above = ABOVE * floor(&costs);
    let follows = |segs: &[Segment], i: usize| segs[i - 1].start + segs[i - 1].len == segs[i].start;
    let mut changed: Vec<usize> = vec![];
    let mut wave: Vec<usize> = (1..segs.len())
        .filter(|&i| costs[i] > above && follows(segs, i))
        .collect();
    // segment `s` started where the model arrives from `p`, refined
    let from = |p: &Segment, s: &Segment, sims: &mut usize| {
        *sims += 1;
        let t = carried(&integ, cmp, p, s, n)?;
        let (t, yt, f) = refine_local(cmp, model, sim, &[t], iterations, false);
        *sims += f.simulations;
        let t = t.into_iter().next().expect("one segment");
        residual(cmp, &t, &yt).map(|(_, c)| {
            let yi = yt.columns(t.start, t.len).into_owned();
            (t, yi, c)
        })
    };
    while !wave.is_empty() {
        let this = &*segs;
        let trials: Vec<(usize, Option<(Segment, DMatrix<f64>, f64)>, usize)> = wave
            .par_iter()
            .map(|&i| {
                let mut sims = 0;
                let mut found = from(&this[i - 1], &this[i], &mut sims);
                if found.as_ref().is_none_or(|f| f.2 > above) {
                    // the segment before refined over both segments
                    let p = &this[i - 1];
                    let both = Segment {
                        len: p.len + this[i].len,
                        ..p.clone()
                    };
                    let (w, _, f) = refine_local(cmp, model, sim, &[both], iterations, false);
                    sims += f.simulations;
                    let w = Segment {
                        len: p.len,
                        ..w.into_iter().next().expect("one segment")
                    };
                    if let Some(g) = from(&w, &this[i], &mut sims)
                        .filter(|g| found.as_ref().is_none_or(|f| g.2 < f.2))
                    {
                        found = Some(g);
                    }
                }
                (i, found, sims)
            })
            .collect();
        let mut moved = vec![];
        for (i, found, k) in trials {
            sims += k;
            if let Some((t, yi, c)) = found.filter(|f| f.2 < costs[i]) {
                y.columns_mut(t.start, t.len).copy_from(&yi);
                segs[i] = t;
                costs[i] = c;
                moved.push(i);
            }
        }
        changed.extend(&moved);
        wave = moved
            .iter()
            .map(|&i| i + 1)
            .filter(|&j| j < segs.len() && costs[j] > above && follows(segs, j))
            .collect();
    }
    changed.sort_unstable();
    changed.dedup();
    (changed, y, sims)
}
