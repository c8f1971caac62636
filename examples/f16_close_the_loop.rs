//! The F-16 ground vibration test (Noël & Schoukens 2017) closed end to
//! end: a modal model identified from the low-level record, the
//! close-the-loop diagnosis on a high-level record with the linear part
//! calibrated, and the open-loop RMS error per channel (m/s², steady-state
//! periods) before and after on that record and on a validation record.
//! Writes OUT/report.json (`validation.before.rms_per_channel`,
//! `validation.after.rms_per_channel`, the effects found), the linear
//! model OUT/f16-linear.toml and the fitted model OUT/model-fitted.toml.
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
//! cubic). `--jenkins` fits the Level-1 model with a Jenkins element
//! (stick–slip friction) between wing and payload taking part of their
//! coupling spring, on the linear record and the estimation record
//! together, by open-loop output error with finite differences, and
//! scores it per channel and per frequency band on every level file in
//! DIR (report.json `jenkins`, OUT/model-jenkins.toml);
//! `--residual-damping Z|identified` sets the damping ratio of the
//! residual mode above the band in that model (default 0.3),
//! `--jenkins-elements N` puts N Jenkins elements in parallel (an Iwan
//! model; default 1); `--jenkins-direction coordinate|points` puts the
//! element on the interface coordinate (default: an unmeasured point
//! whose participation in every in-band mode is fitted with the slip
//! force, started from the fit of the element between the wing and
//! payload points) or between the wing and payload points;
//! `--max-simulations N` limits the simulations of that fit (default 150
//! for the coordinate, 60 between the points).

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
    jenkins: bool,
    residual_damping: Option<f64>,
    jenkins_elements: usize,
    jenkins_direction: f16::jenkins::Direction,
    max_simulations: Option<usize>,
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
        jenkins: false,
        residual_damping: Some(0.3),
        jenkins_elements: 1,
        jenkins_direction: f16::jenkins::Direction::Coordinate,
        max_simulations: None,
    };
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let mut it = argv.iter();
    while let Some(flag) = it.next() {
        if flag == "--interface-fit" {
            a.interface_fit = true;
            continue;
        }
        if flag == "--jenkins" {
            a.jenkins = true;
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
        if flag == "--jenkins-direction" {
            a.jenkins_direction = match value.as_str() {
                "points" => f16::jenkins::Direction::Points,
                "coordinate" => f16::jenkins::Direction::Coordinate,
                _ => anyhow::bail!("--jenkins-direction {value}: expected points or coordinate"),
            };
            continue;
        }
        if flag == "--max-simulations" {
            a.max_simulations = Some(value.parse()?);
            continue;
        }
        if flag == "--jenkins-elements" {
            a.jenkins_elements = value.parse()?;
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
                "unknown option {flag}: expected --data, --linear, --estimate, --validate, -o"
            ),
        };
        *slot = PathBuf::from(value);
    }
    for p in [&mut a.linear, &mut a.estimate, &mut a.validate] {
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
    let mut settings = f16::Settings {
        calibration: a.calibration,
        ..Default::default()
    };
    if let Some(g) = a.min_gain {
        // the share of the residual an effect must remove to be selected
        // and kept (`trace.min_gain`, `screen.min_improvement`)
        settings.diagnose.trace.min_gain = g;
        settings.diagnose.screen.min_improvement = g;
    }
    let (r, fitted, linear_text) =
        f16::run(&a.linear, &a.estimate, &a.validate, &settings, &|m| {
            eprintln!("{m}")
        })?;
    tacit::io::ensure_dir(&a.out)?;
    std::fs::write(a.out.join("f16-linear.toml"), linear_text)?;
    std::fs::write(a.out.join("model-fitted.toml"), fitted.to_toml_string())?;
    std::fs::write(a.out.join("report.json"), serde_json::to_string_pretty(&r)?)?;
    println!("{}", r.summary());
    let mut json = serde_json::to_value(&r)?;
    if a.interface_fit {
        let levels: Vec<PathBuf> = (1..=7)
            .map(|n| a.data.join(format!("F16Data_FullMSine_Level{n}.mat")))
            .filter(|p| p.exists())
            .collect();
        let refs: Vec<&Path> = levels.iter().map(|p| p.as_path()).collect();
        let (fit, model) = f16::interface_study(
            &a.linear,
            &a.estimate,
            &refs,
            (a.interface_linear, a.interface_damper),
            &settings,
        )?;
        println!(
            "interface fit: k3 {:.4e} N/m^3, c2 {:.4e} N s^2/m^2, c3 {:.4e} N s^3/m^3; {:?} after {} iterations",
            fit.k3, fit.c2, fit.c3, fit.termination, fit.iterations
        );
        for p in &fit.parameters {
            println!(
                "  {}: start {:.4e}, fitted {:.4e} ({:+.1} % of nominal){}",
                p.name,
                p.start,
                p.value,
                p.percent_change,
                if p.at_bound { ", at its bound" } else { "" }
            );
        }
        for (file, before, after) in &fit.errors {
            println!("interface model on {file}: Level-1 model {before:.3?}, interface model {after:.3?} m/s^2");
        }
        std::fs::write(a.out.join("model-interface.toml"), model.to_toml_string())?;
        json["interface_fit"] = serde_json::to_value(&fit)?;
    }
    if a.jenkins {
        json["jenkins"] = jenkins_study(&a, &settings)?;
    }
    std::fs::write(
        a.out.join("report.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    println!("report: {}", a.out.join("report.json").display());
    Ok(())
}

/// The Jenkins interface fitted and scored on every level file; prints its
/// table and writes OUT/model-jenkins.toml.
fn jenkins_study(a: &Args, settings: &f16::Settings) -> anyhow::Result<serde_json::Value> {
    let levels: Vec<PathBuf> = (1..=7)
        .map(|n| a.data.join(format!("F16Data_FullMSine_Level{n}.mat")))
        .filter(|p| p.exists())
        .collect();
    let refs: Vec<&Path> = levels.iter().map(|p| p.as_path()).collect();
    let defaults = f16::jenkins::FitSpec::default();
    let spec = f16::jenkins::FitSpec {
        direction: a.jenkins_direction,
        max_simulations: a.max_simulations.unwrap_or(match a.jenkins_direction {
            f16::jenkins::Direction::Points => defaults.max_simulations,
            f16::jenkins::Direction::Coordinate => 150,
        }),
        upper_residual_damping: a.residual_damping,
        elements: a.jenkins_elements,
        substeps: settings.substeps,
        warm_up: settings.warm_up,
        ..defaults
    };
    let (st, model) = f16::jenkins::study(&a.linear, &a.estimate, &refs, &spec, settings)?;
    let f = &st.fitted;
    println!(
        "jenkins interface {}-{}: k_J {:.4e} N/m of the coupling {:.4e} N/m, slip force {:.4e} N \
         (slip at {:.3e} m), {} element(s); cost {:.4} -> {:.4}, {} after {} simulations, {:.1} s",
        f.points[0],
        f.points[1],
        f.stiffness,
        f.coupling,
        f.slip_force,
        f.slip_displacement,
        f.elements,
        f.cost.0,
        f.cost.1,
        f.termination,
        f.simulations,
        f.seconds
    );
    for (hz, d) in &f.participations {
        println!("  interface participation of the {hz:.2}-Hz mode: {d:+.4}");
    }
    println!(
        "  stuck modes {:.3?} Hz\n  slipped modes {:.3?} Hz",
        f.stuck_hz, f.slipped_hz
    );
    if let Some(p) = &st.pair {
        println!(
            "  started from the pair's element: k_J {:.4e} N/m, slip force {:.4e} N",
            p.stiffness, p.slip_force
        );
    }
    for x in &st.scores {
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
    std::fs::write(a.out.join("model-jenkins.toml"), model.to_toml_string())?;
    Ok(serde_json::to_value(&st)?)
}
