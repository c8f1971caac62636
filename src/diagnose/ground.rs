//! Laws acting against ground on a free-free structure.
//!
//! Under acceleration data the reconstruction of a free-free model leaves
//! the rigid-body displacement to its prior: the reconstructed absolute
//! displacement `û_i` wanders away from the truth at low frequency (on a
//! cubic spring from mass 3 to ground, seeds 3 and 4: 1.3e-2 m RMS
//! against 4.1e-4 m of motion; the relative displacements within 1e-5 m).
//! A law in the absolute displacement of one DOF (a cubic spring or a stop
//! against ground) cannot be regressed on those states, and a model with
//! one cannot be simulated from them.
//!
//! The wander is along the rigid-body vector `r` and slow, so it is
//! estimated as a continuous piecewise-linear function `w(t)` with a knot
//! at every segment start ([`Wander`]), together with the law's
//! parameters, by fitting the identified internal force at the DOF:
//! `f̂_i(t) ≈ g(û_i(t) + r_i w(t); θ)` (interval means: `f̂` is the mean
//! over each sample interval, so the law is averaged over its two ends),
//! Levenberg–Marquardt on `(θ, w)` from starts that invert the law
//! ([`fit_law`]). Knots the force does not inform are bridged by a weak
//! penalty on the second differences of `w`, and the first knot is pulled
//! weakly towards the reconstruction (the record's own origin: a stop's
//! gap is measured from it).
//!
//! [`propose`] screens the laws at a located ground DOF this way and
//! proposes the best one as a candidate effect; [`corrected`] gives a
//! model with such laws the states of its own reconstruction, the
//! declared model's corrected by `r w(t)` (and `r ẇ(t)`) fitted with its
//! laws at their values.

use super::prepare::Prepared;
use crate::linear::SampledModel;
use crate::model::Model;
use crate::trace::{Candidate, EffectKind, RankedEffect};
use nalgebra::{DMatrix, DVector};

/// Laws with the 0-based DOF each acts at.
type Laws = Vec<(usize, Law)>;

/// A law from one DOF to ground in its absolute displacement `z`.
#[derive(Debug, Clone, PartialEq)]
pub struct Law {
    /// Cubic (`k3 z³`), quadratic (`k2 z²`), contact (stop: `k (z − g)`
    /// when positive) or ground spring (`k z`).
    pub kind: EffectKind,
    /// `[k3]`, `[k2]`, `[gap, stiffness]` or `[stiffness]`.
    pub params: Vec<f64>,
}

impl Law {
    /// The force `g(z)` (left-hand side, as the simulator's `f_int`).
    pub fn force(&self, z: f64) -> f64 {
        let p = &self.params;
        match self.kind {
            EffectKind::Cubic => p[0] * z * z * z,
            EffectKind::Quadratic => p[0] * z * z,
            EffectKind::Contact => p[1] * (z - p[0]).max(0.0),
            _ => p[0] * z,
        }
    }

    /// `dg/dz`.
    fn slope(&self, z: f64) -> f64 {
        let p = &self.params;
        match self.kind {
            EffectKind::Cubic => 3.0 * p[0] * z * z,
            EffectKind::Quadratic => 2.0 * p[0] * z,
            EffectKind::Contact => {
                if z > p[0] {
                    p[1]
                } else {
                    0.0
                }
            }
            _ => p[0],
        }
    }

    /// `dg/dθ` per parameter.
    fn dparams(&self, z: f64) -> Vec<f64> {
        let p = &self.params;
        match self.kind {
            EffectKind::Cubic => vec![z * z * z],
            EffectKind::Quadratic => vec![z * z],
            EffectKind::Contact if z > p[0] => vec![-p[1], z - p[0]],
            EffectKind::Contact => vec![0.0, 0.0],
            _ => vec![z],
        }
    }

    /// The candidate effect of this law at 0-based DOF `d`, with its
    /// parameters under the report's names.
    fn ranked(&self, d: usize, explained: f64) -> RankedEffect {
        let mut candidate = Candidate::new(self.kind, vec![d]);
        let names: &[&str] = match self.kind {
            EffectKind::Cubic => &["k3"],
            EffectKind::Quadratic => &["k2"],
            EffectKind::Contact => &["gap", "stiffness"],
            _ => &["stiffness"],
        };
        if self.kind == EffectKind::Contact {
            candidate.gap = Some(self.params[0]);
        }
        RankedEffect {
            label: candidate.label(),
            candidate,
            parameters: names
                .iter()
                .zip(&self.params)
                .map(|(n, v)| (n.to_string(), *v))
                .collect(),
            std_errors: vec![],
            residual_explained: explained,
            force_explained: Some(explained),
            bic_change: -1.0,
            hidden: vec![],
        }
    }
}

/// A continuous piecewise-linear function of the sample index: `values[j]`
/// at sample `knots[j]` (increasing, the first 0), constant beyond the
/// ends.
#[derive(Debug, Clone, PartialEq)]
pub struct Wander {
    /// Knot samples.
    pub knots: Vec<usize>,
    /// Values at the knots, m.
    pub values: Vec<f64>,
}

impl Wander {
    /// `(j, a)`: the value at sample `k` is `(1 − a) values[j] + a values[j + 1]`.
    fn locate(&self, k: usize) -> (usize, f64) {
        let j = match self.knots.binary_search(&k) {
            Ok(j) => j,
            Err(j) => j.saturating_sub(1),
        };
        let j = j.min(self.knots.len() - 2);
        let (a, b) = (self.knots[j], self.knots[j + 1]);
        (j, ((k as f64 - a as f64) / (b - a) as f64).clamp(0.0, 1.0))
    }

    /// The value at sample `k`.
    pub fn at(&self, k: usize) -> f64 {
        let (j, a) = self.locate(k);
        (1.0 - a) * self.values[j] + a * self.values[j + 1]
    }

    /// The slope at sample `k` (per second at rate `fs`): that of the
    /// interval starting at or containing `k`.
    pub fn rate(&self, k: usize, fs: f64) -> f64 {
        let (j, _) = self.locate(k);
        let dt = (self.knots[j + 1] - self.knots[j]) as f64 / fs;
        (self.values[j + 1] - self.values[j]) / dt
    }
}

/// The data of a wander fit: the reconstructed absolute displacement and
/// the identified internal force at each DOF carrying a law, with the
/// rigid-body vector's entry there.
pub struct Data<'a> {
    /// `(dof, r_dof, û_dof, f̂_dof)` per DOF with laws (0-based).
    pub rows: Vec<(usize, f64, &'a [f64], &'a [f64])>,
    /// Knot samples (segment starts and the last sample).
    pub knots: Vec<usize>,
}

/// A fitted law set and wander.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The laws with their fitted (or held) parameters, per DOF.
    pub laws: Vec<(usize, Law)>,
    /// The wander.
    pub wander: Wander,
    /// Fraction of the identified force's energy (at those DOFs) the laws
    /// explain.
    pub explained: f64,
}

/// Weight of the second-difference penalty on the wander and of the pull
/// of the first knot towards the reconstruction, in units of one sample's
/// normalized force residual per normalized displacement.
const SMOOTH: f64 = 0.1;
const ANCHOR: f64 = 0.1;

/// Scales: the force's RMS and the part of the displacement a wander
/// cannot take (its RMS about a moving mean over a segment).
fn scales(data: &Data<'_>) -> (f64, f64) {
    let mut fs = 0.0;
    let mut us = 0.0;
    let mut n = 0.0;
    let seg = data.knots.get(1).copied().unwrap_or(16).max(4);
    for (_, _, u, f) in &data.rows {
        fs += f.iter().map(|x| x * x).sum::<f64>();
        let m = moving_mean(u, seg);
        us += u.iter().zip(&m).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        n += u.len() as f64;
    }
    ((fs / n).sqrt().max(1e-300), (us / n).sqrt().max(1e-300))
}

fn moving_mean(x: &[f64], w: usize) -> Vec<f64> {
    let n = x.len();
    let mut c = vec![0.0; n + 1];
    for (i, v) in x.iter().enumerate() {
        c[i + 1] = c[i] + v;
    }
    (0..n)
        .map(|k| {
            let a = k.saturating_sub(w / 2);
            let b = (k + w / 2 + 1).min(n);
            (c[b] - c[a]) / (b - a) as f64
        })
        .collect()
}

/// The normal equations of the wander fit at `(laws, c)`: `(JᵀJ, Jᵀρ,
/// ρᵀρ)` in scaled units (force by `fscale`, displacement by `uscale`,
/// parameters by `pscale`); the parameters first (when `free`), then the
/// knots.
struct Normal {
    jtj: DMatrix<f64>,
    jtr: DVector<f64>,
    cost: f64,
    data_cost: f64,
}

fn normal(
    data: &Data<'_>,
    laws: &[(usize, Law)],
    c: &[f64],
    free: &[(usize, usize)],
    pscale: &[f64],
    (fscale, uscale): (f64, f64),
) -> Normal {
    let np = free.len();
    let nk = c.len();
    let m = np + nk;
    let mut jtj = DMatrix::zeros(m, m);
    let mut jtr = DVector::zeros(m);
    let mut cost = 0.0;
    let w = Wander {
        knots: data.knots.clone(),
        values: c.to_vec(),
    };
    let mut idx = Vec::with_capacity(np + 4);
    let mut val = Vec::with_capacity(np + 4);
    for (dof, r, u, f) in &data.rows {
        for k in 0..u.len().saturating_sub(1) {
            idx.clear();
            val.clear();
            let mut g = 0.0;
            for kk in [k, k + 1] {
                let z = u[kk] + r * w.at(kk);
                let mut slope = 0.0;
                for (li, law) in laws.iter().enumerate() {
                    if law.0 != *dof {
                        continue;
                    }
                    g += 0.5 * law.1.force(z);
                    slope += 0.5 * law.1.slope(z);
                    let dp = law.1.dparams(z);
                    for (fi, &(l, p)) in free.iter().enumerate() {
                        if l == li {
                            idx.push(fi);
                            val.push(0.5 * dp[p] * pscale[fi] / fscale);
                        }
                    }
                }
                let (j, a) = w.locate(kk);
                idx.push(np + j);
                val.push((1.0 - a) * slope * r * uscale / fscale);
                idx.push(np + j + 1);
                val.push(a * slope * r * uscale / fscale);
            }
            let rho = (f[k] - g) / fscale;
            cost += rho * rho;
            for (x, &i) in idx.iter().enumerate() {
                jtr[i] += val[x] * rho;
                for (y, &jj) in idx.iter().enumerate() {
                    jtj[(i, jj)] += val[x] * val[y];
                }
            }
        }
    }
    let data_cost = cost;
    // weak penalties: second differences of the wander, first knot at 0
    for j in 1..nk.saturating_sub(1) {
        let s = SMOOTH.sqrt();
        let rho = -s * (c[j + 1] - 2.0 * c[j] + c[j - 1]) / uscale;
        let g = [(j - 1, s), (j, -2.0 * s), (j + 1, s)];
        cost += rho * rho;
        for &(a, va) in &g {
            jtr[np + a] += va * rho;
            for &(b, vb) in &g {
                jtj[(np + a, np + b)] += va * vb;
            }
        }
    }
    if nk > 0 {
        let s = ANCHOR.sqrt();
        let rho = -s * c[0] / uscale;
        cost += rho * rho;
        jtr[np] += s * rho;
        jtj[(np, np)] += s * s;
    }
    Normal {
        jtj,
        jtr,
        cost,
        data_cost,
    }
}

/// Levenberg–Marquardt on the wander `c` and the laws' parameters listed
/// in `free` (`(law index, parameter index)`), from `(laws, c)`.
fn refine(
    data: &Data<'_>,
    laws: &mut [(usize, Law)],
    c: &mut [f64],
    free: &[(usize, usize)],
) -> f64 {
    let sc = scales(data);
    let pscale: Vec<f64> = free
        .iter()
        .map(|&(l, p)| match (laws[l].1.kind, p) {
            (EffectKind::Contact, 0) => sc.1,
            _ => laws[l].1.params[p].abs().max(1e-300),
        })
        .collect();
    let np = free.len();
    let mut lambda = 1e-3;
    let mut cur = normal(data, laws, c, free, &pscale, sc);
    for _ in 0..60 {
        let mut a = cur.jtj.clone();
        for i in 0..a.nrows() {
            a[(i, i)] += lambda * cur.jtj[(i, i)].max(1e-12);
        }
        let Some(ch) = a.cholesky() else {
            lambda *= 10.0;
            continue;
        };
        let step = ch.solve(&cur.jtr);
        let mut tl = laws.to_vec();
        for (fi, &(l, p)) in free.iter().enumerate() {
            let v = tl[l].1.params[p] + step[fi] * pscale[fi];
            // stiffnesses and coefficients keep their sign
            tl[l].1.params[p] = match (tl[l].1.kind, p) {
                (EffectKind::Contact, 0) => v,
                _ if laws[l].1.params[p] > 0.0 => v.max(1e-3 * laws[l].1.params[p]),
                _ => v,
            };
        }
        let tc: Vec<f64> = c
            .iter()
            .enumerate()
            .map(|(j, v)| v + step[np + j] * sc.1)
            .collect();
        let next = normal(data, &tl, &tc, free, &pscale, sc);
        if next.cost < cur.cost {
            let gain = (cur.cost - next.cost) / cur.cost;
            laws.clone_from_slice(&tl);
            c.copy_from_slice(&tc);
            cur = next;
            lambda = (lambda / 3.0).max(1e-9);
            if gain < 1e-7 {
                break;
            }
        } else {
            lambda *= 4.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    cur.data_cost
}

/// The identified force's energy at the data's DOFs, scaled as in
/// [`normal`].
fn force_energy(data: &Data<'_>) -> f64 {
    let (fscale, _) = scales(data);
    data.rows
        .iter()
        .map(|(_, _, _, f)| {
            f[..f.len().saturating_sub(1)]
                .iter()
                .map(|x| (x / fscale).powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// The wander fitted with every law held at its parameters.
pub fn fit_wander(data: &Data<'_>, laws: &[(usize, Law)]) -> Fitted {
    let mut laws = laws.to_vec();
    let mut c = start_wander(data, &laws);
    let cost = refine(data, &mut laws, &mut c, &[]);
    fitted(data, laws, c, cost)
}

fn fitted(data: &Data<'_>, laws: Vec<(usize, Law)>, c: Vec<f64>, cost: f64) -> Fitted {
    let e = force_energy(data);
    Fitted {
        laws,
        wander: Wander {
            knots: data.knots.clone(),
            values: c,
        },
        explained: if e > 0.0 { 1.0 - cost / e } else { 0.0 },
    }
}

/// A start of the wander for laws held: the law inverted where it can be
/// (the force smoothed over a few samples), each sample weighted by the
/// law's slope there, fitted by the knots with the penalties of
/// [`normal`].
fn start_wander(data: &Data<'_>, laws: &[(usize, Law)]) -> Vec<f64> {
    let nk = data.knots.len();
    let (fscale, uscale) = scales(data);
    let mut a = DMatrix::<f64>::zeros(nk, nk);
    let mut b = DVector::<f64>::zeros(nk);
    let w = Wander {
        knots: data.knots.clone(),
        values: vec![0.0; nk],
    };
    for (dof, r, u, f) in &data.rows {
        let here: Vec<&Law> = laws.iter().filter(|l| l.0 == *dof).map(|l| &l.1).collect();
        let [law] = here.as_slice() else { continue };
        let fsm = moving_mean(f, 5);
        for k in 0..u.len() {
            let Some(z) = invert(law, fsm[k], fscale) else {
                continue;
            };
            let s = law.slope(z) * r * uscale / fscale;
            let target = (z - u[k]) / (r * uscale);
            let (j, al) = w.locate(k);
            for (p, vp) in [(j, 1.0 - al), (j + 1, al)] {
                b[p] += s * s * vp * target;
                for (q, vq) in [(j, 1.0 - al), (j + 1, al)] {
                    a[(p, q)] += s * s * vp * vq;
                }
            }
        }
    }
    for j in 1..nk.saturating_sub(1) {
        let g = [(j - 1, 1.0), (j, -2.0), (j + 1, 1.0)];
        for &(p, vp) in &g {
            for &(q, vq) in &g {
                a[(p, q)] += SMOOTH * vp * vq;
            }
        }
    }
    a[(0, 0)] += ANCHOR;
    match a.cholesky() {
        Some(ch) => ch.solve(&b).iter().map(|v| v * uscale).collect(),
        None => vec![0.0; nk],
    }
}

/// The absolute displacement at which `law` gives the force `f`, where
/// that is well defined: a cubic everywhere, a stop where it pushes
/// (above a tenth of the force's RMS `fscale`), a ground spring
/// everywhere; None else (a quadratic's sign is not known).
fn invert(law: &Law, f: f64, fscale: f64) -> Option<f64> {
    let p = &law.params;
    match law.kind {
        EffectKind::Cubic if p[0] != 0.0 => Some((f / p[0]).cbrt()),
        EffectKind::Contact if f > 0.1 * fscale && p[1] > 0.0 => Some(p[0] + f / p[1]),
        EffectKind::GroundSpring if p[0] != 0.0 => Some(f / p[0]),
        _ => None,
    }
}

/// Fit one law at DOF `d` with the wander: starts over a logarithmic grid
/// of its strength (a stop's gap at the reconstruction's origin), the
/// wander of each from the inverted law ([`start_wander`]), the strength
/// then refitted; the best start refined by Levenberg–Marquardt on the
/// law's parameters and the wander together.
pub fn fit_law(data: &Data<'_>, d: usize, kind: EffectKind) -> Option<Fitted> {
    let (fscale, uscale) = scales(data);
    let base = match kind {
        EffectKind::Cubic => fscale / uscale.powi(3),
        EffectKind::Quadratic => fscale / uscale.powi(2),
        _ => fscale / uscale,
    };
    let law = |s: f64| match kind {
        EffectKind::Contact => Law {
            kind,
            params: vec![0.0, s],
        },
        _ => Law {
            kind,
            params: vec![s],
        },
    };
    let free: Vec<(usize, usize)> = match kind {
        EffectKind::Contact => vec![(0, 0), (0, 1)],
        _ => vec![(0, 0)],
    };
    let strength = free.len() - 1;
    let mut best: Option<(f64, Laws, Vec<f64>)> = None;
    for e in -8..=8 {
        let mut laws = vec![(d, law(base * 10f64.powf(e as f64 / 4.0)))];
        let mut c = start_wander(data, &laws);
        // the strength alone, with the wander held
        let cost = refine(data, &mut laws, &mut c, &[(0, strength)]);
        if cost.is_finite() && best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, laws, c));
        }
    }
    let (_, mut laws, mut c) = best?;
    let cost = refine(data, &mut laws, &mut c, &free);
    cost.is_finite().then(|| fitted(data, laws, c, cost))
}

/// The rigid-body displacement vector of a free-free sampled model seen
/// through `cy` (the displacement part of its unobservable subspace), or
/// None when that subspace is not the one rigid-body displacement and
/// velocity pair.
pub fn rigid_vector(sm: &SampledModel, cy: &DMatrix<f64>) -> Option<DVector<f64>> {
    let hidden = crate::trace::regress::hidden_trajectories(sm, cy, 1);
    // (one direction: a damping to ground, as Rayleigh's mass term, makes
    // the velocity seen)
    if hidden.is_empty() || hidden.len() > 2 {
        return None;
    }
    let n = sm.n;
    let best = hidden
        .iter()
        .map(|e| e.column(0).rows(0, n).into_owned())
        .max_by(|a, b| a.norm().total_cmp(&b.norm()))?;
    let m = best.amax();
    let pivot = best[best.iamax()];
    (m > 0.0).then(|| best / pivot)
}

/// The laws of `model` acting from one DOF to ground in its absolute
/// displacement (cubic, quadratic and contact to ground), 0-based DOFs.
pub fn ground_laws(model: &Model) -> Vec<(usize, Law)> {
    let mut out = vec![];
    for c in model.cubics.iter().filter(|c| c.dofs.len() == 1) {
        out.push((
            c.dofs[0] - 1,
            Law {
                kind: EffectKind::Cubic,
                params: vec![c.k3],
            },
        ));
    }
    for q in model.quadratics.iter().filter(|q| q.dofs.len() == 1) {
        out.push((
            q.dofs[0] - 1,
            Law {
                kind: EffectKind::Quadratic,
                params: vec![q.k2],
            },
        ));
    }
    for c in model.contacts.iter().filter(|c| c.dofs.len() == 1) {
        out.push((
            c.dofs[0] - 1,
            Law {
                kind: EffectKind::Contact,
                params: vec![c.gap, c.stiffness],
            },
        ));
    }
    out
}

/// The knots of a prepared record: its segments' starts and last sample.
fn knots(prep: &Prepared) -> Vec<usize> {
    let n = prep.recon.states.ncols();
    let mut k: Vec<usize> = prep.comparison.segments.iter().map(|s| s.start).collect();
    if k.first() != Some(&0) {
        k.insert(0, 0);
    }
    if k.last().is_some_and(|&l| l + 1 < n) {
        k.push(n - 1);
    }
    k.dedup();
    k
}

/// The rows of a wander fit at the 0-based `dofs` of `prep`.
fn rows<'a>(
    prep: &Prepared,
    r: &DVector<f64>,
    dofs: &[usize],
    buf: &'a [(Vec<f64>, Vec<f64>)],
) -> Data<'a> {
    Data {
        rows: dofs
            .iter()
            .zip(buf)
            .map(|(&d, (u, f))| (d, r[d], u.as_slice(), f.as_slice()))
            .collect(),
        knots: knots(prep),
    }
}

/// `û_d` and `f̂_d` of a prepared record.
fn series(prep: &Prepared, d: usize) -> (Vec<f64>, Vec<f64>) {
    let s = &prep.recon.states;
    let f = &prep.recon.force;
    (
        s.row(d).iter().copied().collect(),
        f.row(d).iter().copied().collect(),
    )
}

/// The laws screened at a located ground DOF.
pub const LAWS: [EffectKind; 3] = [
    EffectKind::Cubic,
    EffectKind::Contact,
    EffectKind::GroundSpring,
];

/// The best law at the 0-based ground DOF `d` of a free-free `declared`
/// model's record `prep` ([`fit_law`] for each of [`LAWS`]), with every
/// law's explained fraction; None when the model is not free-free along
/// one rigid-body vector.
pub fn screen(prep: &Prepared, cy: &DMatrix<f64>, d: usize) -> Option<Vec<(Fitted, RankedEffect)>> {
    let r = rigid_vector(&prep.sampled, cy)?;
    if r[d].abs() < 1e-6 {
        return None;
    }
    let buf = vec![series(prep, d)];
    let data = rows(prep, &r, &[d], &buf);
    let mut out: Vec<(Fitted, RankedEffect)> = LAWS
        .iter()
        .filter_map(|&k| fit_law(&data, d, k))
        .map(|f| {
            let ranked = f.laws[0].1.ranked(d, f.explained);
            (f, ranked)
        })
        .collect();
    out.sort_by(|a, b| b.0.explained.total_cmp(&a.0.explained));
    Some(out)
}

/// `prep` with its states and segment starts corrected by `r w(t)` (and
/// `r ẇ(t)`) for the wander `w`.
pub fn apply(prep: &Prepared, r: &DVector<f64>, w: &Wander) -> Prepared {
    let mut p = prep.clone();
    let n = r.len();
    let fs = p.comparison.fs;
    let cols = p.recon.states.ncols();
    for k in 0..cols {
        let (x, v) = (w.at(k), w.rate(k, fs));
        for i in 0..n {
            p.recon.states[(i, k)] += r[i] * x;
            p.recon.states[(n + i, k)] += r[i] * v;
        }
    }
    let st = &p.recon.states;
    for s in p
        .comparison
        .segments
        .iter_mut()
        .chain([&mut p.comparison.whole])
    {
        for i in 0..n {
            s.u0[i] = st[(i, s.start)];
            s.v0[i] = st[(n + i, s.start)];
        }
    }
    p
}

/// The declared model's reconstruction `prep` corrected for `model`'s
/// laws against ground ([`ground_laws`]), the wander fitted with them at
/// their values ([`fit_wander`]); None when `model` has none or the
/// declared model is not free-free along one rigid-body vector.
pub fn corrected(model: &Model, prep: &Prepared) -> Option<Prepared> {
    let laws = ground_laws(model);
    if laws.is_empty() {
        return None;
    }
    let (cy, _) = prep.sampled.outputs(&prep.channels).ok()?;
    let r = rigid_vector(&prep.sampled, &cy)?;
    let mut dofs: Vec<usize> = laws.iter().map(|l| l.0).collect();
    dofs.sort_unstable();
    dofs.dedup();
    let buf: Vec<_> = dofs.iter().map(|&d| series(prep, d)).collect();
    let data = rows(prep, &r, &dofs, &buf);
    let fit = fit_wander(&data, &laws);
    Some(apply(prep, &r, &fit.wander))
}

/// A law is proposed ahead of the trace's choice when it explains at
/// least this fraction of the identified force at the located ground DOF
/// ([`screen`]; the trace's minimum gain)...
pub const MIN_EXPLAINED: f64 = 0.05;

/// ...and leaves at most this fraction of what a linear spring to ground
/// with the same wander leaves unexplained (measured: a cubic spring at 3
/// leaves 0.14 against the spring's 0.28; a stop at 8 with friction on
/// every mass 0.86 against 0.997).
pub const MAX_LEFT_VS_SPRING: f64 = 0.9;

/// The law against ground proposed at the located ground DOF of a
/// free-free declared model ([`screen`]), ahead of the trace: when the
/// force was located at one DOF to ground, no spring to ground is in the
/// declared or current model, no effect acts at that DOF yet, and the best
/// law is not a linear spring (which the trace fits on its own
/// reconstruction), explains at least [`MIN_EXPLAINED`] of the force
/// there, leaving at most [`MAX_LEFT_VS_SPRING`] of what the spring
/// leaves; once per DOF (a law withdrawn is not proposed again).
pub(super) fn propose(
    ctx: &super::state::Context<'_>,
    st: &super::state::State,
) -> Option<RankedEffect> {
    let loc = ctx.prep.located.as_ref()?;
    let d = loc.directions.iter().find(|x| x.dofs.len() == 1)?.dofs[0] - 1;
    if ctx.declared.has_ground_spring() || st.current.has_ground_spring() {
        return None;
    }
    if st.added.iter().any(|a| a.effect.candidate.dofs == [d]) {
        return None;
    }
    // a law fitted at that DOF in an earlier round and withdrawn
    let tried: Vec<String> = LAWS
        .iter()
        .map(|&k| Candidate::new(k, vec![d]).label())
        .collect();
    if st
        .rounds
        .iter()
        .any(|r| r.proposed.as_ref().is_some_and(|p| tried.contains(p)))
    {
        return None;
    }
    let list = screen(ctx.prep, &ctx.cy, d)?;
    let spring = list
        .iter()
        .find(|x| x.0.laws[0].1.kind == EffectKind::GroundSpring)
        .map_or(0.0, |x| x.0.explained.max(0.0));
    let (best, ranked) = list.into_iter().next()?;
    let left = 1.0 - best.explained;
    (best.laws[0].1.kind != EffectKind::GroundSpring
        && best.explained >= MIN_EXPLAINED
        && left <= MAX_LEFT_VS_SPRING * (1.0 - spring))
        .then_some(ranked)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn wander_interpolates_between_knots_and_gives_the_slope() {
        let w = Wander {
            knots: vec![0, 10, 30],
            values: vec![0.0, 1.0, -1.0],
        };
        assert_eq!(w.at(0), 0.0);
        assert!((w.at(5) - 0.5).abs() < 1e-12);
        assert!((w.at(20) - 0.0).abs() < 1e-12);
        assert_eq!(w.at(30), -1.0);
        // per second at 10 samples/s: 1 over 1 s, then −2 over 2 s
        assert!((w.rate(3, 10.0) - 1.0).abs() < 1e-12);
        assert!((w.rate(10, 10.0) + 1.0).abs() < 1e-12);
    }

    /// A displacement `u` (two tones), the identified force of a cubic
    /// spring to ground on it with 30 % white noise, and the
    /// reconstruction off by a slow wander 20 times the motion.
    fn cubic_record(k3: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let n = 2048;
        let mut g = crate::signal::rng(5);
        let u: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / 512.0;
                3e-4 * (2.0 * std::f64::consts::PI * 23.0 * t).sin()
                    + 2e-4 * (2.0 * std::f64::consts::PI * 41.0 * t + 1.0).sin()
            })
            .collect();
        let wander: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / 512.0;
                6e-3 * (0.7 * t).sin() + 2e-3 * t
            })
            .collect();
        let f: Vec<f64> = (0..n)
            .map(|k| {
                let mean = 0.5 * k3 * (u[k].powi(3) + u[(k + 1).min(n - 1)].powi(3));
                {
                    let e: f64 = StandardNormal.sample(&mut g);
                    mean + 0.3 * 5.0 * e
                }
            })
            .collect();
        let rec: Vec<f64> = u.iter().zip(&wander).map(|(a, b)| a - b).collect();
        (u, rec, f)
    }

    #[test]
    fn cubic_law_and_wander_are_fitted_from_the_force() {
        let k3 = 5e11;
        let (u, rec, f) = cubic_record(k3);
        let knots: Vec<usize> = (0..2048).step_by(51).chain([2047]).collect();
        let data = Data {
            rows: vec![(2, 1.0, &rec, &f)],
            knots,
        };
        let fit = fit_law(&data, 2, EffectKind::Cubic).unwrap();
        let k = fit.laws[0].1.params[0];
        assert!((k / k3 - 1.0).abs() < 0.03, "k3 {k}");
        assert!(fit.explained > 0.8, "{}", fit.explained);
        // the corrected displacement within 5 % of the motion's RMS
        let err: f64 = (0..2048)
            .map(|i| (rec[i] + fit.wander.at(i) - u[i]).powi(2))
            .sum::<f64>()
            / 2048.0;
        let rms: f64 = u.iter().map(|x| x * x).sum::<f64>() / 2048.0;
        assert!(
            err.sqrt() < 0.05 * rms.sqrt(),
            "{} vs {}",
            err.sqrt(),
            rms.sqrt()
        );
        // a linear spring to ground with the same freedom explains less
        let spring = fit_law(&data, 2, EffectKind::GroundSpring).unwrap();
        assert!(
            spring.explained < fit.explained - 0.05,
            "{}",
            spring.explained
        );
    }
}
