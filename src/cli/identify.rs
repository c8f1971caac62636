//! `tacit identify`: reconstruct the internal force a linear model lacks
//! from a record (sliding windows: the paper's scheme or moving-horizon
//! estimation).

use super::{check_dofs, DofList};
use std::path::PathBuf;
use tacit::identify::{
    self, Constraints, IdentifySettings, Method, Problem, Reduce, Regularization, Solver, Status,
};
use tacit::model::Model;
use tacit::record;

/// Identification method on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum CliMethod {
    /// The published sequential windows.
    Paper,
    /// Moving-horizon estimation (default).
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
    /// Sensor DOFs, e.g. 1,5,6 (every output channel at them is fitted).
    #[arg(long)]
    sensors: DofList,
    /// Reduction onto the sensor DOFs (none = full-order model).
    #[arg(long, value_enum, default_value = "serep")]
    reduce: Reduce,
    /// Window length in samples (MHE: samples committed per window).
    #[arg(long, default_value_t = 3)]
    window: usize,
    /// MHE horizon in samples (>= window).
    #[arg(long, default_value_t = 24)]
    horizon: usize,
    /// Integration sub-steps per sample of the linear model.
    #[arg(long, default_value_t = 10)]
    substeps: usize,
    /// Window solver: least squares or QP (Clarabel, with constraints).
    #[arg(long, value_enum, default_value = "ls")]
    solver: Solver,
    /// Scheme: the published sequential windows, moving-horizon estimation,
    /// or the full-horizon optimal-control formulation.
    #[arg(long, value_enum, default_value = "mhe")]
    method: CliMethod,
    /// Horizon method: weight rule for λ, μ (default: discrepancy principle
    /// with the --noise level).
    #[arg(long, value_enum, default_value = "discrepancy")]
    weights: WeightRule,
    /// Horizon method: λ, weight of Σ‖f_k‖² (start of the weight search).
    #[arg(long, default_value_t = 1e-2)]
    lambda: f64,
    /// Horizon method: μ, weight of Σ‖f_{k+1} − f_k‖².
    #[arg(long, default_value_t = 0.0)]
    mu: f64,
    /// Horizon method: channel noise as a fraction of each channel's RMS.
    #[arg(long, default_value_t = 0.01)]
    noise: f64,
    /// Horizon method: the record starts at rest (x0 = 0 instead of estimated).
    #[arg(long)]
    at_rest: bool,
    /// Tikhonov weight α (SI units: (output unit / N)²). Default 1e-3.
    #[arg(long, conflicts_with = "alpha_select")]
    alpha: Option<f64>,
    /// Choose α automatically over --alpha-grid.
    #[arg(long, value_enum)]
    alpha_select: Option<AlphaRule>,
    /// α grid for --alpha-select: lowest,highest,count.
    #[arg(long, default_value = "1e-10,1e2,25", value_parser = parse_grid)]
    alpha_grid: (f64, f64, usize),
    /// Weight of the first differences of the force (same units as α).
    #[arg(long, default_value_t = 0.0)]
    smoothness: f64,
    /// MHE arrival-cost weight μ (relative).
    #[arg(long, default_value_t = 1e-2)]
    prior_weight: f64,
    /// MHE leak ε towards a zero start state (relative, > 0).
    #[arg(long, default_value_t = 1e-4)]
    leak: f64,
    /// QP: lower bound DOF:VALUE (N), repeatable.
    #[arg(long, value_parser = parse_bound)]
    lower: Vec<(usize, f64)>,
    /// QP: upper bound DOF:VALUE (N), repeatable.
    #[arg(long, value_parser = parse_bound)]
    upper: Vec<(usize, f64)>,
    /// QP: the force components sum to zero (purely internal force).
    #[arg(long)]
    equilibrium: bool,
    /// QP: pair I,J with f_I = −f_J, repeatable.
    #[arg(long, value_parser = parse_pair_dofs)]
    pair: Vec<(usize, usize)>,
    /// QP: each pair only pushes apart (f_I >= 0; contact closes as u_I − u_J grows).
    #[arg(long)]
    push_apart: bool,
    /// QP: only these DOFs carry a force.
    #[arg(long)]
    active: Option<DofList>,
    /// Do not draw the figures.
    #[arg(long)]
    no_figures: bool,
    /// Output directory.
    #[arg(short, long)]
    output: PathBuf,
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

/// Run `tacit identify`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let model = Model::from_file(&a.model)?;
    let n = model.ndof();
    check_dofs(&a.sensors.0, n, "--sensors")?;
    let rec = record::read(&a.record)?;
    let regularization = match (a.alpha, a.alpha_select) {
        (_, Some(AlphaRule::Gcv)) => Regularization::Gcv,
        (_, Some(AlphaRule::Lcurve)) => Regularization::LCurve,
        (Some(v), None) => Regularization::Fixed(v),
        (None, None) => IdentifySettings::default().regularization,
    };
    if a.method == CliMethod::Horizon {
        return run_horizon(&a, &model, &rec);
    }
    let settings = IdentifySettings {
        method: if a.method == CliMethod::Paper {
            Method::Paper
        } else {
            Method::Mhe
        },
        solver: a.solver,
        reduce: a.reduce,
        window: a.window,
        horizon: a.horizon,
        substeps: a.substeps,
        regularization,
        alpha_grid: a.alpha_grid,
        smoothness: a.smoothness,
        prior_weight: a.prior_weight,
        leak: a.leak,
        constraints: Constraints {
            lower: a.lower,
            upper: a.upper,
            equilibrium: a.equilibrium,
            pairs: a.pair,
            push_apart: a.push_apart,
            active: a.active.map(|d| d.0),
        },
        ..Default::default()
    };
    let prob = Problem::new(&model.linear_part(), &rec, &a.sensors.0)?;
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
    let files = identify::output::write_all(&est, &a.output, !a.no_figures)?;
    report(&est);
    for f in files {
        println!("wrote {}", f.display());
    }
    Ok(())
}

/// `--method horizon`: the full-horizon formulation through the same
/// outputs as the window methods.
fn run_horizon(a: &Args, model: &Model, rec: &record::Record) -> anyhow::Result<()> {
    use tacit::horizon;
    let prob = Problem::new(&model.linear_part(), rec, &a.sensors.0)?;
    let sys = identify::System::new(&prob, a.reduce, a.substeps)?;
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
    let (_, est) = horizon::convert::identify_problem(&prob, &sys, &[], &hs)?;
    let files = identify::output::write_all(&est, &a.output, !a.no_figures)?;
    report(&est);
    for f in files {
        println!("wrote {}", f.display());
    }
    Ok(())
}

fn report(est: &identify::ForceEstimate) {
    let (b, af, rp) = est.overall_errors();
    println!(
        "{} on {} ({} samples): status {}",
        est.method,
        est.record,
        est.time.len(),
        match &est.status {
            Status::Ok => "ok".to_string(),
            s => serde_json::to_string(s).unwrap_or_default(),
        }
    );
    if let Some(r) = est.diagnostics.spectral_radius {
        println!("closed-loop spectral radius per window: {r:.6}");
    }
    if let Some(reg) = &est.diagnostics.regularization {
        println!("alpha = {:.3e} ({})", reg.alpha, reg.rule);
    }
    if let Some(id) = &est.diagnostics.identifiability {
        println!("identifiability: {}", id.note);
    }
    println!(
        "relative error over all channels: before {:.2} %, after {:.2} %, open-loop replay {:.2} %",
        100.0 * b,
        100.0 * af,
        100.0 * rp
    );
    for c in &est.channels {
        println!(
            "  {:>8}: before {:7.2} %  after {:7.3} %",
            c.name,
            100.0 * c.error_before,
            100.0 * c.error_after
        );
    }
    let rms: Vec<String> = est.force_rms().iter().map(|v| format!("{v:.3}")).collect();
    println!("force RMS per DOF [N]: {}", rms.join(", "));
    println!(
        "time: setup {:.3} s, selection {:.3} s, solve {:.3} s",
        est.timings.setup, est.timings.selection, est.timings.solve
    );
    for w in &est.warnings {
        eprintln!("warning: {w}");
    }
}
