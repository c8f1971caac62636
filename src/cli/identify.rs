//! `tacit identify`: reconstruct the internal force a linear model lacks
//! from a record (the located, lifted smoother, moving-horizon estimation,
//! the paper's sequential windows, or the full-horizon formulation).

use super::out::outln;
use super::{check, check_dofs, DofList};
use std::path::PathBuf;
use tacit::identify::{
    self, Constraints, IdentifySettings, Method, Problem, Reduce, Regularization, Solver, Status,
};
use tacit::model::Model;

/// Identification method on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum CliMethod {
    /// Locate the force, then reconstruct it with a sub-sample resolution
    /// (default; what diagnose starts from).
    Lifted,
    /// The published sequential windows.
    Paper,
    /// Moving-horizon estimation.
    Mhe,
    /// Full-horizon optimal control (Riccati smoother; QP with constraints).
    Horizon,
}

/// Weight rule of the full-horizon method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum WeightRule {
    Fixed,
    Gcv,
    Lcurve,
    Discrepancy,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum AlphaRule {
    Gcv,
    Lcurve,
}

/// Arguments of `tacit identify`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file (TOML); its linear part is used.
    #[arg(long)]
    model: PathBuf,
    /// Record (.h5 or .csv) with the input force and the measured responses.
    #[arg(long)]
    record: PathBuf,
    /// Sensor DOFs numbered from 1, e.g. 1,5,6 (every output channel at
    /// them is fitted). Default: every measured DOF of the record. A model
    /// from matrices names its sensors by point (--points).
    #[arg(long, value_name = "DOFS", conflicts_with = "points")]
    sensors: Option<DofList>,
    /// Model from matrices (or a modal model): the sensor points by label,
    /// comma-separated, e.g. n20:uy,n100:uy (every output channel at them
    /// is fitted). Default: every measured point of the record.
    #[arg(long, value_name = "LABELS", value_delimiter = ',')]
    points: Option<Vec<String>>,
    /// Reduction onto the sensor DOFs (none = full-order model). Default:
    /// serep for paper, mhe and horizon; the lifted method works on the
    /// full-order model only.
    #[arg(long, value_enum)]
    reduce: Option<Reduce>,
    /// Window length in samples, from 1 to the record's length (MHE:
    /// samples committed per window).
    #[arg(long, default_value_t = 3, value_name = "SAMPLES")]
    window: usize,
    /// MHE horizon in samples, from --window to the record's length.
    #[arg(long, default_value_t = 24, value_name = "SAMPLES")]
    horizon: usize,
    /// Integration sub-steps per sample of the linear model, 1 to 1000.
    #[arg(long, default_value_t = 10, value_name = "N")]
    substeps: usize,
    /// Window solver: ls (regularized least squares through a gain
    /// computed once) or qp (quadratic program solved by Clarabel, with the
    /// --lower, --upper, --equilibrium, --pair, --push-apart and --active
    /// constraints).
    #[arg(long, value_enum, default_value = "ls", hide_possible_values = true)]
    solver: Solver,
    /// Scheme: the located, lifted smoother (default), the published
    /// sequential windows, moving-horizon estimation, or the full-horizon
    /// optimal-control formulation.
    #[arg(long, value_enum, default_value = "lifted")]
    method: CliMethod,
    /// Lifted method: sub-intervals per sample on which the force is
    /// constant, 1 to 64.
    #[arg(long, default_value_t = 8, value_name = "R")]
    resolution: usize,
    /// Lifted method: skip the location search (an unknown force at every
    /// DOF).
    #[arg(long)]
    no_locate: bool,
    /// Horizon method: weight rule for λ, μ (default: discrepancy principle
    /// with the --noise level; the L-curve corner when no weight reaches
    /// that level).
    #[arg(long, value_enum, default_value = "discrepancy")]
    weights: WeightRule,
    /// Horizon and lifted methods: λ > 0, weight of Σ‖f_k‖² in 1/N²
    /// relative to the data weight (horizon: start of the weight search;
    /// lifted: the least weight, raised by factors of √10 while the
    /// located force fits the data closer than half the noise).
    #[arg(long, default_value_t = 1e-2)]
    lambda: f64,
    /// Lifted method: least weighted residual RMS (1 = the --noise level)
    /// of the located force's reconstruction, in [0, 1); below it --lambda
    /// is raised. 0 keeps --lambda.
    #[arg(long, default_value_t = 0.5, value_name = "FRACTION")]
    min_residual: f64,
    /// Horizon method: μ >= 0, weight of Σ‖f_{k+1} − f_k‖².
    #[arg(long, default_value_t = 0.0)]
    mu: f64,
    /// Horizon and lifted methods: channel noise as a fraction of each
    /// channel's RMS, in (0, 1].
    #[arg(long, default_value_t = 0.01, value_name = "FRACTION")]
    noise: f64,
    /// Horizon method: the record starts at rest (x0 = 0 instead of estimated).
    #[arg(long)]
    at_rest: bool,
    /// Tikhonov weight α > 0 (SI units: (output unit / N)²). Default 1e-3.
    #[arg(long, conflicts_with = "alpha_select")]
    alpha: Option<f64>,
    /// Choose α automatically over --alpha-grid.
    #[arg(long, value_enum)]
    alpha_select: Option<AlphaRule>,
    /// α grid for --alpha-select: lowest,highest,count (0 < lowest <
    /// highest, 2 to 200 points, log-spaced).
    #[arg(long, default_value = "1e-10,1e2,25", value_parser = parse_grid, value_name = "LO,HI,COUNT")]
    alpha_grid: (f64, f64, usize),
    /// Weight >= 0 of the first differences of the force (same units as α).
    #[arg(long, default_value_t = 0.0)]
    smoothness: f64,
    /// MHE arrival-cost weight >= 0 (relative).
    #[arg(long, default_value_t = 1e-2)]
    prior_weight: f64,
    /// MHE leak ε towards a zero start state (relative, > 0).
    #[arg(long, default_value_t = 1e-4)]
    leak: f64,
    /// QP: lower bound DOF:VALUE (DOF from 1, VALUE in N), repeatable.
    #[arg(long, value_parser = parse_bound, value_name = "DOF:N")]
    lower: Vec<(usize, f64)>,
    /// QP: upper bound DOF:VALUE (DOF from 1, VALUE in N), repeatable.
    #[arg(long, value_parser = parse_bound, value_name = "DOF:N")]
    upper: Vec<(usize, f64)>,
    /// QP: the force components sum to zero (purely internal force).
    #[arg(long)]
    equilibrium: bool,
    /// QP: pair I,J (DOFs from 1) with f_I = −f_J, repeatable.
    #[arg(long, value_parser = parse_pair_dofs, value_name = "I,J")]
    pair: Vec<(usize, usize)>,
    /// QP: each pair only pushes apart (f_I >= 0; contact closes as u_I − u_J grows).
    #[arg(long)]
    push_apart: bool,
    /// QP: only these DOFs (from 1) carry a force.
    #[arg(long, value_name = "DOFS")]
    active: Option<DofList>,
    /// Do not draw the figures.
    #[arg(long)]
    no_figures: bool,
    /// Output directory (created with its parents; written whole at the
    /// end).
    #[arg(short, long)]
    output: PathBuf,
    /// Replace an output directory that already holds tacit output.
    #[arg(long)]
    force: bool,
}

fn parse_grid(s: &str) -> Result<(f64, f64, usize), String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected lowest,highest,count, got '{s}'"));
    }
    let lo = parts[0]
        .parse()
        .map_err(|_| format!("bad number '{}'", parts[0]))?;
    let hi = parts[1]
        .parse()
        .map_err(|_| format!("bad number '{}'", parts[1]))?;
    let n = parts[2]
        .parse()
        .map_err(|_| format!("bad count '{}'", parts[2]))?;
    Ok((lo, hi, n))
}

fn parse_bound(s: &str) -> Result<(usize, f64), String> {
    let (d, v) = s
        .split_once(':')
        .ok_or_else(|| format!("expected DOF:VALUE, got '{s}'"))?;
    let d = d.trim().parse().map_err(|_| format!("bad DOF '{d}'"))?;
    let v = v.trim().parse().map_err(|_| format!("bad value '{v}'"))?;
    Ok((d, v))
}

fn parse_pair_dofs(s: &str) -> Result<(usize, usize), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("expected I,J, got '{s}'"))?;
    let a = a.trim().parse().map_err(|_| format!("bad DOF '{a}'"))?;
    let b = b.trim().parse().map_err(|_| format!("bad DOF '{b}'"))?;
    Ok((a, b))
}

/// Check every numeric option that needs no record.
fn validate(a: &Args) -> anyhow::Result<()> {
    check::substeps(a.substeps)?;
    let (lo, hi, count) = a.alpha_grid;
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo) {
        anyhow::bail!("--alpha-grid {lo},{hi},{count}: give 0 < lowest < highest");
    }
    check::count(
        "--alpha-grid",
        count,
        2,
        check::MAX_GRID,
        "count of α values",
    )?;
    if let Some(x) = a.alpha {
        check::positive("--alpha", x, 1e12, "Tikhonov weight")?;
    }
    check::positive("--lambda", a.lambda, 1e12, "weight of the force")?;
    if !(0.0..1.0).contains(&a.min_residual) {
        anyhow::bail!(
            "--min-residual {}: must be in [0, 1) (least weighted residual, a fraction of the noise)",
            a.min_residual
        );
    }
    check::in_range("--mu", a.mu, 0.0, 1e12, "weight of the force's differences")?;
    check::positive("--noise", a.noise, 1.0, "fraction of each channel's RMS")?;
    check::count(
        "--resolution",
        a.resolution,
        1,
        64,
        "sub-intervals per sample",
    )?;
    if a.method == CliMethod::Lifted && a.reduce.is_some_and(|r| r != Reduce::None) {
        anyhow::bail!(
            "--reduce: the lifted method works on the full-order model; leave --reduce out or give --reduce none"
        );
    }
    check::in_range("--smoothness", a.smoothness, 0.0, 1e12, "weight")?;
    check::in_range(
        "--prior-weight",
        a.prior_weight,
        0.0,
        1e12,
        "relative weight",
    )?;
    check::positive("--leak", a.leak, 1.0, "relative leak")?;
    for (opt, b) in [("--lower", &a.lower), ("--upper", &a.upper)] {
        for &(d, v) in b.iter() {
            if !v.is_finite() {
                anyhow::bail!("{opt} {d}:{v}: the bound must be a finite force in N");
            }
        }
    }
    Ok(())
}

/// Window and horizon against the record's length.
fn validate_windows(a: &Args, samples: usize) -> anyhow::Result<()> {
    check::count(
        "--window",
        a.window,
        1,
        samples,
        "samples per window, at most the record's length",
    )?;
    if a.method == CliMethod::Mhe {
        check::count(
            "--horizon",
            a.horizon,
            a.window,
            samples,
            "samples, from --window to the record's length",
        )?;
    }
    Ok(())
}

/// Options that take DOF numbers, refused on a model from matrices (its
/// DOFs are the record's points after the reduction, numbered by it).
fn matrix_options(a: &Args) -> anyhow::Result<()> {
    let path = a.model.display();
    if a.sensors.is_some() {
        anyhow::bail!("--sensors: {path} is a model from matrices; name the sensors by point with --points (e.g. --points n20:uy,n100:uy), or leave both out to use every measured point");
    }
    let qp = [
        ("--lower", !a.lower.is_empty()),
        ("--upper", !a.upper.is_empty()),
        ("--pair", !a.pair.is_empty()),
        ("--active", a.active.is_some()),
    ];
    if let Some((opt, _)) = qp.iter().find(|q| q.1) {
        anyhow::bail!("{opt}: the QP constraints take DOF numbers, which a model from matrices ({path}) does not have before its reduction; leave {opt} out (the default method locates the force at the points)");
    }
    Ok(())
}

/// The sensor DOFs (from 1): `--sensors`, the DOFs of `--points`, or
/// every DOF the record measures.
fn sensor_dofs(a: &Args, model: &Model, rec: &tacit::record::Record) -> anyhow::Result<Vec<usize>> {
    if let Some(d) = &a.sensors {
        check_dofs(&d.0, model.ndof(), "--sensors")?;
        return Ok(d.0.clone());
    }
    if let Some(p) = &a.points {
        return Ok(tacit::model::matrix::point_dofs(model, p, "--points")?);
    }
    let mut d: Vec<usize> = rec.outputs.iter().map(|c| c.dof).collect();
    d.sort_unstable();
    d.dedup();
    if d.is_empty() {
        anyhow::bail!(
            "record {}: no output channel to identify from",
            a.record.display()
        );
    }
    Ok(d)
}

/// Run `tacit identify`.
pub fn run(a: Args) -> anyhow::Result<()> {
    validate(&a)?;
    if tacit::model::matrix::is_matrix_file(&a.model)? {
        matrix_options(&a)?;
    }
    let staging = super::output::Staging::begin(&a.output, a.force)?;
    // a model from matrices is reduced onto the record's points
    let mut rec = super::read_record(&a.record)?;
    let model = Model::load(&a.model, &mut [&mut rec])?;
    let n = model.ndof();
    let sensors = sensor_dofs(&a, &model, &rec)?;
    rec.validate(Some(n))?;
    validate_windows(&a, rec.len())?;
    super::records::check(&rec, &model, Some(&sensors))?;
    check::memory(
        check::integration_bytes(n, 0, a.substeps, rec.len()) * 4.0
            + (rec.len() as f64) * (n as f64).powi(2) * 8.0 * 4.0,
        "the identification of this record",
    )?;
    let regularization = match (a.alpha, a.alpha_select) {
        (_, Some(AlphaRule::Gcv)) => Regularization::Gcv,
        (_, Some(AlphaRule::Lcurve)) => Regularization::LCurve,
        (Some(v), None) => Regularization::Fixed(v),
        (None, None) => IdentifySettings::default().regularization,
    };
    let prob = Problem::new(&model.linear_part(), &rec, &sensors)?;
    if a.method == CliMethod::Horizon {
        return run_horizon(&a, &model, &prob, staging);
    }
    if a.method == CliMethod::Lifted {
        return run_lifted(&a, &model, &prob, staging);
    }
    let settings = IdentifySettings {
        method: if a.method == CliMethod::Paper {
            Method::Paper
        } else {
            Method::Mhe
        },
        solver: a.solver,
        reduce: a.reduce.unwrap_or(Reduce::Serep),
        window: a.window,
        horizon: a.horizon,
        substeps: a.substeps,
        regularization,
        alpha_grid: a.alpha_grid,
        smoothness: a.smoothness,
        prior_weight: a.prior_weight,
        leak: a.leak,
        constraints: Constraints {
            lower: a.lower.clone(),
            upper: a.upper.clone(),
            equilibrium: a.equilibrium,
            pairs: a.pair.clone(),
            push_apart: a.push_apart,
            active: a.active.as_ref().map(|d| d.0.clone()),
        },
        ..Default::default()
    };
    let bar = if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        let b = indicatif::ProgressBar::new(1);
        b.set_style(
            indicatif::ProgressStyle::with_template("identify {bar:40} {pos}/{len} windows {eta}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b
    } else {
        indicatif::ProgressBar::hidden()
    };
    let est = identify::identify_with_progress(&prob, &settings, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    finish(&a, &model, &est, staging)
}

/// Write the outputs whole, print the summary, and fail (after writing)
/// when the estimate diverged or stopped; fail without writing when it
/// holds a non-finite value.
fn finish(
    a: &Args,
    model: &Model,
    est: &identify::ForceEstimate,
    staging: super::output::Staging,
) -> anyhow::Result<()> {
    if let Some(e) = identify::finite::error(est) {
        return Err(e.into());
    }
    let mut files = identify::output::write_all(est, staging.dir(), !a.no_figures)
        .map_err(|e| staging.user_message(e.into()))?;
    if !model.points.is_empty() {
        let more =
            write_point_forces(est, model, staging.dir()).map_err(|e| staging.user_message(e))?;
        files.extend(more);
    }
    staging.commit()?;
    report(est, model)?;
    for f in files {
        let name = f.file_name().map(|n| a.output.join(n)).unwrap_or(f);
        outln!("wrote {}", name.display());
    }
    match &est.status {
        Status::Diverged { sample, growth } => anyhow::bail!(
            "the identification diverged from sample {sample} on (state {growth:.3e} times its size without force); the files in {} hold the diverged estimate for inspection",
            a.output.display()
        ),
        Status::Failed { window, sample, message } => anyhow::bail!(
            "the identification stopped at window {window} (sample {sample}): {message}; the values after it are NaN"
        ),
        _ => Ok(()),
    }
}

/// `--method horizon`: the full-horizon formulation through the same
/// outputs as the window methods.
fn run_horizon(
    a: &Args,
    model: &Model,
    prob: &Problem,
    staging: super::output::Staging,
) -> anyhow::Result<()> {
    use tacit::horizon;
    let sys = identify::System::new(prob, a.reduce.unwrap_or(Reduce::Serep), a.substeps)?;
    let mut bounds: Vec<(usize, f64, f64)> = vec![];
    for &(d, v) in &a.lower {
        bounds.push((d - 1, v, f64::INFINITY));
    }
    for &(d, v) in &a.upper {
        match bounds.iter_mut().find(|b| b.0 == d - 1) {
            Some(b) => b.2 = v,
            None => bounds.push((d - 1, f64::NEG_INFINITY, v)),
        }
    }
    let hs = horizon::HorizonSettings {
        lambda: a.lambda,
        mu: a.mu,
        noise: horizon::ChannelNoise::RmsFraction { fraction: a.noise },
        initial: if a.at_rest {
            horizon::InitialState::Rest
        } else {
            horizon::HorizonSettings::default().initial
        },
        selection: match a.weights {
            WeightRule::Fixed => horizon::WeightSelection::Fixed,
            WeightRule::Gcv => horizon::WeightSelection::Gcv,
            WeightRule::Lcurve => horizon::WeightSelection::LCurve,
            WeightRule::Discrepancy => horizon::WeightSelection::Discrepancy {
                noise: horizon::NoiseLevel::Known,
                tau: 1.0,
            },
        },
        constraints: horizon::ForceConstraints {
            bounds,
            equilibrium: a.equilibrium,
            pairs: a.pair.iter().map(|&(i, j)| (i - 1, j - 1)).collect(),
        },
        ..Default::default()
    };
    let (_, est) = horizon::convert::identify_problem(prob, &sys, &[], &hs)?;
    finish(a, model, &est, staging)
}

/// The located, lifted smoother through the same outputs.
fn run_lifted(
    a: &Args,
    model: &Model,
    prob: &Problem,
    staging: super::output::Staging,
) -> anyhow::Result<()> {
    let defaults = identify::LocatedSettings::default();
    let settings = identify::LocatedSettings {
        lifted: tacit::diagnose::lifted::LiftedSettings {
            resolution: a.resolution,
            lambda: a.lambda,
            noise_fraction: a.noise,
            min_residual: a.min_residual,
            ..defaults.lifted.clone()
        },
        locate: tacit::diagnose::settings::LocateSettings {
            ratio: if a.no_locate {
                0.0
            } else {
                defaults.locate.ratio
            },
            ..defaults.locate
        },
        substeps: a.substeps,
    };
    let est = identify::identify_located(model, prob, &settings)?;
    finish(a, model, &est, staging)
}

fn report(est: &identify::ForceEstimate, model: &Model) -> anyhow::Result<()> {
    let (b, af, rp) = est.overall_errors();
    outln!(
        "{} on {} ({} samples): status {}",
        est.method,
        est.record,
        est.time.len(),
        status_words(&est.status)
    );
    if let Some(r) = est.diagnostics.spectral_radius {
        outln!("closed-loop spectral radius per window: {r:.6}");
    }
    if let Some(reg) = &est.diagnostics.regularization {
        outln!("alpha = {:.3e} ({})", reg.alpha, reg.rule);
    }
    if let Some(id) = &est.diagnostics.identifiability {
        outln!("identifiability: {}", id.note);
    }
    outln!(
        "relative error over all channels: before {:.2} %, after {:.2} %, open-loop replay {:.2} %",
        100.0 * b,
        100.0 * af,
        100.0 * rp
    );
    for c in &est.channels {
        outln!(
            "  {:>8}: before {:7.2} %  after {:7.3} %",
            c.name,
            100.0 * c.error_before,
            100.0 * c.error_after
        );
    }
    if model.points.is_empty() {
        let rms: Vec<String> = est.force_rms().iter().map(|v| format!("{v:.3}")).collect();
        outln!("force RMS per DOF [N]: {}", rms.join(", "));
    } else {
        outln!("{}", point_summary(est, model));
    }
    outln!(
        "time: setup {:.3} s, selection {:.3} s, solve {:.3} s",
        est.timings.setup,
        est.timings.selection,
        est.timings.solve
    );
    for w in &est.warnings {
        eprintln!("tacit: warning: {w}");
    }
    Ok(())
}

/// The status of an estimate in words.
fn status_words(s: &Status) -> String {
    match s {
        Status::Ok => "ok".into(),
        Status::Warning => "finished with warnings (below)".into(),
        Status::Diverged { sample, growth } => {
            format!("diverged from sample {sample} on (growth {growth:.3e})")
        }
        Status::Failed { window, sample, .. } => {
            format!("stopped at window {window} (sample {sample})")
        }
        Status::NonFinite {
            stage,
            component,
            sample,
        } => format!(
            "non-finite {} at {component} from sample {sample}",
            stage.words()
        ),
    }
}

/// The points the location search selected, by label (`n100:uy`,
/// `a50:uy–b50:uy`), from the estimate's settings; empty when it found
/// none or did not run.
fn located_points(est: &identify::ForceEstimate, model: &Model) -> Vec<String> {
    let dirs = est.settings["located"]["directions"].as_array();
    dirs.into_iter()
        .flatten()
        .filter_map(|d| d["dofs"].as_array())
        .map(|dofs| {
            let names: Vec<String> = dofs
                .iter()
                .filter_map(|v| v.as_u64())
                .map(|d| model.dof_name(d as usize))
                .collect();
            names.join("–")
        })
        .collect()
}

/// One line: the force RMS at each point, the largest on the modal
/// coordinates, and where the force was located.
fn point_summary(est: &identify::ForceEstimate, model: &Model) -> String {
    let rms = est.force_rms();
    let np = model.points.len();
    let at: Vec<String> = model
        .points
        .iter()
        .zip(&rms)
        .map(|(l, v)| format!("{l} {v:.3}"))
        .collect();
    let mut s = format!("force RMS per point [N]: {}", at.join(", "));
    if rms.len() > np {
        let top = rms[np..].iter().fold(0.0f64, |m, &v| m.max(v));
        s += &format!(
            "; generalized force on the {} modal coordinates: largest RMS {top:.3}",
            rms.len() - np
        );
    }
    let located = located_points(est, model);
    if !located.is_empty() {
        s += &format!("\nforce located at point {}", located.join(" + "));
    }
    s
}

/// For a model that names its points: `forces_at_points.csv` (`time`,
/// then the internal force at each point, N, headed by its label) and
/// `points.json` (each point's reduced DOF, label and force RMS, with the
/// true force's RMS and the correlation with it when the record is
/// simulated, the located points, and a model from matrices' reduction).
fn write_point_forces(
    est: &identify::ForceEstimate,
    model: &Model,
    dir: &std::path::Path,
) -> anyhow::Result<Vec<PathBuf>> {
    use std::fmt::Write;
    let csv = dir.join("forces_at_points.csv");
    let mut text = String::from("time");
    for l in &model.points {
        write!(text, ",{l}")?;
    }
    text.push('\n');
    for (k, t) in est.time.iter().enumerate() {
        write!(text, "{t:.9e}")?;
        for i in 0..model.points.len() {
            write!(text, ",{:.9e}", est.force[(i, k)])?;
        }
        text.push('\n');
    }
    tacit::io::write_string(&csv, &text)?;
    let rms = est.force_rms();
    let points: Vec<serde_json::Value> = model
        .points
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let mut p = serde_json::json!({"dof": i + 1, "label": l, "force_rms": rms[i]});
            if let Some(t) = est.truth.as_ref().filter(|t| t.space == "dof") {
                p["true_force_rms"] = t.rms_true[i].into();
                p["correlation_with_truth"] = t.correlation[i].into();
            }
            p
        })
        .collect();
    let doc = serde_json::json!({
        "convention": identify::output::CONVENTION,
        "points": points,
        "modal_coordinates": model.ndof() - model.points.len(),
        "located": located_points(est, model),
        "reduction": model.matrices.as_ref().and_then(|l| l.report.as_ref()),
    });
    let json = dir.join("points.json");
    tacit::io::write_json(&json, &doc)?;
    Ok(vec![csv, json])
}
