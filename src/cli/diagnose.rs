//! `tacit diagnose`: the close-the-loop diagnosis.

use super::out::outln;
use super::{load_record, DofList, RecordOpts};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;
use tacit::diagnose::{self, report, DiagnoseSettings};
use tacit::model::Model;

/// Arguments of `tacit diagnose`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file (TOML): the declared model.
    #[arg(long)]
    model: PathBuf,
    /// Record to diagnose (.h5, .csv, .mat).
    #[arg(long)]
    record: PathBuf,
    /// A second record, not used in the fit, to validate on.
    #[arg(long)]
    validate: Option<PathBuf>,
    /// Sensor DOFs to use (default: every output channel of the record).
    #[arg(long)]
    sensors: Option<DofList>,
    /// Segment length of the multiple-shooting error, s.
    #[arg(long, default_value_t = 0.1)]
    segment: f64,
    /// Most effects to add.
    #[arg(long, default_value_t = 3)]
    max_effects: usize,
    /// Sub-steps per sample of the identification and the trace; the
    /// scored and fitted models use at least this and at least 40, more
    /// for a stiff element.
    #[arg(long, default_value_t = 10)]
    substeps: usize,
    /// Jacobian of the effect fits' race of starts: sens (forward
    /// sensitivities of the integrator) or fd (centered finite differences; the joint fit of
    /// parameters and start states always uses the sensitivities).
    #[arg(long, value_enum, default_value = "sens", hide_possible_values = true)]
    jacobian: tacit::update::JacobianMethod,
    /// Use the truth stored in a simulated record as the states (checks the
    /// later steps independently of the identification).
    #[arg(long, hide = true)]
    truth_states: bool,
    /// A record at a level where the structure behaves linearly
    /// (repeatable): the linear part is calibrated on these instead of on
    /// the record diagnosed, then refined with the effects found.
    #[arg(long = "linear-record")]
    linear_records: Vec<PathBuf>,
    /// Trust the declared linear part: no calibration of springs and
    /// damping, no joint refinement.
    #[arg(long)]
    trust_linear: bool,
    #[command(flatten)]
    rec: RecordOpts,
    /// Output directory (created with its parents; written whole at the
    /// end).
    #[arg(short, long)]
    output: PathBuf,
    /// Replace an output directory that already holds a tacit report.
    #[arg(long)]
    force: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    super::check::diagnose_options(a.segment, a.max_effects, a.substeps)?;
    let staging = super::output::Staging::begin(&a.output, a.force)?;
    let model = Model::from_file(&a.model)?;
    let rec = load_record(&a.record, &a.rec)?;
    let val = match &a.validate {
        Some(p) => Some(load_record(p, &a.rec)?),
        None => None,
    };
    super::check::segment_in_record(a.segment, rec.fs, rec.len())?;
    let chosen = a.sensors.as_ref().map(|d| d.0.as_slice());
    let mut warnings = super::records::check(&rec, &model, chosen)?;
    if let Some(v) = &val {
        warnings.extend(super::records::check(v, &model, chosen)?);
    }
    super::check::memory(
        super::check::diagnose_bytes(model.ndof(), a.substeps, rec.len()),
        "the diagnosis of this record",
    )?;
    let defaults = DiagnoseSettings::default();
    let settings = DiagnoseSettings {
        fit: tacit::update::FitSettings {
            jacobian: a.jacobian,
            ..defaults.fit
        },
        segment_seconds: a.segment,
        max_effects: a.max_effects,
        substeps: a.substeps,
        states: if a.truth_states {
            diagnose::StatesSource::Truth
        } else {
            diagnose::StatesSource::Lifted
        },
        ..defaults
    };
    let sensors = a.sensors.as_ref().map(|d| d.0.clone());
    let bar = if std::io::stderr().is_terminal() {
        let b = ProgressBar::new_spinner();
        b.set_draw_target(ProgressDrawTarget::stderr());
        b.set_style(ProgressStyle::with_template("{spinner} {elapsed} {msg}")?);
        b.enable_steady_tick(std::time::Duration::from_millis(120));
        b
    } else {
        ProgressBar::hidden()
    };
    let linear = a
        .linear_records
        .iter()
        .map(|p| load_record(p, &a.rec))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let cal = diagnose::calibrated::CalibratedSettings {
        off: a.trust_linear,
        ..Default::default()
    };
    let d = diagnose::calibrated::diagnose_calibrated(
        &model,
        &rec,
        val.as_ref(),
        &linear,
        sensors.as_deref(),
        &settings,
        &cal,
        &|m| bar.set_message(m.to_string()),
    )?;
    bar.finish_and_clear();
    let used: Vec<usize> = d.prepared.channels.iter().map(|c| c.1 + 1).collect();
    let meta = report::Meta {
        model: a.model.display().to_string(),
        record: a.record.display().to_string(),
        validation_record: a.validate.as_ref().map(|p| p.display().to_string()),
        sensors: used,
        tacit_version: env!("CARGO_PKG_VERSION").to_string(),
        warnings,
    };
    report::write(staging.dir(), &meta, &d, &settings)
        .map_err(|e| staging.user_message(e.into()))?;
    staging.commit()?;
    outln!("{}", d.verdict);
    let pct = |x: Option<f64>| x.map_or("failed".to_string(), |v| format!("{:.2} %", 100.0 * v));
    outln!(
        "relative_error {} -> {}   simulation_error {} -> {}",
        pct(d.before.relative_error),
        pct(d.after.relative_error),
        pct(d.before.simulation_error),
        pct(d.after.simulation_error)
    );
    if let Some(v) = &d.validation {
        outln!(
            "validation: relative_error {} -> {}",
            pct(v.before.relative_error),
            pct(v.after.relative_error)
        );
    }
    outln!("report: {}", a.output.join("report.md").display());
    Ok(())
}
