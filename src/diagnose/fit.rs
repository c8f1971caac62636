//! Fit the added effects' parameters jointly by the multiple-shooting
//! error: starts from the trace (floored away from zero), from the joint
//! linearization's step, bracketing a cubic spring's `k3`, and from a scan
//! of a contact's or clearance's gap and stiffness (the cost is rough in
//! the gap, see docs/theory.md; a clearance's scan is scored on start
//! states refined for each scanned model); a short race of Levenberg–Marquardt from every start
//! ([`crate::update::race`]), on the reconstructed start states or on
//! those fitted for the model without the new effect when the trial
//! scores far lower there; the best carried on with the
//! segment start states ([`super::polish`]). A friction level beside
//! freed damping may reach the level that dissipates what the damping
//! does.

use super::effects::{self, AddedEffect};
use super::errors::Comparison;
use super::outcome::ToleratedFailure;
use super::polish::{noise_cost, polish, Polished};
use super::settings::{FitGroup, ZeroStarts};
use super::starts;
use super::substeps::resolved;
use super::DiagnoseSettings;
use crate::error::Result;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::trace::{Candidate, EffectKind};
use crate::update::cost::Evaluator;
use crate::update::optimize::FitSettings;
use crate::update::shooting::Segment;
use crate::update::{Parameter, Problem, Target};
use nalgebra::DMatrix;
use std::time::Instant;

/// The fit of the added effects.
pub(super) struct EffectFit {
    /// The model with the fitted values.
    pub model: Model,
    /// How the fit ended.
    pub note: String,
    /// Segment simulations spent.
    pub simulations: usize,
    /// The fit segments with their fitted start states, and the
    /// simulation settings of the fit (None when no start was carried on).
    pub fitted: Option<(Vec<Segment>, SimSettings)>,
    /// Seconds spent in the contact scan, the race and the polish.
    pub stages: [(&'static str, f64); 3],
    /// Failures the fit went on past.
    pub failures: Vec<ToleratedFailure>,
    /// The polished fit's cost on its fit segments (infinite when no
    /// start was carried on).
    pub cost: f64,
}

/// The starts of a fit being gathered.
#[derive(Clone)]
struct Starts {
    /// Scaled parameter vectors.
    list: Vec<Vec<f64>>,
    /// The model at the stiffest start (sets the sub-steps).
    stiffest: Model,
    /// Segment simulations spent on scans.
    simulations: usize,
    /// Seconds spent on scans.
    scan_secs: f64,
    /// Segment start states refined for the best scanned model, which the
    /// race runs on instead of the reconstructed ones (a clearance's scan,
    /// [`scan_contact`]).
    segments: Option<Vec<Segment>>,
}

/// Pick up to `k` segments spread evenly over `all`.
pub(super) fn spread(all: &[Segment], k: usize) -> Vec<Segment> {
    if all.len() <= k || k == 0 {
        return all.to_vec();
    }
    (0..k).map(|i| all[i * all.len() / k].clone()).collect()
}

/// Fit the parameters of all added effects jointly (module docs), the
/// fit segments' start states corrected along the hidden trajectories by
/// `correction` (2n × N) when given, or taken from `fitted` (the start
/// states fitted for the model without the new effect) when the trial
/// scores lower on those ([`closer_start_states`]), with the joint
/// linearization's `predicted` values as further starts.
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_effects(
    trial: &Model,
    all: &[AddedEffect],
    cmp: &Comparison,
    states: &DMatrix<f64>,
    (correction, fitted): (Option<&DMatrix<f64>>, Option<&[Segment]>),
    predicted: Option<&[Vec<f64>]>,
    fs: f64,
    settings: &DiagnoseSettings,
) -> Result<EffectFit> {
    let mut floored = trial.clone();
    for e in all {
        floor_start(
            &mut floored,
            e,
            (states, &cmp.force),
            &settings.fit.zero_starts,
        );
    }
    let trial = &floored;
    let mut params = vec![];
    for e in all {
        params.extend(effects::parameters(trial, e)?);
    }
    raise_friction_bounds(trial, all, &mut params, states, settings.fit.friction_upper);
    let mut segments = spread(&cmp.segments, settings.segments.fit_segments);
    let corrected;
    let states = match correction {
        Some(d) => {
            let n = trial.ndof();
            for s in &mut segments {
                for i in 0..n {
                    s.u0[i] += d[(i, s.start)];
                    s.v0[i] += d[(n + i, s.start)];
                }
            }
            corrected = states + d;
            &corrected
        }
        None => states,
    };
    let mut problem = cmp.problem(trial, segments.clone(), SimSettings::default());
    problem.parameters = params;
    let np = problem.parameters.len();
    let mut starts = Starts {
        list: vec![vec![0.0; np]],
        stiffest: trial.clone(),
        simulations: 0,
        scan_secs: 0.0,
        segments: None,
    };
    // the joint linearization's step at the current fit, when the effect
    // came in on its predicted gain ([`super::screen`])
    for at in predicted.unwrap_or_default() {
        push_start(&mut starts.list, &problem.parameters, at);
    }
    let scan = Scan {
        cmp,
        segments: &segments,
        states,
        settings,
    };
    match all.last().map(|e| (e, e.candidate.kind)) {
        Some((_, EffectKind::Cubic)) => {
            cubic_starts(trial, &problem, &settings.fit.cubic_brackets, &mut starts)
        }
        Some((last, EffectKind::Contact)) => {
            contact_starts(trial, last, &mut problem, &scan, &mut starts)
        }
        Some((last, EffectKind::Clearance)) => {
            clearance_starts(trial, last, &mut problem, &scan, &mut starts)
        }
        _ => {}
    }
    rescan_beside(trial, all, &problem, predicted, &scan, &mut starts);
    problem.sim = resolved(&starts.stiffest, fs, settings, states);
    if let Some(segs) = starts.segments.take() {
        problem.segments = segs;
    } else if let Some(f) = fitted {
        if let Some((choice, ratio, sims)) = closer_start_states(&problem, f, &settings.fit) {
            starts.simulations += sims;
            let mut fit = match choice {
                StartStates::Both => race_on_both(trial, cmp, &problem, f, starts, settings)?,
                _ => {
                    if choice == StartStates::Fitted {
                        problem.segments = f.to_vec();
                    }
                    race_and_polish(trial, cmp, &problem, starts, settings)?
                }
            };
            fit.note = format!(
                "{}; the trial at its start scored {ratio:.3} × lower per sample on the start states fitted without it ({choice:?})",
                fit.note
            );
            return Ok(fit);
        }
    }
    race_and_polish(trial, cmp, &problem, starts, settings)
}

/// Which start states a fit runs on ([`closer_start_states`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum StartStates {
    /// The reconstructed ones (corrected when a correction is given).
    Reconstructed,
    /// Those fitted for the model without the new effect.
    Fitted,
    /// Both, the fit that ends lower kept ([`race_on_both`]).
    Both,
}

/// Race and polish on the problem's start states and on `fitted`, and
/// keep the fit whose polished cost is lower (both polishes refine the
/// start states of the same segments jointly with the parameters, so
/// their costs compare); the simulations and times of both are counted.
fn race_on_both(
    trial: &Model,
    cmp: &Comparison,
    problem: &Problem,
    fitted: &[Segment],
    starts: Starts,
    settings: &DiagnoseSettings,
) -> Result<EffectFit> {
    let again = Starts {
        simulations: 0,
        scan_secs: 0.0,
        ..starts.clone()
    };
    let own = race_and_polish(trial, cmp, problem, starts, settings)?;
    let mut other = problem.clone();
    other.segments = fitted.to_vec();
    let theirs = race_and_polish(trial, cmp, &other, again, settings)?;
    let costs = format!(
        "polished cost {:.4e} on the reconstructed start states, {:.4e} on the fitted ones",
        own.cost, theirs.cost
    );
    let (mut kept, dropped, on) = if theirs.cost < own.cost {
        (theirs, own, "fitted")
    } else {
        (own, theirs, "reconstructed")
    };
    kept.simulations += dropped.simulations;
    for (k, d) in kept.stages.iter_mut().zip(dropped.stages) {
        k.1 += d.1;
    }
    kept.note = format!(
        "{}; raced on both start states, the {on} kept ({costs})",
        kept.note
    );
    Ok(kept)
}

/// The fit segments' start states: those fitted for the model without
/// the new effect (`fitted`, the last kept round's fit) in place of the
/// reconstructed ones when the trial at its start (scaled changes 0)
/// scores lower on them per sample covered by at least
/// [`super::settings::FitGroup::fitted_states_gain`], both from
/// [`super::settings::FitGroup::fitted_states_both`] on. Returns the
/// choice, the ratio of the costs (reconstructed over fitted) and the
/// segment simulations spent; None when there is nothing to compare
/// (`fitted` empty or the problem's own start states).
fn closer_start_states(
    problem: &Problem,
    fitted: &[Segment],
    fit: &FitGroup,
) -> Option<(StartStates, f64, usize)> {
    if fitted.is_empty() || fitted == problem.segments.as_slice() {
        return None;
    }
    let x0 = vec![0.0; problem.parameters.len()];
    let per_sample = |p: &Problem| -> (f64, usize) {
        let mut ev = Evaluator::new(p);
        let cost = ev.residual(&x0).map_or(f64::INFINITY, |r| r.norm_squared());
        let covered: usize = p.segments.iter().map(|s| s.len).sum();
        (cost / covered.max(1) as f64, ev.counters().simulations)
    };
    let (own, n1) = per_sample(problem);
    let mut other = problem.clone();
    other.segments = fitted.to_vec();
    let (on_fitted, n2) = per_sample(&other);
    Some((start_choice(own, on_fitted, fit), own / on_fitted, n1 + n2))
}

/// The start states for per-sample costs `own` (reconstructed) and
/// `on_fitted` ([`closer_start_states`]).
fn start_choice(own: f64, on_fitted: f64, fit: &FitGroup) -> StartStates {
    if fit.fitted_states_gain * on_fitted < own {
        StartStates::Fitted
    } else if fit.fitted_states_both < fit.fitted_states_gain
        && fit.fitted_states_both * on_fitted < own
    {
        StartStates::Both
    } else {
        StartStates::Reconstructed
    }
}

/// The upper bound of a friction level beside freed damping (an effect's
/// damping nuisance parameters, or a damping change found before) raised
/// to at least `factor` × the level that dissipates, along the
/// reconstructed `states`, what the model's damping does
/// ([`super::settings::FitGroup::friction_upper`]); the DOFs of one
/// friction effect share that level. Nothing changes when the damping
/// matrix cannot be formed.
fn raise_friction_bounds(
    trial: &Model,
    all: &[AddedEffect],
    params: &mut [Parameter],
    states: &DMatrix<f64>,
    factor: f64,
) {
    let freed = all
        .iter()
        .any(|e| !e.nuisance.is_empty() || e.candidate.kind == EffectKind::Damping);
    let friction = |e: &&AddedEffect| {
        matches!(
            e.candidate.kind,
            EffectKind::Friction | EffectKind::RelativeFriction
        )
    };
    let n = trial.ndof();
    if !freed || !all.iter().any(|e| friction(&e)) || states.nrows() < 2 * n {
        return;
    }
    for e in all.iter().filter(friction) {
        let Some((dissipated, total)) = dissipation(trial, &e.candidate, states) else {
            continue;
        };
        let level = factor * dissipated / total;
        for p in params.iter_mut().filter(|p| e.targets.contains(&p.target)) {
            p.upper = p.upper.max(level);
        }
    }
}

/// What `model`'s viscous damping dissipates along the reconstructed
/// `states` (`[u; v]`, 2n × N) and the sliding speed of the friction `c`
/// (ground or relative) summed over its DOFs, both summed over the same
/// samples: their ratio is the friction level (one at each DOF) that
/// dissipates what the damping does. None without damping, sliding or a
/// damping matrix.
pub(super) fn dissipation(
    model: &Model,
    c: &Candidate,
    states: &DMatrix<f64>,
) -> Option<(f64, f64)> {
    let n = model.ndof();
    let damping = model.damping_matrix().ok()?;
    // (every `stride`-th sample: a mean)
    let stride = states.ncols().div_ceil(1024).max(1);
    let samples: Vec<usize> = (0..states.ncols()).step_by(stride).collect();
    let v = |k: usize| states.view((n, k), (n, 1));
    let dissipated: f64 = samples.iter().map(|&k| v(k).dot(&(&damping * v(k)))).sum();
    let speed = |k: usize| match c.kind {
        EffectKind::Friction => c.dofs.iter().map(|&d| states[(n + d, k)].abs()).sum(),
        _ => c.delta_rate(states, n, k).abs(),
    };
    let total: f64 = samples.iter().map(|&k| speed(k)).sum();
    (total > 0.0 && dissipated > 0.0).then_some((dissipated, total))
}

/// What a contact scan runs on.
struct Scan<'a> {
    cmp: &'a Comparison,
    segments: &'a [Segment],
    states: &'a DMatrix<f64>,
    settings: &'a DiagnoseSettings,
}

/// A cubic spring: the segment error has local minima in k3 (the traced
/// value comes from linear-model states), so more starts bracket it, at
/// `brackets` times the traced value.
fn cubic_starts(trial: &Model, problem: &Problem, brackets: &[f64], starts: &mut Starts) {
    let np = problem.parameters.len();
    let p = &problem.parameters[np - 1];
    let k3 = trial.cubics[trial.cubics.len() - 1].k3;
    for &f in brackets {
        let mut s = vec![0.0; np];
        s[np - 1] = p.to_x((k3 * f).clamp(p.lower, p.upper));
        starts.list.push(s);
    }
    let c = starts.stiffest.cubics.len() - 1;
    starts.stiffest.cubics[c].k3 = k3 * brackets.iter().copied().fold(1.0, f64::max);
}

/// A contact: starts from a scan of gap and stiffness ([`scan_contact`]);
/// the gap's upper bound raised to the largest reconstructed relative
/// displacement.
fn contact_starts(
    trial: &Model,
    last: &AddedEffect,
    problem: &mut Problem,
    scan: &Scan<'_>,
    starts: &mut Starts,
) {
    let np = problem.parameters.len();
    let ci = trial.contacts.len() - 1;
    // the gap may lie anywhere below the largest reconstructed relative
    // displacement (beyond it the contact never closes), not only within
    // 3× the traced value: a traced gap from a few sensors can be a third
    // of the truth
    let dmax = max_delta(&last.candidate, scan.states);
    let pg = &mut problem.parameters[np - 2];
    pg.upper = pg.upper.max(scan.settings.fit.gap_upper * dmax);
    let kc = scanned_starts(trial, ci, last, problem, scan, starts);
    let c = &mut starts.stiffest.contacts[ci];
    c.stiffness = c.stiffness.max(kc);
}

/// A clearance: starts from a scan as a contact's, on `|δ|`, over its
/// own gaps and stiffnesses ([`super::settings::FitGroup::clearance_gap_quantiles`]);
/// the gap's upper bound raised to the largest reconstructed `|δ|`.
fn clearance_starts(
    trial: &Model,
    last: &AddedEffect,
    problem: &mut Problem,
    scan: &Scan<'_>,
    starts: &mut Starts,
) {
    let np = problem.parameters.len();
    let ci = trial.clearances.len() - 1;
    let dmax = (0..scan.states.ncols())
        .map(|k| last.candidate.delta(scan.states, k).abs())
        .fold(0.0, f64::max);
    let pg = &mut problem.parameters[np - 2];
    pg.upper = pg.upper.max(scan.settings.fit.gap_upper * dmax);
    let kc = scanned_starts(trial, ci, last, problem, scan, starts);
    let c = &mut starts.stiffest.clearances[ci];
    c.stiffness = c.stiffness.max(kc);
}

/// The gap and stiffness scan of a contact or clearance (entry `ci`, its
/// parameters the last two of `problem`) pushed as starts; returns the
/// stiffest scanned stiffness (0 when none).
fn scanned_starts(
    trial: &Model,
    ci: usize,
    last: &AddedEffect,
    problem: &Problem,
    scan: &Scan<'_>,
    starts: &mut Starts,
) -> f64 {
    let np = problem.parameters.len();
    let t = Instant::now();
    let (best, sims, refined) = scan_contact(trial, ci, &last.candidate, scan);
    starts.simulations += sims;
    starts.scan_secs += t.elapsed().as_secs_f64();
    if refined.is_some() {
        starts.segments = refined;
    }
    let (pg, pk) = (&problem.parameters[np - 2], &problem.parameters[np - 1]);
    let mut stiffest: f64 = 0.0;
    for (g, kc) in best {
        let mut s = vec![0.0; np];
        s[np - 2] = pg.to_x(g.clamp(pg.lower, pg.upper));
        s[np - 1] = pk.to_x(kc.clamp(pk.lower, pk.upper));
        if !starts.list.contains(&s) {
            starts.list.push(s);
            stiffest = stiffest.max(kc);
        }
    }
    stiffest
}

/// A change linear in the state beside a contact found before: the
/// contact's gap and stiffness scanned again with the change at the
/// farthest predicted value, or at its start (the contact fitted alone
/// took up part of it).
fn rescan_beside(
    trial: &Model,
    all: &[AddedEffect],
    problem: &Problem,
    predicted: Option<&[Vec<f64>]>,
    scan: &Scan<'_>,
    starts: &mut Starts,
) {
    let np = problem.parameters.len();
    let start_values: Vec<f64> = problem.parameters.iter().map(|p| p.start).collect();
    let far = predicted.and_then(|p| p.last()).unwrap_or(&start_values);
    let Some(last) = all.last() else {
        return;
    };
    let contact = all[..all.len() - 1]
        .iter()
        .rev()
        .find(|e| e.candidate.kind == EffectKind::Contact);
    let Some(c) = contact.filter(|_| last.candidate.kind.linear_in_state() && far.len() == np)
    else {
        return;
    };
    let Some(ci) = c.targets.iter().find_map(|t| match t {
        Target::ContactGap(i) => Some(*i),
        _ => None,
    }) else {
        return;
    };
    let slot = |t: Target| problem.parameters.iter().position(|p| p.target == t);
    let (Some(ig), Some(ik)) = (
        slot(Target::ContactGap(ci)),
        slot(Target::ContactStiffness(ci)),
    ) else {
        return;
    };
    let mut at = trial.clone();
    for (p, &v) in problem.parameters.iter().zip(far) {
        p.target.set(&mut at, v);
    }
    let t = Instant::now();
    let (best, sims, _) = scan_contact(&at, ci, &c.candidate, scan);
    starts.simulations += sims;
    starts.scan_secs += t.elapsed().as_secs_f64();
    for (g, kc) in best {
        let mut v = far.to_vec();
        v[ig] = g;
        v[ik] = kc;
        push_start(&mut starts.list, &problem.parameters, &v);
        if kc > starts.stiffest.contacts[ci].stiffness {
            starts.stiffest.contacts[ci].stiffness = kc;
        }
    }
}

/// The starts race: a few iterations each from the reconstructed start
/// states; the best one or two are carried on ([`polish`]).
fn race_and_polish(
    trial: &Model,
    cmp: &Comparison,
    problem: &Problem,
    starts: Starts,
    settings: &DiagnoseSettings,
) -> Result<EffectFit> {
    let mut sims = starts.simulations;
    let mut stages = [
        ("fit_scan", starts.scan_secs),
        ("fit_race", 0.0),
        ("fit_polish", 0.0),
    ];
    let sub = problem.sim.substeps;
    let fit = settings.fit_settings();
    let race = FitSettings {
        max_iterations: fit.max_iterations.min(settings.fit.race_iterations),
        ..fit
    };
    let t = Instant::now();
    let results = crate::update::race(problem, &race, &starts.list)?;
    sims += results.iter().map(|r| r.simulations).sum::<usize>();
    stages[1].1 += t.elapsed().as_secs_f64();
    let t = Instant::now();
    // the race's starts, best first
    let mut order: Vec<usize> = (0..results.len())
        .filter(|&i| results[i].cost().is_finite())
        .collect();
    order.sort_by(|&a, &b| results[a].cost().total_cmp(&results[b].cost()));
    let floor = noise_cost(cmp, &problem.segments, settings.noise.level);
    let mut kept: Option<Polished> = None;
    let mut failures = vec![];
    for (tries, &i) in order.iter().enumerate() {
        // a second start only when the first ends far above the noise
        if tries >= settings.fit.polish_starts
            || kept
                .as_ref()
                .is_some_and(|k| k.cost <= settings.fit.noise_margin * floor)
        {
            break;
        }
        let r = &results[i];
        let beat = kept.as_ref().map(|k| k.cost);
        let mut p = polish(cmp, problem, &r.x, r.cost(), settings, beat);
        sims += p.simulations;
        failures.append(&mut p.failures);
        p.note = format!(
            "start {} of {} carried on after a {}-iteration race ({:?}; {} sub-steps){}",
            i + 1,
            starts.list.len(),
            r.iterations,
            r.termination,
            sub,
            p.note
        );
        if kept.as_ref().is_none_or(|k| p.cost < k.cost) {
            kept = Some(p);
        }
    }
    // (no start with a finite cost: none was carried on)
    let Some(k) = kept else {
        failures.push(ToleratedFailure {
            step: "fit".into(),
            error: "every start of the race failed".into(),
            fallback: "the traced values".into(),
        });
        return Ok(EffectFit {
            model: trial.clone(),
            note: "every start failed; traced values kept".into(),
            simulations: sims,
            fitted: None,
            stages,
            failures,
            cost: f64::INFINITY,
        });
    };
    stages[2].1 += t.elapsed().as_secs_f64();
    Ok(EffectFit {
        model: k.model,
        note: k.note,
        simulations: sims,
        fitted: Some((k.segments, problem.sim)),
        stages,
        failures,
        cost: k.cost,
    })
}

/// Add the start at parameter `values` (clamped to the bounds, scaled)
/// unless it is there already, has the wrong length or is not finite.
fn push_start(starts: &mut Vec<Vec<f64>>, params: &[Parameter], values: &[f64]) {
    if values.len() != params.len() {
        return;
    }
    let s: Vec<f64> = params
        .iter()
        .zip(values)
        .map(|(p, &v)| p.to_x(v.clamp(p.lower, p.upper)))
        .collect();
    if s.iter().all(|v| v.is_finite()) && !starts.contains(&s) {
        starts.push(s);
    }
}

/// Gap and stiffness starts of a contact from a scan of the
/// multiple-shooting error with the nonlinear model (the cost is rough
/// in the gap): gaps at upper quantiles of the reconstructed
/// relative displacement, stiffnesses at multiples of the stiffest spring
/// the pair touches. A clearance (engaged whenever `|δ|` passes its gap,
/// so its force changes the states over much of the record) is scanned
/// over its own gaps and stiffnesses, each scored on start states refined
/// for that model ([`starts::refine_for_fit`]) when
/// [`super::settings::FitGroup::clearance_refined_scan`]: on the states
/// reconstructed with the linear model every (gap, stiffness), the true
/// one included, leaves about the linear model's error. Returns the two
/// best (gap, stiffness) pairs, the segment simulations spent and the
/// refined start states of the best (None without the refinement).
fn scan_contact(trial: &Model, ci: usize, cand: &Candidate, scan: &Scan<'_>) -> ScanResult {
    const KEEP: usize = 2;
    let Scan {
        cmp,
        segments,
        states,
        settings,
    } = *scan;
    let fs = cmp.fs;
    // a clearance: its gap on |δ|, its own entry
    let two_sided = cand.kind == EffectKind::Clearance;
    let mut d: Vec<f64> = (0..states.ncols())
        .map(|k| cand.delta(states, k))
        .map(|x| if two_sided { x.abs() } else { x })
        .collect();
    d.sort_by(f64::total_cmp);
    let q = |f: f64| d[((d.len() - 1) as f64 * f) as usize].max(0.0);
    let kspring = stiffest_spring(trial, &cand.dofs);
    let f = &settings.fit;
    let (multiples, quantiles) = if two_sided {
        (&f.clearance_stiffnesses, &f.clearance_gap_quantiles)
    } else {
        (&f.contact_stiffnesses, &f.gap_quantiles)
    };
    let grid: Vec<(f64, f64)> = multiples
        .iter()
        .flat_map(|&m| quantiles.iter().map(move |&f| (q(f), m * kspring)))
        .collect();
    let refine = two_sided && f.clearance_refined_scan;
    let mut scored = vec![];
    let mut sims = 0;
    for &(g, kc) in &grid {
        let mut m = trial.clone();
        if two_sided {
            m.clearances[ci].gap = g;
            m.clearances[ci].stiffness = kc;
        } else {
            m.contacts[ci].gap = g;
            m.contacts[ci].stiffness = kc;
        }
        let sim = resolved(&m, fs, settings, states);
        if refine {
            let (segs, y, sf) =
                starts::refine_for_fit(cmp, &m, sim, segments, cmp.starts.iterations);
            sims += sf.simulations;
            let e = cmp.total_error(&y);
            if e.is_finite() {
                scored.push((e, g, kc, Some(segs)));
            }
        } else {
            sims += segments.len();
            if let Ok(y) = cmp.predict(&m, segments, sim) {
                scored.push((cmp.total_error(&y), g, kc, None));
            }
        }
    }
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    // distinct pairs only (upper quantiles of a sparse impact history can
    // coincide)
    let mut best: Vec<(f64, f64)> = vec![];
    let mut refined = None;
    for (_, g, kc, segs) in scored {
        if best.len() < KEEP && !best.contains(&(g, kc)) {
            best.push((g, kc));
            refined = refined.or(segs);
        }
    }
    (best, sims, refined)
}

/// A scan's best (gap, stiffness) pairs, the segment simulations spent
/// and the start states refined for the best, if refined.
type ScanResult = (Vec<(f64, f64)>, usize, Option<Vec<Segment>>);

/// A traced value of zero cannot be scaled relatively (a contact traced
/// to switch on at zero gap, or with zero stiffness; a friction level or
/// a spring of zero): such a value starts the fit at a small positive one
/// instead ([`ZeroStarts`]: by default a gap of 5 % of the largest
/// reconstructed relative displacement, 10× the stiffest spring at the
/// pair, 0.1 % of the largest applied force, 0.1 % of the stiffest
/// spring).
fn floor_start(
    model: &mut Model,
    e: &AddedEffect,
    (states, force): (&DMatrix<f64>, &DMatrix<f64>),
    z: &ZeroStarts,
) {
    for &t in &e.targets {
        let v = t.get(model).unwrap_or(0.0);
        if v != 0.0 && v.is_finite() {
            continue;
        }
        let dofs = &e.candidate.dofs;
        let floor = match t {
            Target::ContactGap(_) => (z.gap * max_delta(&e.candidate, states)).max(1e-9),
            Target::ContactStiffness(_) => z.contact_stiffness * stiffest_spring(model, dofs),
            Target::FrictionLevel(_) => (z.friction * force.amax()).max(1e-9),
            Target::SpringStiffness(_) => z.spring * stiffest_spring(model, dofs),
            _ => continue,
        };
        t.set(model, floor);
    }
}

/// The stiffest spring of `model` at a candidate's DOFs `dofs` (from 0),
/// at least 1 N/m.
fn stiffest_spring(model: &Model, dofs: &[usize]) -> f64 {
    model
        .springs
        .iter()
        .filter(|s| dofs.iter().any(|d| s.dofs.contains(&(d + 1))))
        .map(|s| s.stiffness)
        .fold(0.0, f64::max)
        .max(1.0)
}

/// The largest relative displacement `δ` of a candidate (signed: a
/// contact closes on the positive side) over the reconstructed `states`.
fn max_delta(c: &Candidate, states: &DMatrix<f64>) -> f64 {
    (0..states.ncols())
        .map(|k| c.delta(states, k))
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Damping;
    use crate::trace::{Candidate, RankedEffect};

    /// The fitted start states from `fitted_states_gain` × lower on, both
    /// from `fitted_states_both` × on, the reconstructed ones below; both
    /// never when the two factors are equal.
    #[test]
    fn the_start_states_follow_the_ratio_of_their_costs() {
        let fit = FitGroup::default();
        let (both, gain) = (fit.fitted_states_both, fit.fitted_states_gain);
        assert!(both < gain);
        let choice = |ratio: f64, fit: &FitGroup| start_choice(ratio * 1e-4, 1e-4, fit);
        assert_eq!(choice(1.14, &fit), StartStates::Reconstructed);
        assert_eq!(choice(0.5 * (both + gain), &fit), StartStates::Both);
        assert_eq!(choice(1.01 * gain, &fit), StartStates::Fitted);
        assert_eq!(choice(0.99 * both, &fit), StartStates::Reconstructed);
        let single = FitGroup {
            fitted_states_both: gain,
            ..fit.clone()
        };
        assert_eq!(
            choice(0.5 * (both + gain), &single),
            StartStates::Reconstructed
        );
        // a trial that fails on the fitted states (infinite cost) keeps
        // the reconstructed ones
        assert_eq!(
            start_choice(1e-4, f64::INFINITY, &fit),
            StartStates::Reconstructed
        );
    }

    /// Friction on every mass beside freed Rayleigh damping (`C = α M`):
    /// with every velocity `±v` alternating, the damping dissipates
    /// `α Σ m_i v²` per sample and the friction `F n v`, so the bound is
    /// `factor · α Σ m_i v / n` (above the traced bound, 11 × 0.01 N);
    /// held damping leaves the traced bound.
    #[test]
    fn friction_beside_freed_damping_may_take_what_the_damping_dissipates() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let mut model = Model::from_file(std::path::Path::new(p)).unwrap();
        let alpha = 3.0;
        model.damping = Damping::Rayleigh { alpha, beta: 0.0 };
        let n = model.ndof();
        let c = Candidate::new(EffectKind::Friction, (0..n).collect());
        let ranked = RankedEffect::for_test(c, &[("level", 0.01)]);
        let mut trial = model.clone();
        let mut e = effects::add(&mut trial, &ranked);
        let v = 0.1;
        let states = DMatrix::from_fn(2 * n, 3000, |i, k| match (i >= n, k % 2) {
            (false, _) => 0.0,
            (true, 0) => v,
            (true, _) => -v,
        });
        let bound = |e: &AddedEffect| {
            let mut params = effects::parameters(&trial, e).unwrap();
            raise_friction_bounds(&trial, std::slice::from_ref(e), &mut params, &states, 2.0);
            params
                .iter()
                .filter(|p| matches!(p.target, Target::FrictionLevel(_)))
                .map(|p| p.upper)
                .collect::<Vec<_>>()
        };
        let held = bound(&e);
        assert_eq!(held.len(), n);
        assert!(
            held.iter().all(|&u| (u / 0.11 - 1.0).abs() < 1e-12),
            "{held:?}"
        );
        e.nuisance = effects::damping_targets(&trial);
        let mass: f64 = model.masses.iter().sum();
        let want = 2.0 * alpha * mass * v / n as f64;
        for u in bound(&e) {
            assert!((u / want - 1.0).abs() < 1e-9, "{u} against {want}");
        }
    }
}
