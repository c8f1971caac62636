//! The Riccati core shared by the two smoothers, the full-horizon one
//! ([`crate::horizon`], on the reduced system) and the lifted one
//! ([`crate::identify::lifted`], on the sub-sampled model): one step of
//! the backward recursion of a linear–quadratic stage and its fixed point
//! ([`step`]), the step of a stage with output costs and grouped control
//! weights solved in the output space ([`grouped`], the lifted
//! smoother's), the small dense kernels they run on ([`dense`]), exact
//! symmetrization of the iterates `P_k` (rounding leaves the two
//! triangles of `P − YᵀY` apart, and the recursion would amplify the
//! skew part), and the relative change between iterates by which each
//! sweep decides when to hold its gain.

pub(crate) mod dense;
pub(crate) mod grouped;
pub(crate) mod step;

pub(crate) use grouped::Grouped;
pub(crate) use step::{fixed_point, stein, Riccati, Stage};

use nalgebra::DMatrix;

/// Make a square matrix exactly symmetric (mean of the two triangles).
pub fn symmetrize(p: &mut DMatrix<f64>) {
    let n = p.nrows();
    let a = p.as_mut_slice();
    for j in 0..n {
        // column j against row j, read as the j-th entry of the later columns
        let (left, right) = a.split_at_mut((j + 1) * n);
        let col = &mut left[j * n..];
        for (cj, other) in col[j + 1..].iter_mut().zip(right.chunks_exact_mut(n)) {
            let v = 0.5 * (*cj + other[j]);
            *cj = v;
            other[j] = v;
        }
    }
}

/// What [`rel_change`] divides by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RelativeTo {
    /// `‖b‖_max` (the reference iterate or the fixed point).
    Second,
    /// `max(‖a‖_max, ‖b‖_max)`.
    Larger,
}

/// Relative change `‖a − b‖_max / s` (`s` by `to`; 0 when `s` is 0),
/// in four lanes so that it vectorises.
pub fn rel_change(a: &DMatrix<f64>, b: &DMatrix<f64>, to: RelativeTo) -> f64 {
    let (mut d, mut sa, mut sb) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
    let (ca, cb) = (a.as_slice().chunks_exact(4), b.as_slice().chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..4 {
            let (e, u, v) = ((x[i] - y[i]).abs(), x[i].abs(), y[i].abs());
            d[i] = if e > d[i] { e } else { d[i] };
            sa[i] = if u > sa[i] { u } else { sa[i] };
            sb[i] = if v > sb[i] { v } else { sb[i] };
        }
    }
    for (x, y) in ra.iter().zip(rb) {
        d[0] = d[0].max((x - y).abs());
        sa[0] = sa[0].max(x.abs());
        sb[0] = sb[0].max(y.abs());
    }
    let max = |l: [f64; 4]| l.iter().fold(0.0, |m: f64, v| m.max(*v));
    let s = match to {
        RelativeTo::Second => max(sb),
        RelativeTo::Larger => max(sa).max(max(sb)),
    };
    if s == 0.0 {
        0.0
    } else {
        max(d) / s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetrize_averages_the_triangles_and_rel_change_divides_as_asked() {
        let mut p = DMatrix::from_row_slice(3, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        symmetrize(&mut p);
        assert_eq!(
            p,
            DMatrix::from_row_slice(3, 3, &[1.0, 3.0, 5.0, 3.0, 5.0, 7.0, 5.0, 7.0, 9.0])
        );
        let a = DMatrix::from_element(3, 3, 4.0);
        let b = DMatrix::from_element(3, 3, 2.0);
        assert_eq!(rel_change(&a, &b, RelativeTo::Second), 1.0);
        assert_eq!(rel_change(&a, &b, RelativeTo::Larger), 0.5);
        assert_eq!(rel_change(&b, &b, RelativeTo::Larger), 0.0);
    }
}
