//! The Riccati step of a stage whose costs are outputs and whose many
//! controls come in a few groups that share a weight, solved in the
//! space of the outputs and the next state (size `q = p + n`), never in
//! the control space (size `m`).
//!
//! **Problem.** `x⁺ = A x + B u`, stage cost `‖H_x x + H_u u − r‖² +
//! uᵀΛu`, `Λ` diagonal, positive, changing from step to step but equal
//! to `w_c λ_i` over the controls `i` of group `c` (`λ_i` fixed, `w_c`
//! the step's group weight). With `Z = [H_u; B]` (q × m), `Y = [H_x; A]`
//! (q × n) and `S = diag(I_p, P')`, the control-space step
//! (`Q_uu = Λ + ZᵀSZ`, `L = Q_uu⁻¹ZᵀSY`, `P = YᵀSY − (SY)ᵀZL`) is written
//! through the push-through identity `Q_uu⁻¹Zᵀ = Λ⁻¹Zᵀ(I + SM)⁻¹`,
//! `M = ZΛ⁻¹Zᵀ`:
//!
//! $$ M = \sum_c \frac{N_c}{w_c},\quad N_c = \sum_{i∈c} \frac{z_i z_iᵀ}{λ_i},
//!    \quad F = I + S M,\quad T = F^{-1} S Y, $$
//! $$ \text{closed} = Y − Z L = Y − M T = (I + M S)^{-1} Y,\quad
//!    T = S\,\text{closed},\quad P = Yᵀ T $$
//!
//! (`ZL = M T`, `closed = [H_x − H_u L; A − B L]`; `I − M F⁻¹ S =
//! (I + MS)⁻¹` and `F⁻¹S = S(I + MS)⁻¹`). `closed` comes from one solve
//! with `I + MS = Fᵀ` and `P` from a product with no subtraction, so the
//! change of `P` between steps has no cancellation floor. On the F-16
//! Level-7 record (65 536 samples) the lifted smoother's test for its
//! steady state (a relative change below 10⁻¹³ three times running) was
//! met after 1 991 samples; with `closed` formed as `Y − M T` it was never
//! met, and with the control-space step after 4 627. The group Grams `N_c` are formed once, so a step costs
//! `O(g q² + q² n + q n²)` (`g` groups) whatever `m`: for the lifted
//! smoother on the F-16 modal model (72 controls in 9 groups, q = 21,
//! n = 18) about 45 000 multiply–adds, against about 180 000 for the
//! same step in the control space. The vector pass of a smoother with
//! data `v = [r; e]` (`e = p' − P'c`) is `ω = F⁻¹v` ([`Grouped::feed`]),
//! the control `u = Λ⁻¹Zᵀ(ω − T x)` and `p = closedᵀ v`; a smoother needs
//! only `T` (q × n) and `ω` (q) per sample to recover the controls,
//! against `L` (m × n) and `l` (m).
//!
//! When there are fewer controls than outputs and states (`m < q`: one
//! located force direction, 8 sub-interval forces against 19 for three
//! channels of an 8-DOF model) the step is taken in the control space
//! instead ([`Grouped::direct`]): `Q_uu = Λ + ZᵀSZ` by Cholesky,
//! `K = Q_uu⁻¹Zᵀ`, `L = K S Y`, `closed = Y − Z L`,
//! `P = YᵀSY − (SY)ᵀZL`, and the smoother keeps `L` and `l = K v`, the
//! control being `u = l − L x` (on the LANL bumper record with one
//! located pair, 0.31 s of user CPU for `tacit identify` against 0.46 s in
//! the output space).

use super::dense::{mul, view, view_mut};
use super::symmetrize;
use faer::linalg::solvers::{PartialPivLu, Solve};
use nalgebra::{DMatrix, DVector};

/// The stage and the buffers of its step (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct Grouped {
    /// State size n.
    pub n: usize,
    /// Output rows p.
    pub p: usize,
    /// `Y = [H_x; A]` (q × n).
    y: DMatrix<f64>,
    /// `N_c` (q × q each).
    grams: Vec<DMatrix<f64>>,
    /// `M` of the last step (q × q).
    pub m: DMatrix<f64>,
    /// The step in the control space (`m < q` by default).
    pub direct: bool,
    /// `Z = [H_u; B]` (q × m) and `Zᵀ`.
    z: DMatrix<f64>,
    zt: DMatrix<f64>,
    /// `λ_i` and the group of every control.
    lambda: Vec<f64>,
    group: Vec<usize>,
    /// Control space: `K = Q_uu⁻¹ Zᵀ` of the last step (m × q).
    k: DMatrix<f64>,
    /// The gain of the last step: `T = F⁻¹ S Y` (q × n), or `L` (m × n)
    /// in the control space.
    pub t: DMatrix<f64>,
    /// `Y − Z L` of the last step (q × n).
    pub closed: DMatrix<f64>,
    /// `P` of the last step (n × n).
    pub pm: DMatrix<f64>,
    /// LU factors of `I + M S = Fᵀ` of the last step.
    lu: Option<PartialPivLu<f64>>,
}

impl Grouped {
    /// The stage `x⁺ = A x + B u` with outputs `H_x x + H_u u`; control
    /// `i` belongs to group `group[i]` (0-based, `groups` in all) and has
    /// the fixed weight `lambda[i]` (> 0).
    pub fn new(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        hx: &DMatrix<f64>,
        hu: &DMatrix<f64>,
        group: &[usize],
        groups: usize,
        lambda: &[f64],
    ) -> Grouped {
        let (p, n) = (hx.nrows(), a.ncols());
        let q = p + n;
        let mut y = DMatrix::zeros(q, n);
        y.rows_mut(0, p).copy_from(hx);
        y.rows_mut(p, n).copy_from(a);
        let mut grams = vec![DMatrix::zeros(q, q); groups];
        let mut z = DVector::zeros(q);
        for (i, (&c, &li)) in group.iter().zip(lambda).enumerate() {
            z.rows_mut(0, p).copy_from(&hu.column(i));
            z.rows_mut(p, n).copy_from(&b.column(i));
            grams[c].ger(1.0 / li, &z, &z, 1.0);
        }
        for g in &mut grams {
            symmetrize(g);
        }
        let nu = group.len();
        let mut z = DMatrix::zeros(q, nu);
        z.rows_mut(0, p).copy_from(hu);
        z.rows_mut(p, n).copy_from(b);
        Grouped {
            n,
            p,
            y,
            grams,
            m: DMatrix::zeros(q, q),
            direct: nu < q,
            zt: z.transpose(),
            z,
            lambda: lambda.to_vec(),
            group: group.to_vec(),
            k: DMatrix::zeros(0, 0),
            t: DMatrix::zeros(q, n),
            closed: DMatrix::zeros(q, n),
            pm: DMatrix::zeros(n, n),
            lu: None,
        }
    }

    /// Rows of the gain [`Grouped::t`] and of the vector [`Grouped::feed`]
    /// returns: `q`, or `m` in the control space.
    pub fn gain_rows(&self) -> usize {
        if self.direct {
            self.z.ncols()
        } else {
            self.p + self.n
        }
    }

    /// One step from `pn = P'` with group weights `w` (> 0); false when
    /// `I + M S` is singular (`Q_uu` not positive definite in the control
    /// space).
    pub fn step(&mut self, pn: &DMatrix<f64>, w: &[f64]) -> bool {
        if self.direct {
            return self.step_direct(pn, w);
        }
        let (p, n) = (self.p, self.n);
        let q = p + n;
        self.m.fill(0.0);
        for (g, wc) in self.grams.iter().zip(w) {
            let s = 1.0 / wc;
            for (mi, gi) in self.m.as_mut_slice().iter_mut().zip(g.as_slice()) {
                *mi += s * gi;
            }
        }
        // G = I + M S = Fᵀ
        let mut g = self.m.clone();
        let mright = view(&self.m).submatrix(0, p, q, n);
        mul(
            view_mut(&mut g).submatrix_mut(0, p, q, n),
            false,
            mright,
            view(pn),
            1.0,
        );
        for i in 0..q {
            g[(i, i)] += 1.0;
        }
        // closed = G⁻¹ Y
        let lu = PartialPivLu::new(view(&g));
        self.closed.copy_from(&self.y);
        lu.solve_in_place(view_mut(&mut self.closed));
        if !self.closed.iter().all(|v| v.is_finite()) {
            self.lu = None;
            return false;
        }
        self.lu = Some(lu);
        // T = S closed, P = Yᵀ T
        if self.t.shape() != (q, n) {
            self.t = DMatrix::zeros(q, n);
        }
        self.t.rows_mut(0, p).copy_from(&self.closed.rows(0, p));
        let low = view(&self.closed).submatrix(p, 0, n, n);
        mul(
            view_mut(&mut self.t).submatrix_mut(p, 0, n, n),
            false,
            view(pn),
            low,
            1.0,
        );
        mul(
            view_mut(&mut self.pm),
            false,
            view(&self.y).transpose(),
            view(&self.t),
            1.0,
        );
        symmetrize(&mut self.pm);
        true
    }

    /// The step in the control space (module docs).
    fn step_direct(&mut self, pn: &DMatrix<f64>, w: &[f64]) -> bool {
        let (p, q) = (self.p, self.p + self.n);
        // Zᵀ S = [H_uᵀ, Bᵀ P']
        let mut zts = self.zt.clone();
        let gp = self.zt.columns(p, q - p) * pn;
        zts.columns_mut(p, q - p).copy_from(&gp);
        let mut quu = &zts * &self.z;
        symmetrize(&mut quu);
        for (i, (li, g)) in self.lambda.iter().zip(&self.group).enumerate() {
            quu[(i, i)] += li * w[*g];
        }
        let Some(k) = quu.cholesky().map(|c| c.solve(&self.zt)) else {
            return false;
        };
        let mut sy = self.y.clone();
        let pa = pn * self.y.rows(p, q - p);
        sy.rows_mut(p, q - p).copy_from(&pa);
        self.t = &k * &sy;
        let zlm = &self.z * &self.t;
        self.pm = self.y.transpose() * &sy - sy.transpose() * &zlm;
        symmetrize(&mut self.pm);
        self.closed = &self.y - &zlm;
        self.k = k;
        true
    }

    /// The vector the smoother keeps per sample for data `v = [r; e]`:
    /// `ω = F⁻¹ v` (a transposed solve with the factors of `I + M S = Fᵀ`),
    /// or `l = K v` in the control space; from the last successful step.
    pub fn feed(&self, v: &DVector<f64>) -> DVector<f64> {
        if self.direct {
            return &self.k * v;
        }
        let lu = self.lu.as_ref().expect("a successful step before feed");
        let mut w = v.clone();
        let n = w.len();
        lu.solve_transpose_in_place(faer::MatMut::from_column_major_slice_mut(
            w.as_mut_slice(),
            n,
            1,
        ));
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The step against the control-space formulas, with
    /// uneven weights inside and across groups.
    #[test]
    fn step_matches_the_control_space_formulas() {
        let (n, m) = (3, 4);
        let a = DMatrix::from_fn(n, n, |i, j| 0.2 * (((i * 5 + j * 3) % 7) as f64 - 3.0));
        let b = DMatrix::from_fn(n, m, |i, j| 0.1 * ((i + 2 * j) % 3) as f64 + 0.05);
        let h = DMatrix::from_fn(2, n + m, |i, j| ((i * 3 + j) % 4) as f64 - 1.5);
        let (hx, hu) = (h.columns(0, n).into_owned(), h.columns(n, m).into_owned());
        let group = [0, 1, 0, 1];
        let lambda = [0.7, 0.2, 1.3, 0.4];
        let w = [2.0, 0.5];
        let pn = DMatrix::from_fn(n, n, |i, j| if i == j { 2.0 + i as f64 } else { 0.3 });
        let mut st = Grouped::new(&a, &b, &hx, &hu, &group, 2, &lambda);
        assert!(st.direct, "4 controls against 5 outputs and states");
        assert!(st.step(&pn, &w));
        let direct = st.clone();
        st.direct = false;
        assert!(st.step(&pn, &w));
        let lam = DVector::from_fn(m, |i, _| lambda[i] * w[group[i]]);
        let quu = hu.transpose() * &hu + DMatrix::from_diagonal(&lam) + b.transpose() * &pn * &b;
        let qux = hu.transpose() * &hx + b.transpose() * &pn * &a;
        let chol = quu.cholesky().unwrap();
        let l = chol.solve(&qux);
        let pw = hx.transpose() * &hx + a.transpose() * &pn * &a - qux.transpose() * &l;
        assert!((&st.pm - &pw).amax() < 1e-12 * pw.amax());
        // controls from T: L = Λ⁻¹ Zᵀ T
        let mut z = DMatrix::zeros(2 + n, m);
        z.rows_mut(0, 2).copy_from(&hu);
        z.rows_mut(2, n).copy_from(&b);
        let mut lt = z.transpose() * &st.t;
        for i in 0..m {
            lt.row_mut(i).scale_mut(1.0 / lam[i]);
        }
        assert!((&lt - &l).amax() < 1e-12 * l.amax());
        // closed loop
        let phi = &a - &b * &l;
        assert!((st.closed.rows(2, n) - &phi).amax() < 1e-12);
        // the vector pass: Λ⁻¹ Zᵀ F⁻¹ v = Q_uu⁻¹ Zᵀ S v
        let v = DVector::from_fn(2 + n, |i, _| (i as f64 * 0.7).sin());
        let mut kv = z.transpose() * st.feed(&v);
        for i in 0..m {
            kv[i] /= lam[i];
        }
        let want = chol.solve(&(z.transpose() * v.clone()));
        assert!((&kv - &want).amax() < 1e-12 * want.amax(), "{kv} {want}");
        // the control-space form: L itself, l = K v, the same P and loop
        assert!((&direct.t - &l).amax() < 1e-12 * l.amax());
        assert!((direct.feed(&v) - &want).amax() < 1e-12 * want.amax());
        assert!((&direct.pm - &pw).amax() < 1e-12 * pw.amax());
        assert!((direct.closed.rows(2, n) - &phi).amax() < 1e-12);
        assert_eq!(direct.gain_rows(), m);
        assert_eq!(st.gain_rows(), 2 + n);
    }
}
