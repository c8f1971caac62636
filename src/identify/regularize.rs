//! Choice of the Tikhonov weight α.
//!
//! The penalty rows themselves (`√α f`, first differences `√β Δf`) are
//! built by each scheme ([`super::paper::param`], [`super::mhe::param`]).
//! Here α is chosen over a log-spaced grid by running the whole scheme
//! (least squares; a run costs milliseconds) for each value:
//!
//! - **GCV** (Golub, Heath & Wahba 1979): minimise
//!   `G(α) = n_obs ‖r(α)‖² / (n_obs − p_eff(α))²`, with `r` the residual
//!   of the committed measurements and `p_eff` the sum over windows of the
//!   trace of the influence of a window's committed measurements on their
//!   own prediction ([`super::window::OperatorInfo::influence_trace`]; the
//!   coupling between windows through the carried state is neglected).
//! - **L-curve** (Hansen 1992): the corner, i.e. the largest curvature of
//!   `(log ‖r(α)‖, log ‖f(α)‖)` along `log α` (central differences).
//!
//! A value whose run diverges or fails gets an infinite score.

use super::run::{run, LsSolver};
use super::settings::{IdentifySettings, Regularization};
use super::system::{Problem, System};
use serde::Serialize;

/// How α was chosen, with the scores over the grid.
#[derive(Debug, Clone, Serialize)]
pub struct RegularizationReport {
    /// `fixed`, `gcv` or `lcurve`.
    pub rule: String,
    /// The α used.
    pub alpha: f64,
    /// First-difference weight β.
    pub smoothness: f64,
    /// Grid of α (empty for `fixed`).
    pub grid: Vec<f64>,
    /// ‖r‖ over the committed measurements, per grid value.
    pub residual_norm: Vec<f64>,
    /// ‖f‖ over the record, per grid value.
    pub force_norm: Vec<f64>,
    /// Effective number of parameters, per grid value.
    pub effective_parameters: Vec<f64>,
    /// GCV score, per grid value.
    pub gcv: Vec<f64>,
    /// L-curve curvature, per grid value (NaN at the ends).
    pub curvature: Vec<f64>,
}

impl RegularizationReport {
    /// Report for a fixed α.
    pub fn fixed(alpha: f64, smoothness: f64) -> Self {
        RegularizationReport {
            rule: "fixed".into(),
            alpha,
            smoothness,
            grid: vec![],
            residual_norm: vec![],
            force_norm: vec![],
            effective_parameters: vec![],
            gcv: vec![],
            curvature: vec![],
        }
    }
}

/// Log-spaced grid.
pub fn grid(lo: f64, hi: f64, count: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..count)
        .map(|i| (a + (b - a) * i as f64 / (count - 1) as f64).exp())
        .collect()
}

/// Choose α by the rule of `settings.regularization` (GCV or L-curve).
pub fn select(prob: &Problem, sys: &System, settings: &IdentifySettings) -> RegularizationReport {
    let (lo, hi, count) = settings.alpha_grid;
    let alphas = grid(lo, hi, count);
    let mut rep = RegularizationReport {
        rule: match settings.regularization {
            Regularization::LCurve => "lcurve".into(),
            _ => "gcv".into(),
        },
        alpha: f64::NAN,
        smoothness: settings.smoothness,
        grid: alphas.clone(),
        residual_norm: vec![],
        force_norm: vec![],
        effective_parameters: vec![],
        gcv: vec![],
        curvature: vec![],
    };
    for &a in &alphas {
        let plan = super::build_plan(sys, prob.len(), settings, a);
        let out = run(sys, prob, &plan, &mut LsSolver, &mut |_, _| {});
        let ok = out.failure.is_none();
        let rss: f64 = (&out.yhat - &prob.y).iter().map(|v| v * v).sum();
        let fnorm = out.f.norm();
        let peff: f64 = plan
            .windows
            .iter()
            .map(|&(_, oi)| plan.ops[oi].info.influence_trace)
            .sum();
        let nobs = prob.y.len() as f64;
        let g = if ok && rss.is_finite() && nobs > peff {
            nobs * rss / (nobs - peff).powi(2)
        } else {
            f64::INFINITY
        };
        rep.residual_norm
            .push(if ok { rss.sqrt() } else { f64::NAN });
        rep.force_norm.push(if ok { fnorm } else { f64::NAN });
        rep.effective_parameters.push(peff);
        rep.gcv.push(g);
    }
    rep.curvature = curvature(&alphas, &rep.residual_norm, &rep.force_norm);
    let pick = |scores: &[f64], better: fn(f64, f64) -> bool| -> Option<usize> {
        let mut best: Option<usize> = None;
        for (i, &s) in scores.iter().enumerate() {
            if s.is_finite() && best.is_none_or(|b| better(s, scores[b])) {
                best = Some(i);
            }
        }
        best
    };
    let gcv_best = pick(&rep.gcv, |a, b| a < b);
    let best = match settings.regularization {
        Regularization::LCurve => pick(&rep.curvature, |a, b| a > b).or(gcv_best),
        _ => gcv_best,
    };
    rep.alpha = best.map_or(alphas[alphas.len() - 1], |i| alphas[i]);
    rep
}

/// Signed curvature of the L-curve `(ln ρ, ln η)` parametrised by `ln α`.
fn curvature(alphas: &[f64], rho: &[f64], eta: &[f64]) -> Vec<f64> {
    let n = alphas.len();
    let mut k = vec![f64::NAN; n];
    let lr: Vec<f64> = rho.iter().map(|v| v.ln()).collect();
    let le: Vec<f64> = eta.iter().map(|v| v.ln()).collect();
    for i in 1..n.saturating_sub(1) {
        let h1 = alphas[i].ln() - alphas[i - 1].ln();
        let h2 = alphas[i + 1].ln() - alphas[i].ln();
        let d1 = |v: &[f64]| (v[i + 1] - v[i - 1]) / (h1 + h2);
        let d2 = |v: &[f64]| 2.0 * ((v[i + 1] - v[i]) / h2 - (v[i] - v[i - 1]) / h1) / (h1 + h2);
        let (r1, r2, e1, e2) = (d1(&lr), d2(&lr), d1(&le), d2(&le));
        let den = (r1 * r1 + e1 * e1).powf(1.5);
        let kv = (r1 * e2 - r2 * e1) / den;
        k[i] = if kv.is_finite() { kv } else { f64::NAN };
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_is_log_spaced_and_curvature_finds_a_corner() {
        let g = grid(1e-4, 1e4, 9);
        approx::assert_relative_eq!(g[0], 1e-4, max_relative = 1e-12);
        approx::assert_relative_eq!(g[4], 1.0, max_relative = 1e-12);
        approx::assert_relative_eq!(g[8], 1e4, max_relative = 1e-12);
        // an L: residual flat then rising, force falling then flat, corner at 1
        let rho: Vec<f64> = g.iter().map(|a| 1.0 + a * a).collect();
        let eta: Vec<f64> = g.iter().map(|a| 1.0 + 1.0 / (a * a)).collect();
        let k = curvature(&g, &rho, &eta);
        let best = (1..8)
            .max_by(|&i, &j| k[i].abs().partial_cmp(&k[j].abs()).unwrap())
            .unwrap();
        assert_eq!(best, 4, "{k:?}");
        assert!(k[4] > 0.0, "the corner has positive curvature: {k:?}");
    }
}
