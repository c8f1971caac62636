//! The F-16 ground vibration test (Noël & Schoukens 2017) closed end to
//! end: a modal model identified from the low-level record, the
//! close-the-loop diagnosis on a high-level record with the linear part
//! calibrated, and the open-loop RMS error per channel (m/s², steady-state
//! periods) before and after on that record and on a validation record.
//! Writes OUT/report.json (`validation.before.rms_per_channel`: the
//! Level-1 model; `validation.after.rms_per_channel`: the model after;
//! `effects_found` with the points each joins), the linear model
//! OUT/f16-linear.toml and the model after OUT/model-fitted.toml.
//!
//! `cargo run --release --example f16_close_the_loop -- --data DIR
//! --linear FILE --estimate FILE --validate FILE -o OUT`
//!
//! Defaults: the shared data set beside the checkout, Level 1, Level 7,
//! Level 5, out/f16_close_the_loop. A FILE that does not exist as given is
//! looked up in DIR. `--calibration reidentify|diagnosis` chooses how the
//! linear part is calibrated on the estimation record (default
//! reidentify: the modal model identified again at that level);
//! `--min-gain G` sets the share of the residual an effect must remove to
//! be selected and kept (default the diagnosis's 0.05); `--interface-fit`
//! also fits the Level-1 model with a cubic spring and a damper
//! between wing and payload by open-loop output error on the estimation
//! record and scores it on every level file in DIR (report.json
//! `interface_fit`, OUT/model-interface.toml); `--interface-linear
//! held|free` holds the Level-1 linear part (default) or fits the
//! coupling spring and the wing bending and torsion damping with it;
//! `--interface-damper quadratic|cubic` chooses the damper's law (default
//! cubic).
//!
//! By default the interface candidate of `tacit::diagnose::interface`
//! is fitted on the linear and the estimation record (and the
//! `--also-estimate` files): a Jenkins element between the pair the trace
//! located, then on the interface as a coordinate of its own, then (with
//! `--interface-elements N`, default 4; 1: none) an Iwan model there, then
//! (`--softening SHARE|none`, default 0.2: the start of `k_e / k_J`) the
//! slider with an elastic softening (a saturating spring) on the same
//! coordinate; every model (the
//! Level-1 model, the diagnosed model, the interface models) is ranked by
//! the open-loop error on the estimation records, and the first is the
//! model after (report.json `after_model`, `effects_found`, `interface`;
//! OUT/restoring_interface.png/.svg the interface force against its
//! displacement and the relative motion of the pair). `--no-interface`
//! leaves the diagnosed model as the model after; `--max-simulations N`
//! limits the coordinate fits (default 150); `--residual-damping
//! Z|identified` sets the damping ratio of the residual mode above the
//! band in the interface models (default 0.3); `--also-estimate FILE`
//! (repeatable) adds an estimation record; `--levels` scores every ranked
//! model per channel and per frequency band on every level file in DIR
//! (report.json `levels`).

use std::path::{Path, PathBuf};
use tacit::cases::f16;

struct Args {
    data: PathBuf,
    linear: PathBuf,
    estimate: PathBuf,
    validate: PathBuf,
    out: PathBuf,
    calibration: f16::Calibration,
    min_gain: Option<f64>,
    interface_fit: bool,
    interface_linear: f16::LinearPart,
    interface_damper: f16::Damper,
    interface: bool,
    residual_damping: Option<f64>,
    interface_elements: usize,
    softening: Option<f64>,
    max_simulations: Option<usize>,
    also_estimate: Vec<PathBuf>,
    levels: bool,
}

fn args() -> anyhow::Result<Args> {
    let mut a = Args {
        data: Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/f16"),
        linear: "F16Data_FullMSine_Level1.mat".into(),
        estimate: "F16Data_FullMSine_Level7.mat".into(),
        validate: "F16Data_FullMSine_Level5.mat".into(),
        out: "out/f16_close_the_loop".into(),
        calibration: f16::Calibration::Reidentify,
        min_gain: None,
        interface_fit: false,
        interface_linear: f16::LinearPart::Held,
        interface_damper: f16::Damper::Cubic,
        interface: true,
        residual_damping: Some(0.3),
        interface_elements: 4,
        softening: Some(0.2),
        max_simulations: None,
        also_estimate: vec![],
        levels: false,
    };
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let mut it = argv.iter();
    while let Some(flag) = it.next() {
        if flag == "--interface-fit" {
            a.interface_fit = true;
            continue;
        }
        if flag == "--no-interface" {
            a.interface = false;
            continue;
        }
        if flag == "--levels" {
            a.levels = true;
            continue;
        }
        let value = it
            .next()
            .ok_or_else(|| anyhow::anyhow!("{flag} needs a value"))?;
        if flag == "--residual-damping" {
            a.residual_damping = match value.as_str() {
                "identified" => None,
                v => Some(v.parse().map_err(|e| {
                    anyhow::anyhow!("--residual-damping {v}: {e} (a ratio or identified)")
                })?),
            };
            continue;
        }
        if flag == "--also-estimate" {
            a.also_estimate.push(value.into());
            continue;
        }
        if flag == "--max-simulations" {
            a.max_simulations = Some(value.parse()?);
            continue;
        }
        if flag == "--softening" {
            a.softening = match value.as_str() {
                "none" => None,
                v => Some(v.parse().map_err(|e| {
                    anyhow::anyhow!("--softening {v}: {e} (a share of k_J or none)")
                })?),
            };
            continue;
        }
        if flag == "--interface-elements" {
            a.interface_elements = value
                .parse()
                .map_err(|e| anyhow::anyhow!("--interface-elements {value}: {e}"))?;
            continue;
        }
        if flag == "--min-gain" {
            a.min_gain = Some(value.parse()?);
            continue;
        }
        if flag == "--interface-linear" {
            a.interface_linear = match value.as_str() {
                "held" => f16::LinearPart::Held,
                "free" => f16::LinearPart::Free,
                _ => anyhow::bail!("--interface-linear {value}: expected held or free"),
            };
            continue;
        }
        if flag == "--interface-damper" {
            a.interface_damper = match value.as_str() {
                "quadratic" => f16::Damper::Quadratic,
                "cubic" => f16::Damper::Cubic,
                _ => anyhow::bail!("--interface-damper {value}: expected quadratic or cubic"),
            };
            continue;
        }
        if flag == "--calibration" {
            a.calibration = match value.as_str() {
                "reidentify" => f16::Calibration::Reidentify,
                "diagnosis" => f16::Calibration::Diagnosis,
                _ => anyhow::bail!("--calibration {value}: expected reidentify or diagnosis"),
            };
            continue;
        }
        let slot = match flag.as_str() {
            "--data" => &mut a.data,
            "--linear" => &mut a.linear,
            "--estimate" => &mut a.estimate,
            "--validate" => &mut a.validate,
            "-o" | "--output" => &mut a.out,
            _ => anyhow::bail!(
                "unknown option {flag}: expected --data, --linear, --estimate, --validate, -o \
                 or an option of the module documentation"
            ),
        };
        *slot = PathBuf::from(value);
    }
    let files = [&mut a.linear, &mut a.estimate, &mut a.validate];
    for p in files.into_iter().chain(a.also_estimate.iter_mut()) {
        if !p.exists() {
            *p = a.data.join(&*p);
        }
        if !p.exists() {
            anyhow::bail!("{}: no such file", p.display());
        }
    }
    Ok(a)
}

fn main() -> anyhow::Result<()> {
    let a = args()?;
    let settings = settings(&a)?;
    let out = f16::run(&a.linear, &a.estimate, &a.validate, &settings, &|m| {
        eprintln!("{m}")
    })?;
    let r = &out.result;
    tacit::io::ensure_dir(&a.out)?;
    std::fs::write(a.out.join("f16-linear.toml"), &out.linear_text)?;
    std::fs::write(a.out.join("model-fitted.toml"), out.after.to_toml_string())?;
    if let Some(rf) = &out.restoring {
        let fig = tacit::diagnose::interface::restoring_figure(
            rf,
            &format!("restoring force of the interface ({})", r.after_model),
        );
        tacit::plot::save(&fig, &a.out.join("restoring_interface"))?;
    }
    println!("{}", r.summary());
    let mut json = serde_json::to_value(r)?;
    if let Some(rf) = &out.restoring {
        json["restoring_interface"] = serde_json::json!({
            "record": rf.record,
            "pair": rf.pair,
            "slip_force": rf.slip_force,
            "follows": rf.follows,
            "figure": "restoring_interface.svg",
        });
    }
    if a.interface_fit {
        json["interface_fit"] = cubic_study(&a, &settings)?;
    }
    if a.levels {
        json["levels"] = levels(&a, &out, &settings)?;
    }
    std::fs::write(
        a.out.join("report.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    println!("report: {}", a.out.join("report.json").display());
    Ok(())
}

/// The case's settings from the options.
fn settings(a: &Args) -> anyhow::Result<f16::Settings> {
    let mut s = f16::Settings {
        calibration: a.calibration,
        also_estimate: a.also_estimate.clone(),
        ..Default::default()
    };
    if let Some(g) = a.min_gain {
        // the share of the residual an effect must remove to be selected
        // and kept (`trace.min_gain`, `screen.min_improvement`)
        s.diagnose.trace.min_gain = g;
        s.diagnose.screen.min_improvement = g;
    }
    s.interface = match a.interface {
        false => None,
        true => {
            let mut o = tacit::diagnose::interface::OfferSettings::default();
            if let Some(n) = a.max_simulations {
                o.spec.max_simulations = n;
            }
            o.spec.upper_residual_damping = a.residual_damping;
            o.iwan = Some(a.interface_elements).filter(|&n| n > 1);
            o.softening = a.softening;
            Some(o)
        }
    };
    Ok(s)
}

/// The level files in DIR.
fn level_files(a: &Args) -> Vec<PathBuf> {
    (1..=7)
        .map(|n| a.data.join(format!("F16Data_FullMSine_Level{n}.mat")))
        .filter(|p| p.exists())
        .collect()
}

/// Every ranked model scored per channel and per band on every level file.
fn levels(a: &Args, out: &f16::Outputs, s: &f16::Settings) -> anyhow::Result<serde_json::Value> {
    let l1 = &out.models[0].1;
    let mut recs = vec![];
    for p in level_files(a) {
        let mut r = f16::read(&p)?;
        l1.resolve_channels(&mut r)?;
        recs.push(r);
    }
    let refs: Vec<&tacit::record::Record> = recs.iter().collect();
    let models: Vec<(&str, &tacit::model::Model)> =
        out.models.iter().map(|(n, m)| (n.as_str(), m)).collect();
    let scores = f16::score(&models, &refs, s.warm_up, s.substeps)?;
    for x in &scores {
        let file = Path::new(&x.record)
            .file_name()
            .map_or(x.record.clone(), |n| n.to_string_lossy().into_owned());
        println!(
            "  {file} {:<40} {:.3?} m/s^2; per band {:?}: {:.3?}",
            x.model,
            x.rms_per_channel,
            f16::BANDS_HZ,
            x.rms_per_band
        );
    }
    Ok(serde_json::to_value(&scores)?)
}

/// The cubic-spring-and-damper interface fitted on the estimation record
/// and scored on every level file; writes OUT/model-interface.toml.
fn cubic_study(a: &Args, settings: &f16::Settings) -> anyhow::Result<serde_json::Value> {
    let levels = level_files(a);
    let refs: Vec<&Path> = levels.iter().map(|p| p.as_path()).collect();
    let (fit, model) = f16::interface_study(
        &a.linear,
        &a.estimate,
        &refs,
        (a.interface_linear, a.interface_damper),
        settings,
    )?;
    println!(
        "interface fit: k3 {:.4e} N/m^3, c2 {:.4e} N s^2/m^2, c3 {:.4e} N s^3/m^3; {:?} after {} iterations",
        fit.k3, fit.c2, fit.c3, fit.termination, fit.iterations
    );
    for (file, before, after) in &fit.errors {
        println!("interface model on {file}: Level-1 model {before:.3?}, interface model {after:.3?} m/s^2");
    }
    std::fs::write(a.out.join("model-interface.toml"), model.to_toml_string())?;
    Ok(serde_json::to_value(&fit)?)
}
