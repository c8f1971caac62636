//! Files of a diagnosis: `report.json` (machines, with the settings),
//! `report.md` (people), `settings.toml` (the settings, for
//! `tacit diagnose --settings`), `model-fitted.toml`, and figures (PNG +
//! SVG); and the words for the loop's typed decisions ([`note`],
//! [`fit_note`]).

use super::noise::{NoiseEstimate, NoiseStatus};
use super::{BelowScreen, Decision, Diagnosis, Round, WithdrawReason};
use crate::io::{ensure_dir, write_json, write_string};
use crate::plot::{self, Figure, Panel, Series, SeriesStyle};
use crate::Result;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::ser::SerializeStruct;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What was run, for the report header.
#[derive(Debug, Clone, Serialize)]
pub struct Meta {
    /// Model file.
    pub model: String,
    /// Record file.
    pub record: String,
    /// Validation record file.
    pub validation_record: Option<String>,
    /// Sensor DOFs (from 1) used.
    pub sensors: Vec<usize>,
    /// tacit version.
    pub tacit_version: String,
    /// Warnings of the record checks (units, dead, clipped or spiky
    /// channels, offsets, drift), each naming the file and the channel.
    pub warnings: Vec<String>,
}

#[derive(Serialize)]
struct Doc<'a> {
    #[serde(flatten)]
    meta: &'a Meta,
    #[serde(flatten)]
    diagnosis: &'a Diagnosis,
    settings: &'a super::DiagnoseSettings,
}

/// Write every file into `dir`; returns the paths written.
pub fn write(
    dir: &Path,
    meta: &Meta,
    d: &Diagnosis,
    settings: &super::DiagnoseSettings,
) -> Result<Vec<PathBuf>> {
    ensure_dir(dir)?;
    let mut out = vec![];
    let json = dir.join("report.json");
    write_json(
        &json,
        &Doc {
            meta,
            diagnosis: d,
            settings,
        },
    )?;
    out.push(json);
    let replay = dir.join("settings.toml");
    write_string(&replay, &settings.to_toml_string()?)?;
    out.push(replay);
    let toml = dir.join("model-fitted.toml");
    write_string(&toml, &d.model.to_toml_string())?;
    out.push(toml);
    let figs = figures(dir, d)?;
    let md = dir.join("report.md");
    write_string(&md, &markdown(meta, d, &figs))?;
    out.push(md);
    out.extend(figs);
    Ok(out)
}

/// A fraction as a percentage with two decimals, or `failed` (an error
/// that could not be computed).
pub fn pct(x: Option<f64>) -> String {
    x.map_or("failed".into(), |v| format!("{:.2} %", 100.0 * v))
}

fn markdown(meta: &Meta, d: &Diagnosis, figs: &[PathBuf]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# tacit diagnosis\n");
    let _ = writeln!(
        s,
        "Model `{}`, record `{}`{}, sensors at DOFs {:?}.\n",
        meta.model,
        meta.record,
        meta.validation_record
            .as_ref()
            .map_or(String::new(), |v| format!(", validation record `{v}`")),
        meta.sensors
    );
    let _ = writeln!(s, "**Result: {}.**\n", d.verdict);
    record_warnings(&mut s, &meta.warnings);
    errors_section(&mut s, d);
    noise_section(&mut s, d);
    effects_section(&mut s, d);
    loop_section(&mut s, d);
    let _ = writeln!(s, "\n## Figures\n");
    for f in figs
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "png"))
    {
        let name = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let _ = writeln!(s, "![{name}]({name})");
    }
    s
}

/// The errors before and after, on the record and the validation record.
fn errors_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "## Errors\n");
    let _ = writeln!(
        s,
        "`relative_error`: multiple-shooting prediction over {}-sample segments, each simulated from the state reconstructed at its start and refined for the model scored (Gauss–Newton on the segment's output error); `simulation_error`: open-loop simulation of the whole record.\n",
        d.prepared.segment
    );
    let _ = writeln!(s, "| | relative_error | simulation_error |\n|---|---|---|");
    let _ = writeln!(
        s,
        "| before (declared model) | {} | {} |",
        pct(d.before.relative_error),
        pct(d.before.simulation_error)
    );
    let _ = writeln!(
        s,
        "| after (with the effects) | {} | {} |",
        pct(d.after.relative_error),
        pct(d.after.simulation_error)
    );
    if let Some(v) = &d.validation {
        let _ = writeln!(
            s,
            "| validation, before | {} | {} |",
            pct(v.before.relative_error),
            pct(v.before.simulation_error)
        );
        let _ = writeln!(
            s,
            "| validation, after | {} | {} |",
            pct(v.after.relative_error),
            pct(v.after.simulation_error)
        );
        let _ = writeln!(
            s,
            "\nNon-parametric prediction of the validation record (linear model driven by the force identified on the first record): {}.",
            pct(v.nonparametric_relative_error)
        );
    }
    for (name, e) in [("before", &d.before), ("after", &d.after)] {
        if !e.status.is_ok() {
            let _ = writeln!(s, "\n*{name}: {}*", e.status);
        }
    }
    // how the start states of the scored segments were found
    let starts: Vec<String> = [("before", &d.before), ("after", &d.after)]
        .iter()
        .filter_map(|(name, e)| {
            let f = e.starts.as_ref()?;
            Some(format!(
                "{name}: {} Gauss–Newton iterations, {} segments continued from the one before, {} from a growing horizon, segment cost {:.3e} → {:.3e}",
                f.iterations, f.continued, f.grown, f.cost.0, f.cost.1
            ))
        })
        .collect();
    if !starts.is_empty() {
        let _ = writeln!(s, "\nStart states ({}).", starts.join("; "));
    }
    let _ = writeln!(s, "\nPer channel (relative_error before → after):\n");
    for (b, a) in d.before.per_channel.iter().zip(&d.after.per_channel) {
        let _ = writeln!(
            s,
            "- {}: {} → {}",
            b.channel,
            pct(b.relative_error),
            pct(a.relative_error)
        );
    }
}

/// Which level the noise-related thresholds used, in words.
fn thresholds(n: &NoiseEstimate) -> String {
    if n.used == n.assumed && n.level > n.assumed && n.status != NoiseStatus::White {
        format!(
            "The residual is coloured, so part of the measured level is model error; the noise-related thresholds keep the assumed {:.2} %.",
            100.0 * n.assumed
        )
    } else if n.used == n.assumed {
        format!(
            "It confirms the assumed {:.2} % (within the search's factor), which the noise-related thresholds use.",
            100.0 * n.assumed
        )
    } else {
        format!(
            "The noise-related thresholds use {:.3} % instead of the assumed {:.2} %.",
            100.0 * n.used,
            100.0 * n.assumed
        )
    }
}

/// The noise measured on the record, per channel.
fn noise_section(s: &mut String, d: &Diagnosis) {
    let Some(n) = &d.noise else {
        return;
    };
    let _ = writeln!(
        s,
        "\n## Noise\n\nMeasured on the record from what the located-force reconstruction leaves (median over {} frequency bands; a band far above the median holds model error, not noise): {}. {}\n",
        n.bands,
        n.summary(),
        thresholds(n)
    );
    let _ = writeln!(
        s,
        "| channel | noise std | % of RMS | worst band / median |\n|---|---|---|---|"
    );
    for c in &n.channels {
        let _ = writeln!(
            s,
            "| {} | {:.3e} {} | {:.3} % | {:.1} ({:.0}–{:.0} Hz) |",
            c.channel,
            c.std,
            c.unit,
            100.0 * c.fraction,
            c.colour,
            c.band_hz.0,
            c.band_hz.1
        );
    }
}

/// The effects found, with their fitted values.
fn effects_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "\n## Effects found\n");
    if d.effects.is_empty() {
        let _ = writeln!(s, "No missing effect found: no candidate removes enough of the residual to pay for its parameters.\n");
    }
    for e in &d.effects {
        let params: Vec<String> = e
            .parameters
            .iter()
            .map(|(k, v)| {
                let se = e.std_errors.get(k).copied().flatten();
                match se {
                    Some(se) => format!("{k} = {v:.4e} ± {se:.1e}"),
                    None => format!("{k} = {v:.4e}"),
                }
            })
            .collect();
        let _ = writeln!(
            s,
            "- **{}** (DOFs {:?}): {}; removed {:.1} % of the remaining residual in the trace; multiple-shooting error {} → {}.",
            e.label,
            e.dofs,
            params.join(", "),
            100.0 * e.score.residual_explained,
            pct(e.score.error_before),
            pct(e.score.error_after)
        );
    }
}

/// The rounds of the loop, the first trace's ranking, the cost.
fn loop_section(s: &mut String, d: &Diagnosis) {
    if let Some(c) = &d.calibration {
        linear_corrections(s, c);
    }
    let _ = writeln!(s, "\n## How the loop went\n");
    for (i, r) in d.rounds.iter().enumerate() {
        let _ = writeln!(
            s,
            "{}. {} — {}{}",
            i + 1,
            r.proposed.clone().unwrap_or_else(|| "no candidate".into()),
            note(&r.decision),
            fit_note(r).map_or(String::new(), |f| format!(" (fit: {f})"))
        );
    }
    let _ = writeln!(s, "\nBest candidates of the first trace round:\n\n| candidate | residual removed | BIC change | parameters |\n|---|---|---|---|");
    for r in d.ranking.iter().take(8) {
        let p: Vec<String> = r
            .parameters
            .iter()
            .map(|(k, v)| format!("{k} = {v:.3e}"))
            .collect();
        let _ = writeln!(
            s,
            "| {} | {:.1} % | {:.0} | {} |",
            r.label,
            100.0 * r.residual_explained,
            r.bic_change,
            p.join(", ")
        );
    }
    let _ = writeln!(s, "\nIdentification: {}.", d.identification);
    let _ = writeln!(
        s,
        "Sub-steps per sample: {} (declared model), {} (final model). Segment simulations: {} (fits, start-state refinement, errors), {} linear (trace). Time: {:.2} s.",
        d.substeps.0,
        d.substeps.1,
        d.simulations,
        d.trace_simulations,
        d.timings.get("total").copied().unwrap_or(f64::NAN)
    );
}

/// The record checks' warnings, before the results they may spoil.
fn record_warnings(s: &mut String, warnings: &[String]) {
    if warnings.is_empty() {
        return;
    }
    let _ = writeln!(s, "## Warnings about the records\n");
    for w in warnings {
        let _ = writeln!(s, "- {w}");
    }
    let _ = writeln!(s);
}

/// The linear corrections, apart from the effects.
fn linear_corrections(s: &mut String, c: &super::calibrated::CalibrationReport) {
    let _ = writeln!(s, "\n## Linear part: corrections to the declared model\n");
    let on = &c.calibration.records;
    let _ = writeln!(
        s,
        "Springs and damping calibrated on {} (relative output error of the linear model {:.2} % → {:.2} %), then refined with the effects found: {}. {}.\n",
        on.join(", "),
        100.0 * c.calibration.error_before,
        100.0 * c.calibration.error_after,
        c.refinement,
        c.choice
    );
    let _ = writeln!(
        s,
        "± is one standard error from measurement noise alone (white residual assumed); a correction is significant when it exceeds 3 standard errors and 0.5 %.\n"
    );
    let _ = writeln!(
        s,
        "| parameter | declared | calibrated | final | change | ± | significant | identifiable |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    for x in &c.corrections {
        let unit = if x.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", x.unit)
        };
        let _ = writeln!(
            s,
            "| {} | {:.4e}{unit} | {:.4e}{unit} | {:.4e}{unit} | {:+.2} % | {} | {} | {} |",
            x.name,
            x.declared,
            x.calibrated,
            x.value,
            100.0 * x.change,
            x.std_error.map_or("—".into(), |e| format!("{e:.2e}{unit}")),
            if x.significant { "yes" } else { "no" },
            if x.identifiable { "yes" } else { "no" }
        );
    }
}

fn row(m: &DMatrix<f64>, r: usize) -> Vec<f64> {
    m.row(r).iter().copied().collect()
}

fn figures(dir: &Path, d: &Diagnosis) -> Result<Vec<PathBuf>> {
    let prep = &d.prepared;
    let cmp = &prep.comparison;
    let ns = cmp.force.ncols();
    let t: Vec<f64> = (0..ns).map(|k| k as f64 / cmp.fs).collect();
    let meas = cmp.measured();
    // (figure, path) pairs, drawn in parallel at the end
    let mut jobs = vec![];
    // residuals before / after
    let mut panels = vec![];
    for (c, o) in cmp.observations.iter().enumerate() {
        let mut series = vec![];
        if let Some(b) = &d.predictions.0 {
            series.push((
                "before".to_string(),
                (0..ns).map(|k| meas[(c, k)] - b[(c, k)]).collect(),
                SeriesStyle::Line,
            ));
        }
        if let Some(a) = &d.predictions.1 {
            series.push((
                "after".to_string(),
                (0..ns).map(|k| meas[(c, k)] - a[(c, k)]).collect(),
                SeriesStyle::Line,
            ));
        }
        panels.push(plot::time_panel(&o.name(), "residual", &t, series));
    }
    jobs.push((
        Figure::new("Segment residual, before and after", panels, 1),
        dir.join("residual"),
    ));
    // responses over the first 0.5 s
    let kmax = ((0.5 * cmp.fs) as usize).min(ns);
    let tt = &t[..kmax];
    let mut panels = vec![];
    for (c, o) in cmp.observations.iter().enumerate() {
        let mut series = vec![(
            "measured".to_string(),
            row(&meas, c)[..kmax].to_vec(),
            SeriesStyle::Line,
        )];
        if let Some(b) = &d.predictions.0 {
            series.push((
                "before".to_string(),
                row(b, c)[..kmax].to_vec(),
                SeriesStyle::DashedLine,
            ));
        }
        if let Some(a) = &d.predictions.1 {
            series.push((
                "after".to_string(),
                row(a, c)[..kmax].to_vec(),
                SeriesStyle::DashedLine,
            ));
        }
        panels.push(plot::time_panel(
            &o.name(),
            o.quantity.si_unit(),
            tt,
            series,
        ));
    }
    jobs.push((
        Figure::new("Responses (segments), first 0.5 s", panels, 1),
        dir.join("responses"),
    ));
    jobs.extend(force_figures(dir, d, &t));
    let saved = jobs
        .par_iter()
        .map(|(fig, path)| plot::save(fig, path))
        .collect::<Result<Vec<_>>>()?;
    Ok(saved.into_iter().flatten().collect())
}

/// The identified force, and the restoring-force plots of the effects
/// (of the best candidate when none was found).
fn force_figures(dir: &Path, d: &Diagnosis, t: &[f64]) -> Vec<(Figure, PathBuf)> {
    let prep = &d.prepared;
    let ns = t.len();
    let mut jobs = vec![];
    let f = &prep.recon.force;
    let n = f.nrows();
    let panels: Vec<Panel> = (0..n)
        .map(|i| {
            plot::time_panel(
                &format!("DOF {}", i + 1),
                "f_int [N]",
                t,
                vec![(format!("f{}", i + 1), row(f, i), SeriesStyle::Line)],
            )
        })
        .collect();
    jobs.push((
        Figure::new("Identified internal force (left-hand side)", panels, 2),
        dir.join("identified_force"),
    ));
    // restoring-force plots of the effects (and of the best candidate when none)
    let states = &prep.recon.states;
    let cands: Vec<crate::trace::Candidate> = if d.effects.is_empty() {
        d.ranking
            .iter()
            .take(1)
            .map(|r| r.candidate.clone())
            .collect()
    } else {
        d.effects
            .iter()
            .map(|e| crate::trace::Candidate::new(e.kind, e.dofs.iter().map(|x| x - 1).collect()))
            .collect()
    };
    for (i, c) in cands.iter().enumerate() {
        if c.dofs.len() > 2 {
            continue;
        }
        let fy: Vec<f64> = (0..ns)
            .map(|k| match c.dofs.get(1) {
                Some(&j) => 0.5 * (f[(c.dofs[0], k)] - f[(j, k)]),
                None => f[(c.dofs[0], k)],
            })
            .collect();
        let dx: Vec<f64> = (0..ns).map(|k| c.delta(states, k)).collect();
        let dv: Vec<f64> = (0..ns).map(|k| c.delta_rate(states, n, k)).collect();
        let what = if c.dofs.len() == 2 {
            format!("u{} − u{}", c.dofs[0] + 1, c.dofs[1] + 1)
        } else {
            format!("u{}", c.dofs[0] + 1)
        };
        let p1 = Panel::xy(
            "force vs displacement",
            format!("{what} [m]"),
            "f_int [N]",
            vec![Series::points("identified", dx, fy.clone())],
        );
        let p2 = Panel::xy(
            "force vs velocity",
            format!("d/dt({what}) [m/s]"),
            "f_int [N]",
            vec![Series::points("identified", dv, fy)],
        );
        jobs.push((
            Figure::new(format!("Restoring force: {}", c.label()), vec![p1, p2], 2),
            dir.join(format!("restoring_{}", i + 1)),
        ));
    }
    jobs
}

/// An error (a fraction) to four decimals, `NaN` when missing.
fn p4(x: Option<f64>) -> String {
    format!("{:.4}", x.unwrap_or(f64::NAN))
}

/// What a candidate below the screen adds to its round's note.
fn below_note(b: &BelowScreen) -> String {
    let pre = if b.screened_out.is_empty() {
        String::new()
    } else {
        format!(
            "; predicted below {:.0} %: {}",
            100.0 * b.screen,
            screened_out(b)
        )
    };
    format!(
        " (below the screen: {}{pre}; fitted because the joint linearization predicts it removes at least {:.0} % of the fit cost)",
        b.trace,
        100.0 * b.screen
    )
}

/// The candidates the screen turned away, with their predicted gains.
fn screened_out(b: &BelowScreen) -> String {
    let s: Vec<String> = b
        .screened_out
        .iter()
        .map(|(label, g)| format!("{label} {:.1} %", 100.0 * g))
        .collect();
    s.join(", ")
}

/// A round's decision in words.
pub fn note(d: &Decision) -> String {
    let why = |b: &Option<BelowScreen>| b.as_ref().map_or(String::new(), below_note);
    match d {
        Decision::AtNoise { error, floor } => format!(
            "the model explains the record up to noise and integration error (multiple-shooting error {:.2} % ≤ {:.2} %)",
            100.0 * error,
            100.0 * floor
        ),
        Decision::NothingPays { reason } => reason.clone(),
        Decision::ScreenedOut(b) => format!(
            "not fitted: at the current fit, with the segment start states free, the candidates below the screen are predicted to remove {} of the fit cost (screen {:.0} %; below the screen: {})",
            screened_out(b),
            100.0 * b.screen,
            b.trace
        ),
        Decision::Kept {
            before,
            after,
            below,
        } => format!(
            "kept: multiple-shooting error {} → {}{}",
            p4(*before),
            p4(*after),
            why(below)
        ),
        Decision::Withdrawn {
            reason,
            below,
            refit_kept,
        } => {
            let mut s = match reason {
                WithdrawReason::NotItself { without, with, need } => format!(
                    "withdrawn: switched off in the fitted model, the error is {} against {} with it: it does not itself remove {:.0} % of the squared error{}",
                    p4(*without),
                    p4(*with),
                    100.0 * need,
                    why(below)
                ),
                WithdrawReason::TooLittle {
                    need,
                    before,
                    after,
                } => format!(
                    "withdrawn: the fitted effect does not remove {:.0} % of the squared multiple-shooting error ({} → {}){}",
                    100.0 * need,
                    p4(*before),
                    p4(*after),
                    why(below)
                ),
            };
            if let Some((a, w)) = refit_kept {
                s = format!(
                    "{s}; the effects found, as refitted beside it, are kept: multiple-shooting error {} → {}",
                    p4(*a),
                    p4(*w)
                );
            }
            s
        }
    }
}

/// How a round's fit ended, with the cubic alternative when one was tried.
pub fn fit_note(r: &Round) -> Option<String> {
    let fit = r.fit.as_ref()?;
    let Some(a) = &r.alternative else {
        return Some(fit.clone());
    };
    let line = format!(
        "{} fitted too, from {}: {}{}",
        a.label,
        a.start
            .iter()
            .map(|p| format!("{} {:.3e}", p.0, p.1))
            .collect::<Vec<_>>()
            .join(", "),
        a.error
            .map_or("failed".into(), |e| format!("{:.2} %", 100.0 * e)),
        if a.taken { ", taken" } else { "" }
    );
    Some(if a.taken {
        format!(
            "{fit}; {line} instead of {} at {:.2} %",
            a.instead_of.0,
            100.0 * a.instead_of.1.unwrap_or(f64::NAN)
        )
    } else {
        format!("{fit}; {line}")
    })
}

impl Serialize for Round {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        let mut r = s.serialize_struct("Round", 7)?;
        r.serialize_field("proposed", &self.proposed)?;
        r.serialize_field("kept", &self.kept())?;
        r.serialize_field("note", &note(&self.decision))?;
        r.serialize_field("fit", &fit_note(self))?;
        r.serialize_field("simulations", &self.simulations)?;
        r.serialize_field("decision", &self.decision)?;
        r.serialize_field("alternative", &self.alternative)?;
        r.end()
    }
}
