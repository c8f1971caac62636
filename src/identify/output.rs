//! The identification result, [`ForceEstimate`], shared by every method
//! (the window schemes here and any full-horizon method), and its writers:
//!
//! - `DIR/forces.h5` — HDF5, readable by h5py:
//!   - root attributes `format = "tacit-forces"`, `version = 1`,
//!     `method`, `model`, `record`, `status`, `convention` (strings), `fs`
//!     (Hz), `summary` (the JSON summary as a string);
//!   - `/time` (N);
//!   - `/force` (n × N, N): internal force per DOF (row = DOF − 1), sign
//!     convention below; `/force_std` (n × N) when available;
//!   - `/generalized/force` (m × N) and `/generalized/basis` (n × m, `T`),
//!     attribute `kept` (DOFs from 1, comma-separated), when reduced;
//!   - `/states/u`, `/states/v`, `/states/a` (n × N): reconstructed
//!     displacement, velocity, acceleration at every DOF (expanded with `T`);
//!   - `/channels/measured`, `/channels/predicted`, `/channels/no_force`,
//!     `/channels/replay`, `/channels/residual` (p × N), attribute `names`;
//!   - `/truth/fint` (n × N) when the record carries the true internal force.
//! - `DIR/forces.csv` — `time, f_1 … f_n[, g_<dof> …][, std_1 … std_n]`.
//! - `DIR/channels.csv` — `time`, then per channel `<name>_measured`,
//!   `<name>_predicted`, `<name>_no_force`, `<name>_replay`.
//! - `DIR/summary.json` — [`Summary`].
//! - figures `before`, `forces`, `after` (PNG and SVG): the paper's Figs 8–10.
//!
//! **Sign convention.** `force` is the internal force on the left-hand side
//! of `M ü + C u̇ + K u + f = f_ext` (the convention of the model and of the
//! records' truth, `fint`): the linear model lacks `−f` on its right-hand
//! side. A contact between DOFs i and j that closes when `u_i − u_j` grows
//! gives `f_i ≥ 0`, `f_j = −f_i`.
//!
//! Channels: `predicted` is the method's reconstruction (its state estimate
//! and force through the output equation), `replay` re-simulates the linear
//! model open-loop from the estimated initial state under the measured input
//! and the identified force, `no_force` the same without the identified
//! force (the paper's "before").

use super::system::{Problem, System};
use super::window::OperatorInfo;
use crate::error::{Result, TacitError};
use crate::metrics::relative_error;
use crate::plot::{self, Figure, SeriesStyle};
use crate::record::Quantity;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The sign convention, as written in the outputs.
pub const CONVENTION: &str =
    "internal force f on the left-hand side of M a + C v + K u + f = f_ext (as the truth fint)";

/// Outcome of a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Status {
    /// Finished without warning.
    Ok,
    /// Finished; see the warnings (e.g. spectral radius ≥ 1, rank deficiency).
    Warning,
    /// Finished, but the estimate grew without bound from `sample` on.
    Diverged {
        /// First sample where the state exceeded the growth limit.
        sample: usize,
        /// Largest state norm over the largest no-force state norm.
        growth: f64,
    },
    /// Finished, but a value that should be a number is NaN or infinite
    /// ([`super::finite`]): the estimate means nothing.
    NonFinite {
        /// The stage that produced it.
        stage: super::finite::Stage,
        /// The component: `f_5`, `u_3` (DOF from 1) or a channel's name.
        component: String,
        /// The first sample where it is not finite.
        sample: usize,
    },
    /// Stopped early; the values after `sample` are NaN.
    Failed {
        /// Window index.
        window: usize,
        /// Start sample of that window.
        sample: usize,
        /// What happened.
        message: String,
    },
}

/// One measured channel and its reconstructions.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelFit {
    /// Channel name, e.g. `accel_5`.
    pub name: String,
    /// Measured quantity.
    pub quantity: Quantity,
    /// DOF, from 1.
    pub dof: usize,
    /// Measured.
    #[serde(skip)]
    pub measured: Vec<f64>,
    /// The method's reconstruction.
    #[serde(skip)]
    pub predicted: Vec<f64>,
    /// Linear model without the identified force.
    #[serde(skip)]
    pub no_force: Vec<f64>,
    /// Linear model re-simulated open-loop with the identified force.
    #[serde(skip)]
    pub replay: Vec<f64>,
    /// Relative error of `no_force` (before identification).
    pub error_before: f64,
    /// Relative error of `predicted` (after identification).
    pub error_after: f64,
    /// Relative error of `replay`.
    pub error_replay: f64,
}

/// The generalized force of a reduced model.
#[derive(Debug, Clone)]
pub struct GeneralizedForce {
    /// Kept DOFs, from 1.
    pub kept: Vec<usize>,
    /// Basis `T` (n × m).
    pub basis: DMatrix<f64>,
    /// `Tᵀ f` (m × N).
    pub force: DMatrix<f64>,
}

/// Reconstructed states at every DOF of the full-order model (n × N).
#[derive(Debug, Clone)]
pub struct States {
    /// Displacement, m.
    pub u: DMatrix<f64>,
    /// Velocity, m/s.
    pub v: DMatrix<f64>,
    /// Acceleration, m/s².
    pub a: DMatrix<f64>,
}

/// Comparison with the true internal force of a simulated record.
#[derive(Debug, Clone, Serialize)]
pub struct TruthComparison {
    /// `"dof"` (full order) or `"generalized"` (`Tᵀf` vs `Tᵀf_true`).
    pub space: String,
    /// Labels of the components (`f_5`, `g_1`).
    pub labels: Vec<String>,
    /// RMS of the truth per component.
    pub rms_true: Vec<f64>,
    /// RMS of the estimate per component.
    pub rms_identified: Vec<f64>,
    /// ‖est − true‖/‖true‖ per component.
    pub relative_error: Vec<f64>,
    /// Correlation coefficient per component.
    pub correlation: Vec<f64>,
    /// Over all components.
    pub overall_relative_error: f64,
}

/// Method-specific diagnostics; fields that do not apply stay `None`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Diagnostics {
    /// Closed-loop spectral radius of the window recursion.
    pub spectral_radius: Option<f64>,
    /// The window operators used.
    pub operators: Vec<OperatorInfo>,
    /// Rank and singular values: which force combinations the sensors see.
    pub identifiability: Option<super::identifiability::Identifiability>,
    /// The Tikhonov weight and how it was chosen.
    pub regularization: Option<super::regularize::RegularizationReport>,
    /// Windows (or solves) carried out.
    pub windows: usize,
    /// Solver iterations (QP).
    pub solver_iterations: u64,
    /// Noise level estimated from the residual (per output value).
    pub residual_sigma: Option<f64>,
    /// RMS of the identified force (all components) in each tenth of the
    /// record: a flat profile means nothing grows.
    pub force_rms_by_tenth: Vec<f64>,
    /// RMS of the reconstructed state norm in each tenth, over the same for
    /// the no-force response.
    pub state_ratio_by_tenth: Vec<f64>,
}

/// Wall-clock times, s.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Timings {
    /// Reduction, sampling and window operators.
    pub setup: f64,
    /// Choice of α (GCV / L-curve).
    pub selection: f64,
    /// The run over the record.
    pub solve: f64,
    /// Everything.
    pub total: f64,
}

/// The identified internal force and everything needed to judge it.
#[derive(Debug, Clone)]
pub struct ForceEstimate {
    /// Method name (`paper`, `mhe`, …).
    pub method: String,
    /// Model name.
    pub model: String,
    /// Record file.
    pub record: String,
    /// Sample rate, Hz.
    pub fs: f64,
    /// Time of every sample, s.
    pub time: Vec<f64>,
    /// Internal force per DOF (n × N), [`CONVENTION`].
    pub force: DMatrix<f64>,
    /// Standard deviation per component and sample, when estimated.
    pub force_std: Option<DMatrix<f64>>,
    /// Generalized force when the model was reduced.
    pub generalized: Option<GeneralizedForce>,
    /// Reconstructed states at every DOF.
    pub states: States,
    /// Measured channels and reconstructions.
    pub channels: Vec<ChannelFit>,
    /// True internal force (n × N), when the record carries it.
    pub truth_fint: Option<DMatrix<f64>>,
    /// Comparison with it.
    pub truth: Option<TruthComparison>,
    /// Settings of the method, as JSON.
    pub settings: serde_json::Value,
    /// Diagnostics.
    pub diagnostics: Diagnostics,
    /// Timings.
    pub timings: Timings,
    /// Outcome.
    pub status: Status,
    /// Warnings, in plain words.
    pub warnings: Vec<String>,
}

/// A state norm this many times the no-force one counts as divergence.
pub const GROWTH_LIMIT: f64 = 1e3;

impl ForceEstimate {
    /// Build the result from a method's reduced states `xr` (2m × N) and
    /// internal force `f` (n × N) on `sys`; `predicted` are the method's own
    /// output reconstructions (computed from `xr` and `f` when `None`).
    /// Diagnostics, timings and settings are left for the caller.
    pub fn assemble(
        method: &str,
        prob: &Problem,
        sys: &System,
        xr: &DMatrix<f64>,
        f: &DMatrix<f64>,
        predicted: Option<DMatrix<f64>>,
    ) -> ForceEstimate {
        let ns = prob.len();
        let m = sys.m();
        let w = &sys.bf * f + &sys.be * &prob.e;
        let yhat = predicted.unwrap_or_else(|| &sys.cy * xr + &sys.dy * &w);
        let x0 = xr.column(0).into_owned();
        let x0 = if x0.iter().all(|v| v.is_finite()) {
            x0
        } else {
            DVector::zeros(2 * m)
        };
        let f_clean = f.map(|v| if v.is_finite() { v } else { 0.0 });
        let (xnf, ynf) = sys.simulate(&x0, &DMatrix::zeros(sys.n(), ns), &prob.e);
        let (_, yrp) = sys.simulate(&x0, &f_clean, &prob.e);
        let ur = xr.rows(0, m);
        let vr = xr.rows(m, m);
        let ar = &sys.sm.m_inv * (&w - &sys.sm.c * vr - &sys.sm.k * ur);
        let states = States {
            u: &sys.t * ur,
            v: &sys.t * vr,
            a: &sys.t * ar,
        };
        let row =
            |mat: &DMatrix<f64>, i: usize| -> Vec<f64> { mat.row(i).iter().copied().collect() };
        let channels = prob
            .channels
            .iter()
            .enumerate()
            .map(|(i, &(q, d))| {
                let meas = row(&prob.y, i);
                let (pr, nf, rp) = (row(&yhat, i), row(&ynf, i), row(&yrp, i));
                ChannelFit {
                    name: prob.channel_names[i].clone(),
                    quantity: q,
                    dof: d + 1,
                    error_before: relative_error(&nf, &meas),
                    error_after: relative_error(&pr, &meas),
                    error_replay: relative_error(&rp, &meas),
                    measured: meas,
                    predicted: pr,
                    no_force: nf,
                    replay: rp,
                }
            })
            .collect();
        let generalized = sys.reduction.as_ref().map(|r| GeneralizedForce {
            kept: r.kept.iter().map(|d| d + 1).collect(),
            basis: r.t.clone(),
            force: r.t.transpose() * f,
        });
        let truth = prob
            .truth_fint
            .as_ref()
            .map(|tf| compare_truth(f, tf, sys.reduction.as_ref().map(|r| &r.t)));
        let mut est = ForceEstimate {
            method: method.to_string(),
            model: prob.model_name.clone(),
            record: prob.record_name.clone(),
            fs: prob.fs,
            time: prob.times(),
            force: f.clone(),
            force_std: None,
            generalized,
            states,
            channels,
            truth_fint: prob.truth_fint.clone(),
            truth,
            settings: serde_json::Value::Null,
            diagnostics: Diagnostics::default(),
            timings: Timings::default(),
            status: Status::Ok,
            warnings: vec![],
        };
        est.diagnostics.force_rms_by_tenth = by_tenth(f, None);
        est.diagnostics.state_ratio_by_tenth = by_tenth(xr, Some(&xnf));
        if let Some((sample, growth)) = divergence(xr, &xnf) {
            est.status = Status::Diverged { sample, growth };
            est.warnings.push(format!(
                "the estimate diverged: from sample {sample} the state norm exceeds {GROWTH_LIMIT:.0e} times the largest no-force state norm (largest ratio {growth:.3e})"
            ));
        }
        est
    }

    /// Relative error over all channels: (before, after, replay).
    pub fn overall_errors(&self) -> (f64, f64, f64) {
        let cat = |g: &dyn Fn(&ChannelFit) -> &Vec<f64>| -> Vec<f64> {
            self.channels.iter().flat_map(|c| g(c).clone()).collect()
        };
        let meas = cat(&|c| &c.measured);
        (
            relative_error(&cat(&|c| &c.no_force), &meas),
            relative_error(&cat(&|c| &c.predicted), &meas),
            relative_error(&cat(&|c| &c.replay), &meas),
        )
    }

    /// RMS of the force per DOF.
    pub fn force_rms(&self) -> Vec<f64> {
        (0..self.force.nrows())
            .map(|i| rms(self.force.row(i).iter().copied()))
            .collect()
    }

    /// The JSON summary.
    pub fn summary(&self) -> Summary {
        let (b, a, r) = self.overall_errors();
        Summary {
            tacit_version: env!("CARGO_PKG_VERSION").to_string(),
            method: self.method.clone(),
            model: self.model.clone(),
            record: self.record.clone(),
            samples: self.time.len(),
            fs: self.fs,
            convention: CONVENTION.to_string(),
            status: self.status.clone(),
            warnings: self.warnings.clone(),
            settings: self.settings.clone(),
            error_before: b,
            error_after: a,
            error_replay: r,
            channels: self.channels.clone(),
            force_rms: self.force_rms(),
            generalized_rms: self.generalized.as_ref().map(|g| {
                (0..g.force.nrows())
                    .map(|i| rms(g.force.row(i).iter().copied()))
                    .collect()
            }),
            truth: self.truth.clone(),
            diagnostics: self.diagnostics.clone(),
            timings: self.timings.clone(),
        }
    }
}

/// What `summary.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Version of tacit that wrote it.
    pub tacit_version: String,
    /// Method.
    pub method: String,
    /// Model.
    pub model: String,
    /// Record.
    pub record: String,
    /// Samples.
    pub samples: usize,
    /// Sample rate, Hz.
    pub fs: f64,
    /// Sign convention of the force.
    pub convention: String,
    /// Outcome.
    pub status: Status,
    /// Warnings.
    pub warnings: Vec<String>,
    /// Settings.
    pub settings: serde_json::Value,
    /// Relative error over all channels without the identified force.
    pub error_before: f64,
    /// Relative error of the reconstruction.
    pub error_after: f64,
    /// Relative error of the open-loop replay.
    pub error_replay: f64,
    /// Per channel (errors only).
    pub channels: Vec<ChannelFit>,
    /// RMS of the force per DOF, N.
    pub force_rms: Vec<f64>,
    /// RMS of the generalized force, when reduced.
    pub generalized_rms: Option<Vec<f64>>,
    /// Comparison with the truth.
    pub truth: Option<TruthComparison>,
    /// Diagnostics.
    pub diagnostics: Diagnostics,
    /// Timings, s.
    pub timings: Timings,
}

fn rms(it: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = it.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / (saa * sbb).sqrt()
    } else {
        0.0
    }
}

fn compare_truth(f: &DMatrix<f64>, tf: &DMatrix<f64>, t: Option<&DMatrix<f64>>) -> TruthComparison {
    let (est, tru, space, prefix) = match t {
        None => (f.clone(), tf.clone(), "dof", "f_"),
        Some(t) => (t.transpose() * f, t.transpose() * tf, "generalized", "g_"),
    };
    let row = |m: &DMatrix<f64>, i: usize| -> Vec<f64> { m.row(i).iter().copied().collect() };
    let k = est.nrows();
    TruthComparison {
        space: space.into(),
        labels: (1..=k).map(|i| format!("{prefix}{i}")).collect(),
        rms_true: (0..k).map(|i| rms(tru.row(i).iter().copied())).collect(),
        rms_identified: (0..k).map(|i| rms(est.row(i).iter().copied())).collect(),
        relative_error: (0..k)
            .map(|i| relative_error(&row(&est, i), &row(&tru, i)))
            .collect(),
        correlation: (0..k).map(|i| corr(&row(&est, i), &row(&tru, i))).collect(),
        overall_relative_error: relative_error(est.as_slice(), tru.as_slice()),
    }
}

/// RMS of the column norms in each tenth (optionally over a reference's).
fn by_tenth(x: &DMatrix<f64>, reference: Option<&DMatrix<f64>>) -> Vec<f64> {
    let n = x.ncols();
    if n < 10 {
        return vec![];
    }
    (0..10)
        .map(|t| {
            let (a, b) = (t * n / 10, (t + 1) * n / 10);
            let r = rms((a..b).map(|k| x.column(k).norm()));
            match reference {
                None => r,
                Some(refm) => {
                    let d = rms((a..b).map(|k| refm.column(k).norm()));
                    if d > 0.0 {
                        r / d
                    } else {
                        f64::NAN
                    }
                }
            }
        })
        .collect()
}

/// First sample where ‖x_k‖ > GROWTH_LIMIT × max‖x_nf‖, with the largest ratio.
fn divergence(x: &DMatrix<f64>, xnf: &DMatrix<f64>) -> Option<(usize, f64)> {
    let refn = (0..xnf.ncols())
        .map(|k| xnf.column(k).norm())
        .fold(0.0, f64::max);
    if refn.is_nan() || refn <= 0.0 {
        return None;
    }
    let norms: Vec<f64> = (0..x.ncols()).map(|k| x.column(k).norm()).collect();
    let first = norms
        .iter()
        .position(|&v| v.is_finite() && v > GROWTH_LIMIT * refn)?;
    let worst = norms
        .iter()
        .filter(|v| v.is_finite())
        .fold(0.0f64, |a, &b| a.max(b));
    Some((first, worst / refn))
}

/// Write every output into `dir` (created if needed): `forces.h5`,
/// `forces.csv`, `channels.csv`, `summary.json` and, when `figures` is set,
/// the figures over the whole record. Each file is written atomically.
pub fn write_all(est: &ForceEstimate, dir: &Path, figures: bool) -> Result<Vec<PathBuf>> {
    crate::io::ensure_dir(dir)?;
    let mut files = vec![dir.join("forces.h5"), dir.join("forces.csv")];
    files.push(dir.join("channels.csv"));
    files.push(dir.join("summary.json"));
    write_h5(est, &files[0])?;
    write_forces_csv(est, &files[1])?;
    write_channels_csv(est, &files[2])?;
    crate::io::write_json(&files[3], &est.summary())?;
    if figures {
        files.extend(write_figures(est, dir, "", 0..est.time.len())?);
    }
    Ok(files)
}

fn h5err(path: &Path, what: &str) -> impl Fn(hdf5::Error) -> TacitError {
    let path = path.to_path_buf();
    let what = what.to_string();
    move |e| TacitError::io(&path, std::io::Error::other(format!("{what}: HDF5: {e}")))
}

/// Write `forces.h5` (layout in the module docs).
pub fn write_h5(est: &ForceEstimate, path: &Path) -> Result<()> {
    use hdf5::types::VarLenUnicode;
    use std::str::FromStr;
    let summary = serde_json::to_string(&est.summary())
        .map_err(|e| TacitError::Setting(format!("JSON encoding of the summary: {e}")))?;
    crate::io::write_atomic(path, |tmp| {
        let err = |w: &str| h5err(path, w);
        crate::record::hdf5io::no_file_locking();
        let file = hdf5::File::create(tmp).map_err(err("create"))?;
        let put_str = |loc: &hdf5::Location, name: &str, v: &str| -> Result<()> {
            let s = VarLenUnicode::from_str(v).map_err(|e| {
                TacitError::Setting(format!(
                    "attribute {name}: not storable as HDF5 string: {e}"
                ))
            })?;
            loc.new_attr::<VarLenUnicode>()
                .shape(())
                .create(name)
                .and_then(|a| a.write_scalar(&s))
                .map_err(err(name))
        };
        let put_mat = |g: &hdf5::Group, name: &str, m: &DMatrix<f64>| -> Result<()> {
            let arr = ndarray::Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)]);
            g.new_dataset_builder()
                .with_data(&arr)
                .create(name)
                .map(|_| ())
                .map_err(err(name))
        };
        put_str(&file, "format", "tacit-forces")?;
        file.new_attr::<i64>()
            .shape(())
            .create("version")
            .and_then(|a| a.write_scalar(&1i64))
            .map_err(err("version"))?;
        file.new_attr::<f64>()
            .shape(())
            .create("fs")
            .and_then(|a| a.write_scalar(&est.fs))
            .map_err(err("fs"))?;
        put_str(&file, "method", &est.method)?;
        put_str(&file, "model", &est.model)?;
        put_str(&file, "record", &est.record)?;
        put_str(&file, "convention", CONVENTION)?;
        put_str(
            &file,
            "status",
            &serde_json::to_string(&est.status).unwrap_or_default(),
        )?;
        put_str(&file, "summary", &summary)?;
        file.new_dataset_builder()
            .with_data(est.time.as_slice())
            .create("time")
            .map_err(err("time"))?;
        put_mat(&file, "force", &est.force)?;
        if let Some(s) = &est.force_std {
            put_mat(&file, "force_std", s)?;
        }
        if let Some(g) = &est.generalized {
            let grp = file
                .create_group("generalized")
                .map_err(err("generalized"))?;
            put_mat(&grp, "force", &g.force)?;
            put_mat(&grp, "basis", &g.basis)?;
            let kept: Vec<String> = g.kept.iter().map(|d| d.to_string()).collect();
            put_str(&grp, "kept", &kept.join(","))?;
        }
        let st = file.create_group("states").map_err(err("states"))?;
        put_mat(&st, "u", &est.states.u)?;
        put_mat(&st, "v", &est.states.v)?;
        put_mat(&st, "a", &est.states.a)?;
        let ch = file.create_group("channels").map_err(err("channels"))?;
        let names: Vec<String> = est.channels.iter().map(|c| c.name.clone()).collect();
        put_str(&ch, "names", &names.join(","))?;
        let stack = |g: &dyn Fn(&ChannelFit) -> Vec<f64>| -> DMatrix<f64> {
            let rows: Vec<Vec<f64>> = est.channels.iter().map(g).collect();
            let nt = est.time.len();
            DMatrix::from_fn(rows.len(), nt, |i, k| rows[i][k])
        };
        put_mat(&ch, "measured", &stack(&|c| c.measured.clone()))?;
        put_mat(&ch, "predicted", &stack(&|c| c.predicted.clone()))?;
        put_mat(&ch, "no_force", &stack(&|c| c.no_force.clone()))?;
        put_mat(&ch, "replay", &stack(&|c| c.replay.clone()))?;
        let res = |c: &ChannelFit| -> Vec<f64> {
            c.measured
                .iter()
                .zip(&c.predicted)
                .map(|(m, p)| m - p)
                .collect()
        };
        put_mat(&ch, "residual", &stack(&res))?;
        if let Some(tf) = &est.truth_fint {
            let tg = file.create_group("truth").map_err(err("truth"))?;
            put_mat(&tg, "fint", tf)?;
        }
        file.close().map_err(err("close"))
    })
}

fn csv_err(path: &Path) -> impl Fn(csv::Error) -> TacitError + '_ {
    move |e| TacitError::io(path, std::io::Error::other(e.to_string()))
}

fn write_table(path: &Path, header: &[String], cols: &[&[f64]]) -> Result<()> {
    crate::io::write_atomic(path, |tmp| {
        let mut w = csv::Writer::from_path(tmp).map_err(csv_err(path))?;
        w.write_record(header).map_err(csv_err(path))?;
        let n = cols.first().map_or(0, |c| c.len());
        for k in 0..n {
            let rec: Vec<String> = cols.iter().map(|c| format!("{:e}", c[k])).collect();
            w.write_record(&rec).map_err(csv_err(path))?;
        }
        w.flush().map_err(|e| TacitError::io(path, e))
    })
}

/// Write `forces.csv`.
pub fn write_forces_csv(est: &ForceEstimate, path: &Path) -> Result<()> {
    let mut header = vec!["time".to_string()];
    let mut cols: Vec<Vec<f64>> = vec![est.time.clone()];
    let rows = |m: &DMatrix<f64>| -> Vec<Vec<f64>> {
        (0..m.nrows())
            .map(|i| m.row(i).iter().copied().collect())
            .collect()
    };
    for (i, r) in rows(&est.force).into_iter().enumerate() {
        header.push(format!("f_{}", i + 1));
        cols.push(r);
    }
    if let Some(g) = &est.generalized {
        for (i, r) in rows(&g.force).into_iter().enumerate() {
            header.push(format!("g_{}", g.kept[i]));
            cols.push(r);
        }
    }
    if let Some(s) = &est.force_std {
        for (i, r) in rows(s).into_iter().enumerate() {
            header.push(format!("std_{}", i + 1));
            cols.push(r);
        }
    }
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    write_table(path, &header, &refs)
}

/// Write `channels.csv`.
pub fn write_channels_csv(est: &ForceEstimate, path: &Path) -> Result<()> {
    let mut header = vec!["time".to_string()];
    let mut cols: Vec<&[f64]> = vec![&est.time];
    for c in &est.channels {
        for (suffix, v) in [
            ("measured", &c.measured),
            ("predicted", &c.predicted),
            ("no_force", &c.no_force),
            ("replay", &c.replay),
        ] {
            header.push(format!("{}_{suffix}", c.name));
            cols.push(v);
        }
    }
    write_table(path, &header, &cols)
}

/// The measured channels against the no-force linear model (`after =
/// false`, the paper's Fig. 8) or against the identified model (`after =
/// true`, Fig. 10), over the samples `range`.
pub fn channel_figure(est: &ForceEstimate, after: bool, range: std::ops::Range<usize>) -> Figure {
    let r = clamp(range, est.time.len());
    let t = &est.time[r.clone()];
    let panels = est
        .channels
        .iter()
        .map(|c| {
            let (label, y) = if after {
                ("identified model", &c.predicted)
            } else {
                ("linear model, no force", &c.no_force)
            };
            let err = relative_error(&y[r.clone()], &c.measured[r.clone()]);
            plot::time_panel(
                &format!("{} (relative error {:.1} %)", c.name, 100.0 * err),
                c.quantity.si_unit(),
                t,
                vec![
                    (
                        "measured".into(),
                        c.measured[r.clone()].to_vec(),
                        SeriesStyle::Line,
                    ),
                    (label.into(), y[r.clone()].to_vec(), SeriesStyle::DashedLine),
                ],
            )
        })
        .collect();
    let what = if after { "after" } else { "before" };
    Figure::new(
        format!(
            "{}: responses {what} identification ({}, {})",
            est.model,
            est.method,
            span(&r)
        ),
        panels,
        1,
    )
}

/// The identified internal force per DOF (with the truth when known; the
/// paper's Fig. 9), over the samples `range`.
pub fn force_figure(est: &ForceEstimate, range: std::ops::Range<usize>) -> Figure {
    let r = clamp(range, est.time.len());
    let t = &est.time[r.clone()];
    let mut panels = Vec::new();
    let cut = |m: &DMatrix<f64>, i: usize| -> Vec<f64> {
        m.row(i).columns_range(r.clone()).iter().copied().collect()
    };
    for i in 0..est.force.nrows() {
        let mut series = vec![(
            "identified".to_string(),
            cut(&est.force, i),
            SeriesStyle::Line,
        )];
        if let Some(tf) = &est.truth_fint {
            series.push((
                "true f_int".to_string(),
                cut(tf, i),
                SeriesStyle::DashedLine,
            ));
        }
        panels.push(plot::time_panel(&format!("DOF {}", i + 1), "N", t, series));
    }
    if let Some(g) = &est.generalized {
        for i in 0..g.force.nrows() {
            let mut series = vec![(
                "identified Tᵀf".to_string(),
                cut(&g.force, i),
                SeriesStyle::Line,
            )];
            if let Some(tf) = &est.truth_fint {
                let tg = g.basis.transpose() * tf;
                series.push((
                    "true Tᵀf_int".to_string(),
                    cut(&tg, i),
                    SeriesStyle::DashedLine,
                ));
            }
            panels.push(plot::time_panel(
                &format!("generalized force at DOF {}", g.kept[i]),
                "N",
                t,
                series,
            ));
        }
    }
    Figure::new(
        format!(
            "{}: identified internal forces ({}, {})",
            est.model,
            est.method,
            span(&r)
        ),
        panels,
        2,
    )
}

fn clamp(r: std::ops::Range<usize>, n: usize) -> std::ops::Range<usize> {
    r.start.min(n)..r.end.min(n)
}

fn span(r: &std::ops::Range<usize>) -> String {
    format!("samples {}–{}", r.start, r.end.saturating_sub(1))
}

/// Write the figures `<prefix>before`, `<prefix>forces`, `<prefix>after`
/// (PNG + SVG) over the samples `range`: the paper's Figs 8, 9 and 10.
pub fn write_figures(
    est: &ForceEstimate,
    dir: &Path,
    prefix: &str,
    range: std::ops::Range<usize>,
) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let stem = |name: &str| dir.join(format!("{prefix}{name}"));
    files.extend(plot::save(
        &channel_figure(est, false, range.clone()),
        &stem("before"),
    )?);
    files.extend(plot::save(
        &force_figure(est, range.clone()),
        &stem("forces"),
    )?);
    files.extend(plot::save(
        &channel_figure(est, true, range),
        &stem("after"),
    )?);
    Ok(files)
}
