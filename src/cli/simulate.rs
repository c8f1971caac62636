//! `tacit simulate`: simulate a model and write a record with its truth.

use super::out::outln;
use super::{check, check_dofs, parse_pair, DofList};
use std::path::PathBuf;
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::record::{self, Quantity};
use tacit::simulate::{
    continuous_substeps, simulate_continuous, simulate_record, InputSpec, RecordSpec,
};

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum InputKind {
    Random,
    Sweep,
    Impulse,
    Record,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum Kind {
    Accel,
    Vel,
    Disp,
}

/// Arguments of `tacit simulate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file (TOML).
    #[arg(long)]
    model: PathBuf,
    /// Input: band-limited random, linear sine sweep, half-sine impulse, or
    /// the force channels of a record (--from).
    #[arg(long, value_enum, default_value = "random")]
    input: InputKind,
    /// RMS of the random force, N (> 0).
    #[arg(long, default_value_t = 20.0, value_name = "N")]
    rms: f64,
    /// Band of the random force, Hz: low,high (below the Nyquist
    /// frequency fs/2).
    #[arg(long, default_value = "5,200", value_parser = parse_pair, value_name = "LOW,HIGH")]
    band: (f64, f64),
    /// Sweep frequencies, Hz: start,end (below fs/2).
    #[arg(long, default_value = "5,200", value_parser = parse_pair, value_name = "START,END")]
    sweep: (f64, f64),
    /// Amplitude of the sweep or impulse, N.
    #[arg(long, default_value_t = 20.0, value_name = "N")]
    amplitude: f64,
    /// Impulse duration, samples (>= 1).
    #[arg(long, default_value_t = 3, value_name = "SAMPLES")]
    width: usize,
    /// Record whose force channel drives the model (with --input record).
    #[arg(long = "from", value_name = "RECORD")]
    from: Option<PathBuf>,
    /// DOF where the force acts (random, sweep, impulse), numbered from 1.
    #[arg(long, default_value_t = 1, value_name = "DOF")]
    input_dof: usize,
    /// Sample rate, Hz (> 0).
    #[arg(long, default_value_t = 512.0, value_name = "HZ")]
    fs: f64,
    /// Number of samples (>= 16).
    #[arg(long, default_value_t = 4096)]
    samples: usize,
    /// Sensor DOFs numbered from 1, e.g. 1,5,6 or 1-8 (default: all).
    #[arg(long, value_name = "DOFS")]
    sensors: Option<DofList>,
    /// Model from matrices: the sensor points by label, comma-separated
    /// (channels are named `accel:<label>`).
    #[arg(long, value_delimiter = ',')]
    points: Vec<String>,
    /// Model from matrices: the point the force acts at (random, sweep,
    /// impulse).
    #[arg(long)]
    input_point: Option<String>,
    /// Measured quantity (repeatable).
    #[arg(long, value_enum, default_values_t = vec![Kind::Accel])]
    kind: Vec<Kind>,
    /// Noise standard deviation as a fraction of each channel's RMS, in
    /// [0, 1].
    #[arg(long, default_value_t = 0.0, value_name = "FRACTION")]
    noise: f64,
    /// Seed of the input and the noise.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Integration sub-steps per sample, 1 to 1000. Default: enough for the
    /// record to stand for the continuous structure (ω h ≤ 0.02 for the
    /// stiffest spring, contact or clearance, and for a cubic or quadratic
    /// spring's tangent at the largest stroke of a first run; at least
    /// 100, at most 1000): 4.8 % of integration error at 10 sub-steps on
    /// data/lanl8dof.toml, 0.3 % at 40.
    #[arg(long, value_name = "N")]
    substeps: Option<usize>,
    /// HHT-α in [-1/3, 0] (0 = Newmark average acceleration).
    #[arg(
        long,
        default_value_t = 0.0,
        allow_hyphen_values = true,
        value_name = "ALPHA"
    )]
    hht_alpha: f64,
    /// Output record: .h5 (with its truth) or .csv (truth in
    /// <name>-truth.csv); missing parent directories are created.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
}

/// Check every numeric option (before the model is read).
fn validate(a: &Args) -> anyhow::Result<()> {
    if let Some(n) = a.substeps {
        check::substeps(n)?;
    }
    check::in_range("--hht-alpha", a.hht_alpha, -1.0 / 3.0, 0.0, "HHT-α")?;
    check::in_range(
        "--noise",
        a.noise,
        0.0,
        1.0,
        "fraction of each channel's RMS",
    )?;
    if matches!(a.input, InputKind::Record) {
        return Ok(());
    }
    check::positive("--fs", a.fs, 1e7, "sample rate, Hz")?;
    check::count("--samples", a.samples, 16, check::MAX_SAMPLES, "samples")?;
    match a.input {
        InputKind::Random => {
            check::positive("--rms", a.rms, 1e9, "RMS of the random force, N")?;
            check::band("--band", a.band, a.fs)?;
        }
        InputKind::Sweep => {
            check::band(
                "--sweep",
                (a.sweep.0.min(a.sweep.1), a.sweep.0.max(a.sweep.1)),
                a.fs,
            )?;
            check::positive("--amplitude", a.amplitude.abs(), 1e9, "N")?;
        }
        InputKind::Impulse => {
            check::count(
                "--width",
                a.width,
                1,
                a.samples,
                "impulse duration, samples",
            )?;
            check::positive("--amplitude", a.amplitude.abs(), 1e9, "N")?;
        }
        InputKind::Record => {}
    }
    Ok(())
}

/// The output location: a known extension, a UTF-8 name for HDF5, not a
/// directory.
fn check_output(path: &std::path::Path) -> anyhow::Result<record::Format> {
    let fmt = record::Format::from_path(path)?;
    if matches!(fmt, record::Format::Mat | record::Format::Uff) {
        anyhow::bail!(
            "{}: tacit writes .h5 or .csv records, not .mat or universal files",
            path.display()
        );
    }
    if fmt == record::Format::Hdf5 && path.to_str().is_none() {
        anyhow::bail!(
            "{}: an HDF5 file name must be valid UTF-8 (the HDF5 library reads only such names)",
            path.display()
        );
    }
    if path.is_dir() {
        anyhow::bail!(
            "{}: is a directory; give a file name ending in .h5 or .csv",
            path.display()
        );
    }
    let parent = super::output::parent_of(path);
    std::fs::create_dir_all(&parent)
        .map_err(|e| anyhow::anyhow!("{}: cannot create the directory: {e}", parent.display()))?;
    Ok(fmt)
}

pub fn run(a: Args) -> anyhow::Result<()> {
    validate(&a)?;
    let fmt = check_output(&a.output)?;
    let (model, labelled) = load_model(&a)?;
    let n = model.ndof();
    let sensors = match &labelled {
        Some((s, _)) => s.clone(),
        None => a
            .sensors
            .clone()
            .map(|d| d.0)
            .unwrap_or_else(|| (1..=n).collect()),
    };
    let a = Args {
        input_dof: labelled.as_ref().map_or(a.input_dof, |l| l.1),
        ..a
    };
    check_dofs(&sensors, n, "--sensors")?;
    check_dofs(&[a.input_dof], n, "--input-dof")?;
    let (input, fs, samples, input_dof) = input_of(&a, n)?;
    let kinds = a
        .kind
        .iter()
        .map(|k| match k {
            Kind::Accel => Quantity::Accel,
            Kind::Vel => Quantity::Vel,
            Kind::Disp => Quantity::Disp,
        })
        .collect();
    let spec = RecordSpec {
        fs,
        samples,
        input_dof,
        input,
        sensors,
        kinds,
        noise: a.noise,
        seed: a.seed,
        settings: SimSettings {
            substeps: a
                .substeps
                .unwrap_or_else(|| continuous_substeps(&model, fs, None)),
            hht_alpha: a.hht_alpha,
            ..Default::default()
        },
        u0: vec![],
        v0: vec![],
    };
    check::memory(
        check::integration_bytes(n, model.contacts.len(), spec.settings.substeps, samples),
        &format!(
            "{samples} samples of {n} DOFs at {} sub-steps",
            spec.settings.substeps
        ),
    )?;
    let t = std::time::Instant::now();
    let (mut rec, sim) = match a.substeps {
        Some(_) => simulate_record(&model, &spec)?,
        None => simulate_continuous(&model, &spec)?,
    };
    if a.substeps.is_none() {
        unresolved_warning(&model, fs, &sim);
    }
    if labelled.is_some() {
        for c in rec.inputs.iter_mut().chain(rec.outputs.iter_mut()) {
            c.point = Some(model.dof_name(c.dof));
        }
    }
    let elapsed = t.elapsed();
    rec.validate(None)?;
    let written = write_outputs(&rec, &a.output, fmt)?;
    let active = sim.fint.column_iter().filter(|c| c.amax() > 0.0).count();
    eprintln!(
        "simulated {} samples of {} ({} sub-steps, {} Newton iterations) in {:.1} ms; nonlinear force active in {:.1} % of samples",
        sim.len(),
        model.name,
        sim.steps,
        sim.newton_iterations,
        elapsed.as_secs_f64() * 1e3,
        100.0 * active as f64 / sim.len() as f64
    );
    outln!("wrote {}", written.join(", "));
    Ok(())
}

/// The force, sampling rate, length and input DOF of `--input`.
fn input_of(a: &Args, n: usize) -> anyhow::Result<(InputSpec, f64, usize, usize)> {
    Ok(match a.input {
        InputKind::Random => (
            InputSpec::Random {
                band: a.band,
                rms: a.rms,
            },
            a.fs,
            a.samples,
            a.input_dof,
        ),
        InputKind::Sweep => (
            InputSpec::Sweep {
                f0: a.sweep.0,
                f1: a.sweep.1,
                amplitude: a.amplitude,
            },
            a.fs,
            a.samples,
            a.input_dof,
        ),
        InputKind::Impulse => (
            InputSpec::Impulse {
                amplitude: a.amplitude,
                width: a.width,
            },
            a.fs,
            a.samples,
            a.input_dof,
        ),
        InputKind::Record => {
            let path = a
                .from
                .as_ref()
                .ok_or_else(|| anyhow::anyhow!("--input record needs --from <record>"))?;
            let rec = super::read_record(path)?;
            rec.validate(Some(n))?;
            let ch = match rec.inputs.as_slice() {
                [one] => one,
                [] => anyhow::bail!("{}: the record has no force channel", path.display()),
                _ => anyhow::bail!(
                    "{}: the record has {} force channels; only one input DOF is supported",
                    path.display(),
                    rec.inputs.len()
                ),
            };
            (InputSpec::Given(ch.data.clone()), rec.fs, rec.len(), ch.dof)
        }
    })
}

/// Writes the record (and for CSV its truth file beside it) atomically;
/// the paths written.
fn write_outputs(
    rec: &record::Record,
    output: &std::path::Path,
    fmt: record::Format,
) -> anyhow::Result<Vec<String>> {
    let write_rec = |p: &std::path::Path| -> anyhow::Result<()> {
        match fmt {
            record::Format::Csv => record::csvio::write(rec, p)?,
            _ => record::hdf5io::write(rec, p)?,
        }
        Ok(())
    };
    let write_truth =
        |p: &std::path::Path| -> anyhow::Result<()> { Ok(record::csvio::write_truth(rec, p)?) };
    let mut written = vec![output.display().to_string()];
    if fmt == record::Format::Csv {
        let tpath = super::with_suffix(output, "-truth");
        super::output::write_files(&[(output, &write_rec), (&tpath, &write_truth)])?;
        written.push(tpath.display().to_string());
    } else {
        super::output::write_files(&[(output, &write_rec)])?;
    }
    Ok(written)
}

/// The model, and for a model from matrices the sensor and input DOFs of
/// `--points` and `--input-point` in the reduced numbering (the reduction
/// keeps them physical, its cut-off from the excitation band).
type Labelled = Option<(Vec<usize>, usize)>;

fn load_model(a: &Args) -> anyhow::Result<(Model, Labelled)> {
    let text = std::fs::read_to_string(&a.model).map_err(|e| tacit::TacitError::io(&a.model, e))?;
    if !tacit::model::matrix::is_matrix_model(&text) {
        if !a.points.is_empty() || a.input_point.is_some() {
            anyhow::bail!("--points and --input-point name points of a model from matrices; {} is a lumped model (use --sensors and --input-dof)", a.model.display());
        }
        return Ok((Model::from_file(&a.model)?, None));
    }
    let mm = tacit::model::matrix::MatrixModel::from_file(&a.model)?;
    if a.points.is_empty() {
        anyhow::bail!(
            "{}: a model from matrices needs the sensor points (--points a,b,...)",
            a.model.display()
        );
    }
    let input = match (&a.input_point, a.input) {
        (Some(p), _) => p.clone(),
        (None, InputKind::Record) => anyhow::bail!("--input record with a model from matrices: not supported; use --input-point with a random, sweep or impulse input"),
        (None, _) => anyhow::bail!("{}: a model from matrices needs the input point (--input-point)", a.model.display()),
    };
    let top = match a.input {
        InputKind::Random => a.band.1,
        InputKind::Sweep => a.sweep.0.max(a.sweep.1),
        _ => a.fs / 4.0,
    };
    let mut labels = a.points.clone();
    labels.push(input.clone());
    let model = mm.reduce(&labels, Some(top))?;
    let dof = |l: &str| model.points.iter().position(|p| p == l).map(|i| i + 1);
    let sensors = a
        .points
        .iter()
        .map(|l| dof(l).expect("kept point"))
        .collect();
    let input_dof = dof(&input).expect("kept point");
    if let Some(r) = model.matrices.as_ref().and_then(|l| l.report.as_ref()) {
        eprintln!(
            "reduced {} DOFs to {} points + {} modes (cut-off {:.1} Hz) in {:.2} s; frequency error {:.3} % up to {:.1} Hz",
            r.full_dofs,
            r.kept.len(),
            r.modal_coordinates,
            r.cutoff_hz,
            r.seconds,
            100.0 * r.max_error,
            r.check_up_to_hz
        );
    }
    Ok((model, Some((sensors, input_dof))))
}

/// A warning when what the stiffest element asks for (at the strokes of
/// `sim`) is beyond the most sub-steps allowed, at which the default ran.
fn unresolved_warning(model: &Model, fs: f64, sim: &tacit::integrate::Simulation) {
    let need = tacit::simulate::continuous_need(model, fs, Some(&sim.u));
    let most = tacit::integrate::newmark::MAX_SUBSTEPS;
    if need > most {
        eprintln!(
            "tacit: warning: the stiffest element asks for {need} sub-steps per sample (ω h ≤ {}); simulated at the most allowed, {most} (pass --substeps to choose)",
            tacit::simulate::CONTINUOUS_OMEGA_H
        );
    }
}
