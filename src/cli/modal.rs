//! `tacit modal`: natural frequencies and mode shapes of a model; with
//! `--test-modes` or `--record`, test-analysis correlation against test
//! modes (MAC, pairing, frequency error: the paper's Tables 2–3) and, with
//! `--update`, modal updating of the spring stiffnesses (Figs 2–3); with
//! `--record ... --write-model FILE` and no model, a modal model identified
//! from the records ([`tacit::correlate::modelfit`]).

use super::out::{out, outln};
use super::{check, DofList};
use std::path::{Path, PathBuf};
use tacit::correlate::{
    self, report, CorrelationSettings, Expansion, FitSettings, FrfSettings, Residue, TestModes,
    UpdateSettings, Window,
};
use tacit::model::Model;

/// Arguments of `tacit modal`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file (TOML); not needed with `--write-model`.
    #[arg(long, required_unless_present = "write_model")]
    model: Option<PathBuf>,
    /// Identify a linear modal model from the records (`--record`, one
    /// force at a measured point, accelerations) and write it to this
    /// file: the modes in `--band`, mass-normalised through the driving
    /// point, residual modes where they matter, the measured points named.
    #[arg(long, value_name = "FILE", requires = "record", conflicts_with_all = ["model", "test_modes", "update"])]
    write_model: Option<PathBuf>,
    /// FRF window for `--write-model`: hann (random excitation, 50 %
    /// overlap) or rectangular (periodic excitation with a segment of
    /// whole periods, no overlap).
    #[arg(long, value_parser = parse_window, requires = "write_model", value_name = "hann|rectangular")]
    window: Option<Window>,
    /// Curve-fit orders for `--write-model`, as `lo,hi` (default 8,48).
    #[arg(long, value_parser = super::parse_pair, requires = "write_model", value_name = "LO,HI")]
    orders: Option<(f64, f64)>,
    /// Warm-up left out of every record for `--write-model`: samples
    /// (`8192`) or seconds (`20.48s`).
    #[arg(long, value_name = "SAMPLES|SECONDS", value_parser = tacit::record::WarmUp::parse, requires = "write_model")]
    warm_up: Option<tacit::record::WarmUp>,
    #[command(flatten)]
    rec: super::RecordOpts,
    /// Print JSON instead of tables.
    #[arg(long)]
    json: bool,
    /// Test modes to correlate with the model (TOML: `dofs`, then
    /// `[[mode]]` tables with `frequency_hz`, `damping`, `shape`; see
    /// docs/modal.md).
    #[arg(long, conflicts_with = "record")]
    test_modes: Option<PathBuf>,
    /// Record(s) with a force input and accelerations (HDF5 or CSV) to
    /// identify test modes from (H1 averaged over all of them, then an
    /// LSCF/LSFD curve fit). Repeat for several records.
    #[arg(long)]
    record: Vec<PathBuf>,
    /// Accelerometer DOFs used from the record(s), numbered from 1, e.g.
    /// `1-8` or `1,4,7` (default: every acceleration channel of the first
    /// record).
    #[arg(long, requires = "record", value_name = "DOFS")]
    sensors: Option<DofList>,
    /// DOF of the input force, from 1 (default: the record's only force
    /// channel).
    #[arg(long, requires = "record", value_name = "DOF")]
    input_dof: Option<usize>,
    /// Curve-fit band, Hz, as `lo,hi` below the Nyquist frequency
    /// (default 5,150).
    #[arg(long, value_parser = super::parse_pair, requires = "record", value_name = "LO,HI")]
    band: Option<(f64, f64)>,
    /// FRF segment length in samples, 16 to the record's length (default
    /// 2048).
    #[arg(long, requires = "record", value_name = "SAMPLES")]
    segment: Option<usize>,
    /// Correlate (and update with) the first N test modes only (N >= 1).
    #[arg(long, value_name = "N")]
    modes: Option<usize>,
    /// Correlate at these DOFs only (a subset of the measured ones,
    /// numbered from 1), e.g. `1,4,7`.
    #[arg(long, value_name = "DOFS")]
    dofs: Option<DofList>,
    /// Update the spring stiffnesses by minimising modal residues:
    /// `force` (force residues) or `hybrid` (hybrid residues).
    #[arg(long, value_parser = parse_residue, value_name = "force|hybrid")]
    update: Option<Residue>,
    /// Expansion of the test shapes to unmeasured DOFs for `--update`:
    /// `serep` or `dynamic`.
    #[arg(long, value_parser = parse_expansion, default_value = "serep", value_name = "serep|dynamic")]
    expansion: Expansion,
    /// Write figures (MAC matrix, stiffness adjustments) as
    /// `<STEM>_mac.{png,svg}` and `<STEM>_update.{png,svg}`.
    #[arg(long, value_name = "STEM")]
    plot: Option<PathBuf>,
    /// Write the test modes (identified or read) to this TOML file.
    #[arg(long, value_name = "FILE")]
    save_test_modes: Option<PathBuf>,
    /// Write the updated model to this TOML file (with `--update`).
    #[arg(long, requires = "update", value_name = "FILE")]
    save_model: Option<PathBuf>,
    /// Model from matrices without a record: the full model's modes up to
    /// this frequency, Hz (default: the model file's [reduction]
    /// cutoff_hz).
    #[arg(long, value_name = "HZ", conflicts_with = "record")]
    up_to: Option<f64>,
    /// Model from matrices without a record: the points (labels,
    /// comma-separated) at which to give the mode shapes, e.g.
    /// n20:uy,n100:uy (default: none, frequencies only).
    #[arg(
        long,
        value_name = "LABELS",
        value_delimiter = ',',
        conflicts_with = "record"
    )]
    points: Option<Vec<String>>,
}

fn parse_window(s: &str) -> Result<Window, String> {
    match s {
        "hann" => Ok(Window::Hann),
        "rectangular" | "rect" => Ok(Window::Rectangular),
        _ => Err(format!("'{s}': expected hann or rectangular")),
    }
}

fn parse_residue(s: &str) -> Result<Residue, String> {
    s.parse()
}

fn parse_expansion(s: &str) -> Result<Expansion, String> {
    s.parse()
}

#[derive(serde::Serialize)]
struct ModeOut {
    mode: usize,
    frequency_hz: f64,
    rigid: bool,
    shape: Vec<f64>,
}

/// Run `tacit modal`.
pub fn run(a: Args) -> anyhow::Result<()> {
    if let Some(out) = &a.write_model {
        return write_model(&a, out);
    }
    let path = a
        .model
        .as_ref()
        .expect("clap requires --model without --write-model");
    let from_matrices = tacit::model::matrix::is_matrix_file(path)?;
    if from_matrices {
        matrix_options(&a, path)?;
        if a.record.is_empty() {
            return full_model_modes(&a, path);
        }
    } else if a.up_to.is_some() || a.points.is_some() {
        anyhow::bail!(
            "--up-to and --points: {} is not a model from matrices (its modes are all listed without them)",
            path.display()
        );
    }
    let model = if from_matrices {
        // reduced onto the records' points, its cut-off set by their band
        let mut recs = a
            .record
            .iter()
            .map(|p| super::read_record(p))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let mut refs: Vec<&mut tacit::record::Record> = recs.iter_mut().collect();
        Model::load(path, &mut refs)?
    } else {
        Model::from_file(path)?
    };
    if a.test_modes.is_none() && a.record.is_empty() {
        if a.update.is_some() || a.dofs.is_some() || a.modes.is_some() {
            anyhow::bail!("--update, --dofs and --modes need --test-modes or --record");
        }
        return model_modes(&model, a.json);
    }
    let (test, fit_doc) = test_modes(&a, &model)?;
    let mut test = match &a.dofs {
        Some(d) => {
            super::check_dofs(&d.0, model.ndof(), "--dofs")?;
            test.restrict(&d.0)?
        }
        None => test,
    };
    if let Some(n) = a.modes {
        if n == 0 {
            anyhow::bail!("--modes must be >= 1");
        }
        test = test.first(n);
    }
    if let Some(p) = &a.save_test_modes {
        super::output::save_text(p, &test.to_toml_string())?;
    }
    let modes = tacit::modal::solve(&model.mass_matrix(), &model.stiffness_matrix())?;
    let corr = correlate::correlate(&test, &modes, &CorrelationSettings::default())?;
    let update = match a.update {
        Some(res) => {
            let s = UpdateSettings::new(res).with_expansion(a.expansion.clone());
            let r = correlate::update_stiffness(&model, &test, &s)?;
            let m2 = &r.model;
            let modes2 = tacit::modal::solve(&m2.mass_matrix(), &m2.stiffness_matrix())?;
            let after = correlate::correlate(&test, &modes2, &CorrelationSettings::default())?;
            if let Some(p) = &a.save_model {
                super::output::save_text(p, &m2.to_toml_string())?;
            }
            Some((r, after))
        }
        None => None,
    };
    if let Some(stem) = &a.plot {
        write_plots(stem, &corr, &test, &model, update.as_ref().map(|u| &u.0))?;
    }
    if a.json {
        #[derive(serde::Serialize)]
        struct Doc<'a> {
            model: &'a str,
            #[serde(skip_serializing_if = "Option::is_none")]
            points: Option<Vec<String>>,
            #[serde(skip_serializing_if = "Option::is_none")]
            reduction: Option<&'a tacit::model::matrix::ReductionReport>,
            test_modes: &'a TestModes,
            fit: Option<serde_json::Value>,
            correlation: &'a correlate::Correlation,
            update: Option<&'a correlate::UpdateResult>,
            correlation_after_update: Option<&'a correlate::Correlation>,
        }
        let doc = Doc {
            model: &model.name,
            points: (!model.points.is_empty())
                .then(|| test.dofs.iter().map(|&d| model.dof_name(d)).collect()),
            reduction: reduction(&model),
            test_modes: &test,
            fit: fit_doc,
            correlation: &corr,
            update: update.as_ref().map(|u| &u.0),
            correlation_after_update: update.as_ref().map(|u| &u.1),
        };
        outln!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(());
    }
    outln!(
        "test modes: {} ({} modes at DOFs {:?}{})",
        test.name,
        test.modes.len(),
        test.dofs,
        if test.mass_normalized {
            ", mass-normalized"
        } else {
            ""
        }
    );
    if !model.points.is_empty() {
        let at: Vec<String> = test
            .dofs
            .iter()
            .map(|&d| format!("{d} = {}", model.dof_name(d)))
            .collect();
        outln!("measured points (DOF = label): {}", at.join(", "));
    }
    if let Some(r) = reduction(&model) {
        outln!("{}", reduction_line(r));
    }
    out!("{}", report::modes_table(&[(test.name.as_str(), &test)]));
    outln!("\ncorrelation with model {} (before updating)", model.name);
    out!("{}", report::correlation_table(&corr, None));
    if let Some((r, after)) = &update {
        outln!(
            "\nstiffness updating: {:?} residues, {:?} expansion",
            r.residue,
            r.expansion
        );
        out!("{}", report::adjustment_table(&[("change", r)]));
        outln!("\ncorrelation with the updated model");
        out!("{}", report::correlation_table(after, None));
    }
    Ok(())
}

/// Identify a modal model from the records and write it.
fn write_model(a: &Args, out: &Path) -> anyhow::Result<()> {
    let mut recs = Vec::with_capacity(a.record.len());
    for p in &a.record {
        let r = super::load_record(p, &a.rec)?;
        let mut r = match a.warm_up {
            Some(w) => r.without_warm_up(w)?,
            None => r,
        };
        r.source = p.clone();
        recs.push(r);
    }
    let window = a.window.unwrap_or_default();
    let mut frf = FrfSettings {
        window,
        overlap: if window == Window::Rectangular {
            0.0
        } else {
            0.5
        },
        ..Default::default()
    };
    let mut fit = segment_and_band(a, &recs, &mut frf)?;
    if let Some((lo, hi)) = a.orders {
        let ok = |v: f64| v.fract() == 0.0 && (2.0..=200.0).contains(&v);
        if !(ok(lo) && ok(hi) && lo <= hi) {
            anyhow::bail!("--orders {lo},{hi}: whole numbers with 2 <= lo <= hi <= 200");
        }
        fit.orders = (lo as usize, hi as usize);
    }
    let settings = correlate::modelfit::ModelFitSettings {
        frf,
        fit,
        residuals: true,
    };
    let id = correlate::modelfit::identify_model(&recs, &settings)?;
    for d in &id.diagnostics {
        eprintln!("tacit: note: {d}");
    }
    let names: Vec<String> = a.record.iter().map(|p| p.display().to_string()).collect();
    let description = format!(
        "identified by tacit modal from {} ({} averages, band {:?} Hz)",
        names.join(", "),
        id.frf.averages,
        fit.band_hz
    );
    let name = out
        .file_stem()
        .map_or("modal".into(), |s| s.to_string_lossy().to_string());
    let text = tacit::model::modal::to_toml_string(&name, &description, &id.section);
    // the file must load as a model before it is written
    tacit::model::modal::from_toml_str(&text, &out.display().to_string())?;
    super::output::save_text(out, &text)?;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&id)?);
        return Ok(());
    }
    outln!(
        "modal model: {} ({} points: {})",
        out.display(),
        id.section.points.len(),
        id.section.points.join(", ")
    );
    outln!(
        "{:>4} {:>10} {:>9}  shape at the points (mass-normalised)",
        "mode",
        "freq (Hz)",
        "damping"
    );
    for (r, m) in id.section.modes.iter().enumerate() {
        let shape: Vec<String> = m.shape.iter().map(|v| format!("{v:>10.4e}")).collect();
        let tag = if m.residual { "  (residual)" } else { "" };
        outln!(
            "{:>4} {:>10.4} {:>9.4}  {}{tag}",
            r + 1,
            m.frequency_hz,
            m.damping,
            shape.join(" ")
        );
    }
    let pct: Vec<String> = id
        .fit_error
        .iter()
        .map(|e| format!("{:.2} %", 100.0 * e))
        .collect();
    outln!("FRF fit error per point: {}", pct.join(", "));
    Ok(())
}

/// `--segment` (checked against the shortest record) into `frf`; the
/// curve-fit settings with `--band` (checked against the first record's
/// Nyquist frequency).
fn segment_and_band(
    a: &Args,
    recs: &[tacit::record::Record],
    frf: &mut FrfSettings,
) -> anyhow::Result<FitSettings> {
    if let Some(s) = a.segment {
        let shortest = recs.iter().map(|r| r.len()).min().unwrap_or(0);
        check::count(
            "--segment",
            s,
            16,
            shortest.max(16),
            "FRF segment length, samples, at most the record's length",
        )?;
        frf.segment = s;
    }
    let mut fit = FitSettings::default();
    if let Some(b) = a.band {
        check::band("--band", b, recs[0].fs)?;
        fit.band_hz = b;
    }
    Ok(fit)
}

/// Test modes from a file or identified from records; the curve-fit
/// summary for JSON.
fn test_modes(a: &Args, model: &Model) -> anyhow::Result<(TestModes, Option<serde_json::Value>)> {
    if let Some(p) = &a.test_modes {
        return Ok((TestModes::from_file(p, model.ndof())?, None));
    }
    let mut recs = Vec::with_capacity(a.record.len());
    for p in &a.record {
        let mut r = super::read_record_for(p, model)?;
        r.validate(Some(model.ndof()))?;
        r.source = p.clone();
        recs.push(r);
    }
    let sensors: Vec<usize> = match &a.sensors {
        Some(d) => d.0.clone(),
        None => {
            let mut d: Vec<usize> = recs[0]
                .outputs
                .iter()
                .filter(|c| c.quantity == tacit::record::Quantity::Accel)
                .map(|c| c.dof)
                .collect();
            d.sort_unstable();
            d.dedup();
            if d.is_empty() {
                anyhow::bail!(
                    "{}: no acceleration channel to identify modes from",
                    a.record[0].display()
                );
            }
            d
        }
    };
    super::check_dofs(&sensors, model.ndof(), "--sensors")?;
    for r in &recs {
        super::records::check(r, model, Some(&sensors))?;
    }
    let mut frf = FrfSettings::default();
    let fit = segment_and_band(a, &recs, &mut frf)?;
    if let Some(d) = a.input_dof {
        super::check_dofs(&[d], model.ndof(), "--input-dof")?;
    }
    let id = correlate::identify_records(&recs, a.input_dof, &sensors, &frf, &fit)?;
    for d in &id.fit.diagnostics {
        eprintln!("tacit: note: {d}");
    }
    let name = format!(
        "identified from {} record(s), {} averages",
        recs.len(),
        id.frf.averages
    );
    let t = id.fit.test_modes(&name, model.ndof())?;
    let doc = serde_json::json!({
        "status": id.fit.status,
        "averages": id.frf.averages,
        "support": id.fit.support,
        "fit_error": id.fit.fit_error,
        "diagnostics": id.fit.diagnostics,
    });
    Ok((t, Some(doc)))
}

fn write_plots(
    stem: &Path,
    corr: &correlate::Correlation,
    test: &TestModes,
    model: &Model,
    update: Option<&correlate::UpdateResult>,
) -> anyhow::Result<()> {
    if let Some(dir) = stem.parent().filter(|d| !d.as_os_str().is_empty()) {
        tacit::io::ensure_dir(dir)?;
    }
    let fig = report::mac_figure("MAC: test vs model", corr, &test.name, &model.name);
    tacit::plot::save(&fig, &append(stem, "_mac"))?;
    if let Some(r) = update {
        let fig = report::adjustment_figure(
            &format!("Stiffness adjustments ({:?} residues)", r.residue),
            &[(format!("{:?}", r.residue), r)],
        );
        tacit::plot::save(&fig, &append(stem, "_update"))?;
    }
    Ok(())
}

/// `stem` with `suffix` appended to its file name.
fn append(stem: &Path, suffix: &str) -> PathBuf {
    let mut name = stem.file_name().unwrap_or_default().to_os_string();
    name.push(suffix);
    stem.with_file_name(name)
}

/// The model's own modes (no test data).
fn model_modes(model: &Model, json: bool) -> anyhow::Result<()> {
    let modes = tacit::modal::solve(&model.mass_matrix(), &model.stiffness_matrix())?;
    let n = model.ndof();
    let out: Vec<ModeOut> = (0..n)
        .map(|r| {
            let col = modes.shapes.column(r);
            let scale = col.amax().max(f64::MIN_POSITIVE);
            ModeOut {
                mode: r + 1,
                frequency_hz: modes.freq_hz[r],
                rigid: modes.rigid[r],
                shape: col.iter().map(|x| x / scale).collect(),
            }
        })
        .collect();
    if json {
        #[derive(serde::Serialize)]
        struct Doc<'a> {
            model: &'a str,
            ndof: usize,
            modes: &'a [ModeOut],
        }
        let doc = Doc {
            model: &model.name,
            ndof: n,
            modes: &out,
        };
        outln!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(());
    }
    outln!(
        "model {} ({} DOFs), undamped modes, shapes scaled to max |φ| = 1",
        model.name,
        n
    );
    out!("{:>4} {:>10}  ", "mode", "freq (Hz)");
    for d in 1..=n {
        out!("{:>7}", format!("dof{d}"));
    }
    outln!();
    for m in &out {
        let f = if m.rigid {
            "rigid".to_string()
        } else {
            format!("{:.3}", m.frequency_hz)
        };
        out!("{:>4} {:>10}  ", m.mode, f);
        for x in &m.shape {
            out!("{x:>7.3}");
        }
        outln!();
    }
    Ok(())
}

/// The reduction of a model from matrices, if the model is one.
fn reduction(model: &Model) -> Option<&tacit::model::matrix::ReductionReport> {
    model.matrices.as_ref().and_then(|l| l.report.as_ref())
}

/// The reduction in one paragraph: size, kept points, the full model's
/// frequencies in the check against the reduced ones.
fn reduction_line(r: &tacit::model::matrix::ReductionReport) -> String {
    let f: Vec<String> = r
        .frequencies
        .iter()
        .map(|c| format!("{:.3} ({:.3})", c.full_hz, c.reduced_hz))
        .collect();
    format!(
        "model reduced (Craig–Bampton): {} DOFs → {} points + {} modes up to {:.1} Hz; full (reduced) model frequencies up to {:.1} Hz: {}; largest error {:.3} %",
        r.full_dofs,
        r.kept.len(),
        r.modal_coordinates,
        r.cutoff_hz,
        r.check_up_to_hz,
        f.join(", "),
        100.0 * r.max_error
    )
}

/// Options that take DOF numbers or update springs, refused on a model
/// from matrices; the error names the option.
fn matrix_options(a: &Args, path: &Path) -> anyhow::Result<()> {
    let p = path.display();
    if a.test_modes.is_some() {
        anyhow::bail!("--test-modes: {p} is a model from matrices, reduced onto the points of a record; give the record (--record) to identify the test modes at its points");
    }
    if a.update.is_some() {
        anyhow::bail!("--update: modal updating corrects the springs of a lumped model; {p} is a model from matrices (for its stiffness use `tacit update --free stiffness_scale`)");
    }
    let by_dof = [
        ("--sensors", a.sensors.is_some()),
        ("--input-dof", a.input_dof.is_some()),
        ("--dofs", a.dofs.is_some()),
    ];
    if let Some((opt, _)) = by_dof.iter().find(|o| o.1) {
        anyhow::bail!("{opt}: {p} is a model from matrices, whose DOFs are the record's points after the reduction; leave {opt} out (every acceleration channel and the record's force are used, named by point)");
    }
    Ok(())
}

/// A model from matrices without a record: the full model's modes up to
/// `--up-to` (or the file's cut-off), shapes at `--points`.
fn full_model_modes(a: &Args, path: &Path) -> anyhow::Result<()> {
    let mm = tacit::model::matrix::MatrixModel::from_file(path)?;
    let top = match (a.up_to, mm.reduction.cutoff_hz) {
        (Some(f), _) | (None, Some(f)) => f,
        (None, None) => anyhow::bail!(
            "{}: a model from matrices has more modes than can be listed; give --up-to HZ (or a record with --record)",
            path.display()
        ),
    };
    check::positive("--up-to", top, 1e7, "frequency, Hz")?;
    let points = a.points.clone().unwrap_or_default();
    let modes = mm.full_modes(top, 1000, &points)?;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&modes)?);
        return Ok(());
    }
    outln!(
        "model {} ({} DOFs), full model, undamped modes up to {top} Hz{}{}",
        path.display(),
        mm.n,
        if modes.complete {
            ""
        } else {
            " (stopped at 1000 modes)"
        },
        if points.is_empty() {
            String::new()
        } else {
            ", mass-normalised shapes at the points".into()
        }
    );
    out!("{:>4} {:>10}  ", "mode", "freq (Hz)");
    for p in &points {
        out!("{p:>11}");
    }
    outln!();
    for (r, f) in modes.freq_hz.iter().enumerate() {
        out!("{:>4} {f:>10.4}  ", r + 1);
        for x in &modes.shapes[r] {
            out!("{x:>11.4e}");
        }
        outln!();
    }
    Ok(())
}
