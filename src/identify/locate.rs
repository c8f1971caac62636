//! Where the missing force acts, from the measurements alone.
//!
//! With an unknown force at every DOF ([`lifted::reconstruct`]) and fewer
//! sensors than DOFs the states are set as much by the force prior as by
//! the data: on the LANL bumper record with accelerometers at 1, 5 and 6
//! the relative displacements come back with 16–23 % error. A force
//! restricted to one direction — equal and opposite on a spring-joined
//! pair, or at one DOF to ground — leaves far fewer unknowns than
//! measurements, so the states are determined (5–7 % on the same record),
//! and how well each restriction fits the data tells where the force acts.
//!
//! [`locate`] runs a greedy forward selection over these directions: each
//! step adds the direction whose restricted reconstruction
//! ([`lifted::reconstruct_along`], quadratic prior only, for speed) has the
//! smallest weighted residual, if that residual is *dominant*: at most
//! `ratio` times the residual without it and at most `ratio` times the
//! residual of the runner-up. Both tests are ratios, so they hold whatever
//! the noise level. A force spread over many DOFs (friction on every mass)
//! has no dominant direction: the selection is then empty and the
//! reconstruction keeps a force at every DOF. The selection stops when
//! the residual is within `noise_stop` (1.5) × the assumed noise (a further direction
//! would only fit noise) and takes at most one direction per two
//! channels (with accelerometers at 1, 2, 3 a pair 2–3 and a force at 2
//! fitted the noise of channel 2: 0.65 → 0.16).

use super::lifted::{self, LiftedSettings};
use crate::error::Result;
use crate::linear::SampledModel;
use crate::model::Model;
use crate::record::Quantity;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The force-location search ([`locate`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocateSettings {
    /// Dominance ratio: a direction is taken when its weighted residual is
    /// at most this times the residual without it and that of the
    /// runner-up (default 0.8; 0 ≤ ratio < 1, 0 disables the search: an
    /// unknown force at every DOF). Reason: a ratio holds whatever the
    /// noise level; 0.8 separated every single-place effect of the test
    /// matrix from distributed friction.
    pub ratio: f64,
    /// Most directions selected (default 3; the search also takes at most
    /// one per two channels). Reason: each direction needs about two
    /// channels' worth of data beyond the states.
    pub max: usize,
    /// Weighted residual RMS (1 = the assumed noise) at which the search
    /// stops adding directions (default 1.5; > 0). Reason: below it a
    /// further direction only fits noise.
    pub noise_stop: f64,
    /// Directions after the best tried together with it when it does not
    /// dominate alone (default 4; ≥ 0). Reason: two effects at two places.
    pub pair_trials: usize,
}

impl Default for LocateSettings {
    fn default() -> Self {
        LocateSettings {
            ratio: 0.8,
            max: 3,
            noise_stop: 1.5,
            pair_trials: 4,
        }
    }
}

/// A direction of the unknown force: a spring-joined pair (`[i, j]`, force
/// `+f` at `i`, `−f` at `j`) or one DOF to ground (`[i]`); DOFs from 1.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Direction {
    /// DOFs from 1.
    pub dofs: Vec<usize>,
}

impl Direction {
    /// `pair 5–6` or `DOF 1`.
    pub fn label(&self) -> String {
        match self.dofs.as_slice() {
            [i, j] => format!("pair {i}–{j}"),
            [i] => format!("DOF {i}"),
            _ => "?".into(),
        }
    }

    fn column(&self, n: usize) -> nalgebra::DVector<f64> {
        let mut e = nalgebra::DVector::zeros(n);
        e[self.dofs[0] - 1] = 1.0;
        if let Some(&j) = self.dofs.get(1) {
            e[j - 1] = -1.0;
        }
        e
    }
}

/// One step of the selection.
#[derive(Debug, Clone, Serialize)]
pub struct LocateStep {
    /// Weighted residual RMS of the current selection (1 = the assumed noise).
    pub current: f64,
    /// Best addition and its weighted residual RMS.
    pub best: (String, f64),
    /// Runner-up and its weighted residual RMS.
    pub runner_up: Option<(String, f64)>,
    /// Whether the best addition was dominant and taken.
    pub taken: bool,
    /// When the best was not dominant: the direction added together with
    /// it (the best of the next [`LocateSettings::pair_trials`]), the pair's weighted
    /// residual RMS, and whether the pair was taken (two effects at two
    /// places).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pair: Option<(String, f64, bool)>,
}

/// The result of [`locate`].
#[derive(Debug, Clone, Serialize)]
pub struct Located {
    /// Directions selected, in order (empty: no dominant direction).
    pub directions: Vec<Direction>,
    /// The steps.
    pub steps: Vec<LocateStep>,
}

/// The direction matrix (n × q) of `dirs`, one column each.
pub fn direction_matrix(dirs: &[Direction], n: usize) -> DMatrix<f64> {
    let mut e = DMatrix::zeros(n, dirs.len());
    for (c, d) in dirs.iter().enumerate() {
        e.set_column(c, &d.column(n));
    }
    e
}

impl Located {
    /// The direction matrix (n × q) of the selection.
    pub fn matrix(&self, n: usize) -> DMatrix<f64> {
        direction_matrix(&self.directions, n)
    }

    /// One line for reports.
    pub fn summary(&self) -> String {
        if self.directions.is_empty() {
            let why = self.steps.first().map_or(String::new(), |s| {
                format!(
                    " (best {} at {:.2}, runner-up {})",
                    s.best.0,
                    s.best.1,
                    s.runner_up
                        .as_ref()
                        .map_or("none".into(), |r| format!("{} at {:.2}", r.0, r.1))
                )
            });
            format!("no dominant force direction{why}: unknown force at every DOF")
        } else {
            let d: Vec<String> = self.directions.iter().map(Direction::label).collect();
            let w: Vec<String> = self
                .steps
                .iter()
                .filter(|s| s.taken)
                .map(|s| match &s.pair {
                    Some((d, w, true)) => format!(
                        "{:.2} → {:.2} with {} and {} together",
                        s.current, w, s.best.0, d
                    ),
                    _ => format!("{:.2} → {:.2}", s.current, s.best.1),
                })
                .collect();
            format!(
                "force located at {} (weighted residual {})",
                d.join(" + "),
                w.join(", ")
            )
        }
    }
}

/// Candidate directions of a model: every spring-joined pair and
/// interface pair, every physical DOF (point) to ground.
pub fn directions(model: &Model) -> Vec<Direction> {
    let mut out = vec![];
    let pairs = model.springs.iter().filter_map(|sp| match sp.ends() {
        (i, Some(j)) => Some([i + 1, j + 1]),
        _ => None,
    });
    for [i, j] in pairs.chain(model.interface_pairs.iter().copied()) {
        let d = Direction {
            dofs: vec![i.min(j), i.max(j)],
        };
        if !out.contains(&d) {
            out.push(d);
        }
    }
    for i in 1..=model.physical_ndof() {
        out.push(Direction { dofs: vec![i] });
    }
    out
}

/// Greedy forward selection of force directions (module docs): at most
/// `search.max` directions, dominance `search.ratio` in (0, 1).
pub fn locate(
    model: &Model,
    sm: &SampledModel,
    known_force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
    settings: &LiftedSettings,
    search: &LocateSettings,
) -> Result<Located> {
    let (ratio, max) = (search.ratio, search.max);
    let n = sm.n;
    let quick = LiftedSettings {
        reweight_passes: 0,
        ..settings.clone()
    };
    let fit = |sel: &[Direction]| -> Result<f64> {
        let e = direction_matrix(sel, n);
        Ok(
            lifted::reconstruct_along(sm, &e, known_force, measured, channels, &quick)?
                .weighted_rms,
        )
    };
    let pool = directions(model);
    let mut chosen: Vec<Direction> = vec![];
    let mut current = fit(&chosen)?;
    let mut steps = vec![];
    // each direction needs about two channels' worth of data beyond the
    // states; and once the residual is at the noise level a further
    // direction only fits noise
    let max = max.min(channels.len() / 2).max(1);
    while chosen.len() < max && (chosen.is_empty() || current > search.noise_stop) {
        // the trial directions are independent: in parallel, collected in
        // pool order
        let mut scored = pool
            .par_iter()
            .filter(|d| !chosen.contains(d))
            .map(|d| {
                let mut sel = chosen.clone();
                sel.push(d.clone());
                Ok((d.clone(), fit(&sel)?))
            })
            .collect::<Result<Vec<_>>>()?;
        scored.sort_by(|a, b| a.1.total_cmp(&b.1));
        let Some((best, wb)) = scored.first().cloned() else {
            break;
        };
        let runner = scored.get(1).cloned();
        let taken = wb <= ratio * current && runner.as_ref().is_none_or(|r| wb <= ratio * r.1);
        // two effects at two places: neither direction dominates the
        // runner-up (which may be a variant of the best one, at a DOF of
        // its pair), but the best together with one of the next few
        // dominates the best alone. At the first step only: later, with
        // most of the force placed, two more directions fit what is left
        // of a spread force as well as any (after a contact 6→7, a spring
        // to ground at 8 was placed at DOFs 4 and 5)
        let mut pair = None;
        if !taken && chosen.is_empty() && wb <= ratio * current && max >= 2 {
            let next = &scored[1..scored.len().min(1 + search.pair_trials)];
            // in parallel, collected in order: the lowest, the first of
            // equals
            let tried = next
                .par_iter()
                .map(|(d, _)| Ok((d.clone(), fit(&[best.clone(), d.clone()])?)))
                .collect::<Result<Vec<_>>>()?;
            pair = tried
                .into_iter()
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(d, wp)| (d, wp, wp <= ratio * wb));
        }
        steps.push(LocateStep {
            current,
            best: (best.label(), wb),
            runner_up: runner.as_ref().map(|r| (r.0.label(), r.1)),
            taken: taken || pair.as_ref().is_some_and(|p| p.2),
            pair: pair.as_ref().map(|p| (p.0.label(), p.1, p.2)),
        });
        match (taken, pair) {
            (true, _) => {
                chosen.push(best);
                current = wb;
            }
            (false, Some((d, wp, true))) => {
                chosen.push(best);
                chosen.push(d);
                current = wp;
            }
            _ => break,
        }
    }
    Ok(Located {
        directions: chosen,
        steps,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::SimSettings;
    use crate::model::{Contact, Friction};
    use crate::simulate::{simulate_record, RecordSpec};

    fn lanl() -> Model {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        Model::from_file(std::path::Path::new(p)).unwrap()
    }

    fn run(truth: &Model, sensors: &[usize], seed: u64) -> Located {
        let spec = RecordSpec {
            samples: 1024,
            sensors: sensors.to_vec(),
            noise: 0.01,
            seed,
            settings: SimSettings {
                substeps: 20,
                ..Default::default()
            },
            ..Default::default()
        };
        let rec = simulate_record(truth, &spec).unwrap().0;
        let declared = lanl();
        let sm = SampledModel::from_model(&declared, rec.fs, 10).unwrap();
        let force = crate::signal::force_matrix(&rec, 8);
        let ch: Vec<_> = rec
            .outputs
            .iter()
            .map(|c| (c.quantity, c.dof - 1))
            .collect();
        let y = DMatrix::from_fn(ch.len(), rec.len(), |c, k| rec.outputs[c].data[k]);
        locate(
            &declared,
            &sm,
            &force,
            &y,
            &ch,
            &LiftedSettings::default(),
            &LocateSettings::default(),
        )
        .unwrap()
    }

    #[test]
    fn a_contact_is_located_at_its_pair_in_either_direction() {
        for (i, j) in [(2, 3), (7, 6)] {
            let mut m = lanl();
            m.contacts = vec![Contact {
                dofs: vec![i, j],
                gap: 0.2e-3,
                stiffness: 2e6,
            }];
            let l = run(&m, &[1, i, j], 5);
            assert_eq!(
                l.directions,
                vec![Direction {
                    dofs: vec![i.min(j), i.max(j)]
                }],
                "{}",
                l.summary()
            );
        }
    }

    #[test]
    fn distributed_friction_and_no_effect_have_no_dominant_direction() {
        let mut m = lanl();
        m.frictions = (1..=8)
            .map(|d| Friction {
                dof: d,
                level: 0.5,
                velocity: 1e-3,
            })
            .collect();
        for model in [m, lanl()] {
            let l = run(&model, &[1, 5, 6], 9);
            assert!(l.directions.is_empty(), "{}", l.summary());
        }
    }
}
