//! `tacit diagnose`: the close-the-loop diagnosis.

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
    /// Jacobian of the effect fits' race of starts: forward sensitivities
    /// of the integrator or centered finite differences (the joint fit of
    /// parameters and start states always uses the sensitivities).
    #[arg(long, value_enum, default_value = "sens")]
    jacobian: tacit::update::JacobianMethod,
    /// Use the truth stored in a simulated record as the states (checks the
    /// later steps independently of the identification).
    #[arg(long, hide = true)]
    truth_states: bool,
    #[command(flatten)]
    rec: RecordOpts,
    /// Output directory.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let mut rec = load_record(&a.record, &a.rec)?;
    let mut val = match &a.validate {
        Some(p) => Some(load_record(p, &a.rec)?),
        None => None,
    };
    // a model from matrices is reduced onto the records' points
    let mut recs: Vec<&mut tacit::record::Record> = vec![&mut rec];
    recs.extend(val.as_mut());
    let model = Model::load(&a.model, &mut recs)?;
    if !(a.segment > 0.0) {
        anyhow::bail!("--segment {} must be > 0", a.segment);
    }
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
    let d = diagnose::diagnose(
        &model,
        &rec,
        val.as_ref(),
        sensors.as_deref(),
        &settings,
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
    };
    report::write(&a.output, &meta, &d, &settings)?;
    if let Some(r) = model.matrices.as_ref().and_then(|l| l.report.as_ref()) {
        let effects: Vec<(String, Vec<usize>)> = d
            .effects
            .iter()
            .map(|e| (e.label.clone(), e.dofs.clone()))
            .collect();
        tacit::model::matrix::append_report(&a.output, r, &effects)?;
    }
    println!("{}", d.verdict);
    let pct = |x: Option<f64>| x.map_or("failed".to_string(), |v| format!("{:.2} %", 100.0 * v));
    println!(
        "relative_error {} -> {}   simulation_error {} -> {}",
        pct(d.before.relative_error),
        pct(d.after.relative_error),
        pct(d.before.simulation_error),
        pct(d.after.simulation_error)
    );
    if let Some(v) = &d.validation {
        println!(
            "validation: relative_error {} -> {}",
            pct(v.before.relative_error),
            pct(v.after.relative_error)
        );
    }
    println!("report: {}", a.output.join("report.md").display());
    Ok(())
}
