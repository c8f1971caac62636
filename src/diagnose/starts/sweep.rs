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
//!
//! The sweep runs only where the start states are weakly observed: when
//! the record measures fewer DOFs than the model has ([`weakly_observed`]).
//! With every DOF measured a segment's outputs fix its start (the
//! refinement converges from the reconstruction), so a segment above the
//! floor is one the model does not predict, and a start carried from the
//! segment before only lowers wrong models' errors: on
//! `tests/diagnose_effects.rs`'s bumper with spring 5 −14 % (8 sensors)
//! the sweep moved the fit's local minimum from a spring delta of
//! −12.66 % to −12.58 %, outside the test's tolerance (docs/calibration.md,
//! "A grazing contact under three sensors").

use super::{carried, copy_segment, refine_local, residual, segment_costs, Comparison, Evaluation};
use crate::integrate::{Integrator, SimSettings};
use crate::model::Model;
use crate::update::shooting::Segment;
use nalgebra::DMatrix;
use rayon::prelude::*;

/// The quantile of the segment costs taken as the floor.
const FLOOR: f64 = 0.125;

/// A segment above this multiple of the floor is swept.
const ABOVE: f64 = 2.0;

/// Whether the record measures fewer distinct DOFs than `model` has: the
/// states of the unmeasured masses are seen only through the coupling, and
/// a segment's refined start may fit its outputs while wrong in them.
pub(super) fn weakly_observed(cmp: &Comparison, model: &Model) -> bool {
    let mut dofs: Vec<usize> = cmp.observations.iter().map(|o| o.dof).collect();
    dofs.sort_unstable();
    dofs.dedup();
    dofs.len() < model.ndof()
}

/// The floor of `costs` ([`FLOOR`]; infinite for none).
pub(super) fn floor(costs: &[f64]) -> f64 {
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

/// A segment's new start, its prediction (p × len) and cost.
type Found = Option<(Segment, DMatrix<f64>, f64)>;

/// The model and its integrator, shared by the trials of a sweep.
struct Sweep<'a> {
    cmp: &'a Comparison,
    model: &'a Model,
    sim: SimSettings,
    iterations: usize,
    integ: Integrator,
    /// Cost above which a segment is swept.
    above: f64,
}

impl Sweep<'_> {
    /// Segment `s` started where the model arrives from `p`, refined.
    fn from(&self, p: &Segment, s: &Segment, sims: &mut usize) -> Found {
        *sims += 1;
        let t = carried(&self.integ, self.cmp, p, s, self.model.ndof())?;
        let (t, yt, f) = self.refine(t);
        *sims += f;
        residual(self.cmp, &t, &yt).map(|(_, c)| {
            let yi = yt.columns(t.start, t.len).into_owned();
            (t, yi, c)
        })
    }

    /// One segment refined alone: the segment, the prediction (p × N)
    /// and the simulations run.
    fn refine(&self, s: Segment) -> (Segment, DMatrix<f64>, usize) {
        let (t, yt, f) = refine_local(self.cmp, self.model, self.sim, &[s], self.iterations, false);
        let t = t.into_iter().next().expect("one segment");
        (t, yt, f.simulations)
    }

    /// The best start of segment `i` from the segment before (module
    /// docs), and the simulations run.
    fn trial(&self, segs: &[Segment], i: usize) -> (Found, usize) {
        let mut sims = 0;
        let (p, s) = (&segs[i - 1], &segs[i]);
        let mut found = self.from(p, s, &mut sims);
        if found.as_ref().is_none_or(|f| f.2 > self.above) {
            // the segment before refined over both segments
            let both = Segment {
                len: p.len + s.len,
                ..p.clone()
            };
            let (w, _, f) = self.refine(both);
            sims += f;
            let w = Segment { len: p.len, ..w };
            if let Some(g) = self
                .from(&w, s, &mut sims)
                .filter(|g| found.as_ref().is_none_or(|f| g.2 < f.2))
            {
                found = Some(g);
            }
        }
        (found, sims)
    }
}

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
    let mut costs = segment_costs(res);
    let sweep = Sweep {
        cmp,
        model,
        sim,
        iterations,
        integ,
        above: ABOVE * floor(&costs),
    };
    let follows = |segs: &[Segment], i: usize| segs[i - 1].start + segs[i - 1].len == segs[i].start;
    let (mut changed, mut sims) = (vec![], 0);
    let mut wave: Vec<usize> = (1..segs.len())
        .filter(|&i| costs[i] > sweep.above && follows(segs, i))
        .collect();
    while !wave.is_empty() {
        let this = &*segs;
        let trials: Vec<(usize, (Found, usize))> = wave
            .par_iter()
            .map(|&i| (i, sweep.trial(this, i)))
            .collect();
        let mut moved = vec![];
        for (i, (found, k)) in trials {
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
            .filter(|&j| j < segs.len() && costs[j] > sweep.above && follows(segs, j))
            .collect();
    }
    changed.sort_unstable();
    changed.dedup();
    (changed, y, sims)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::settings::StartSettings;
    use crate::record::Quantity;
    use crate::update::problem::Observation;

    fn comparison(dofs: &[usize]) -> Comparison {
        let seg = Segment {
            start: 0,
            len: 2,
            u0: vec![0.0; 8],
            v0: vec![0.0; 8],
        };
        Comparison {
            fs: 512.0,
            force: DMatrix::zeros(8, 2),
            observations: dofs
                .iter()
                .map(|&dof| Observation {
                    quantity: Quantity::Accel,
                    dof,
                    weight: 1.0,
                    data: vec![0.0; 2],
                    point: None,
                })
                .collect(),
            segments: vec![seg.clone()],
            whole: seg,
            unscored: 0,
            starts: StartSettings::default(),
        }
    }

    #[test]
    fn the_sweep_runs_only_with_unmeasured_dofs() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let m = Model::from_file(std::path::Path::new(p)).unwrap();
        assert!(weakly_observed(&comparison(&[2, 3, 7]), &m));
        // a DOF measured twice counts once
        assert!(weakly_observed(&comparison(&[1, 1, 2, 3, 4, 5, 6, 7]), &m));
        assert!(!weakly_observed(&comparison(&[1, 2, 3, 4, 5, 6, 7, 8]), &m));
    }

    #[test]
    fn the_floor_is_the_lowest_eighth() {
        let costs: Vec<f64> = (1..=16).map(f64::from).collect();
        assert_eq!(floor(&costs), 3.0);
        assert_eq!(floor(&[]), f64::INFINITY);
    }
}
