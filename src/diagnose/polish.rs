//! Carry a race result on: refine the segment start states for the
//! fitted model ([`super::starts`]), fit parameters and start states
//! together ([`super::joint`]), run in the segments left far above the
//! others, and repeat while the cost falls.

use super::errors::Comparison;
use super::outcome::ToleratedFailure;
use super::{joint, starts, DiagnoseSettings};
use crate::model::Model;
use crate::update::shooting::Segment;
use crate::update::Problem;

/// The cost white noise of `level` times each channel's RMS would leave
/// on `segments` ([`crate::update::Observation::noise_std`] per residual row).
pub(super) fn noise_cost(cmp: &Comparison, segments: &[Segment], level: f64) -> f64 {
    let covered: usize = segments.iter().map(|s| s.len).sum();
    let per_sample: f64 = cmp
        .observations
        .iter()
        .map(|o| o.noise_std(level).powi(2))
        .sum();
    per_sample * covered as f64
}

/// A race result carried on.
pub(super) struct Polished {
    pub model: Model,
    pub cost: f64,
    pub segments: Vec<Segment>,
    pub note: String,
    pub simulations: usize,
    pub failures: Vec<ToleratedFailure>,
}

/// Carry a race result on (scaled parameters `x0` at cost `cost0`, on
/// `base`'s segments): the start states the race used were
/// reconstructed with the linear model, so refine them for the fitted
/// model (continuity starts and Gauss–Newton, [`starts::refine`]), then fit
/// the parameters and the start states together ([`joint::fit`]); segments
/// left far above the others are run in from the segment before
/// ([`starts::run_in`]); again while that lowers the cost by `alternation_gain` (1 %) or a
/// run-in took, and while the cost is below twice `beat` (the cost of a
/// start already carried on).
pub(super) fn polish(
    cmp: &Comparison,
    base: &Problem,
    x0: &[f64],
    cost0: f64,
    settings: &DiagnoseSettings,
    beat: Option<f64>,
) -> Polished {
    let mut problem = base.clone();
    let mut model = problem.model_at(x0);
    let mut x = x0.to_vec();
    let mut cost = cost0;
    let mut sims = 0;
    let mut rounds = 0;
    // segments already run in, by first sample (a refinement may split
    // segments, [`starts`])
    let mut tried = std::collections::BTreeSet::new();
    let mut run_ins = 0;
    let mut failures = vec![];
    let fit_settings = settings.fit_settings();
    let s = &settings.starts;
    let stall = joint::Stall {
        steps: s.stall_steps,
        gain: s.stall_gain,
    };
    while cmp.starts.iterations > 0 && rounds < s.alternations {
        rounds += 1;
        let (segs, _, sf) = starts::refine_for_fit(
            cmp,
            &model,
            problem.sim,
            &problem.segments,
            cmp.starts.iterations,
        );
        sims += sf.simulations;
        problem.segments = segs;
        let j = match joint::fit(&problem, &x, &fit_settings, stall) {
            Ok(j) => j,
            Err(e) => {
                failures.push(ToleratedFailure {
                    step: "joint fit of parameters and start states".into(),
                    error: e.to_string(),
                    fallback: "the fit so far".into(),
                });
                break;
            }
        };
        sims += j.simulations;
        model = problem.model_at(&j.x);
        x = j.x;
        problem.segments = j.segments;
        let gain = 1.0 - j.cost.1 / cost;
        // what the joint fit itself gained: once it finds nothing to add
        // to the refined start states, another refinement from its end
        // does not either (measured on the main job: 1e-4 of the cost)
        let joint_gain = 1.0 - j.cost.1 / j.cost.0;
        cost = j.cost.1;
        // a segment far above the others is likely started in a wrong
        // basin: run it in from the segment before it
        let was: Vec<bool> = (problem.segments.iter())
            .map(|s| tried.contains(&s.start))
            .collect();
        let picks = starts::outliers(&j.segment_costs, &was, cmp.starts.outlier)
            .into_iter()
            .filter_map(|i| {
                let start = problem.segments[i].start;
                tried.insert(start);
                let k = cmp.segments.iter().position(|s| s.start == start)?;
                let before = cmp.segments.get(k.checked_sub(1)?)?.clone();
                Some((i, before, j.segment_costs[i]))
            })
            .collect::<Vec<_>>();
        let (changed, n) = starts::run_in(
            cmp,
            &model,
            problem.sim,
            &mut problem.segments,
            &picks,
            cmp.starts.iterations,
        );
        sims += n;
        run_ins += changed.len();
        if (!(gain > s.alternation_gain) || !(joint_gain > s.stall_gain)) && changed.is_empty() {
            break;
        }
        // a second start that stays well above the first is given up
        if beat.is_some_and(|b| cost > s.give_up * b) {
            break;
        }
    }
    let mut note = String::new();
    if run_ins > 0 {
        note = format!("{note}; {run_ins} segments run in from the one before");
    }
    if rounds > 0 {
        note = format!(
            "{note}; {rounds} rounds of start-state refinement and joint fit of parameters and start states (cost {cost:.4e})"
        );
    }
    Polished {
        model,
        cost,
        segments: problem.segments,
        note,
        simulations: sims,
        failures,
    }
}
