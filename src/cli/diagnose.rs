//! `tacit diagnose`: the close-the-loop diagnosis.

use super::out::outln;
use super::{load_record, DofList, RecordOpts};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;
use tacit::diagnose::{self, report, DiagnoseSettings};
use tacit::model::Model;
use tacit::record::{Record, SampleRange};

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
    /// Settings of the diagnosis (TOML, or JSON: a settings object or a
    /// report.json, whose settings are replayed); the options below
    /// override it. Default: the library's defaults.
    #[arg(long)]
    settings: Option<PathBuf>,
    /// Segment length of the multiple-shooting error, s
    /// (`segments.seconds`).
    #[arg(long)]
    segment: Option<f64>,
    /// Most effects to add (`screen.max_effects`).
    #[arg(long)]
    max_effects: Option<usize>,
    /// Sub-steps per sample of the identification and the trace; the
    /// scored and fitted models use at least this and at least
    /// `substeps.min`, more for a stiff element (`substeps.base`).
    #[arg(long)]
    substeps: Option<usize>,
    /// Jacobian of the effect fits' race of starts: sens (forward
    /// sensitivities of the integrator) or fd (centered finite
    /// differences); the joint fit of parameters and start states always
    /// uses the sensitivities (`fit.jacobian`).
    #[arg(long, value_enum, hide_possible_values = true)]
    jacobian: Option<tacit::update::JacobianMethod>,
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
    /// Warm-up left out of every record (the diagnosed, validation and
    /// linear records): samples (`8192`) or seconds (`20.48s`), e.g. the
    /// transient first period of a periodic excitation started from rest.
    /// Those samples are neither fitted nor scored; the open-loop
    /// simulation starts at the state reconstructed at the first sample
    /// kept.
    #[arg(long, value_name = "SAMPLES|SECONDS", value_parser = tacit::record::WarmUp::parse)]
    warm_up: Option<tacit::record::WarmUp>,
    /// Keep samples START..END of the record (0-based, END excluded), cut
    /// after the whole file is read (and its mean removed); e.g. a
    /// benchmark's estimation range.
    #[arg(long, value_name = "START..END", value_parser = SampleRange::parse)]
    samples: Option<SampleRange>,
    /// Keep samples START..END of the validation record (as --samples).
    /// Without --validate, the record file itself is cut again: a
    /// benchmark's test range of the same file.
    #[arg(long, value_name = "START..END", value_parser = SampleRange::parse)]
    validation_samples: Option<SampleRange>,
    /// Samples at the start of every record that the open-loop error
    /// simulates but does not score (`simulation_error`,
    /// `rms_per_channel`; `unscored` of the settings): a benchmark's
    /// state initialisation (the Silverbox: 50).
    #[arg(long, value_name = "SAMPLES")]
    skip: Option<usize>,
    /// The force channels were measured band-limited (an anti-aliased
    /// acquisition): their samples are compensated for the linear
    /// interpolation of tacit's integrators (spectrum divided by
    /// sinc²(f/fs), on the whole file before --samples), so that the
    /// simulations see the measured force up to the Nyquist frequency.
    #[arg(long)]
    band_limited_force: bool,
    /// After the diagnosis and the joint refinement, refine every
    /// parameter (linear ones included) by the open-loop simulation error
    /// over the whole record.
    #[arg(long)]
    refine_open_loop: bool,
    /// After the diagnosis of a modal model (from `tacit modal`), offer the
    /// interface as a coordinate of its own (a Jenkins element, then an
    /// Iwan model with --interface-elements, on an unmeasured point whose
    /// participation in every mode is fitted), fitted and ranked with the
    /// declared and the diagnosed model by the open-loop error on the
    /// record and the --linear-record files: interface.json,
    /// interface.md, model-interface.toml, restoring_interface.svg.
    #[arg(long)]
    interface: bool,
    /// Jenkins elements of the interface's Iwan stage (1: none).
    #[arg(long, default_value_t = 1, requires = "interface")]
    interface_elements: usize,
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

/// The settings file (or the defaults) with the options on top, validated.
fn settings(a: &Args) -> anyhow::Result<DiagnoseSettings> {
    let mut s = match &a.settings {
        Some(p) => DiagnoseSettings::from_file(p)?,
        None => DiagnoseSettings::default(),
    };
    if let Some(v) = a.segment {
        s.segments.seconds = v;
    }
    if let Some(v) = a.max_effects {
        s.screen.max_effects = v;
    }
    if let Some(v) = a.substeps {
        s.substeps.base = v;
    }
    if let Some(v) = a.jacobian {
        s.fit.jacobian = v;
    }
    if a.truth_states {
        s.states = diagnose::StatesSource::Truth;
    }
    if let Some(v) = a.skip {
        s.unscored = v;
    }
    Ok(s)
}

/// `--skip` must leave samples of every record to score; the error names
/// the option and the record.
fn check_skip(
    skip: Option<usize>,
    rec: &tacit::record::Record,
    val: Option<&tacit::record::Record>,
) -> anyhow::Result<()> {
    let Some(k) = skip else { return Ok(()) };
    for r in std::iter::once(rec).chain(val) {
        if k >= r.len() {
            anyhow::bail!(
                "--skip {k}: the record {} has only {} samples (after --samples / --validation-samples); the skip must leave some to score",
                r.source.display(),
                r.len()
            );
        }
    }
    Ok(())
}

/// The record, the validation record and the linear records, each cut to
/// its sample range and without its warm-up.
type Records = (Record, Option<Record>, Vec<Record>);

fn load_records(a: &Args) -> anyhow::Result<Records> {
    let load = |p: &std::path::Path, range: Option<(&str, SampleRange)>| {
        let mut r = load_record(p, &a.rec)?;
        if a.band_limited_force {
            r = r.with_band_limited_force();
        }
        if let Some((option, range)) = range {
            r = range
                .cut(&r)
                .map_err(|e| anyhow::anyhow!("{option} {range}: {e}"))?;
        }
        Ok::<_, anyhow::Error>(match a.warm_up {
            Some(w) => r.without_warm_up(w)?,
            None => r,
        })
    };
    let rec = load(&a.record, a.samples.map(|r| ("--samples", r)))?;
    let vrange = a.validation_samples.map(|r| ("--validation-samples", r));
    let val = match (&a.validate, vrange) {
        (Some(p), _) => Some(load(p, vrange)?),
        (None, Some(_)) => Some(load(&a.record, vrange)?),
        (None, None) => None,
    };
    check_skip(a.skip, &rec, val.as_ref())?;
    let linear = a
        .linear_records
        .iter()
        .map(|p| load(p, None))
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok((rec, val, linear))
}

/// A spinner with the stage's message on a terminal, hidden when piped.
fn spinner() -> anyhow::Result<ProgressBar> {
    Ok(if std::io::stderr().is_terminal() {
        let b = ProgressBar::new_spinner();
        b.set_draw_target(ProgressDrawTarget::stderr());
        b.set_style(ProgressStyle::with_template("{spinner} {elapsed} {msg}")?);
        b.enable_steady_tick(std::time::Duration::from_millis(120));
        b
    } else {
        ProgressBar::hidden()
    })
}

/// The verdict and the errors before and after, on the terminal.
fn print_summary(d: &diagnose::Diagnosis, output: &std::path::Path) -> anyhow::Result<()> {
    outln!("{}", d.verdict);
    let pct = report::pct;
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
    for e in d.effects.iter() {
        let (structural, noisy): (Vec<&String>, Vec<&String>) = e
            .undetermined
            .iter()
            .partition(|k| e.unobservable.contains(k));
        let names = |v: &[&String]| v.iter().map(|k| k.as_str()).collect::<Vec<_>>().join(", ");
        if !structural.is_empty() {
            outln!(
                "warning: {}: {} not observable with these sensors (it trades with the absolute position, which accelerations do not give; report.md, Effects found)",
                e.label,
                names(&structural)
            );
        }
        if !noisy.is_empty() {
            outln!(
                "warning: {}: {} not determined by these records (standard error above the value; report.md, Effects found)",
                e.label,
                names(&noisy)
            );
        }
    }
    outln!("report: {}", output.join("report.md").display());
    Ok(())
}

/// The interface candidate after the diagnosis ([`super::interface`]).
fn interface_step(
    a: &Args,
    model: &Model,
    d: &diagnose::Diagnosis,
    dir: &std::path::Path,
) -> anyhow::Result<()> {
    let mut records = vec![a.record.as_path()];
    records.extend(a.linear_records.iter().map(|p| p.as_path()));
    let inputs = super::interface::Inputs {
        model_path: &a.model,
        records,
        validation: a.validate.as_deref(),
        rec: &a.rec,
        samples: a.samples,
        warm_up: a.warm_up,
        elements: a.interface_elements,
        substeps: d.substeps.1.max(1),
    };
    super::interface::run(&inputs, model, d, dir)
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let settings = settings(&a)?;
    super::check::diagnose_options(
        settings.segments.seconds,
        settings.screen.max_effects,
        settings.substeps.base,
    )?;
    settings.validate()?;
    if a.interface {
        super::interface::check_model(&a.model)?;
    }
    let staging = super::output::Staging::begin(&a.output, a.force)?;
    let (mut rec, mut val, mut linear) = load_records(&a)?;
    // a model from matrices is reduced onto the records' points
    let mut recs: Vec<&mut tacit::record::Record> = vec![&mut rec];
    recs.extend(val.as_mut());
    recs.extend(linear.iter_mut());
    let model = Model::load(&a.model, &mut recs)?;
    if a.trust_linear && model.free.is_some() {
        anyhow::bail!(
            "{}: the model marks its linear parameters free ([free]); --trust-linear would leave them at their starting values",
            a.model.display()
        );
    }
    let chosen = a.sensors.as_ref().map(|d| d.0.as_slice());
    let mut warnings = super::records::check(&rec, &model, chosen)?;
    if let Some(v) = &val {
        warnings.extend(super::records::check(v, &model, chosen)?);
    }
    super::check::segment_in_record(settings.segments.seconds, rec.fs, rec.len())?;
    super::check::memory(
        super::check::diagnose_bytes(model.ndof(), settings.substeps.base, rec.len()),
        "the diagnosis of this record",
    )?;
    let sensors = a.sensors.as_ref().map(|d| d.0.clone());
    let bar = spinner()?;
    let cal = diagnose::calibrated::CalibratedSettings {
        off: a.trust_linear,
        open_loop: a.refine_open_loop,
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
    if let Some(r) = model.matrices.as_ref().and_then(|l| l.report.as_ref()) {
        let effects: Vec<(String, Vec<usize>)> = d
            .effects
            .iter()
            .map(|e| (e.label.clone(), e.dofs.clone()))
            .collect();
        tacit::model::matrix::append_report(staging.dir(), r, &effects)
            .map_err(|e| staging.user_message(e.into()))?;
    }
    if a.interface {
        interface_step(&a, &model, &d, staging.dir()).map_err(|e| staging.user_message(e))?;
    }
    staging.commit()?;
    print_summary(&d, &a.output)
}
