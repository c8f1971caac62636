//! The computations: simulate, modes, identify, diagnose. Each releases
//! the interpreter lock while it runs. Structured results cross as JSON
//! text, parsed into dicts by the Python package, with the large arrays
//! beside them as NumPy arrays.

use crate::model::Model;
use crate::record::Record;
use crate::{convert, err};
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use std::path::{Path, PathBuf};
use tacit::diagnose::{calibrated, report, DiagnoseSettings};
use tacit::identify::{identify_located, LocatedSettings, Problem};
use tacit::integrate::SimSettings;
use tacit::record::{model_checks, Quantity};
use tacit::simulate::{simulate_continuous, simulate_record, InputSpec, RecordSpec};

/// Frequencies (Hz), shapes (columns) and rigid-body flags.
type ModesOut<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Vec<bool>,
);

/// Summary JSON, force (ndof × samples), time.
type IdentifyOut<'py> = (String, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>);

/// The input of a simulation from its name and parameters.
fn input_spec(
    input: &str,
    rms: f64,
    band: (f64, f64),
    amplitude: f64,
    sweep: (f64, f64),
    force: Option<Vec<f64>>,
) -> PyResult<InputSpec> {
    Ok(match (input, force) {
        (_, Some(f)) => InputSpec::Given(f),
        ("random", None) => InputSpec::Random { band, rms },
        ("sweep", None) => InputSpec::Sweep {
            f0: sweep.0,
            f1: sweep.1,
            amplitude,
        },
        ("none", None) => InputSpec::None,
        (other, None) => {
            return Err(err(format!(
                "input \"{other}\": give random, sweep or none, or a force array"
            )))
        }
    })
}

/// Simulate a model (nonlinear elements included) and sample a record
/// with its truth. `input`: `random` (band-limited, `rms` N over `band`
/// Hz), `sweep` (`amplitude` N from `sweep[0]` to `sweep[1]` Hz), `none`,
/// or the force history `force` (N, at least `samples` values) at
/// `input_dof` (from 1). `sensors`: DOFs from 1 (default: every DOF);
/// `kinds`: any of `disp`, `vel`, `accel`; `noise`: standard deviation as
/// a fraction of each channel's RMS; `substeps`: Newmark sub-steps per
/// sample (default: enough for the record to stand for the continuous
/// structure, as `tacit simulate` chooses them). A model from matrices
/// takes `points` (sensor labels) and `input_point` instead of `sensors`
/// and `input_dof`: it is reduced onto them (cut-off twice the top of the
/// input's band) and the channels are named by point (`accel:n20:uy`).
#[pyfunction]
#[pyo3(signature = (model, samples = 4096, fs = 512.0, input = "random", rms = 20.0,
    band = (5.0, 200.0), amplitude = 10.0, sweep = (5.0, 150.0), force = None,
    input_dof = 1, sensors = None, kinds = vec!["accel".to_string()], noise = 0.0,
    seed = 7, substeps = None, points = None, input_point = None))]
#[allow(clippy::too_many_arguments)]
pub fn simulate(
    py: Python<'_>,
    model: &Model,
    samples: usize,
    fs: f64,
    input: &str,
    rms: f64,
    band: (f64, f64),
    amplitude: f64,
    sweep: (f64, f64),
    force: Option<numpy::PyReadonlyArray1<'_, f64>>,
    input_dof: usize,
    sensors: Option<Vec<usize>>,
    kinds: Vec<String>,
    noise: f64,
    seed: u64,
    substeps: Option<usize>,
    points: Option<Vec<String>>,
    input_point: Option<String>,
) -> PyResult<Record> {
    let top = match (input, &force) {
        (_, Some(_)) => fs / 4.0,
        ("sweep", None) => sweep.0.max(sweep.1),
        _ => band.1,
    };
    let (reduced, sensors, input_dof) =
        at_points(model, points, input_point, top, sensors, input_dof)?;
    let model = &reduced;
    let kinds = kinds
        .iter()
        .map(|k| {
            Quantity::from_prefix(k)
                .filter(|q| *q != Quantity::Force)
                .ok_or_else(|| err(format!("kind \"{k}\": give disp, vel or accel")))
        })
        .collect::<PyResult<Vec<_>>>()?;
    let spec = RecordSpec {
        fs,
        samples,
        input_dof,
        input: input_spec(
            input,
            rms,
            band,
            amplitude,
            sweep,
            force.map(|f| convert::to_vec(&f)),
        )?,
        sensors: sensors.unwrap_or_else(|| (1..=model.ndof()).collect()),
        kinds,
        noise,
        seed,
        settings: SimSettings {
            substeps: substeps.unwrap_or(1),
            ..Default::default()
        },
        u0: vec![],
        v0: vec![],
    };
    spec.settings.validate().map_err(err)?;
    let m = &**model;
    let run = || match substeps {
        Some(_) => simulate_record(m, &spec),
        None => simulate_continuous(m, &spec),
    };
    let (mut inner, _) = py.detach(run).map_err(err)?;
    if !m.points.is_empty() {
        for c in inner.inputs.iter_mut().chain(inner.outputs.iter_mut()) {
            c.point = Some(m.dof_name(c.dof));
        }
    }
    Ok(Record { inner })
}

/// The model to simulate with its sensor and input DOFs: a model from
/// matrices reduced onto `points` and `input_point` (its DOFs in the
/// reduced numbering), any other model as it is with `sensors` and
/// `input_dof`.
fn at_points(
    model: &Model,
    points: Option<Vec<String>>,
    input_point: Option<String>,
    band_top: f64,
    sensors: Option<Vec<usize>>,
    input_dof: usize,
) -> PyResult<(
    std::borrow::Cow<'_, tacit::model::Model>,
    Option<Vec<usize>>,
    usize,
)> {
    let Some(mm) = &model.matrix else {
        if points.is_some() || input_point.is_some() {
            return Err(err(format!("points and input_point name points of a model from matrices; {} is not one (give sensors and input_dof)", model.inner.name)));
        }
        return Ok((std::borrow::Cow::Borrowed(&model.inner), sensors, input_dof));
    };
    let name = mm.source.display();
    if sensors.is_some() {
        return Err(err(format!("sensors: {name} is a model from matrices; give the sensor points by label (points=[...])")));
    }
    let (Some(points), Some(input)) = (points, input_point) else {
        return Err(err(format!("{name}: a model from matrices needs points=[...] (the sensors) and input_point=\"...\" (where the force acts)")));
    };
    let mut labels = points.clone();
    labels.push(input.clone());
    let reduced = mm.reduce(&labels, Some(band_top)).map_err(err)?;
    let dof = |l: &str| {
        reduced
            .points
            .iter()
            .position(|p| p == l)
            .map_or(0, |i| i + 1)
    };
    let sensors = points.iter().map(|l| dof(l)).collect();
    let input_dof = dof(&input);
    Ok((std::borrow::Cow::Owned(reduced), Some(sensors), input_dof))
}

/// Modes of the undamped linear part: `(freq_hz, shapes, rigid)` with
/// the frequencies in Hz (ascending), the mass-normalized shapes one
/// column per mode (ndof × ndof) and a flag per rigid-body mode.
#[pyfunction]
pub fn modal<'py>(py: Python<'py>, model: &Model) -> PyResult<ModesOut<'py>> {
    let lin = model.reduced("modal")?.linear_part();
    let modes = tacit::modal::solve(&lin.mass_matrix(), &lin.stiffness_matrix()).map_err(err)?;
    Ok((
        convert::vector(py, &modes.freq_hz),
        convert::matrix(py, &modes.shapes),
        modes.rigid,
    ))
}

/// Identify the internal force the linear part of `model` lacks, with
/// the located, lifted smoother (`tacit identify`'s default). Returns
/// `(summary_json, force, time)`: the summary as `summary.json` holds it,
/// the force per DOF (N, ndof × samples, left-hand side of
/// M a + C v + K u + f = f_ext) and the time of every sample (s).
#[pyfunction]
#[pyo3(signature = (model, record, sensors = None, resolution = 8, noise = 0.01, locate = true, substeps = 10))]
#[allow(clippy::too_many_arguments)]
pub fn identify<'py>(
    py: Python<'py>,
    model: &Model,
    record: &Record,
    sensors: Option<Vec<usize>>,
    resolution: usize,
    noise: f64,
    locate: bool,
    substeps: usize,
) -> PyResult<IdentifyOut<'py>> {
    let mut s = LocatedSettings {
        substeps,
        ..Default::default()
    };
    s.lifted.resolution = resolution;
    s.lifted.noise_fraction = noise;
    if !locate {
        s.locate.ratio = 0.0;
    }
    if model.matrix.is_some() && sensors.is_some() {
        return Err(err("sensors: a model from matrices uses every measured point of the record (leave sensors out)"));
    }
    let reduced = model.for_records(&[&record.inner])?;
    let rec = resolved(&reduced, &record.inner)?;
    let sensors = sensors.unwrap_or_else(|| {
        let mut d: Vec<usize> = rec.outputs.iter().map(|c| c.dof).collect();
        d.sort_unstable();
        d.dedup();
        d
    });
    let (m, rec) = (&*reduced, &rec);
    let est = py
        .detach(|| {
            let prob = Problem::new(&m.linear_part(), rec, &sensors)?;
            identify_located(m, &prob, &s)
        })
        .map_err(err)?;
    if let Some(e) = tacit::identify::finite::error(&est) {
        return Err(err(e));
    }
    let summary = serde_json::to_string(&est.summary()).map_err(err)?;
    Ok((
        summary,
        convert::matrix(py, &est.force),
        convert::vector(py, &est.time),
    ))
}

/// A copy of `rec` with its channels resolved against `model` (a
/// universal file's node and direction: the node on a lumped model).
fn resolved(
    model: &tacit::model::Model,
    rec: &tacit::record::Record,
) -> PyResult<tacit::record::Record> {
    let mut r = rec.clone();
    model.resolve_channels(&mut r).map_err(err)?;
    Ok(r)
}

/// Refuse an output directory that holds something unless `force`.
fn check_output(dir: &Path, force: bool) -> PyResult<()> {
    let busy = std::fs::read_dir(dir).is_ok_and(|mut d| d.next().is_some());
    if busy && !force {
        return Err(err(format!(
            "output directory {} is not empty: give force=True to replace its files",
            dir.display()
        )));
    }
    Ok(())
}

/// The diagnosis of `record` against `model` (as `tacit diagnose`),
/// written into `output` (report.json, report.md, figures, the fitted
/// model). Returns `(paths, fitted_model)`; the Python package reads the
/// report back as a dict.
#[pyfunction]
#[pyo3(signature = (model, record, output, validation = None, sensors = None,
    linear_records = vec![], trust_linear = false, settings = None, force = false))]
#[allow(clippy::too_many_arguments)]
pub fn diagnose(
    py: Python<'_>,
    model: &Model,
    record: &Record,
    output: PathBuf,
    validation: Option<PyRef<'_, Record>>,
    sensors: Option<Vec<usize>>,
    linear_records: Vec<PyRef<'_, Record>>,
    trust_linear: bool,
    settings: Option<PathBuf>,
    force: bool,
) -> PyResult<(Vec<PathBuf>, Model)> {
    check_output(&output, force)?;
    let settings = match settings {
        Some(p) => DiagnoseSettings::from_file(&p).map_err(err)?,
        None => DiagnoseSettings::default(),
    };
    settings.validate().map_err(err)?;
    // a model from matrices is reduced onto the records' points
    let mut all: Vec<&tacit::record::Record> = vec![&record.inner];
    all.extend(validation.as_ref().map(|v| &v.inner));
    all.extend(linear_records.iter().map(|r| &r.inner));
    let reduced = model.for_records(&all)?;
    let linear: Vec<tacit::record::Record> = linear_records
        .iter()
        .map(|r| resolved(&reduced, &r.inner))
        .collect::<PyResult<_>>()?;
    let val = validation
        .as_ref()
        .map(|v| resolved(&reduced, &v.inner))
        .transpose()?;
    let rec = resolved(&reduced, &record.inner)?;
    let (m, rec) = (&*reduced, &rec);
    let cal = calibrated::CalibratedSettings {
        off: trust_linear,
        ..Default::default()
    };
    let meta = meta(model, m, rec, val.as_ref(), sensors.as_deref()).map_err(err)?;
    let (paths, fitted) = py
        .detach(|| -> tacit::error::Result<_> {
            let d = calibrated::diagnose_calibrated(
                m,
                rec,
                val.as_ref(),
                &linear,
                sensors.as_deref(),
                &settings,
                &cal,
                &|_| {},
            )?;
            let mut meta = meta;
            meta.sensors = d.prepared.channels.iter().map(|c| c.1 + 1).collect();
            let mut paths = report::write(&output, &meta, &d, &settings)?;
            if let Some(r) = m.matrices.as_ref().and_then(|l| l.report.as_ref()) {
                let effects: Vec<(String, Vec<usize>)> = d
                    .effects
                    .iter()
                    .map(|e| (e.label.clone(), e.dofs.clone()))
                    .collect();
                tacit::model::matrix::append_report(&output, r, &effects)?;
                paths.push(output.join("reduction.json"));
            }
            Ok((paths, d.model))
        })
        .map_err(err)?;
    Ok((paths, Model::dense(fitted, None)))
}

/// The report header: files (or `<memory>`), the warnings of the record
/// checks against the model (as `tacit diagnose`); an error where a
/// record cannot be used.
fn meta(
    model: &Model,
    reduced: &tacit::model::Model,
    record: &tacit::record::Record,
    val: Option<&tacit::record::Record>,
    sensors: Option<&[usize]>,
) -> tacit::Result<report::Meta> {
    let name = |p: &Path| {
        if p.as_os_str().is_empty() {
            "<memory>".to_string()
        } else {
            p.display().to_string()
        }
    };
    let mut warnings = vec![];
    for r in std::iter::once(record).chain(val) {
        let found = model_checks::warnings(r, reduced, sensors)?;
        warnings.extend(model_checks::labelled(&name(&r.source), &found));
    }
    Ok(report::Meta {
        model: model.path.as_deref().map_or("<memory>".into(), name),
        record: name(&record.source),
        validation_record: val.map(|v| name(&v.source)),
        sensors: vec![],
        tacit_version: env!("CARGO_PKG_VERSION").to_string(),
        warnings,
    })
}
