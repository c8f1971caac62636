//! `tacit update`: time-domain model updating (GLS or PCD) of a model
//! against a record.

use super::check;
use super::out::outln;
use std::path::PathBuf;
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::plot;
use tacit::record::{self, Quantity, Record};
use tacit::update::{
    self, shooting, FitResult, FitSettings, JacobianMethod, Metric, Optimizer, Problem,
};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum MetricArg {
    Gls,
    Pcd,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ReduceArg {
    None,
    Guyan,
    Serep,
    Irs,
}

/// Arguments of `tacit update`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file (TOML) at its nominal values.
    #[arg(long)]
    model: PathBuf,
    /// Record with the measured channels (and the force, if any).
    #[arg(long)]
    record: PathBuf,
    /// Free parameters, comma-separated: spring labels as in the model
    /// file (k3) or ranges (k1..k4), m<i> (mass of DOF i), zeta, and the
    /// elements' gap<i>, kc<i> (contact), friction<i>, cubic<i> or cubic,
    /// cgap<i>, kcl<i> (clearance), rfriction<i> (relative friction), where
    /// i counts the model file's elements of that kind from 1; a model
    /// from matrices also takes stiffness_scale and mass_scale (multipliers
    /// of its stiffness and mass matrices).
    #[arg(long, value_name = "PARAMS")]
    free: String,
    /// Metric: generalized least squares or principal components.
    #[arg(long, value_enum, default_value = "gls")]
    metric: MetricArg,
    /// Measured quantities to fit: disp, vel, accel (comma-separated).
    #[arg(long, default_value = "disp")]
    data: String,
    /// Only these measured DOFs, numbered from 1 (default: every channel
    /// of the kinds).
    #[arg(long, value_name = "DOFS", conflicts_with = "points")]
    dofs: Option<super::DofList>,
    /// Model from matrices (or a modal model): only these measured points,
    /// by label, comma-separated, e.g. n60:uy,n100:uy (default: every
    /// channel of the kinds).
    #[arg(long, value_name = "LABELS", value_delimiter = ',')]
    points: Option<Vec<String>>,
    /// Model order: full, or reduced to the measured DOFs (a model from
    /// matrices is already reduced onto its points: none only).
    #[arg(long, value_enum, default_value = "none")]
    reduce: ReduceArg,
    /// Optimizer: lm (Levenberg–Marquardt), gn (Gauss–Newton), bfgs or
    /// simplex (Nelder–Mead).
    #[arg(long, value_enum, default_value = "lm", hide_possible_values = true)]
    optimizer: Optimizer,
    /// Jacobian: sens (forward sensitivities of the integrator, one
    /// simulation per segment; reduced models fall back to fd) or fd
    /// (centered finite differences).
    #[arg(long, value_enum, default_value = "sens", hide_possible_values = true)]
    jacobian: JacobianMethod,
    /// Weight α >= 0 of the minimum-change term.
    #[arg(long, default_value_t = 0.0)]
    alpha: f64,
    /// Multiple shooting: segments of this many samples (>= 2), started
    /// from the record's true states (simulated records only). Default:
    /// one segment.
    #[arg(long, value_name = "SAMPLES")]
    segment: Option<usize>,
    /// Initial displacement of every DOF, m (comma-separated); default: the
    /// record's true state at sample 0 if it has one, else zero.
    #[arg(long, allow_hyphen_values = true)]
    u0: Option<String>,
    /// Initial velocity of every DOF, m/s (as --u0).
    #[arg(long, allow_hyphen_values = true)]
    v0: Option<String>,
    /// Integration sub-steps per sample, 1 to 1000.
    #[arg(long, default_value_t = 10, value_name = "N")]
    substeps: usize,
    /// Iteration limit of the optimizer, 1 to 100000.
    #[arg(long, value_name = "N")]
    max_iterations: Option<usize>,
    /// Output directory (created with its parents, written whole at the
    /// end: summary.json, report.md, figures).
    #[arg(short, long)]
    output: PathBuf,
    /// Replace an output directory that already holds tacit output.
    #[arg(long)]
    force: bool,
}

/// Check the numeric options that need no record.
fn validate(a: &Args) -> anyhow::Result<()> {
    check::substeps(a.substeps)?;
    check::in_range(
        "--alpha",
        a.alpha,
        0.0,
        1e12,
        "weight of the minimum-change term",
    )?;
    if let Some(m) = a.max_iterations {
        check::count("--max-iterations", m, 1, 100_000, "optimizer iterations")?;
    }
    Ok(())
}

/// Options that take DOF numbers or a further reduction, refused on a
/// model from matrices (its DOFs are the record's points after the
/// Craig–Bampton reduction, numbered by it).
fn matrix_options(a: &Args) -> anyhow::Result<()> {
    let path = a.model.display();
    if a.dofs.is_some() {
        anyhow::bail!("--dofs: {path} is a model from matrices; name the measured points with --points (e.g. --points n60:uy,n100:uy), or leave both out to fit every channel");
    }
    if a.reduce != ReduceArg::None {
        anyhow::bail!("--reduce: {path} is a model from matrices, already reduced (Craig–Bampton) onto the record's points and the elements' points; leave --reduce out");
    }
    for (opt, given) in [("--u0", &a.u0), ("--v0", &a.v0)] {
        if given.is_some() {
            anyhow::bail!("{opt}: {path} is a model from matrices, whose reduced coordinates are set by the reduction; leave {opt} out (the start is the record's true state when it has one of the same reduction, else rest)");
        }
    }
    Ok(())
}

pub fn run(a: Args) -> anyhow::Result<()> {
    validate(&a)?;
    if tacit::model::matrix::is_matrix_file(&a.model)? {
        matrix_options(&a)?;
    }
    let staging = super::output::Staging::begin(&a.output, a.force)?;
    // a model from matrices is reduced onto the record's points
    let mut rec = super::read_record(&a.record)?;
    let model = Model::load(&a.model, &mut [&mut rec])?;
    rec.validate(Some(model.ndof()))?;
    if let Some(f) = tacit::record::checks::magnitudes(&rec) {
        anyhow::bail!(
            "record {}: cannot be used as it is: {f}",
            rec.source.display()
        );
    }
    if let Some(len) = a.segment {
        check::count(
            "--segment",
            len,
            2,
            rec.len(),
            "samples per segment, at most the record's length",
        )?;
    }
    check::memory(
        check::integration_bytes(model.ndof(), model.contacts.len(), a.substeps, rec.len()) * 8.0,
        "the updating of this record",
    )?;
    let problem = build_problem(&a, &model, &rec)?;
    problem.validate()?;
    let mut settings = FitSettings::with(a.optimizer);
    settings.jacobian = a.jacobian;
    if let Some(m) = a.max_iterations {
        settings.max_iterations = m;
    }
    settings.validate()?;
    let result = update::fit(&problem, &settings)?;
    let what = format!("the updating of {}", a.record.display());
    update::usable(&problem, &result, &what)?;
    let predicted = |x: &[f64], which: &str| {
        update::predict(&problem, x).map_err(|f| {
            anyhow::anyhow!("{what}: the {which} model cannot be simulated over the record ({f}); nothing was written")
        })
    };
    let before = predicted(&problem.x_start(), "start")?;
    let after = predicted(&result.x, "fitted")?;
    let dir = staging.dir().to_path_buf();
    let files = || -> anyhow::Result<Vec<String>> {
        tacit::io::write_json(&dir.join("summary.json"), &result)?;
        tacit::io::write_string(&dir.join("report.md"), &report(&a, &problem, &result))?;
        let t = rec.times();
        let mut written = vec!["summary.json".to_string(), "report.md".to_string()];
        for (stem, pred, title) in [
            ("update_before", &before, "before updating"),
            ("update_after", &after, "after updating"),
        ] {
            let fig = update::figures::responses(&problem, &t, pred, &format!("Responses {title}"));
            plot::save(&fig, &dir.join(stem))?;
            written.push(format!("{stem}.png/.svg"));
        }
        Ok(written)
    };
    let written = files().map_err(|e| staging.user_message(e))?;
    staging.commit()?;
    print_summary(&problem, &result)?;
    outln!("wrote {} in {}", written.join(", "), a.output.display());
    Ok(())
}

fn build_problem(a: &Args, model: &Model, rec: &Record) -> anyhow::Result<Problem> {
    let params = update::parse_free(&a.free, model)?;
    let quantities = parse_quantities(&a.data)?;
    if let Some(d) = &a.dofs {
        super::check_dofs(&d.0, model.ndof(), "--dofs")?;
    }
    let chosen = match &a.points {
        Some(p) => Some(tacit::model::matrix::point_dofs(model, p, "--points")?),
        None => a.dofs.as_ref().map(|d| d.0.clone()),
    };
    let n = model.ndof();
    let state = |given: &Option<String>, row: fn(&record::Truth) -> &Vec<Vec<f64>>, what: &str| {
        initial_state(given, rec, n, row, what)
    };
    let u0 = state(&a.u0, |t| &t.u, "--u0")?;
    let v0 = state(&a.v0, |t| &t.v, "--v0")?;
    let dofs = chosen.as_deref();
    let mut p = Problem::from_record(model, rec, &quantities, dofs, params, u0, v0)?;
    if let Some(len) = a.segment {
        p.segments = shooting::from_truth(rec, len)?;
    }
    p.metric = match a.metric {
        MetricArg::Gls => Metric::Gls,
        MetricArg::Pcd => Metric::pcd(),
    };
    p.reduction = match a.reduce {
        ReduceArg::None => None,
        ReduceArg::Guyan => Some(tacit::reduce::Method::Guyan),
        ReduceArg::Serep => Some(tacit::reduce::Method::Serep),
        ReduceArg::Irs => Some(tacit::reduce::Method::Irs),
    };
    p.alpha = a.alpha;
    p.sim = SimSettings {
        substeps: a.substeps,
        ..Default::default()
    };
    Ok(p)
}

/// Where a parameter acts, by point label on a model that names its
/// points (`n100:uy`, `a50:uy–b50:uy`), by DOF otherwise; empty for a
/// parameter of the whole model.
fn place(t: update::Target, m: &Model) -> String {
    use update::Target;
    let dofs: Vec<usize> = match t {
        Target::SpringStiffness(i) => m.springs.get(i).map(|s| s.dofs.clone()).unwrap_or_default(),
        Target::Mass(i) => vec![i + 1],
        Target::ContactGap(i) | Target::ContactStiffness(i) => m
            .contacts
            .get(i)
            .map(|e| e.dofs.clone())
            .unwrap_or_default(),
        Target::FrictionLevel(i) => m.frictions.get(i).map(|e| vec![e.dof]).unwrap_or_default(),
        Target::CubicK3(i) => m.cubics.get(i).map(|e| e.dofs.clone()).unwrap_or_default(),
        Target::ClearanceGap(i) | Target::ClearanceStiffness(i) => m
            .clearances
            .get(i)
            .map(|e| e.dofs.clone())
            .unwrap_or_default(),
        Target::RelativeFrictionLevel(i) => m
            .relative_frictions
            .get(i)
            .map(|e| e.dofs.clone())
            .unwrap_or_default(),
        _ => vec![],
    };
    let names: Vec<String> = dofs.iter().map(|&d| m.dof_name(d)).collect();
    names.join("–")
}

fn parse_quantities(s: &str) -> anyhow::Result<Vec<Quantity>> {
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let q = match part {
            "disp" | "d" => Quantity::Disp,
            "vel" | "v" => Quantity::Vel,
            "accel" | "a" => Quantity::Accel,
            _ => anyhow::bail!("--data: '{part}' is not one of disp, vel, accel"),
        };
        if !out.contains(&q) {
            out.push(q);
        }
    }
    if out.is_empty() {
        anyhow::bail!("--data: give at least one of disp, vel, accel");
    }
    Ok(out)
}

fn initial_state(
    given: &Option<String>,
    rec: &Record,
    n: usize,
    rows: fn(&record::Truth) -> &Vec<Vec<f64>>,
    what: &str,
) -> anyhow::Result<Vec<f64>> {
    if let Some(s) = given {
        let v: Vec<f64> = s
            .split(',')
            .map(|x| {
                x.trim()
                    .parse::<f64>()
                    .map_err(|_| anyhow::anyhow!("{what}: '{x}' is not a number"))
            })
            .collect::<anyhow::Result<_>>()?;
        if v.len() != n {
            anyhow::bail!("{what}: {} values given, the model has {n} DOFs", v.len());
        }
        return Ok(v);
    }
    match &rec.truth {
        Some(t) if rows(t).len() == n => Ok(rows(t).iter().map(|r| r[0]).collect()),
        _ => Ok(vec![0.0; n]),
    }
}

fn print_summary(problem: &Problem, r: &FitResult) -> anyhow::Result<()> {
    for p in &r.parameters {
        let at = problem
            .parameters
            .iter()
            .find(|x| x.name == p.name)
            .map_or(String::new(), |x| place(x.target, &problem.model));
        let at = if at.is_empty() {
            at
        } else {
            format!(" ({at})")
        };
        outln!(
            "{:>10}{at}: {:>12.6e} -> {:>12.6e} ({:+.2} %){}",
            p.name,
            p.nominal,
            p.value,
            p.percent_change,
            if p.at_bound { " at bound" } else { "" }
        );
    }
    outln!(
        "termination: {}; {} iterations, {} simulations, {:.2} s",
        r.termination.words(),
        r.iterations,
        r.simulations,
        r.elapsed_s
    );
    outln!("jacobian: {}", jacobian_line(r));
    if let Some(id) = &r.identifiability {
        outln!("identifiability: {}", id.verdict);
    }
    Ok(())
}

/// Method, counts and time of the Jacobians, and why the method differs
/// from the requested one.
fn jacobian_line(r: &FitResult) -> String {
    let mut s = format!(
        "{}, {} Jacobians ({} simulations with sensitivities), {:.2} s",
        jacobian_words(r.jacobian),
        r.jacobians,
        r.sensitivity_simulations,
        r.jacobian_s
    );
    if let Some(note) = &r.jacobian_note {
        s.push_str(&format!(" ({note})"));
    }
    if r.sensitivity_fallbacks > 0 {
        s.push_str(&format!(
            "; {} sensitivity Jacobians failed and were replaced by finite differences",
            r.sensitivity_fallbacks
        ));
    }
    s
}

fn report(a: &Args, p: &Problem, r: &FitResult) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "# Model updating of {}\n\nRecord `{}`; metric {}; reduction {}; optimizer {}; α = {}; {} segment(s).\n\n",
        p.model.name,
        a.record.display(),
        match r.metric {
            Metric::Gls => "GLS (generalized least squares)",
            Metric::Pcd { .. } => "PCD (principal components)",
        },
        match r.reduction {
            None => "none (full-order model)",
            Some(tacit::reduce::Method::Guyan) => "Guyan",
            Some(tacit::reduce::Method::Serep) => "SEREP",
            Some(tacit::reduce::Method::Irs) => "IRS",
        },
        match r.optimizer {
            Optimizer::Lm => "Levenberg–Marquardt",
            Optimizer::Gn => "Gauss–Newton",
            Optimizer::Bfgs => "BFGS",
            Optimizer::Simplex => "Nelder–Mead simplex",
        },
        p.alpha,
        p.segments.len()
    ));
    s.push_str(
        "| parameter | at | nominal | fitted | change % | bounds |\n|---|---|---|---|---|---|\n",
    );
    for q in &r.parameters {
        s.push_str(&format!(
            "| {} | {} | {:.6e} | {:.6e} | {:+.2} | [{:.3e}, {:.3e}]{} |\n",
            q.name,
            p.parameters
                .iter()
                .find(|x| x.name == q.name)
                .map_or(String::new(), |x| place(x.target, &p.model)),
            q.nominal,
            q.value,
            q.percent_change,
            q.lower,
            q.upper,
            if q.at_bound { " (at bound)" } else { "" }
        ));
    }
    s.push_str(&format!(
        "\nTermination: {}. Iterations {}, cost evaluations {}, simulations {}, failed trials {}, {:.2} s.\n\n",
        r.termination.words(),
        r.iterations, r.evaluations, r.simulations, r.failed_trials, r.elapsed_s
    ));
    s.push_str(&format!("Jacobian: {}.\n\n", jacobian_line(r)));
    s.push_str("| channel | error before | error after |\n|---|---|---|\n");
    if let (Some(b), Some(f)) = (&r.errors_before, &r.errors_after) {
        for (x, y) in b.channels.iter().zip(&f.channels) {
            s.push_str(&format!(
                "| {} | {:.4} | {:.4} |\n",
                x.channel, x.relative_error, y.relative_error
            ));
        }
        s.push_str(&format!("| all | {:.4} | {:.4} |\n", b.overall, f.overall));
    }
    if let Some(e) = r.reduction_error {
        s.push_str(&format!(
            "\nReduced vs full-order response at the solution: {:.4} relative difference.\n",
            e
        ));
    }
    if let Some(id) = &r.identifiability {
        s.push_str(&format!(
            "\n## Identifiability\n\n{}\n\nJacobian singular values: {:?}\n\n| parameter | std at {:.2} % noise (scaled) | determined |\n|---|---|---|\n",
            id.verdict,
            id.singular_values,
            id.noise_level * 100.0
        ));
        for q in &id.parameters {
            s.push_str(&format!(
                "| {} | {:.4} | {} |\n",
                q.name, q.std_scaled, q.determined
            ));
        }
    }
    s.push_str("\nFigures: update_before.png, update_after.png (test solid, model dashed).\n");
    s
}

/// The Jacobian method, in words.
fn jacobian_words(j: JacobianMethod) -> &'static str {
    match j {
        JacobianMethod::Sensitivity => "forward sensitivities",
        JacobianMethod::CentralDifference => "centered finite differences",
    }
}
