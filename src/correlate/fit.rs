//! Modal curve fit of measured FRFs: poles by a least-squares complex
//! frequency-domain (LSCF) common-denominator fit over a range of model
//! orders with a stabilisation check, then mode shapes by a least-squares
//! frequency-domain (LSFD) fit of real modal constants.
//!
//! **Poles.** Every FRF of the band `[f_lo, f_hi]` is modelled as
//! `H_o(ω) ≈ N_o(z) / D(z)` with real polynomials of order `p` in
//! `z = exp(iπ f / f_hi)` (the band mapped onto the upper unit half-circle,
//! which keeps the basis well conditioned). The linearised error
//! `N_o(z_k) − H_o(ω_k) D(z_k)` is minimised in least squares over all
//! outputs; the numerator coefficients are eliminated, leaving the reduced
//! normal equations in the denominator (Guillaume et al., "A poly-reference
//! implementation of the least-squares complex frequency-domain estimator",
//! IMAC 2003, in its single-reference form). The roots of `D` are the
//! discrete poles (eigenvalues of its companion matrix, with faer), mapped
//! back to `s = ln z / Δt'` with `Δt' = 1 / (2 f_hi)`: `ω_n = |s|`,
//! `ζ = −Re s / |s|`.
//!
//! **Stabilisation.** A physical pole of order `p` (inside the band,
//! `0 < ζ < ζ_max`) is stable when the previous order has a pole within
//! `freq_tol` in frequency and `damping_tol` (relative) in damping. Stable
//! poles are grouped by frequency; a group holding at least `min_stable`
//! poles is a mode, with the median frequency and damping of its poles.
//!
//! **Shapes.** With the poles fixed, each FRF is fitted by
//!
//! $$ H_o(ω) = (iω)^d \Big[ \sum_r \frac{A_{or}}{ω_r^2 − ω^2 + 2 i ζ_r ω_r ω}
//!    − \frac{L_o}{ω^2} + U_o \Big] $$
//!
//! (`d` = 0, 1, 2 for displacement, velocity, acceleration outputs; `L_o`
//! and `U_o` the lower and upper residuals, which take up the rigid-body
//! mode and the modes outside the band) with real modal constants
//! `A_or = φ_or φ_ir` (real normal modes, `i` the input DOF). When the input
//! DOF is also measured (a driving point), `φ_ir = √A_ir` and the shapes
//! are mass-normalized; otherwise they are scaled to a largest entry of 1.

use super::frf::Frf;
use super::testmodes::{TestMode, TestModes};
use crate::error::{Result, TacitError};
use crate::record::Quantity;
use nalgebra::{DMatrix, DVector};
use rustfft::num_complex::Complex;
use serde::Serialize;

/// Settings of the curve fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitSettings {
    /// Fitted band, Hz: `0 < lo < hi <= fs/2` (default 5–150 Hz).
    pub band_hz: (f64, f64),
    /// Smallest and largest denominator order (number of poles), stepped
    /// by 2 (default 8–48). The largest must exceed twice the number of
    /// modes in the band.
    pub orders: (usize, usize),
    /// Relative frequency tolerance of the stabilisation check and of the
    /// grouping of poles (default 0.01).
    pub freq_tol: f64,
    /// Relative damping tolerance of the stabilisation check (default 0.05).
    pub damping_tol: f64,
    /// Largest damping ratio of a physical pole (default 0.3).
    pub max_damping: f64,
    /// Stable poles a group needs to be a mode (default 5).
    pub min_stable: usize,
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings {
            band_hz: (5.0, 150.0),
            orders: (8, 48),
            freq_tol: 0.01,
            damping_tol: 0.05,
            max_damping: 0.3,
            min_stable: 5,
        }
    }
}

impl FitSettings {
    /// Check the settings against a sample rate; the error repeats the rule.
    pub fn validate(&self, fs: f64) -> Result<()> {
        let (lo, hi) = self.band_hz;
        if !(lo > 0.0 && hi > lo && hi <= fs / 2.0 + 1e-9) {
            return Err(TacitError::Setting(format!(
                "fit band {lo}..{hi} Hz: must satisfy 0 < low < high <= fs/2 = {}",
                fs / 2.0
            )));
        }
        let (a, b) = self.orders;
        if !(a >= 2 && b >= a && b <= 200) {
            return Err(TacitError::Setting(format!(
                "fit orders {a}..{b}: must satisfy 2 <= min <= max <= 200"
            )));
        }
        for (name, v, hi) in [
            ("freq_tol", self.freq_tol, 0.2),
            ("damping_tol", self.damping_tol, 1.0),
            ("max_damping", self.max_damping, 1.0),
        ] {
            if !(v > 0.0 && v <= hi) {
                return Err(TacitError::Setting(format!(
                    "fit {name} = {v}: must be in (0, {hi}]"
                )));
            }
        }
        if self.min_stable < 1 {
            return Err(TacitError::Setting("fit min_stable must be >= 1".into()));
        }
        Ok(())
    }
}

/// One pole of the stabilisation diagram.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StabPole {
    /// Denominator order.
    pub order: usize,
    /// Natural frequency, Hz.
    pub freq_hz: f64,
    /// Damping ratio.
    pub damping: f64,
    /// Stable against the previous order.
    pub stable: bool,
}

/// How the fit ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FitStatus {
    /// At least one mode was identified.
    Identified,
    /// No group of stable poles: no mode (raise the orders, widen the band,
    /// or average more).
    NoStableMode,
}

/// Result of the curve fit.
#[derive(Debug, Clone, Serialize)]
pub struct FitResult {
    /// How the fit ended.
    pub status: FitStatus,
    /// Measured DOFs (the FRF outputs).
    pub dofs: Vec<usize>,
    /// Identified modes in ascending frequency; shapes at `dofs`.
    pub modes: Vec<TestMode>,
    /// True when the shapes are mass-normalized (driving point measured
    /// and every driving-point constant positive).
    pub mass_normalized: bool,
    /// The stabilisation diagram.
    pub poles: Vec<StabPole>,
    /// Relative error ‖H − Ĥ‖ / ‖H‖ of the LSFD fit per output, over the band.
    pub fit_error: Vec<f64>,
    /// Stable poles per identified mode.
    pub support: Vec<usize>,
    /// Things the user should know (failed orders, negative driving-point
    /// constants, …).
    pub diagnostics: Vec<String>,
}

impl FitResult {
    /// The identified modes as a [`TestModes`] set; an error when no mode
    /// was identified.
    pub fn test_modes(&self, name: &str, ndof: usize) -> Result<TestModes> {
        if self.modes.is_empty() {
            return Err(TacitError::Numerical(format!(
                "{name}: the curve fit identified no mode ({})",
                self.diagnostics.join("; ")
            )));
        }
        TestModes::new(
            name,
            self.dofs.clone(),
            self.modes.clone(),
            self.mass_normalized,
            ndof,
        )
    }
}

/// A mode found in the stabilisation diagram: frequency (Hz), damping
/// ratio, number of stable poles behind it.
pub(crate) type Group = (f64, f64, usize);

/// Lines of the FRF inside the band (Hz).
pub(crate) fn band_lines(frf: &Frf, band: (f64, f64)) -> Vec<usize> {
    (0..frf.freq_hz.len())
        .filter(|&l| frf.freq_hz[l] >= band.0 && frf.freq_hz[l] <= band.1)
        .collect()
}

/// Identify modes from FRFs (LSCF poles + LSFD shapes).
pub fn identify(frf: &Frf, settings: &FitSettings) -> Result<FitResult> {
    settings.validate(frf.fs)?;
    let lines = band_lines(frf, settings.band_hz);
    let pmax = settings.orders.1;
    if lines.len() < pmax + 2 {
        return Err(TacitError::Setting(format!(
            "fit band {:?} Hz holds {} FRF lines, fewer than the largest order {} + 2",
            settings.band_hz,
            lines.len(),
            pmax
        )));
    }
    if frf.h.is_empty() {
        return Err(TacitError::Setting("the FRF has no output".into()));
    }
    let mut diagnostics = Vec::new();
    let poles = stabilisation(frf, &lines, settings, &mut diagnostics)?;
    let groups = group_poles(&poles, settings);
    if groups.is_empty() {
        diagnostics.push(format!(
            "no frequency holds {} stable poles over orders {}..{}",
            settings.min_stable, settings.orders.0, settings.orders.1
        ));
        return Ok(FitResult {
            status: FitStatus::NoStableMode,
            dofs: frf.output_dofs.clone(),
            modes: vec![],
            mass_normalized: false,
            poles,
            fit_error: vec![],
            support: vec![],
            diagnostics,
        });
    }
    let (consts, fit_error) = lsfd(frf, &lines, &groups, true)?;
    let (modes, mass_normalized) = shapes_from_constants(frf, &groups, &consts, &mut diagnostics);
    Ok(FitResult {
        status: FitStatus::Identified,
        dofs: frf.output_dofs.clone(),
        modes,
        mass_normalized,
        poles,
        fit_error,
        support: groups.iter().map(|g| g.2).collect(),
        diagnostics,
    })
}

/// Normal-equation blocks of one output: S_o, T_o and its weight².
type OutputBlocks = (DMatrix<f64>, DMatrix<f64>, f64);

/// LSCF poles at every order, with the stabilisation flag.
fn stabilisation(
    frf: &Frf,
    lines: &[usize],
    s: &FitSettings,
    diagnostics: &mut Vec<String>,
) -> Result<Vec<StabPole>> {
    let pmax = s.orders.1;
    let fhi = s.band_hz.1;
    let dt = 1.0 / (2.0 * fhi);
    let nb = pmax + 1;
    // z_k^j for every line and power
    let zpow: Vec<Vec<Complex<f64>>> = lines
        .iter()
        .map(|&l| {
            let z = Complex::from_polar(1.0, std::f64::consts::PI * frf.freq_hz[l] / fhi);
            let mut v = Vec::with_capacity(nb);
            let mut acc = Complex::new(1.0, 0.0);
            for _ in 0..nb {
                v.push(acc);
                acc *= z;
            }
            v
        })
        .collect();
    // Re Σ_k c_k conj(z_k^i) z_k^j
    let gram = |f: &dyn Fn(usize) -> Complex<f64>| -> DMatrix<f64> {
        let mut m = DMatrix::zeros(nb, nb);
        for (k, zp) in zpow.iter().enumerate() {
            let c = f(k);
            for i in 0..nb {
                let a = zp[i].conj() * c;
                for j in 0..nb {
                    m[(i, j)] += (a * zp[j]).re;
                }
            }
        }
        m
    };
    let r = gram(&|_| Complex::new(1.0, 0.0));
    let mut st: Vec<OutputBlocks> = Vec::with_capacity(frf.h.len());
    for h in &frf.h {
        let hb: Vec<Complex<f64>> = lines.iter().map(|&l| h[l]).collect();
        let rms = (hb.iter().map(|c| c.norm_sqr()).sum::<f64>() / hb.len() as f64).sqrt();
        if rms == 0.0 || !rms.is_finite() {
            continue;
        }
        let w2 = 1.0 / (rms * rms);
        let sm = gram(&|k| -hb[k]) * w2;
        let tm = gram(&|k| Complex::new(hb[k].norm_sqr(), 0.0)) * w2;
        st.push((sm, tm, w2));
    }
    if st.is_empty() {
        return Err(TacitError::Numerical(
            "every FRF is zero (or not finite) in the fit band".into(),
        ));
    }
    let mut out: Vec<StabPole> = Vec::new();
    let mut prev: Vec<(f64, f64)> = Vec::new();
    let mut p = s.orders.0;
    while p <= pmax {
        match lscf_poles(&r, &st, p, dt) {
            Some(poles) => {
                let phys: Vec<(f64, f64)> = poles
                    .into_iter()
                    .filter(|&(f, z)| f >= s.band_hz.0 && f <= fhi && z > 0.0 && z < s.max_damping)
                    .collect();
                for &(f, z) in &phys {
                    let stable = prev.iter().any(|&(fp, zp)| {
                        (f - fp).abs() <= s.freq_tol * f && (z - zp).abs() <= s.damping_tol * z
                    });
                    out.push(StabPole {
                        order: p,
                        freq_hz: f,
                        damping: z,
                        stable,
                    });
                }
                prev = phys;
            }
            None => {
                diagnostics.push(format!(
                    "order {p}: singular LSCF normal equations, skipped"
                ));
                prev.clear();
            }
        }
        p += 2;
    }
    Ok(out)
}

/// Poles (frequency Hz, damping ratio) of the order-`p` LSCF denominator;
/// `None` when the reduced normal equations are singular.
fn lscf_poles(r: &DMatrix<f64>, st: &[OutputBlocks], p: usize, dt: f64) -> Option<Vec<(f64, f64)>> {
    let n = p + 1;
    let rp = r.view((0, 0), (n, n)).into_owned();
    let mut m = DMatrix::<f64>::zeros(n, n);
    for (sm, tm, w2) in st {
        let chol = (&rp * *w2).cholesky()?;
        let s = sm.view((0, 0), (n, n)).into_owned();
        let x = chol.solve(&s);
        m += tm.view((0, 0), (n, n)) - s.transpose() * x;
    }
    // α_p = 1: M[0..p, 0..p] α = −M[0..p, p]
    let a = m.view((0, 0), (p, p)).into_owned();
    let b = -m.view((0, p), (p, 1)).into_owned();
    let alpha = a.lu().solve(&b)?;
    if alpha.iter().any(|v| !v.is_finite()) {
        return None;
    }
    // companion matrix of z^p + α_{p−1} z^{p−1} + … + α_0
    let mut c = faer::Mat::<f64>::zeros(p, p);
    for j in 0..p {
        c[(0, j)] = -alpha[(p - 1 - j, 0)];
    }
    for i in 1..p {
        c[(i, i - 1)] = 1.0;
    }
    let eig = c.eigenvalues().ok()?;
    let mut poles = Vec::new();
    for z in eig {
        let zc = Complex::new(z.re, z.im);
        if zc.norm() == 0.0 || zc.im <= 0.0 || !zc.norm().is_finite() {
            continue;
        }
        let sp = zc.ln() / dt;
        let wn = sp.norm();
        poles.push((wn / (2.0 * std::f64::consts::PI), -sp.re / wn));
    }
    Some(poles)
}

/// Groups of stable poles, ascending in frequency.
fn group_poles(poles: &[StabPole], s: &FitSettings) -> Vec<Group> {
    let mut stable: Vec<&StabPole> = poles.iter().filter(|p| p.stable).collect();
    stable.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    let mut groups = Vec::new();
    let mut i = 0;
    while i < stable.len() {
        let mut j = i + 1;
        while j < stable.len()
            && stable[j].freq_hz - stable[j - 1].freq_hz <= s.freq_tol * stable[j - 1].freq_hz
        {
            j += 1;
        }
        let g = &stable[i..j];
        if g.len() >= s.min_stable {
            let mut f: Vec<f64> = g.iter().map(|p| p.freq_hz).collect();
            let mut z: Vec<f64> = g.iter().map(|p| p.damping).collect();
            groups.push((median(&mut f), median(&mut z), g.len()));
        }
        i = j;
    }
    groups
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// LSFD: real modal constants (outputs × modes) and the relative fit error
/// per output; with `residual_terms`, the lower and upper residuals
/// `−L/ω²` and `U` are fitted beside the modes (and not returned).
pub(crate) fn lsfd(
    frf: &Frf,
    lines: &[usize],
    groups: &[Group],
    residual_terms: bool,
) -> Result<(DMatrix<f64>, Vec<f64>)> {
    let nm = groups.len();
    let nc = if residual_terms { nm + 2 } else { nm };
    let d = match frf.quantity {
        Quantity::Disp => 0,
        Quantity::Vel => 1,
        Quantity::Accel => 2,
        Quantity::Force => {
            return Err(TacitError::Setting(
                "an FRF output cannot be a force".into(),
            ))
        }
    };
    let two_pi = 2.0 * std::f64::consts::PI;
    let basis: Vec<Vec<Complex<f64>>> = lines
        .iter()
        .map(|&l| {
            let w = two_pi * frf.freq_hz[l];
            let mult = Complex::new(0.0, w).powu(d);
            let mut row: Vec<Complex<f64>> = groups
                .iter()
                .map(|&(f, z, _)| {
                    let wr = two_pi * f;
                    mult / Complex::new(wr * wr - w * w, 2.0 * z * wr * w)
                })
                .collect();
            if residual_terms {
                row.push(mult * (-1.0 / (w * w)));
                row.push(mult);
            }
            row
        })
        .collect();
    let nl = lines.len();
    // column scaling for conditioning
    let scale: Vec<f64> = (0..nc)
        .map(|c| {
            let s = (basis.iter().map(|b| b[c].norm_sqr()).sum::<f64>() / nl as f64).sqrt();
            if s > 0.0 {
                1.0 / s
            } else {
                1.0
            }
        })
        .collect();
    let a = DMatrix::from_fn(2 * nl, nc, |i, c| {
        let b = basis[i / 2][c] * scale[c];
        if i % 2 == 0 {
            b.re
        } else {
            b.im
        }
    });
    let svd = a.clone().svd(true, true);
    let mut consts = DMatrix::zeros(frf.h.len(), nm);
    let mut errs = Vec::with_capacity(frf.h.len());
    for (o, h) in frf.h.iter().enumerate() {
        let y = DVector::from_fn(2 * nl, |i, _| {
            let v = h[lines[i / 2]];
            if i % 2 == 0 {
                v.re
            } else {
                v.im
            }
        });
        let x = svd.solve(&y, 1e-12).map_err(|e| {
            TacitError::Numerical(format!("LSFD at DOF {}: {e}", frf.output_dofs[o]))
        })?;
        let fit = &a * &x;
        let den = y.norm();
        errs.push(if den > 0.0 {
            (&fit - &y).norm() / den
        } else {
            0.0
        });
        for r in 0..nm {
            consts[(o, r)] = x[r] * scale[r];
        }
    }
    Ok((consts, errs))
}

/// Shapes from the modal constants (mass-normalized through the driving
/// point when it is measured).
fn shapes_from_constants(
    frf: &Frf,
    groups: &[Group],
    consts: &DMatrix<f64>,
    diagnostics: &mut Vec<String>,
) -> (Vec<TestMode>, bool) {
    let dp = frf.output_index(frf.input_dof);
    let mut mass_normalized = dp.is_some();
    let mut modes = Vec::with_capacity(groups.len());
    for (r, &(f, z, _)) in groups.iter().enumerate() {
        let col: Vec<f64> = consts.column(r).iter().copied().collect();
        let shape = match dp {
            Some(i) if col[i] > 0.0 => {
                let phi_in = col[i].sqrt();
                col.iter().map(|a| a / phi_in).collect()
            }
            _ => {
                if let Some(i) = dp {
                    diagnostics.push(format!(
                        "mode {} ({f:.2} Hz): driving-point constant {:.3e} at DOF {} is not positive; shapes scaled to max 1",
                        r + 1,
                        col[i],
                        frf.input_dof
                    ));
                    mass_normalized = false;
                }
                col
            }
        };
        modes.push(TestMode {
            frequency_hz: f,
            damping: z,
            shape,
        });
    }
    if !mass_normalized {
        for m in &mut modes {
            let mx = m.shape.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            let imax = m.shape.iter().position(|v| v.abs() == mx).unwrap_or(0);
            let s = if m.shape[imax] < 0.0 { -1.0 } else { 1.0 };
            if mx > 0.0 {
                m.shape.iter_mut().for_each(|v| *v *= s / mx);
            }
        }
    }
    (modes, mass_normalized)
}
