//! Segment-wise regression of the residual on candidate effects, and the
//! greedy selection with the Bayesian information criterion.

use super::candidates::{damping_parts, library, Candidate, EffectKind};
use crate::linear::SampledModel;
use crate::model::Model;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;

/// Settings of the trace step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TraceSettings {
    /// Smallest fraction of the remaining residual energy an effect must
    /// remove to be selected (default 0.05).
    pub min_gain: f64,
    /// Most effects selected (default 3).
    pub max_effects: usize,
    /// Friction regularisation velocity, m/s (default 1e-3).
    pub friction_vreg: f64,
    /// Points of the coarse gap scan of a contact (default 24).
    pub gap_grid: usize,
}

impl Default for TraceSettings {
    fn default() -> Self {
        TraceSettings {
            min_gain: 0.05,
            max_effects: 3,
            friction_vreg: 1e-3,
            gap_grid: 24,
        }
    }
}

/// What the trace step needs.
#[derive(Debug, Clone, Copy)]
pub struct TraceInput<'a> {
    /// The declared model (its linear part is `sampled`).
    pub model: &'a Model,
    /// The linear model's sampled map.
    pub sampled: &'a SampledModel,
    /// Output map rows for the measured channels (p × 2n).
    pub cy: &'a DMatrix<f64>,
    /// Output feed-through (p × n).
    pub dy: &'a DMatrix<f64>,
    /// Measured channels (p × N).
    pub measured: &'a DMatrix<f64>,
    /// External force (n × N).
    pub force_ext: &'a DMatrix<f64>,
    /// Reconstructed states `[u; v]` (2n × N).
    pub states: &'a DMatrix<f64>,
    /// Identified internal force (n × N, left-hand-side convention), if any.
    pub identified_force: Option<&'a DMatrix<f64>>,
    /// Samples per segment.
    pub segment: usize,
    /// Segment predictions of the current model (p × N) when it is not the
    /// linear model (after effects were added); `None`: the linear model's
    /// segments from the reconstructed states.
    pub baseline: Option<&'a DMatrix<f64>>,
    /// Effects already in the model (not proposed again).
    pub exclude: &'a [Candidate],
    /// Directions the force was located along (n × q, from
    /// [`crate::identify::locate`]); a candidate acting along them is
    /// preferred to a better-scoring one acting elsewhere, when it pays.
    pub located: Option<&'a DMatrix<f64>>,
}

/// A scored effect with its parameters from the regression.
#[derive(Debug, Clone, Serialize)]
pub struct RankedEffect {
    /// The candidate (with its gap for a contact).
    pub candidate: Candidate,
    /// Label with DOFs from 1.
    pub label: String,
    /// Parameters (SI names: gap, stiffness, level, k3, delta).
    pub parameters: Vec<(String, f64)>,
    /// Standard errors of the parameters (same order).
    pub std_errors: Vec<f64>,
    /// Fraction of the remaining residual energy removed.
    pub residual_explained: f64,
    /// Fraction of the identified force's energy it explains (if given).
    pub force_explained: Option<f64>,
    /// Change of the information criterion (negative pays).
    pub bic_change: f64,
    /// Correction of the reconstructed states along the hidden
    /// trajectories ([`TraceResult::hidden`]) fitted with the effect, one
    /// coefficient per trajectory (empty when the effect does not see them).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub hidden: Vec<f64>,
}

#[cfg(test)]
impl RankedEffect {
    /// An effect as the trace ranks one (30 % of the residual, BIC change
    /// −100, no standard errors) with the given parameters, for tests.
    pub(crate) fn for_test(candidate: Candidate, parameters: &[(&str, f64)]) -> Self {
        RankedEffect {
            label: candidate.label(),
            candidate,
            parameters: parameters.iter().map(|&(n, v)| (n.into(), v)).collect(),
            std_errors: vec![],
            residual_explained: 0.3,
            force_explained: None,
            bic_change: -100.0,
            hidden: vec![],
        }
    }
}

/// Result of the trace step.
#[derive(Debug, Clone, Serialize)]
pub struct TraceResult {
    /// Every candidate of the first round, best first.
    pub ranking: Vec<RankedEffect>,
    /// Effects selected, in order.
    pub selected: Vec<RankedEffect>,
    /// Weighted residual energy before any effect and after each selected one.
    pub rss_history: Vec<f64>,
    /// Why the selection stopped.
    pub stop_reason: String,
    /// Linear segment simulations run.
    pub simulations: usize,
    /// Trajectories of the linear model (2n × N each) the measured channels
    /// never see ([`hidden_trajectories`]).
    #[serde(skip)]
    pub hidden: Vec<DMatrix<f64>>,
}

/// Trajectories of the linear model the measured channels never see, one
/// 2n × N matrix per direction: `e_{k+1} = A e_k` from an orthonormal basis
/// (in states scaled to velocity units) of the unobservable subspace of
/// `(A, C_y)`. Under acceleration data a free-free model has two, the
/// rigid-body displacement `(r, 0)` and velocity `(t r, r)`. The
/// reconstruction cannot place the states along them, so the force of a
/// candidate that is linear in the state is fitted together with them
/// (`θ φ(x̂ + Σ c_j e_j) = θ φ(x̂) + Σ (θ c_j) φ(e_j)`): a spring to ground
/// acts on the absolute displacement the data do not fix.
pub fn hidden_trajectories(sm: &SampledModel, cy: &DMatrix<f64>, ns: usize) -> Vec<DMatrix<f64>> {
    let n = sm.n;
    let d = sm.state_scale();
    let a_s = DMatrix::from_fn(2 * n, 2 * n, |r, c| sm.a[(r, c)] * d[c] / d[r]);
    let h_s = DMatrix::from_fn(cy.nrows(), 2 * n, |r, c| cy[(r, c)] * d[c]);
    let null = crate::linear::unobservable(&a_s, &h_s);
    (0..null.ncols())
        .map(|j| {
            let mut e = DMatrix::zeros(2 * n, ns);
            if ns > 0 {
                e.set_column(0, &null.column(j).component_mul(&d));
            }
            for k in 1..ns {
                let next = &sm.a * e.column(k - 1);
                e.set_column(k, &next);
            }
            e
        })
        .collect()
}

/// Segment responses of the linear model: each segment of `seg` samples
/// starts from `starts` (the state at its first sample) or from rest, under
/// the force `f` (n × N, right-hand side). Returns p × N.
pub fn segment_response(
    sm: &SampledModel,
    cy: &DMatrix<f64>,
    dy: &DMatrix<f64>,
    starts: Option<&DMatrix<f64>>,
    f: &DMatrix<f64>,
    seg: usize,
) -> DMatrix<f64> {
    let ns = f.ncols();
    let mut y = DMatrix::zeros(cy.nrows(), ns);
    let mut x = DVector::zeros(2 * sm.n);
    let mut xn = DVector::zeros(2 * sm.n);
    for k in 0..ns {
        if k % seg == 0 {
            match starts {
                Some(s) => x.copy_from(&s.column(k)),
                None => x.fill(0.0),
            }
        }
        let mut yk = y.column_mut(k);
        yk.gemv(1.0, cy, &x, 0.0);
        yk.gemv(1.0, dy, &f.column(k), 1.0);
        if k + 1 < ns && (k + 1) % seg != 0 {
            xn.gemv(1.0, &sm.a, &x, 0.0);
            xn.gemv(1.0, &sm.b0, &f.column(k), 1.0);
            xn.gemv(1.0, &sm.b1, &f.column(k + 1), 1.0);
            std::mem::swap(&mut x, &mut xn);
        }
    }
    y
}

/// Segment response to a force history resolved at the sub-step nodes
/// (`forces` n × ((N−1)S+1), right-hand side), from rest at every segment
/// start: `x_{k+1} = A x_k + Σ_j N_j f_{kS+j}`, `y_k = C_y x_k + D_y f_{kS}`.
/// A force given along one direction `dir` with scalar node history `phi`
/// uses the projected node inputs `N_j dir` (much cheaper). Fills the
/// columns `k0..k1` of `y` (p × N), whole segments (`k0` a segment start);
/// the history starts at node `k0 S`.
fn node_response(
    ctx: &Context<'_, '_>,
    force: NodeForce<'_>,
    y: &mut DMatrix<f64>,
    k0: usize,
    k1: usize,
) {
    let sm = ctx.input.sampled;
    let (cy, dy) = (ctx.input.cy, ctx.input.dy);
    let s = ctx.nodes.len() - 1;
    let nx = 2 * sm.n;
    // the node inputs side by side, [N_0 … N_S] (projected on the
    // direction: [N_0 d … N_S d]), so that one product per sample takes
    // the S + 1 node values, contiguous in the history
    let (width, feed, data): (usize, DMatrix<f64>, &[f64]) = match force {
        NodeForce::Along(dir, phi) => {
            let mut b = DMatrix::zeros(nx, s + 1);
            for (j, nj) in ctx.nodes.iter().enumerate() {
                b.set_column(j, &(nj * dir));
            }
            (1, b, phi)
        }
        NodeForce::Full(f) => {
            let n = sm.n;
            let mut b = DMatrix::zeros(nx, n * (s + 1));
            for (j, nj) in ctx.nodes.iter().enumerate() {
                b.columns_mut(j * n, n).copy_from(nj);
            }
            (n, b, f.as_slice())
        }
    };
    // the feed-through of the same inputs
    let dd = match force {
        NodeForce::Along(dir, _) => {
            DMatrix::from_column_slice(dy.nrows(), 1, (dy * dir).as_slice())
        }
        NodeForce::Full(_) => dy.clone(),
    };
    let kernel = NodeKernel {
        a: sm.a.as_slice(),
        cy: cy.as_slice(),
        feed: feed.as_slice(),
        dd: dd.as_slice(),
        data,
        width,
        s,
        seg: ctx.seg,
        nx,
    };
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked at run time)
        unsafe { kernel.run_avx2(y, k0, k1) };
        return;
    }
    kernel.run(y, k0, k1);
}

/// The recursion of [`node_response`] on column-major slices: the state
/// `x` (2n), the output map `cy` (p × 2n), the node inputs `feed`
/// (2n × width (S + 1)) and their feed-through `dd` (p × width), the node
/// history `data` (width values per node, from node `k0 S`).
struct NodeKernel<'a> {
    a: &'a [f64],
    cy: &'a [f64],
    feed: &'a [f64],
    dd: &'a [f64],
    data: &'a [f64],
    width: usize,
    s: usize,
    seg: usize,
    nx: usize,
}

impl NodeKernel<'_> {
    /// [`NodeKernel::run`] compiled for AVX2 (the same operations in the
    /// same order: the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn run_avx2(&self, y: &mut DMatrix<f64>, k0: usize, k1: usize) {
        self.run(y, k0, k1);
    }

    /// Fill the columns `k0..k1` of `y`.
    #[inline(always)]
    fn run(&self, y: &mut DMatrix<f64>, k0: usize, k1: usize) {
        let (nx, p) = (self.nx, y.nrows());
        let ys = y.as_mut_slice();
        let (s, width) = (self.s, self.width);
        let mut x = vec![0.0; nx];
        let mut xn = vec![0.0; nx];
        // a contact's force is zero while it is open: products with a
        // zero state or a zero input are skipped (y stays zero there)
        let mut rest = true;
        for k in k0..k1 {
            if k % self.seg == 0 {
                x.fill(0.0);
                rest = true;
            }
            let off = (k - k0) * s * width;
            let here = &self.data[off..off + width];
            let yk = &mut ys[k * p..(k + 1) * p];
            if !rest {
                gemv(yk, self.cy, &x, false);
            }
            if here.iter().any(|&v| v != 0.0) {
                gemv(yk, self.dd, here, true);
            }
            if k + 1 < k1 && (k + 1) % self.seg != 0 {
                let input = &self.data[off..off + (s + 1) * width];
                let driven = input.iter().any(|&v| v != 0.0);
                if !rest {
                    gemv(&mut xn, self.a, &x, false);
                    if driven {
                        gemv(&mut xn, self.feed, input, true);
                    }
                    std::mem::swap(&mut x, &mut xn);
                } else if driven {
                    gemv(&mut x, self.feed, input, false);
                    rest = false;
                }
            }
        }
    }
}

/// `y = M x` (`add`: `y += M x`), `M` column-major with `y.len()` rows, as
/// nalgebra's `gemv` forms it — the columns accumulated in order, each
/// `y_i ← M_ij x_j + y_i` — so the same bits; the rows in blocks held in
/// registers across the columns.
#[inline(always)]
fn gemv(y: &mut [f64], m: &[f64], x: &[f64], add: bool) {
    let r = y.len();
    if r == 0 {
        return;
    }
    debug_assert_eq!(m.len(), r * x.len());
    let mut i0 = 0;
    while r - i0 >= 16 {
        gemv_rows::<16>(y, m, x, add, i0);
        i0 += 16;
    }
    if r - i0 >= 8 {
        gemv_rows::<8>(y, m, x, add, i0);
        i0 += 8;
    }
    if r - i0 >= 4 {
        gemv_rows::<4>(y, m, x, add, i0);
        i0 += 4;
    }
    while i0 < r {
        gemv_rows::<1>(y, m, x, add, i0);
        i0 += 1;
    }
}

/// Rows `i0..i0 + B` of [`gemv`].
#[inline(always)]
fn gemv_rows<const B: usize>(y: &mut [f64], m: &[f64], x: &[f64], add: bool, i0: usize) {
    let r = y.len();
    let mut acc = [0.0; B];
    let mut cols = m.chunks_exact(r).zip(x);
    if add {
        acc.copy_from_slice(&y[i0..i0 + B]);
    } else if let Some((c, &xj)) = cols.next() {
        for (a, &v) in acc.iter_mut().zip(&c[i0..i0 + B]) {
            *a = v * xj;
        }
    }
    for (c, &xj) in cols {
        for (a, &v) in acc.iter_mut().zip(&c[i0..i0 + B]) {
            *a += v * xj;
        }
    }
    y[i0..i0 + B].copy_from_slice(&acc);
}

/// A force history at the sub-step nodes.
enum NodeForce<'a> {
    /// Along one direction with a scalar history.
    Along(&'a DVector<f64>, &'a [f64]),
    /// Full n × nodes matrix.
    Full(&'a DMatrix<f64>),
}

/// Weighted, stacked vector of a p × N matrix.
fn stack(m: &DMatrix<f64>, w: &[f64]) -> DVector<f64> {
    let p = m.nrows();
    if p == 0 {
        return DVector::zeros(0);
    }
    let cols = m.as_slice().chunks_exact(p);
    DVector::from_iterator(
        m.len(),
        cols.flat_map(|c| c.iter().zip(w).map(|(&v, &wi)| wi * v)),
    )
}

/// The current selection: the column blocks of the selected effects
/// (strength column first, then its hidden-state columns), an orthonormal
/// basis of them, the residual energy and the parameter count.
struct Selection {
    q: Vec<DVector<f64>>,
    blocks: Vec<Vec<DVector<f64>>>,
    r0: DVector<f64>,
    rss: f64,
    nobs: f64,
    npar: usize,
}

/// `t ← t − Σ (q·t) q` over the orthonormal vectors `qs`.
fn project_out(t: &mut DVector<f64>, qs: &[DVector<f64>]) {
    for q in qs {
        let c = q.dot(t);
        t.axpy(-c, q, 1.0);
    }
}

/// A block of columns fitted to the residual on top of the selection.
struct Fit {
    /// RSS after adding the block.
    rss: f64,
    /// Coefficients of the columns (least squares, selection projected out).
    coef: Vec<f64>,
    /// `(PᵀP)⁻¹` diagonal of the projected block (for standard errors).
    inv_diag: Vec<f64>,
    /// Orthonormal basis of the projected block.
    qs: Vec<DVector<f64>>,
}

impl Selection {
    /// Fit the block `cols` to `r` (orthogonal to the selection already)
    /// with the selection projected out; None when the first column adds
    /// nothing or the block is rank deficient.
    fn fit_block(&self, cols: &[DVector<f64>], r: &DVector<f64>) -> Option<Fit> {
        let proj: Vec<DVector<f64>> = cols
            .iter()
            .map(|s| {
                let mut t = s.clone();
                project_out(&mut t, &self.q);
                t
            })
            .collect();
        let mut qs: Vec<DVector<f64>> = vec![];
        for (t, s) in proj.iter().zip(cols) {
            let mut t = t.clone();
            // twice: Gram–Schmidt loses orthogonality on near-dependent columns
            project_out(&mut t, &qs);
            project_out(&mut t, &qs);
            let nn = t.norm();
            if !(nn > 1e-10 * s.norm()) {
                return None;
            }
            qs.push(t / nn);
        }
        let m = proj.len();
        let g = DMatrix::from_fn(m, m, |i, j| proj[i].dot(&proj[j]));
        let b = DVector::from_fn(m, |i, _| proj[i].dot(r));
        let ginv = g.try_inverse()?;
        let coef = &ginv * b;
        let rss = self.rss - qs.iter().map(|q| q.dot(r).powi(2)).sum::<f64>();
        Some(Fit {
            rss,
            coef: coef.iter().copied().collect(),
            inv_diag: (0..m).map(|i| ginv[(i, i)]).collect(),
            qs,
        })
    }

    /// Joint least-squares strengths of the selected effects (the first
    /// column of each block) and their standard errors.
    fn coefficients(&self) -> (Vec<f64>, Vec<f64>) {
        let cols: Vec<&DVector<f64>> = self.blocks.iter().flatten().collect();
        let firsts: Vec<usize> = self
            .blocks
            .iter()
            .scan(0, |at, b| {
                let i = *at;
                *at += b.len();
                Some(i)
            })
            .collect();
        let m = cols.len();
        let nb = self.blocks.len();
        let g = DMatrix::from_fn(m, m, |i, j| cols[i].dot(cols[j]));
        let b = DVector::from_fn(m, |i, _| cols[i].dot(&self.r0));
        let Some(ginv) = g.try_inverse() else {
            return (vec![f64::NAN; nb], vec![f64::NAN; nb]);
        };
        let th = &ginv * b;
        let s2 = self.rss.max(0.0) / (self.nobs - self.npar as f64).max(1.0);
        let se = firsts
            .iter()
            .map(|&i| (s2 * ginv[(i, i)]).max(0.0).sqrt())
            .collect();
        (firsts.iter().map(|&i| th[i]).collect(), se)
    }
}

/// Run the trace: rank every candidate, then select effects greedily.
pub fn trace(input: &TraceInput<'_>, settings: &TraceSettings) -> TraceResult {
    let sm = input.sampled;
    let (p, ns) = input.measured.shape();
    let seg = input.segment.max(2);
    // channel weights 1 / RMS (1 for a channel that is zero throughout)
    let w: Vec<f64> = crate::signal::channel_weights(input.measured, 1.0)
        .into_iter()
        .map(|w| w.unwrap_or(1.0))
        .collect();
    let r0 = match input.baseline {
        Some(b) => stack(&(input.measured - b), &w),
        None => {
            let ylin = segment_response(
                sm,
                input.cy,
                input.dy,
                Some(input.states),
                input.force_ext,
                seg,
            );
            stack(&(input.measured - &ylin), &w)
        }
    };
    let rss0 = r0.norm_squared();
    let lib = library(input.model, sm.c.amax() > 0.0, settings.friction_vreg);
    let nodes = match sm.node_inputs() {
        Ok(n) => n,
        Err(e) => {
            return TraceResult {
                ranking: vec![],
                selected: vec![],
                rss_history: vec![rss0],
                stop_reason: format!("sub-step input matrices could not be built: {e}"),
                simulations: 0,
                hidden: vec![],
            }
        }
    };
    let hidden = hidden_trajectories(sm, input.cy, ns);
    let damping = damping_columns(input, &lib, &w, seg, &nodes, &hidden);
    let mut sel = Selection {
        q: vec![],
        blocks: vec![],
        r0: r0.clone(),
        rss: rss0,
        nobs: (p * ns) as f64,
        npar: 0,
    };
    let mut r = r0;
    let mut selected: Vec<RankedEffect> = vec![];
    let mut ranking = vec![];
    let mut history = vec![rss0];
    let mut sims = 0usize;
    let mut stop = String::from("effect limit reached");
    for round in 0..settings.max_effects {
        let ctx = Context {
            input,
            w: &w,
            seg,
            settings,
            nodes: &nodes,
            hidden: &hidden,
            damping: beside(&damping, &selected, &sel, &r),
        };
        // candidates are independent: in parallel, collected in library
        // order (the same ranking whatever the thread count)
        let results: Vec<(Option<Scored>, usize)> = lib
            .par_iter()
            .filter(|c| !selected.iter().any(|s| same_effect(&s.candidate, c)))
            .filter(|c| !input.exclude.iter().any(|s| same_effect(s, c)))
            .map(|c| {
                let mut n = 0;
                (score(c, &ctx, &sel, &r, &mut n), n)
            })
            .collect();
        sims += results.iter().map(|x| x.1).sum::<usize>();
        let mut scored: Vec<Scored> = results.into_iter().filter_map(|x| x.0).collect();
        scored.sort_by(|a, b| a.effect.bic_change.total_cmp(&b.effect.bic_change));
        let pays =
            |e: &RankedEffect| e.bic_change < 0.0 && e.residual_explained >= settings.min_gain;
        if let Some(dirs) = input.located.filter(|d| d.ncols() > 0) {
            // the best paying candidate along them; moved first when its
            // kind takes the preference
            if let Some(i) = scored
                .iter()
                .position(|s| pays(&s.effect) && acts_along(&s.effect.candidate, dirs))
                .filter(|&i| scored[i].effect.candidate.kind.preferred_when_located())
            {
                let s = scored.remove(i);
                scored.insert(0, s);
            }
        }
        smooth_first(&mut scored, &pays);
        gap_before_quadratic(&mut scored, &pays);
        if round == 0 {
            ranking = scored.iter().map(|s| s.effect.clone()).collect();
        }
        let Some(best) = scored.into_iter().next() else {
            stop = "no candidate could be evaluated".into();
            break;
        };
        let e = &best.effect;
        if !pays(e) {
            stop = format!(
                "best remaining candidate ({}) removes {:.1} % of the residual (threshold {:.1} %), BIC change {:.1}",
                e.label,
                100.0 * e.residual_explained,
                100.0 * settings.min_gain,
                e.bic_change
            );
            break;
        }
        // its columns again (the scores keep none: one record-long column
        // per candidate would hold the whole library's at once); the same
        // inputs give the same columns
        let Some(ev) = evaluate(&best.effect.candidate, &ctx, &sel, &r, &mut 0, None) else {
            stop = format!("{} could not be evaluated again", best.effect.label);
            break;
        };
        project_out(&mut r, &ev.qs);
        sel.npar += best.effect.candidate.nparams() + ev.cols.len() - 1;
        sel.q.extend(ev.qs);
        sel.blocks.push(ev.cols);
        sel.rss = r.norm_squared();
        history.push(sel.rss);
        selected.push(best.effect);
        let (th, se) = sel.coefficients();
        for (i, eff) in selected.iter_mut().enumerate() {
            set_strength(eff, th[i], se[i]);
        }
    }
    if let Some(f) = input.identified_force {
        for eff in selected.iter_mut().chain(ranking.iter_mut().take(10)) {
            let th = strength(eff);
            eff.force_explained = Some(force_explained(&eff.candidate, th, f, input.states, &sm.c));
        }
    }
    TraceResult {
        ranking,
        selected,
        rss_history: history,
        stop_reason: stop,
        simulations: sims,
        hidden,
    }
}

/// A clearance ahead of the cubic spring on the same pair gives its place
/// to the cubic when the cubic pays: both are odd stiffening laws, and on
/// the linear model's reconstructed states the regression does not tell
/// them apart (measured: on a clearance record the cubic removed 34.8 %,
/// the clearance 33.8 %; on a cubic record the clearance came first).
/// The cubic has one parameter less; the loop fits the clearance when the
/// cubic's fit leaves the error far from the noise
/// (`crate::diagnose`'s alternative of a fitted effect).
fn smooth_first(scored: &mut Vec<Scored>, pays: &dyn Fn(&RankedEffect) -> bool) {
    let Some(first) = scored.first() else {
        return;
    };
    if first.effect.candidate.kind != EffectKind::Clearance {
        return;
    }
    let pair = sorted_pair(&first.effect.candidate);
    if let Some(i) = scored.iter().position(|s| {
        s.effect.candidate.kind == EffectKind::Cubic
            && sorted_pair(&s.effect.candidate) == pair
            && pays(&s.effect)
    }) {
        let s = scored.remove(i);
        scored.insert(0, s);
    }
}

/// A quadratic spring ranked first gives its place to a paying contact on
/// the same pair acting on the same side: `k₂ δ²` pushes one way whatever
/// the sign of `δ`, the one-sided part of a stop, and on the linear
/// model's reconstructed states the response regression can prefer the
/// smooth law (measured: a contact 3→2 of 0.3 mm behind a calibration that
/// stiffened spring 2–3 by 47 %: quadratic 2–3 11.8 % of the residual,
/// the contact 9.1 %). The side: a contact `i→j` pushes `i` away from `j`
/// (force `+` on `i`), as a quadratic with `k₂ > 0` on `[i, j]`. Only
/// when the contact removes at least [`ALIKE`] of the quadratic's share:
/// on a record of a quadratic spring 5–6 the quadratic removed 96.8 %, the
/// contact 28.1 %.
fn gap_before_quadratic(scored: &mut Vec<Scored>, pays: &dyn Fn(&RankedEffect) -> bool) {
    let Some(first) = scored.first() else {
        return;
    };
    let q = &first.effect.candidate;
    if q.kind != EffectKind::Quadratic || q.dofs.len() != 2 {
        return;
    }
    let (k2, gain) = (strength(&first.effect), first.effect.residual_explained);
    let side = if k2 > 0.0 {
        q.dofs.clone()
    } else {
        vec![q.dofs[1], q.dofs[0]]
    };
    if let Some(i) = scored.iter().position(|s| {
        s.effect.candidate.kind == EffectKind::Contact
            && s.effect.candidate.dofs == side
            && s.effect.residual_explained >= ALIKE * gain
            && pays(&s.effect)
    }) {
        let s = scored.remove(i);
        scored.insert(0, s);
    }
}

/// The share of the residual, relative to the first-ranked smooth law's,
/// from which a gap law on the same pair counts as fitting alike
/// ([`gap_before_quadratic`]).
pub const ALIKE: f64 = 0.5;

/// The candidate's DOFs in ascending order.
pub fn sorted_pair(c: &Candidate) -> Vec<usize> {
    let mut d = c.dofs.clone();
    d.sort_unstable();
    d
}

/// The candidate's force lies in the span of the columns of `dirs`.
pub fn acts_along(cand: &Candidate, dirs: &DMatrix<f64>) -> bool {
    let Some(d) = cand.direction(dirs.nrows()) else {
        return false;
    };
    let g = dirs.transpose() * dirs;
    let Some(gi) = g.try_inverse() else {
        return false;
    };
    let fit = dirs * (gi * (dirs.transpose() * &d));
    (d - fit).norm() <= 1e-9
}

/// The same physical effect (so it is not selected twice).
fn same_effect(a: &Candidate, b: &Candidate) -> bool {
    a.kind == b.kind
        && match a.kind {
            EffectKind::Friction => a.dofs.iter().any(|d| b.dofs.contains(d)),
            _ => a.dofs == b.dofs,
        }
}

/// Index of the strength among an effect's parameters.
fn strength_index(kind: EffectKind) -> usize {
    usize::from(kind.has_gap())
}

fn strength(e: &RankedEffect) -> f64 {
    e.parameters[strength_index(e.candidate.kind)].1
}

fn set_strength(e: &mut RankedEffect, th: f64, se: f64) {
    let i = strength_index(e.candidate.kind);
    e.parameters[i].1 = th;
    e.std_errors[i] = se;
}

/// Name of the strength parameter in reports.
pub fn strength_name(kind: EffectKind) -> &'static str {
    match kind {
        EffectKind::Contact | EffectKind::GroundSpring | EffectKind::Clearance => "stiffness",
        EffectKind::Friction | EffectKind::RelativeFriction => "level",
        EffectKind::Cubic => "k3",
        EffectKind::Stiffness | EffectKind::Damping => "delta",
        EffectKind::Quadratic => "k2",
        EffectKind::QuadraticDamping => "c2",
        EffectKind::CubicDamping => "c3",
    }
}

/// Strength must be positive for these kinds.
fn positive_only(kind: EffectKind) -> bool {
    matches!(
        kind,
        EffectKind::Contact
            | EffectKind::Friction
            | EffectKind::GroundSpring
            | EffectKind::Clearance
            | EffectKind::RelativeFriction
            | EffectKind::QuadraticDamping
            | EffectKind::CubicDamping
    )
}

struct Context<'a, 'b> {
    input: &'a TraceInput<'b>,
    w: &'a [f64],
    seg: usize,
    settings: &'a TraceSettings,
    /// Node input matrices of one sample.
    nodes: &'a [DMatrix<f64>],
    /// Hidden trajectories at the samples.
    hidden: &'a [DMatrix<f64>],
    /// The damping's columns fitted beside a dissipative candidate, with
    /// the residual energy they leave alone ([`beside`]).
    damping: Option<(&'a [DVector<f64>], f64)>,
}

struct Scored {
    effect: RankedEffect,
}

/// The response columns of the model's damping parts
/// ([`damping_parts`]: one per damping parameter, the force `C_i v̂` on
/// the reconstructed states), computed once for the trace; empty when no
/// candidate is dissipative or the model has no damping. A dissipative
/// candidate (friction, a nonlinear damper) is fitted in the loop with the
/// damping's parameters free beside it (`diagnose::effects::damping_targets`),
/// and a damping calibrated without it has taken its equivalent viscous
/// part: on that damping alone the law's share of the residual is the
/// difference between the law and its linearization, small.
fn damping_columns(
    input: &TraceInput<'_>,
    lib: &[Candidate],
    w: &[f64],
    seg: usize,
    nodes: &[DMatrix<f64>],
    hidden: &[DMatrix<f64>],
) -> Vec<DVector<f64>> {
    let sm = input.sampled;
    if !lib.iter().any(|c| c.kind.dissipative())
        || input.exclude.iter().any(|c| frees_damping(c.kind))
    {
        return vec![];
    }
    let settings = TraceSettings::default();
    let ctx = Context {
        input,
        w,
        seg,
        settings: &settings,
        nodes,
        hidden,
        damping: None,
    };
    damping_parts(input.model)
        .iter()
        .filter(|c| c.shape() == (sm.n, sm.n))
        .map(|c| column_of_matrix(c, &ctx, input.states))
        .collect()
}

/// An effect of this kind already frees the model's damping: no damping
/// columns beside another.
fn frees_damping(kind: EffectKind) -> bool {
    kind.dissipative() || kind == EffectKind::Damping
}

/// The damping's columns and the residual energy they leave on top of the
/// selection, for the candidates of this round; None when there are none,
/// an effect selected frees the damping already, or they are rank
/// deficient.
fn beside<'a>(
    damping: &'a [DVector<f64>],
    selected: &[RankedEffect],
    sel: &Selection,
    r: &DVector<f64>,
) -> Option<(&'a [DVector<f64>], f64)> {
    if damping.is_empty() || selected.iter().any(|s| frees_damping(s.candidate.kind)) {
        return None;
    }
    let fit = sel.fit_block(damping, r)?;
    Some((damping, fit.rss))
}

/// Weighted stacked response column of the force `−C v̂` (`c` n × n), as
/// [`column`] forms a force at every DOF.
fn column_of_matrix(
    c: &DMatrix<f64>,
    ctx: &Context<'_, '_>,
    states: &DMatrix<f64>,
) -> DVector<f64> {
    let n = ctx.input.sampled.n;
    let mut y = DMatrix::zeros(ctx.input.cy.nrows(), ctx.input.measured.ncols());
    full_force_response(ctx, states, &mut y, |hires| -(c * hires.rows(n, n)));
    stack(&y, ctx.w)
}

/// The response `y` to a force at every DOF, `force` of the node states
/// (2n × nodes), formed one segment at a time on the cubic Hermite
/// interpolation of `states` (no record-long matrix at the node rate).
fn full_force_response(
    ctx: &Context<'_, '_>,
    states: &DMatrix<f64>,
    y: &mut DMatrix<f64>,
    force: impl Fn(&DMatrix<f64>) -> DMatrix<f64>,
) {
    let sm = ctx.input.sampled;
    let ns = ctx.input.measured.ncols();
    let mut k0 = 0;
    while k0 < ns {
        let k1 = (k0 + ctx.seg).min(ns);
        let hires = crate::linear::hermite_upsample(
            &states.columns(k0, k1 - k0).into_owned(),
            sm.fs,
            sm.substeps,
        );
        node_response(ctx, NodeForce::Full(&force(&hires)), y, k0, k1);
        k0 = k1;
    }
}

/// One evaluation of a candidate.
struct Eval {
    /// Residual energy its share is measured against: the damping's
    /// columns' alone when they are fitted beside it (None: the
    /// selection's).
    base: Option<f64>,
    /// Residual energy with it.
    rss: f64,
    /// Strength.
    th: f64,
    /// `(PᵀP)⁻¹` of the strength (its variance per unit noise variance).
    var: f64,
    /// Strength column, then the hidden-state columns or the damping's.
    cols: Vec<DVector<f64>>,
    /// Orthonormal basis of the projected columns.
    qs: Vec<DVector<f64>>,
    /// State correction along each hidden trajectory (0 where unused).
    hidden: Vec<f64>,
}

/// Weighted stacked response column of a candidate at unit strength on the
/// states `states` (at the samples; the candidate's law is evaluated at the
/// sub-step nodes, on the cubic Hermite interpolation of the states,
/// [`crate::linear::hermite_upsample`]; internal force on the left-hand
/// side → minus on the right). The node states are formed where they are
/// used — the candidate's own rows for a force along one direction, one
/// segment at a time for a force at every DOF — so that the trace holds
/// no record-long matrix at the node rate.
/// With `node_deltas` (the contact's relative displacement at every node,
/// computed once for a gap scan) the shape is formed from them.
fn column(
    cand: &Candidate,
    ctx: &Context<'_, '_>,
    states: &DMatrix<f64>,
    node_deltas: Option<&[f64]>,
) -> DVector<f64> {
    let sm = ctx.input.sampled;
    let ns = ctx.input.measured.ncols();
    let mut y = DMatrix::zeros(ctx.input.cy.nrows(), ns);
    match cand.direction(sm.n) {
        Some(dir) => {
            let phi: Vec<f64> = match (cand.kind, node_deltas) {
                (k, Some(d)) if k.has_gap() => d.iter().map(|&x| -cand.gap_law(x)).collect(),
                _ => {
                    let (own, hires) = own_nodes(cand, states, sm);
                    own.shape(&hires, own.dofs.len())
                        .iter()
                        .map(|x| -x)
                        .collect()
                }
            };
            node_response(ctx, NodeForce::Along(&dir, &phi), &mut y, 0, ns);
        }
        None => full_force_response(ctx, states, &mut y, |hires| -cand.force(hires, &sm.c)),
    }
    stack(&y, ctx.w)
}

/// The candidate with its DOFs renumbered from 0 and the node states of
/// those DOFs alone (`[u_i, u_j, v_i, v_j]` upsampled): its shape and
/// relative displacement at the nodes, as on the whole node states.
fn own_nodes(
    cand: &Candidate,
    states: &DMatrix<f64>,
    sm: &SampledModel,
) -> (Candidate, DMatrix<f64>) {
    let (n, d) = (sm.n, cand.dofs.len());
    let rows: Vec<usize> = cand
        .dofs
        .iter()
        .copied()
        .chain(cand.dofs.iter().map(|&i| n + i))
        .collect();
    let sub = states.select_rows(rows.iter());
    let own = Candidate {
        dofs: (0..d).collect(),
        ..cand.clone()
    };
    (
        own,
        crate::linear::hermite_upsample(&sub, sm.fs, sm.substeps),
    )
}

fn evaluate(
    cand: &Candidate,
    ctx: &Context<'_, '_>,
    sel: &Selection,
    r: &DVector<f64>,
    sims: &mut usize,
    node_deltas: Option<&[f64]>,
) -> Option<Eval> {
    *sims += 1;
    let col = column(cand, ctx, ctx.input.states, node_deltas);
    let mut cols = vec![col];
    let mut used = vec![];
    if cand.kind.linear_in_state() {
        for (j, e) in ctx.hidden.iter().enumerate() {
            *sims += 1;
            let c = column(cand, ctx, e, None);
            if c.norm() > 1e-8 * cols[0].norm() {
                cols.push(c);
                used.push(j);
            }
        }
    }
    let positive = |f: &Fit| !positive_only(cand.kind) || f.coef[0] > 0.0;
    let alone = sel.fit_block(&cols, r).filter(positive);
    // a dissipative candidate also beside the damping's columns, measured
    // against them alone; the larger share is taken
    let beside = ctx
        .damping
        .filter(|_| cand.kind.dissipative())
        .and_then(|(d, base)| {
            let mut all = cols.clone();
            all.extend(d.iter().cloned());
            let f = sel.fit_block(&all, r).filter(positive)?;
            Some((all, f, base))
        });
    let share = |rss: f64, base: f64| if base > 0.0 { 1.0 - rss / base } else { 0.0 };
    let (cols, fit, base) = match (alone, beside) {
        (Some(a), Some((all, f, base))) if share(f.rss, base) > share(a.rss, sel.rss) => {
            (all, f, Some(base))
        }
        (Some(a), _) => (cols, a, None),
        (None, Some((all, f, base))) => (all, f, Some(base)),
        (None, None) => return None,
    };
    let th = fit.coef[0];
    let mut hidden = vec![0.0; if used.is_empty() { 0 } else { ctx.hidden.len() }];
    for (k, &j) in used.iter().enumerate() {
        hidden[j] = fit.coef[k + 1] / th;
    }
    Some(Eval {
        base,
        rss: fit.rss,
        th,
        var: fit.inv_diag[0],
        cols,
        qs: fit.qs,
        hidden,
    })
}

/// Scan the gap of a contact candidate (coarse grid over the upper half of
/// the relative displacement — of its magnitude for a clearance — then
/// golden-section refinement); returns the
/// best candidate, its evaluation and a standard error of the gap from the
/// curvature of the residual.
fn scan_gap(
    cand: &Candidate,
    ctx: &Context<'_, '_>,
    sel: &Selection,
    r: &DVector<f64>,
    sims: &mut usize,
) -> Option<(Candidate, Eval, f64)> {
    let states = ctx.input.states;
    let two_sided = cand.kind == EffectKind::Clearance;
    let mut sorted: Vec<f64> = (0..states.ncols())
        .map(|k| cand.delta(states, k))
        .map(|d| if two_sided { d.abs() } else { d })
        .collect();
    sorted.sort_by(f64::total_cmp);
    let quant = |f: f64| sorted[((sorted.len() - 1) as f64 * f) as usize];
    let (lo, hi) = (quant(0.5).max(0.0), quant(0.999));
    if !(hi > lo) {
        return None;
    }
    let ng = ctx.settings.gap_grid.max(4);
    let gaps: Vec<f64> = (0..ng)
        .map(|i| lo + (hi - lo) * i as f64 / (ng - 1) as f64)
        .collect();
    let (own, hires) = own_nodes(cand, states, ctx.input.sampled);
    let node_deltas: Vec<f64> = (0..hires.ncols()).map(|k| own.delta(&hires, k)).collect();
    drop(hires);
    let at = |g: f64, sims: &mut usize| {
        let c = Candidate {
            gap: Some(g),
            ..cand.clone()
        };
        evaluate(&c, ctx, sel, r, sims, Some(&node_deltas)).map(|e| (c, e))
    };
    let mut best: Option<(usize, Candidate, Eval)> = None;
    for (i, &g) in gaps.iter().enumerate() {
        if let Some((c, e)) = at(g, sims) {
            if best.as_ref().is_none_or(|b| e.rss < b.2.rss) {
                best = Some((i, c, e));
            }
        }
    }
    let (bi, mut c_best, mut e_best) = best?;
    let (mut a, mut b) = (gaps[bi.saturating_sub(1)], gaps[(bi + 1).min(ng - 1)]);
    // golden section: the interior point kept from one bracket to the
    // next is evaluated once; the best point seen is kept
    const PHI: f64 = 0.618_033_988_75;
    let mut probe = |x: f64, sims: &mut usize| -> f64 {
        match at(x, sims) {
            Some((c, e)) => {
                let v = e.rss;
                if v < e_best.rss {
                    c_best = c;
                    e_best = e;
                }
                v
            }
            None => f64::INFINITY,
        }
    };
    let (mut x1, mut x2) = (b - PHI * (b - a), a + PHI * (b - a));
    let (mut v1, mut v2) = (probe(x1, sims), probe(x2, sims));
    for _ in 0..10 {
        if v1 < v2 {
            b = x2;
            (x2, v2) = (x1, v1);
            x1 = b - PHI * (b - a);
            v1 = probe(x1, sims);
        } else {
            a = x1;
            (x1, v1) = (x2, v2);
            x2 = a + PHI * (b - a);
            v2 = probe(x2, sims);
        }
    }
    let g = c_best.gap.unwrap_or(0.0);
    let h = ((hi - lo) / ng as f64 * 0.25).max(1e-9);
    let rp = at(g + h, sims).map(|e| e.1.rss);
    let rm = at((g - h).max(0.0), sims).map(|e| e.1.rss);
    let se = match (rp, rm) {
        (Some(p), Some(m)) if p - 2.0 * e_best.rss + m > 0.0 => {
            let curv = (p - 2.0 * e_best.rss + m) / (h * h);
            let s2 = e_best.rss / (sel.nobs - (sel.npar + 2) as f64).max(1.0);
            (2.0 * s2 / curv).sqrt()
        }
        _ => f64::NAN,
    };
    Some((c_best, e_best, se))
}

fn score(
    cand: &Candidate,
    ctx: &Context<'_, '_>,
    sel: &Selection,
    r: &DVector<f64>,
    sims: &mut usize,
) -> Option<Scored> {
    let (cand, ev, gap_se) = if cand.kind.has_gap() {
        let (c, e, se) = scan_gap(cand, ctx, sel, r, sims)?;
        (c, e, Some(se))
    } else {
        (cand.clone(), evaluate(cand, ctx, sel, r, sims, None)?, None)
    };
    let rss = ev.rss;
    // a dissipative candidate is measured against the damping's columns
    // alone: its share is what the damping cannot take
    let base = ev.base.unwrap_or(sel.rss);
    let gain = if base > 0.0 { 1.0 - rss / base } else { 0.0 };
    let npar = cand.nparams() + ev.cols.len() - 1;
    let counted = npar
        - ctx
            .damping
            .filter(|_| ev.base.is_some())
            .map_or(0, |d| d.0.len());
    let bic = sel.nobs * (rss.max(1e-300) / base.max(1e-300)).ln() + counted as f64 * sel.nobs.ln();
    let dof = (sel.nobs - (sel.npar + npar) as f64).max(1.0);
    let se_th = (rss.max(0.0) / dof * ev.var).max(0.0).sqrt();
    let mut parameters = vec![];
    let mut std_errors = vec![];
    if let Some(g) = cand.gap {
        parameters.push(("gap".to_string(), g));
        std_errors.push(gap_se.unwrap_or(f64::NAN));
    }
    parameters.push((strength_name(cand.kind).to_string(), ev.th));
    std_errors.push(se_th);
    Some(Scored {
        effect: RankedEffect {
            label: cand.label(),
            candidate: cand,
            parameters,
            std_errors,
            residual_explained: gain,
            force_explained: None,
            bic_change: bic,
            hidden: ev.hidden,
        },
    })
}

/// 1 − ‖f̂ − θΦ‖² / ‖f̂‖².
fn force_explained(
    cand: &Candidate,
    th: f64,
    f: &DMatrix<f64>,
    states: &DMatrix<f64>,
    c: &DMatrix<f64>,
) -> f64 {
    let den = f.norm_squared();
    if den > 0.0 {
        1.0 - (f - cand.force(states, c) * th).norm_squared() / den
    } else {
        f64::NAN
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scored(c: Candidate, strength: f64, gain: f64) -> Scored {
        let mut parameters = vec![];
        if c.kind.has_gap() {
            parameters.push(("gap".to_string(), 3e-4));
        }
        parameters.push((strength_name(c.kind).to_string(), strength));
        Scored {
            effect: RankedEffect {
                label: c.label(),
                std_errors: vec![0.0; parameters.len()],
                candidate: c,
                parameters,
                residual_explained: gain,
                force_explained: None,
                bic_change: -100.0,
                hidden: vec![],
            },
        }
    }

    fn order(list: &[Scored]) -> Vec<String> {
        list.iter().map(|s| s.effect.label.clone()).collect()
    }

    /// A contact on the quadratic's side with a comparable share goes
    /// first; one on the other side, or one far behind, does not.
    #[test]
    fn a_contact_alike_goes_before_the_quadratic_on_its_side() {
        let pays = |e: &RankedEffect| e.bic_change < 0.0 && e.residual_explained >= 0.05;
        let quad = |k2: f64| scored(Candidate::new(EffectKind::Quadratic, vec![1, 2]), k2, 0.118);
        let contact = |i: usize, j: usize, gain: f64| {
            scored(Candidate::new(EffectKind::Contact, vec![i, j]), 1e5, gain)
        };
        // k2 < 0 on [1, 2] pushes DOF 2 (0-based) away from 1: contact 3→2
        let mut l = vec![quad(-3e7), contact(1, 2, 0.09), contact(2, 1, 0.091)];
        gap_before_quadratic(&mut l, &pays);
        assert_eq!(order(&l)[0], "contact 3→2");
        // k2 > 0: contact 2→3 is on its side
        let mut l = vec![quad(3e7), contact(2, 1, 0.09), contact(1, 2, 0.09)];
        gap_before_quadratic(&mut l, &pays);
        assert_eq!(order(&l)[0], "contact 2→3");
        // far behind (a quadratic spring's own record: 96.8 % against 28 %)
        let mut l = vec![quad(3e7), contact(1, 2, 0.05)];
        gap_before_quadratic(&mut l, &pays);
        assert_eq!(order(&l)[0], "quadratic 2–3");
        // not paying
        let mut l = vec![quad(3e7), contact(1, 2, 0.07)];
        l[1].effect.bic_change = 5.0;
        gap_before_quadratic(&mut l, &pays);
        assert_eq!(order(&l)[0], "quadratic 2–3");
    }
}
