//! Identifiability: which combinations of the n force components the
//! sensors can see.
//!
//! Three operators are analysed by their singular values:
//! - per sample, `D_y B_f` (p × n): what one sample of the measured outputs
//!   sees of the force at the same sample (accelerations see the force at
//!   the sensor DOFs directly through `M⁻¹`, or `Tᵀ f` when reduced);
//! - over a window of `L` samples, the response from rest to a force
//!   constant over the window (`(L+1)p × n`, the paper's window operator):
//!   its right singular vectors above the threshold are the **visible**
//!   force combinations, the others (the null space) are invisible and are
//!   set by the regularization alone. With a reduction onto m DOFs the rank
//!   is at most m: only `Tᵀ f` can be seen (docs/theory.md, fact R2);
//! - the method's own window operator `H_θ` restricted to the force
//!   unknowns.
//!
//! Ranks are counted with the relative threshold
//! [`super::IdentifySettings::rank_rtol`].

use super::system::System;
use super::window::RawWindow;
use nalgebra::DMatrix;
use serde::Serialize;

/// Singular values and numerical rank of one operator.
#[derive(Debug, Clone, Serialize)]
pub struct SvdSummary {
    /// What the operator is.
    pub operator: String,
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Singular values, descending.
    pub singular_values: Vec<f64>,
    /// Numerical rank at `rtol`.
    pub rank: usize,
    /// Relative threshold.
    pub rtol: f64,
    /// Largest over smallest singular value (∞ when one is zero).
    pub condition: f64,
}

/// The identifiability report.
#[derive(Debug, Clone, Serialize)]
pub struct Identifiability {
    /// Per-sample feedthrough `D_y B_f`.
    pub per_sample: SvdSummary,
    /// Constant force over one window, from rest.
    pub window: SvdSummary,
    /// The method's window operator (force unknowns only).
    pub method_window: Option<SvdSummary>,
    /// Visible force combinations (unit vectors over the n DOFs), strongest
    /// first.
    pub visible: Vec<Vec<f64>>,
    /// A basis of the invisible combinations.
    pub invisible: Vec<Vec<f64>>,
    /// One line in plain words.
    pub note: String,
}

/// SVD summary of `a`.
pub fn svd_summary(operator: &str, a: &DMatrix<f64>, rtol: f64) -> SvdSummary {
    let sv = a.clone().svd(false, false).singular_values;
    let mut s: Vec<f64> = sv.iter().copied().collect();
    s.sort_by(|x, y| y.total_cmp(x));
    let smax = s.first().copied().unwrap_or(0.0);
    let rank = s.iter().filter(|&&v| v > rtol * smax && v > 0.0).count();
    let smin = s.last().copied().unwrap_or(0.0);
    SvdSummary {
        operator: operator.into(),
        rows: a.nrows(),
        cols: a.ncols(),
        condition: if smin > 0.0 {
            smax / smin
        } else {
            f64::INFINITY
        },
        singular_values: s,
        rank,
        rtol,
    }
}

/// Analyse the sensors' view of the force for windows of `window` samples;
/// `method_h` is the method's `H_θ` restricted to its force unknowns.
pub fn analyse(
    sys: &System,
    window: usize,
    method_h: Option<&DMatrix<f64>>,
    rtol: f64,
) -> Identifiability {
    let n = sys.n();
    let p = sys.p();
    let per = &sys.dy * &sys.bf;
    let raw = RawWindow::build(sys, window);
    let mut wop = DMatrix::zeros((window + 1) * p, n);
    for j in 0..=window {
        for jj in 0..=window {
            let blk = raw.y[j].columns(raw.col_f(jj), n);
            let mut dst = wop.rows_mut(j * p, p);
            dst += blk;
        }
    }
    let wsum = svd_summary("constant force over one window, from rest", &wop, rtol);
    let svd = wop.clone().svd(false, true);
    let vt = svd.v_t.expect("v_t requested");
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let smax = svd.singular_values.max();
    let mut visible = Vec::new();
    let mut invisible = Vec::new();
    let clean = |v: Vec<f64>| -> Vec<f64> {
        // sign: largest component positive; round tiny values
        let big = v
            .iter()
            .cloned()
            .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
        let s = if big < 0.0 { -1.0 } else { 1.0 };
        v.iter()
            .map(|x| {
                let y = s * x;
                if y.abs() < 1e-12 {
                    0.0
                } else {
                    y
                }
            })
            .collect()
    };
    for &i in &order {
        let v: Vec<f64> = vt.row(i).iter().copied().collect();
        if svd.singular_values[i] > rtol * smax {
            visible.push(clean(v));
        } else {
            invisible.push(clean(v));
        }
    }
    // complete the invisible basis when the operator has fewer rows than n
    if visible.len() + invisible.len() < n {
        let mut proj = DMatrix::<f64>::identity(n, n);
        for v in visible.iter().chain(&invisible) {
            let vv = nalgebra::DVector::from_column_slice(v);
            proj -= &vv * vv.transpose();
        }
        let s2 = proj.svd(true, false);
        let u = s2.u.expect("u requested");
        for (i, &s) in s2.singular_values.iter().enumerate() {
            if s > 0.5 {
                invisible.push(clean(u.column(i).iter().copied().collect()));
            }
        }
    }
    let note = format!(
        "{} of {n} force combinations are visible through {p} channel(s) over a window of {window} samples{}",
        visible.len(),
        if sys.reduction.is_some() {
            format!(" (the reduced model has {} coordinates: only Tᵀf is observable)", sys.m())
        } else {
            String::new()
        }
    );
    Identifiability {
        per_sample: svd_summary("per-sample feedthrough D_y B_f", &per, rtol),
        window: wsum,
        method_window: method_h
            .map(|h| svd_summary("method window operator (force unknowns)", h, rtol)),
        visible,
        invisible,
        note,
    }
}
