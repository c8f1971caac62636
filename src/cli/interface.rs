//! `tacit diagnose --interface`: the interface candidate of
//! [`tacit::diagnose::interface`] offered after the diagnosis of a modal
//! model, ranked with the declared and the diagnosed model by the
//! open-loop error on the estimation records (the record and every
//! `--linear-record`), and written beside the diagnosis's report:
//! `interface.json`, `interface.md`, `model-interface.toml` (the best
//! interface model) and `restoring_interface.png`/`.svg`.

use super::out::outln;
use super::RecordOpts;
use std::path::{Path, PathBuf};
use tacit::diagnose::{interface, Diagnosis};
use tacit::model::{modal, Model};
use tacit::record::{Record, SampleRange, WarmUp};

/// What the interface step needs from the command line.
pub struct Inputs<'a> {
    /// The model file (must hold a `[modal]` section).
    pub model_path: &'a Path,
    /// The estimation record and the linear records.
    pub records: Vec<&'a Path>,
    /// The validation record.
    pub validation: Option<&'a Path>,
    /// How records are read.
    pub rec: &'a RecordOpts,
    /// The estimation record's sample range.
    pub samples: Option<SampleRange>,
    /// The warm-up left out of the scores.
    pub warm_up: Option<WarmUp>,
    /// Elements of the Iwan stage (1: none).
    pub elements: usize,
    /// Sub-steps per sample of the simulations.
    pub substeps: usize,
}

/// A record read whole (its warm-up kept: the open-loop simulation starts
/// from rest at the first sample and the warm-up is not scored), cut to
/// `range`, channels resolved to `model`.
fn load(
    p: &Path,
    opts: &RecordOpts,
    range: Option<SampleRange>,
    model: &Model,
) -> anyhow::Result<Record> {
    let mut r = super::load_record(p, opts)?;
    if let Some(range) = range {
        r = range
            .cut(&r)
            .map_err(|e| anyhow::anyhow!("--samples {range}: {e}"))?;
    }
    model.resolve_channels(&mut r)?;
    Ok(r)
}

/// The model file must be a modal model: checked before the diagnosis so
/// that a wrong model is refused before minutes of work.
pub fn check_model(path: &Path) -> anyhow::Result<String> {
    let text =
        std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if !modal::is_modal_model(&text) {
        anyhow::bail!(
            "--interface: {} is not a modal model (no [modal] section); the interface coordinate is added to the modes of a model from `tacit modal`",
            path.display()
        );
    }
    Ok(text)
}

/// Fit, rank and write the interface candidate into `dir`; the lines for
/// people are printed.
pub fn run(inp: &Inputs<'_>, declared: &Model, d: &Diagnosis, dir: &Path) -> anyhow::Result<()> {
    let text = check_model(inp.model_path)?;
    let src = inp.model_path.display().to_string();
    let section = modal::section_from_toml_str(&text, &src)?;
    let mut recs = vec![];
    for (i, p) in inp.records.iter().enumerate() {
        let range = if i == 0 { inp.samples } else { None };
        recs.push(load(p, inp.rec, range, declared)?);
    }
    let warm_up = inp.warm_up.map_or(0, |w| w.samples(recs[0].fs));
    let pair = interface::trace_pair(d)
        .or_else(|| interface::coupled_pair(declared))
        .ok_or_else(|| {
            anyhow::anyhow!(
                "--interface: the trace located no pair of points and the model couples none"
            )
        })?;
    let mut o = interface::OfferSettings {
        iwan: Some(inp.elements).filter(|&n| n > 1),
        ..Default::default()
    };
    o.spec.pair = pair;
    o.spec.substeps = inp.substeps;
    o.spec.warm_up = warm_up;
    let refs: Vec<&Record> = recs.iter().collect();
    let alternatives = vec![
        ("declared model".to_string(), declared.clone()),
        ("diagnosed model".to_string(), d.model.clone()),
    ];
    let (offer, models) =
        interface::offer(&section, &refs, alternatives, &o, &|m| eprintln!("{m}"))?;
    let validation = match inp.validation {
        Some(p) => Some(validation_scores(p, inp, declared, &models, warm_up)?),
        None => None,
    };
    write(
        dir,
        &offer,
        &models,
        validation,
        (pair, &recs[0], inp.substeps),
    )?;
    outln!("interface candidate (ranked on the estimation records):");
    outln!("{}", offer.summary().trim_end());
    Ok(())
}

/// The validation record and every ranked model's RMS error per channel.
type Scores = (PathBuf, Vec<(String, Vec<f64>)>);
type Validated = Option<Scores>;

/// Every ranked model's open-loop RMS error per channel on the validation
/// record (reported, not used to choose).
fn validation_scores(
    p: &Path,
    inp: &Inputs<'_>,
    declared: &Model,
    models: &[(String, Model)],
    warm_up: usize,
) -> anyhow::Result<Scores> {
    let r = load(p, inp.rec, None, declared)?;
    let mut out = vec![];
    for (name, m) in models {
        let e = interface::open_loop_errors(m, &r, warm_up, inp.substeps)?;
        out.push((
            name.clone(),
            e.iter().map(|c| tacit::signal::rms_of(c)).collect(),
        ));
    }
    Ok((p.to_path_buf(), out))
}

/// interface.json, interface.md, model-interface.toml and the restoring
/// force figure.
fn write(
    dir: &Path,
    offer: &interface::Offer,
    models: &[(String, Model)],
    validation: Validated,
    (pair, rec, substeps): ([usize; 2], &Record, usize),
) -> anyhow::Result<()> {
    let best = [interface::IWAN, interface::JENKINS]
        .into_iter()
        .filter(|n| models.iter().any(|m| m.0 == *n))
        .min_by_key(|n| offer.ranking.iter().position(|r| r.name == *n))
        .and_then(|n| models.iter().find(|m| m.0 == n))
        .ok_or_else(|| anyhow::anyhow!("no interface model was fitted"))?;
    let r = interface::restoring(&best.1, rec, pair, substeps, 8192.min(rec.len()))?;
    let fig = interface::restoring_figure(
        &r,
        &format!("restoring force of the interface ({})", best.0),
    );
    tacit::plot::save(&fig, &dir.join("restoring_interface"))?;
    tacit::io::write_string(&dir.join("model-interface.toml"), &best.1.to_toml_string())?;
    let json = serde_json::json!({
        "chosen": offer.chosen(),
        "interface": offer,
        "validation": validation.as_ref().map(|(p, v)| serde_json::json!({
            "record": p.display().to_string(),
            "rms_per_channel": v.iter().map(|(n, e)| serde_json::json!({"model": n, "rms_per_channel": e})).collect::<Vec<_>>(),
        })),
        "restoring_interface": {"record": r.record, "pair": r.pair, "slip_force": r.slip_force, "follows": r.follows},
    });
    tacit::io::write_string(
        &dir.join("interface.json"),
        &serde_json::to_string_pretty(&json)?,
    )?;
    let mut md = markdown(offer, validation.as_ref());
    md += &format!(
        "\nThe interface's velocity against the measured relative velocities in the simulation of {} (correlation):\n\n",
        r.record
    );
    for (w, c) in &r.follows {
        md += &format!("- {w}: {c:+.3}\n");
    }
    tacit::io::write_string(&dir.join("interface.md"), &md)?;
    Ok(())
}

/// interface.md: the ranking, the participations, where it couples.
fn markdown(offer: &interface::Offer, validation: Option<&Scores>) -> String {
    let mut s = String::from("# The interface candidate\n\n");
    s += &format!(
        "Ranked by the weighted open-loop error on the estimation records ({}); chosen: **{}**.\n\n",
        offer.records.join(", "),
        offer.chosen()
    );
    s += "| model | acts | cost | RMS per channel per record, m/s² |\n|---|---|---|---|\n";
    for r in &offer.ranking {
        s += &format!(
            "| {} | {} | {:.4} | {:.3?} |\n",
            r.name, r.acts, r.cost, r.rms_per_channel
        );
    }
    if let Some((p, v)) = validation {
        s += &format!(
            "\nOn the validation record {} (not used to choose):\n\n",
            p.display()
        );
        for (n, e) in v {
            s += &format!("- {n}: {e:.3?} m/s²\n");
        }
    }
    let f = offer.best_interface();
    s += &format!(
        "\nInterface: {} element(s), k_J {:.4e} N/m, slip force {:.4e} N, spread {:.3}; ![restoring force](restoring_interface.svg)\n\n",
        f.elements, f.stiffness, f.slip_force, f.spread
    );
    for (hz, d) in &f.participations {
        s += &format!("- participation of the {hz:.2}-Hz mode: {d:+.4}\n");
    }
    s += "\nThe participations against those of each relative displacement (cosine):\n\n";
    for (w, c) in &offer.coupling {
        s += &format!("- {w}: {c:+.3}\n");
    }
    s
}
