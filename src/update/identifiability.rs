//! Identifiability at the solution: can the data separate the parameters?
//!
//! Whatever metric the fit used, the information the *data* carry about the
//! parameters is measured on the GLS residual `r = w_c (y − ŷ)` of the same
//! channels and segments. With white measurement noise of standard
//! deviation `η · rms(y_c)` on channel c, a residual row has noise
//! `σ_row = η w_c rms(y_c)`, and to first order the scaled parameters have
//! the covariance
//!
//! $$ \mathrm{Cov}(x) = (\tilde J^\top \tilde J)^{-1}, \qquad \tilde J = \mathrm{diag}(1/σ_{row}) J $$
//!
//! (the Cramér–Rao bound). The report gives the singular values of the
//! weighted Jacobian `J` (and of `J̃`), the standard deviation of every
//! parameter at the noise level η, a flag per parameter (determined when
//! that deviation is below a tolerance) and the least determined direction
//! (the right singular vector of the smallest singular value): the
//! combination of parameters the data cannot see.

use super::param::Parameter;
use nalgebra::DMatrix;
use serde::Serialize;

/// Identifiability report.
#[derive(Debug, Clone, Serialize)]
pub struct Identifiability {
    /// Singular values of the GLS Jacobian with respect to the scaled
    /// parameters, descending.
    pub singular_values: Vec<f64>,
    /// Ratio of the largest to the smallest singular value.
    pub condition: f64,
    /// Noise level η assumed (fraction of each channel's RMS).
    pub noise_level: f64,
    /// Per parameter.
    pub parameters: Vec<ParameterIdentifiability>,
    /// Least determined direction: (parameter name, component) of the
    /// right singular vector of the smallest singular value.
    pub weakest_direction: Vec<(String, f64)>,
    /// True when every parameter is determined.
    pub all_determined: bool,
    /// One-line verdict.
    pub verdict: String,
}

/// Identifiability of one parameter.
#[derive(Debug, Clone, Serialize)]
pub struct ParameterIdentifiability {
    /// Name.
    pub name: String,
    /// Standard deviation of the scaled parameter at the noise level
    /// (for relative parameters, × 100 gives percentage points).
    pub std_scaled: f64,
    /// The same in the parameter's unit.
    pub std_value: f64,
    /// `std_scaled` below the tolerance.
    pub determined: bool,
}

/// Build the report from the GLS Jacobian `jac` (rows: data residuals),
/// the noise standard deviation of every row `sigma_rows`, the parameters,
/// and the tolerance on the scaled standard deviation.
pub fn report(
    jac: &DMatrix<f64>,
    sigma_rows: &[f64],
    params: &[Parameter],
    noise_level: f64,
    tol: f64,
) -> Identifiability {
    let p = jac.ncols();
    let sv_of = |a: &DMatrix<f64>| -> (Vec<f64>, DMatrix<f64>) {
        let svd = a.clone().svd(false, true);
        let s = svd.singular_values;
        let vt = svd.v_t.unwrap_or_else(|| DMatrix::identity(p, p));
        let mut idx: Vec<usize> = (0..s.len()).collect();
        idx.sort_by(|&a, &b| s[b].total_cmp(&s[a]));
        let v = DMatrix::from_fn(p, idx.len(), |i, j| vt[(idx[j], i)]);
        (idx.iter().map(|&i| s[i]).collect(), v)
    };
    let (sv, v) = sv_of(jac);
    let mut jw = jac.clone();
    for (r, &s) in sigma_rows.iter().enumerate() {
        let w = if s > 0.0 { 1.0 / s } else { 0.0 };
        jw.row_mut(r).scale_mut(w);
    }
    let (svw, vw) = sv_of(&jw);
    let smax = svw.first().copied().unwrap_or(0.0);
    // Cov = V Σ⁻² Vᵀ of the whitened Jacobian; numerically null directions
    // give an infinite deviation
    let mut std = vec![0.0f64; p];
    for (k, &s) in svw.iter().enumerate() {
        let inv2 = if s > 1e-12 * smax && s > 0.0 {
            1.0 / (s * s)
        } else {
            f64::INFINITY
        };
        for i in 0..p {
            let c = vw[(i, k)] * vw[(i, k)];
            if c > 0.0 {
                std[i] += c * inv2;
            }
        }
    }
    if svw.len() < p {
        std.iter_mut().for_each(|s| *s = f64::INFINITY);
    }
    let parameters: Vec<ParameterIdentifiability> = params
        .iter()
        .zip(&std)
        .map(|(prm, var)| {
            let sd = var.sqrt();
            ParameterIdentifiability {
                name: prm.name.clone(),
                std_scaled: sd,
                std_value: sd * prm.scale(),
                determined: sd < tol,
            }
        })
        .collect();
    let weakest_direction = match v.ncols() {
        0 => vec![],
        k => params
            .iter()
            .enumerate()
            .map(|(i, prm)| (prm.name.clone(), v[(i, k - 1)]))
            .collect(),
    };
    let condition = match (sv.first(), sv.last()) {
        (Some(a), Some(b)) if *b > 0.0 => a / b,
        _ => f64::INFINITY,
    };
    let all_determined = parameters.iter().all(|p| p.determined);
    let verdict = verdict(
        &parameters,
        &weakest_direction,
        noise_level,
        tol,
        all_determined,
    );
    Identifiability {
        singular_values: sv,
        condition,
        noise_level,
        parameters,
        weakest_direction,
        all_determined,
        verdict,
    }
}

fn verdict(
    params: &[ParameterIdentifiability],
    weakest: &[(String, f64)],
    noise: f64,
    tol: f64,
    all: bool,
) -> String {
    if all {
        return format!(
            "every parameter is determined: standard deviation below {tol} (scaled) at {:.3} % noise",
            noise * 100.0
        );
    }
    let bad: Vec<String> = params
        .iter()
        .filter(|p| !p.determined)
        .map(|p| format!("{} (±{:.3})", p.name, p.std_scaled))
        .collect();
    let mut combo: Vec<&(String, f64)> = weakest.iter().filter(|(_, c)| c.abs() > 0.2).collect();
    combo.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    let combo: Vec<String> = combo.iter().map(|(n, c)| format!("{c:+.2}·{n}")).collect();
    format!(
        "the data do not determine {} (scaled standard deviation at {:.3} % noise above {tol}); least determined combination: {}",
        bad.join(", "),
        noise * 100.0,
        combo.join(" ")
    )
}
