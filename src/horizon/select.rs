//! Automatic choice of the weights. Every rule scales the settings' λ_0,
//! μ_0 by one factor α, `λ = α λ_0`, `μ = α μ_0`, searched on a
//! logarithmic grid `α ∈ [10^{−d}, 10^{d}]` and refined:
//!
//! - **GCV** (Golub, Heath & Wahba 1979): minimise
//!   `N p ‖r‖²_W / (N p − tr H)²`, `tr H = Σ_k tr(Ĉ Σ_k Ĉᵀ W)` from the
//!   smoother covariance (the influence matrix's diagonal blocks are
//!   `∂ŷ_k/∂y_k = Ĉ Σ_k Ĉᵀ W`); refined by golden-section search.
//! - **L-curve** (Hansen 1992): the point of maximum curvature of
//!   `(log ‖r‖_W, log ‖w‖)` against log α, by finite differences on the
//!   grid.
//! - **Discrepancy principle** (Morozov 1966): the largest α with
//!   `‖r‖²_W ≤ τ N p σ²`, σ² = 1 when `W` is the true inverse noise
//!   variance, or the GCV estimate `‖r‖²_W / (N p − tr H)`; refined by
//!   bisection on log α. When even the smallest α of the grid leaves a
//!   residual above the target (the noise level is below what the model
//!   can fit: model error, or a wrong noise level), the principle has no
//!   answer; the smallest α would then fit the residual floor with an
//!   unbounded force (thousands of N on the shipped bumper record for a
//!   true 36 N), so the L-curve corner is used instead and reported as
//!   the rule applied.
//!
//! Candidates whose solve reports numerical trouble (other than a
//! rank-deficient initial state) are skipped.

use super::settings::{HorizonSettings, NoiseLevel, WeightSelection};
use super::{solve, Candidate, HorizonData, HorizonStatus, SelectedWeights};
use crate::error::Result;
use crate::linear::SampledModel;
use std::time::Instant;

struct Search<'a> {
    model: &'a SampledModel,
    data: &'a HorizonData<'a>,
    settings: &'a HorizonSettings,
    candidates: Vec<(f64, Candidate)>,
}

impl Search<'_> {
    /// Evaluate at log10 α = `t`; None when the solve had trouble.
    fn eval(&mut self, t: f64, cov: bool) -> Result<Option<Candidate>> {
        let a = 10f64.powf(t);
        let (l, mu) = (a * self.settings.lambda, a * self.settings.mu);
        let r = solve(self.model, self.data, self.settings, l, mu, cov)?;
        // a rank-deficient initial state still gives a valid (minimum-norm)
        // answer; other trouble skips the candidate
        let usable = matches!(
            r.status,
            HorizonStatus::Solved | HorizonStatus::RankDeficient { .. }
        );
        if !usable || !r.diagnostics.rss.is_finite() {
            return Ok(None);
        }
        let np = self.data.measured.len() as f64;
        let d = r.diagnostics;
        let gcv = if cov {
            np * d.rss / (np - d.tr_h).powi(2)
        } else {
            f64::NAN
        };
        let c = Candidate {
            lambda: l,
            mu,
            rss: d.rss,
            force_norm2: r.force.norm_squared(),
            tr_h: d.tr_h,
            gcv,
        };
        self.candidates.push((t, c.clone()));
        Ok(Some(c))
    }

    fn gcv_at(&mut self, t: f64) -> Result<f64> {
        Ok(self.eval(t, true)?.map_or(f64::INFINITY, |c| c.gcv))
    }

    fn grid(&self) -> Vec<f64> {
        let d = self.settings.selection_decades;
        let ppd = self.settings.selection_points_per_decade as f64;
        let steps = (2.0 * d * ppd).round() as usize;
        (0..=steps).map(|i| -d + i as f64 / ppd).collect()
    }
}

/// Choose λ, μ by the settings' rule. Returns `(λ, μ, report, seconds)`.
pub fn choose(
    model: &SampledModel,
    data: &HorizonData<'_>,
    settings: &HorizonSettings,
) -> Result<(f64, f64, SelectedWeights, f64)> {
    let t0 = Instant::now();
    let mut s = Search {
        model,
        data,
        settings,
        candidates: vec![],
    };
    let mut applied = settings.selection.clone();
    let (t, criterion) = match &settings.selection {
        WeightSelection::Fixed => (0.0, f64::NAN),
        WeightSelection::Gcv => gcv(&mut s)?,
        WeightSelection::LCurve => lcurve(&mut s)?,
        WeightSelection::Discrepancy { noise, tau } => match discrepancy(&mut s, noise, *tau)? {
            Some(found) => found,
            None => {
                applied = WeightSelection::LCurve;
                lcurve(&mut s)?
            }
        },
    };
    let a = 10f64.powf(t);
    let mut cands = std::mem::take(&mut s.candidates);
    cands.sort_by(|x, y| x.0.total_cmp(&y.0));
    let report = SelectedWeights {
        lambda: a * settings.lambda,
        mu: a * settings.mu,
        selection: applied,
        criterion,
        candidates: cands.into_iter().map(|c| c.1).collect(),
    };
    Ok((
        a * settings.lambda,
        a * settings.mu,
        report,
        t0.elapsed().as_secs_f64(),
    ))
}

fn gcv(s: &mut Search<'_>) -> Result<(f64, f64)> {
    let grid = s.grid();
    let mut vals = Vec::with_capacity(grid.len());
    for &t in &grid {
        vals.push(s.gcv_at(t)?);
    }
    let mut ib = 0;
    for (i, v) in vals.iter().enumerate() {
        if *v < vals[ib] {
            ib = i;
        }
    }
    let lo = grid[ib.saturating_sub(1)];
    let hi = grid[(ib + 1).min(grid.len() - 1)];
    golden(s, lo, hi, (grid[ib], vals[ib]))
}

/// Golden-section minimisation of GCV on [lo, hi] (log10 α), keeping the
/// best point seen.
fn golden(s: &mut Search<'_>, lo: f64, hi: f64, best: (f64, f64)) -> Result<(f64, f64)> {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (lo, hi);
    let mut best = best;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (s.gcv_at(c)?, s.gcv_at(d)?);
    for _ in 0..10 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = s.gcv_at(c)?;
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = s.gcv_at(d)?;
        }
    }
    for (t, v) in [(c, fc), (d, fd)] {
        if v < best.1 {
            best = (t, v);
        }
    }
    Ok(best)
}

fn lcurve(s: &mut Search<'_>) -> Result<(f64, f64)> {
    let grid = s.grid();
    let mut pts = Vec::new();
    for &t in &grid {
        if let Some(c) = s.eval(t, false)? {
            if c.rss > 0.0 && c.force_norm2 > 0.0 {
                pts.push((t, 0.5 * c.rss.ln(), 0.5 * c.force_norm2.ln()));
            }
        }
    }
    let mut best = (0.0, f64::NEG_INFINITY);
    for i in 1..pts.len().saturating_sub(1) {
        let (t0, r0, e0) = pts[i - 1];
        let (t1, r1, e1) = pts[i];
        let (t2, r2, e2) = pts[i + 1];
        let (h0, h1) = (t1 - t0, t2 - t1);
        let d1 = |a: f64, c: f64| (c - a) / (h0 + h1);
        let d2 = |a: f64, b: f64, c: f64| 2.0 * ((c - b) / h1 - (b - a) / h0) / (h0 + h1);
        let (rp, ep) = (d1(r0, r2), d1(e0, e2));
        let (rpp, epp) = (d2(r0, r1, r2), d2(e0, e1, e2));
        let den = (rp * rp + ep * ep).powf(1.5);
        if den > 0.0 {
            let kappa = (rp * epp - rpp * ep) / den;
            if kappa > best.1 {
                best = (t1, kappa);
            }
        }
    }
    if best.1 == f64::NEG_INFINITY {
        return Ok((0.0, f64::NAN));
    }
    Ok(best)
}

/// The discrepancy principle's α and residual / target; None when the
/// target is above the residual of every α (no α reaches it).
fn discrepancy(s: &mut Search<'_>, noise: &NoiseLevel, tau: f64) -> Result<Option<(f64, f64)>> {
    let np = s.data.measured.len() as f64;
    let sigma2 = match noise {
        NoiseLevel::Known => 1.0,
        NoiseLevel::Estimated => {
            let (t, _) = gcv(s)?;
            s.eval(t, true)?.map_or(1.0, |c| c.rss / (np - c.tr_h))
        }
    };
    let target = tau * np * sigma2;
    let grid = s.grid();
    let mut prev: Option<f64> = None;
    for &t in &grid {
        let rss = s.eval(t, false)?.map_or(f64::INFINITY, |c| c.rss);
        if rss > target {
            return match prev {
                None => Ok(None),
                Some(lo) => bisect(s, lo, t, target).map(Some),
            };
        }
        prev = Some(t);
    }
    let t = grid.last().copied().unwrap_or(0.0);
    let rss = s.eval(t, false)?.map_or(f64::NAN, |c| c.rss);
    Ok(Some((t, rss / target)))
}

fn bisect(s: &mut Search<'_>, mut lo: f64, mut hi: f64, target: f64) -> Result<(f64, f64)> {
    let mut ratio = f64::NAN;
    while hi - lo > 1e-3 {
        let mid = 0.5 * (lo + hi);
        let rss = s.eval(mid, false)?.map_or(f64::INFINITY, |c| c.rss);
        if rss > target {
            hi = mid;
        } else {
            lo = mid;
            ratio = rss / target;
        }
    }
    if ratio.is_nan() {
        ratio = s.eval(lo, false)?.map_or(f64::NAN, |c| c.rss / target);
    }
    Ok((lo, ratio))
}
