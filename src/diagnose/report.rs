//! Files of a diagnosis: `report.json` (machines, with the settings),
//! `report.md` (people: plain words and units in the main text, the
//! solver's details in a collapsible appendix; docs/interpreting-the-report.md
//! explains it), `settings.toml` (the settings, for
//! `tacit diagnose --settings`), `model-fitted.toml`, and figures (PNG +
//! SVG, `super::figures`); and the words for the loop's typed decisions
//! ([`note`], [`fit_note`]).

use super::noise::{NoiseEstimate, NoiseStatus, Remaining};
use super::EffectReport;
use super::{BelowScreen, Decision, Diagnosis, Round, WithdrawReason};
use crate::io::{ensure_dir, write_json, write_string};
use crate::Result;
use nalgebra::DMatrix;
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
    /// What the fitted model leaves of the record.
    remaining: Option<&'a Remaining>,
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
    let remaining = d.remaining(settings.noise.bands);
    write_json(
        &json,
        &Doc {
            meta,
            diagnosis: d,
            remaining: remaining.as_ref(),
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
    let figs = super::figures::write(dir, d)?;
    let md = dir.join("report.md");
    write_string(&md, &markdown(meta, d, remaining.as_ref(), &figs))?;
    out.push(md);
    out.extend(figs);
    Ok(out)
}

/// A fraction as a percentage with two decimals, or `failed` (an error
/// that could not be computed).
pub fn pct(x: Option<f64>) -> String {
    x.map_or("failed".into(), |v| format!("{:.2} %", 100.0 * v))
}

/// Above this open-loop error (a fraction), when it is also
/// [`OPEN_LOOP_RATIO`] times the segment error, report.md says why it
/// stays high.
const OPEN_LOOP_HIGH: f64 = 0.2;
/// See [`OPEN_LOOP_HIGH`].
const OPEN_LOOP_RATIO: f64 = 3.0;
/// Window of the open-loop error's growth over time, s.
const DRIFT_WINDOW_S: f64 = 0.5;

fn markdown(meta: &Meta, d: &Diagnosis, remaining: Option<&Remaining>, figs: &[PathBuf]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# tacit diagnosis\n");
    let _ = writeln!(
        s,
        "Model `{}`, record `{}`{}, sensors at DOFs {:?}. How to read this report: docs/interpreting-the-report.md in tacit's repository.\n",
        meta.model,
        meta.record,
        meta.validation_record
            .as_ref()
            .map_or(String::new(), |v| format!(", validation record `{v}`")),
        meta.sensors
    );
    let _ = writeln!(s, "**Result: {}.**\n", d.verdict);
    record_warnings(&mut s, &meta.warnings);
    effects_section(&mut s, d);
    errors_section(&mut s, d);
    if let Some(c) = &d.calibration {
        linear_corrections(&mut s, c);
    }
    noise_section(&mut s, d);
    remaining_section(&mut s, d, remaining);
    figures_section(&mut s, figs);
    appendix(&mut s, d);
    s
}

/// How a parameter is shown: its unit, the factor from SI to it, and
/// whether in fixed-point (else scientific) notation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shown {
    /// Unit as printed.
    pub unit: &'static str,
    /// Factor from the SI value to the printed one.
    pub factor: f64,
    /// Fixed-point (decimals set by the uncertainty) or scientific.
    pub fixed: bool,
}

/// How the effect parameter `name` is shown: `gap` in mm, `stiffness`
/// N/m, `level` N, `k2` N/m², `k3` N/m³, `c2` N·s²/m², `c3` N·s³/m³,
/// `delta` (a relative change of the nominal) in %.
pub fn shown(name: &str) -> Shown {
    let (unit, factor, fixed) = match name {
        "gap" => ("mm", 1e3, true),
        "stiffness" => ("N/m", 1.0, false),
        "level" => ("N", 1.0, true),
        "k2" => ("N/m²", 1.0, false),
        "k3" => ("N/m³", 1.0, false),
        "c2" => ("N·s²/m²", 1.0, false),
        "c3" => ("N·s³/m³", 1.0, false),
        "delta" => ("%", 100.0, true),
        _ => ("(SI)", 1.0, false),
    };
    Shown {
        unit,
        factor,
        fixed,
    }
}

impl Shown {
    /// Decimals giving two significant digits to the smallest positive
    /// uncertainty in `unc` (SI), else four to the value `v`.
    fn decimals(&self, v: f64, unc: &[Option<f64>]) -> usize {
        let u = unc
            .iter()
            .flatten()
            .map(|u| (u * self.factor).abs())
            .filter(|u| *u > 0.0 && u.is_finite())
            .fold(f64::INFINITY, f64::min);
        let r = if u.is_finite() {
            u
        } else {
            (v * self.factor).abs() / 1e3
        };
        if !(r > 0.0) {
            return 3;
        }
        (1.0 - r.log10().floor()).clamp(0.0, 9.0) as usize
    }

    /// `v` (SI) in this unit, with `dec` decimals when fixed.
    fn value(&self, v: f64, dec: usize) -> String {
        match (self.fixed, self.unit) {
            (true, "%") => format!("{:+.*} %", dec, v * self.factor),
            (true, u) => format!("{:.*} {u}", dec, v * self.factor),
            (false, u) => format!("{:.4e} {u}", v * self.factor),
        }
    }

    /// An uncertainty `u` (SI) in this unit.
    fn error(&self, u: Option<f64>, dec: usize) -> String {
        match (u, self.fixed) {
            (None, _) => "—".into(),
            (Some(u), true) => format!("{:.*} {}", dec, u * self.factor, self.unit),
            (Some(u), false) => format!("{:.1e} {}", u * self.factor, self.unit),
        }
    }

    /// Several values (SI) in this unit, the unit once at the end.
    fn list(&self, vs: &[f64], dec: usize) -> String {
        let each: Vec<String> = vs
            .iter()
            .map(|v| match self.fixed {
                true => format!("{:.*}", dec, v * self.factor),
                false => format!("{:.3e}", v * self.factor),
            })
            .collect();
        format!("{} {}", each.join(", "), self.unit)
    }
}

/// A parameter (SI) with its unit, for lists: `gap = 0.3157 mm`.
pub fn with_unit(name: &str, v: f64) -> String {
    let sh = shown(name);
    format!("{name} = {}", sh.value(v, sh.decimals(v, &[])))
}

/// The table row of one parameter of an effect.
fn parameter_row(e: &EffectReport, name: &str, v: f64, first: bool) -> String {
    let sh = shown(name);
    let se = e.std_errors.get(name).copied().flatten();
    let spread = e.spread_error(name);
    let dec = sh.decimals(v, &[se, spread]);
    let groups = e
        .group_estimates
        .get(name)
        .filter(|g| !g.is_empty())
        .map_or("—".into(), |g| sh.list(g, dec));
    format!(
        "| {} | {name} | {} | {} | {} | {groups} |",
        if first { e.label.as_str() } else { "" },
        sh.value(v, dec),
        sh.error(se, dec),
        sh.error(spread, dec),
    )
}

/// The effects found: a table of their parameters with units and both
/// spreads, how much each removed, and what the ± mean.
fn effects_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "## Effects found\n");
    if d.effects.is_empty() {
        let _ = writeln!(s, "No missing effect found: no candidate removes enough of the residual to pay for its parameters.\n");
        return;
    }
    let _ = writeln!(
        s,
        "| effect | parameter | value | ± noise | ± across the record | on each quarter of the record |\n|---|---|---|---|---|---|"
    );
    for e in &d.effects {
        for (i, (name, v)) in e.parameters.iter().enumerate() {
            let _ = writeln!(s, "{}", parameter_row(e, name, *v, i == 0));
        }
    }
    let _ = writeln!(s);
    for e in &d.effects {
        let _ = writeln!(
            s,
            "- **{}** (DOFs {}): the trace put {:.1} % of the residual on it; added and fitted, it takes the segment error from {} to {}.",
            e.label,
            e.dofs.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", "),
            100.0 * e.score.residual_explained,
            pct(e.score.error_before),
            pct(e.score.error_after)
        );
    }
    let _ = writeln!(
        s,
        "\n**What ± means.** *± noise* is one standard error from measurement noise alone (white noise at the level measured below, through the fit's Jacobian with the segments' start states free); it ignores every model error and is a lower bound. *± across the record* comes from the same parameter fitted on each quarter of the record separately (the values in the last column; one linearized step from the fit, the start states re-estimated): the standard deviation of the quarters' values divided by 2 (√4), combined with how far their mean lies from the value reported; it includes model error, coloured residual and a fit stopped short of its minimum, and is the one to quote."
    );
    for e in &d.effects {
        offset_note(s, e);
        undetermined_note(s, e);
    }
    if let Some((name, label, ratio)) = worst_ratio(&d.effects) {
        let _ = writeln!(
            s,
            "\nThe quarters' values scatter by up to {ratio:.0} × the noise-only value ({name} of {label}): the model's remaining error or a coloured residual, not the noise, limits how well the parameters are known.",
        );
    }
    let _ = writeln!(s);
}

/// A sentence when the quarters agree with each other but their mean lies
/// far from the value reported (more than 3 of their standard errors and
/// 3 noise standard errors): the fit stopped short of its minimum, or the
/// cost is too rough for the linearized step.
fn offset_note(s: &mut String, e: &EffectReport) {
    let far: Vec<String> = e
        .parameters
        .iter()
        .filter_map(|(k, v)| {
            let (mean, se_q) = e.quarters(k)?;
            let se = e.std_errors.get(k).copied().flatten().unwrap_or(0.0);
            let off = (mean - v).abs();
            (off > 3.0 * se_q && off > 3.0 * se).then(|| {
                let sh = shown(k);
                let dec = sh.decimals(*v, &[Some(se_q), Some(se)]);
                format!("{k} {} against {}", sh.value(mean, dec), sh.value(*v, dec))
            })
        })
        .collect();
    if !far.is_empty() {
        let _ = writeln!(
            s,
            "\n**{}: the quarters agree with each other but not with the value reported** ({}): one linearized step on the whole record would move the value to the quarters' mean, so either the fit stopped short of its minimum (how it ended is in the appendix) or the cost is too rough there for one linearized step (a contact's cost is rough at the sub-step scale); the ± across the record includes that distance.",
            e.label,
            far.join("; ")
        );
    }
}

/// A sentence for the parameters the records do not determine
/// ([`EffectReport::undetermined`]): those no record from these sensors
/// could determine first, with their cause, then those the noise could
/// move by more than their size.
fn undetermined_note(s: &mut String, e: &EffectReport) {
    let with_se = |k: &String| {
        let (v, se) = (
            *e.parameters.get(k)?,
            e.std_errors.get(k).copied().flatten(),
        );
        let sh = shown(k);
        let value = sh.value(v, sh.decimals(v, &[]));
        Some(match se {
            Some(se) => format!("{k} {value} ± {}", sh.value(se, sh.decimals(se, &[]))),
            None => format!("{k} {value}"),
        })
    };
    let (structural, noisy): (Vec<&String>, Vec<&String>) = e
        .undetermined
        .iter()
        .partition(|k| e.unobservable.contains(k));
    if !structural.is_empty() {
        let each: Vec<String> = structural.into_iter().filter_map(with_se).collect();
        let _ = writeln!(
            s,
            "\n**{}: not observable with these sensors** ({}): a threshold against ground is measured from the structure's absolute position, which accelerations do not give; the structure can move as a rigid body, so each segment's free start position takes up any gap and the predictions do not change with it. The value is where the fit stopped, not a measurement, whatever its ±; the effect's other parameters and the errors stand. A displacement sensor on the structure would determine it.",
            e.label,
            each.join("; ")
        );
    }
    if noisy.is_empty() {
        return;
    }
    let each: Vec<String> = noisy.into_iter().filter_map(with_se).collect();
    let _ = writeln!(
        s,
        "\n**{}: not determined by these records** ({}): the noise alone could move the value by more than its size; the effect's other parameters and the errors stand, this value is not a measurement.",
        e.label,
        each.join("; ")
    );
}

/// The parameter whose quarters' standard error
/// ([`EffectReport::quarters`]) is the most times its noise-only standard
/// error, when that is above 3.
fn worst_ratio(effects: &[EffectReport]) -> Option<(String, String, f64)> {
    effects
        .iter()
        .flat_map(|e| {
            e.parameters.keys().filter_map(move |k| {
                let se = e.std_errors.get(k).copied().flatten()?;
                let r = e.quarters(k)?.1 / se;
                r.is_finite().then(|| (k.clone(), e.label.clone(), r))
            })
        })
        .max_by(|a, b| a.2.total_cmp(&b.2))
        .filter(|w| w.2 > 3.0)
}

/// The errors before and after, on the record and the validation record,
/// and why the open-loop error stays high when it does.
fn errors_section(s: &mut String, d: &Diagnosis) {
    let cmp = &d.prepared.comparison;
    let seg_s = d.prepared.segment as f64 / cmp.fs;
    let _ = writeln!(s, "## How well the models predict the record\n");
    let _ = writeln!(
        s,
        "Both errors are ‖measured − predicted‖ / ‖measured‖ over all channels: the RMS of the error as a percentage of the RMS response (0 % is perfect, 100 % as large as the response).\n\n- **Segment error** (`relative_error` in report.json): the model predicts the record {seg_s:.2} s ({} samples) at a time, each stretch started from the state estimated from the measurements — the test of the model's dynamics.\n- **Open-loop error** (`simulation_error`): the model simulated over the whole record ({:.2} s), driven by the measured force from the estimated start state alone.\n",
        d.prepared.segment,
        cmp.force.ncols() as f64 / cmp.fs
    );
    let _ = writeln!(s, "| | segment error | open-loop error |\n|---|---|---|");
    let mut rows = vec![
        ("before (declared model)", &d.before),
        ("after (fitted model)", &d.after),
    ];
    if let Some(v) = &d.validation {
        rows.push(("validation record, before", &v.before));
        rows.push(("validation record, after", &v.after));
    }
    for (name, e) in rows {
        let _ = writeln!(
            s,
            "| {name} | {} | {} |",
            pct(e.relative_error),
            pct(e.simulation_error)
        );
    }
    if let Some(v) = &d.validation {
        let _ = writeln!(
            s,
            "\nFor comparison, the declared linear model driven by the internal force identified on the first record (a force history, no fitted law) predicts the validation record with a segment error of {}.",
            pct(v.nonparametric_relative_error)
        );
        for m in &v.datum {
            let _ = writeln!(
                s,
                "\nThe gap of {} against ground is not observable (it is counted from the structure's absolute position, which each record reconstructs with its own offset): on the validation record it was taken again from that record's positions, {:.4} mm against {:.4} mm fitted, everything else held.",
                m.label,
                1e3 * m.here,
                1e3 * m.fitted
            );
        }
    }
    for (name, e) in [("before", &d.before), ("after", &d.after)] {
        if !e.status.is_ok() {
            let _ = writeln!(s, "\n*{name}: {}*", e.status);
        }
    }
    if let Some(w) = open_loop_note(d) {
        let _ = writeln!(s, "\n{w}");
    }
    per_channel(s, d);
}

/// Errors per channel, before and after.
fn per_channel(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(
        s,
        "\n| channel | segment error before | after | open-loop error before | after |\n|---|---|---|---|---|"
    );
    for (b, a) in d.before.per_channel.iter().zip(&d.after.per_channel) {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} |",
            b.channel,
            pct(b.relative_error),
            pct(a.relative_error),
            pct(b.simulation_error),
            pct(a.simulation_error)
        );
    }
}

/// Relative error over all channels in consecutive windows of `len`
/// samples (the last one shorter).
pub fn window_errors(meas: &DMatrix<f64>, pred: &DMatrix<f64>, len: usize) -> Vec<f64> {
    let ns = meas.ncols().min(pred.ncols());
    (0..ns)
        .step_by(len.max(1))
        .map(|k0| {
            let k1 = (k0 + len.max(1)).min(ns);
            let (mut num, mut den) = (0.0, 0.0);
            for k in k0..k1 {
                for c in 0..meas.nrows() {
                    let (m, p) = (meas[(c, k)], pred[(c, k)]);
                    num += (p - m) * (p - m);
                    den += m * m;
                }
            }
            crate::metrics::ratio(num, den)
        })
        .collect()
}

/// One sentence on why the fitted model's open-loop error stays high
/// while its segment error is low, with how it grows over the record.
fn open_loop_note(d: &Diagnosis) -> Option<String> {
    let (sim, rel) = (d.after.simulation_error?, d.after.relative_error?);
    if !(sim > OPEN_LOOP_HIGH && sim > OPEN_LOOP_RATIO * rel) {
        return None;
    }
    let cmp = &d.prepared.comparison;
    let len = ((DRIFT_WINDOW_S * cmp.fs) as usize).max(1);
    let w = window_errors(&cmp.measured(), d.after.open_loop_prediction.as_ref()?, len);
    let first = *w.first()?;
    let growth = match w.iter().position(|e| *e > 0.5) {
        Some(i) => format!(
            "and passes 50 % in the window from {:.1} s",
            i as f64 * DRIFT_WINDOW_S
        ),
        None => format!(
            "and {} over the last {DRIFT_WINDOW_S} s",
            pct(w.last().copied())
        ),
    };
    let impacts = d.effects.iter().any(|e| {
        matches!(
            e.kind,
            crate::trace::EffectKind::Contact | crate::trace::EffectKind::Clearance
        )
    });
    let nonlinear = d.effects.iter().any(|e| !e.kind.linear_in_state());
    let why = if impacts {
        "each impact's timing depends on the exact state when the gap closes, so small differences grow from impact to impact and the simulated response drifts out of phase with the measured one"
    } else if nonlinear {
        "a nonlinear response depends on its own amplitude, so small differences in the state grow over time and the simulated response drifts out of phase with the measured one"
    } else {
        "a small error in a lightly damped mode's frequency or damping accumulates into a phase error over the record"
    };
    Some(format!(
        "**Why the open-loop error stays high** ({} against a segment error of {}): {why}; its open-loop error is {} over the first {DRIFT_WINDOW_S} s {growth}. Judge such a model by the segment error, restarted from the measured state every stretch, and by the FRF (frf.png), which does not depend on phase.",
        pct(Some(sim)),
        pct(Some(rel)),
        pct(Some(first)),
    ))
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
        "\n## Noise\n\nNoise measured on the record from what remains after the force reconstruction (the lower quartile of {} frequency bands' levels, scaled by what white noise alone gives, so that model error confined to fewer than three bands in four does not raise it; a band far above the median holds model error, not noise): {}. {}\n",
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

/// What the fitted model leaves of the record, and what that says of the
/// noise measured on the reconstruction.
fn remaining_section(s: &mut String, d: &Diagnosis, r: Option<&Remaining>) {
    let Some(r) = r else {
        return;
    };
    let _ = writeln!(
        s,
        "\n## What the fitted model leaves\n\nThe residual of the fitted model's segment predictions (measured − predicted over the samples predicted; {} frequency bands): {}.",
        r.bands,
        r.summary()
    );
    let coloured_before = d
        .noise
        .as_ref()
        .filter(|n| matches!(n.status, NoiseStatus::Coloured { .. }) && n.level > r.level);
    if let (NoiseStatus::White, Some(n)) = (&r.status, coloured_before) {
        let _ = writeln!(
            s,
            "\nIt is white and below the {:.3} % measured on the reconstruction: the noise is at most {:.3} %, and the level measured above holds model error the reconstruction left (a force off the located directions).",
            100.0 * n.level,
            100.0 * r.level
        );
    }
    let _ = writeln!(
        s,
        "\n| channel | left, % of RMS | worst band / median |\n|---|---|---|"
    );
    for c in &r.channels {
        let _ = writeln!(
            s,
            "| {} | {:.3} % | {:.1} ({:.0}–{:.0} Hz) |",
            c.channel,
            100.0 * c.fraction,
            c.colour,
            c.band_hz.0,
            c.band_hz.1
        );
    }
}

/// What each figure shows, by its file stem.
fn caption(stem: &str) -> String {
    match stem {
        "responses" => "Measured response (black dots) and the segment predictions of the declared (orange, dashed) and fitted (blue) models: the first half second of each channel and a 0.1 s zoom around its largest peak.".into(),
        "residual" => "Measured minus the segment prediction over the whole record, before and after, with each residual's RMS in the legend.".into(),
        "frf" => "Frequency response (H1, from the largest input force to each channel) of the measurement and of both models' open-loop simulations driven by the same force: it does not depend on phase, so it judges a model whose open-loop response drifts.".into(),
        "identified_force" => "The internal force identified from the measurements at each DOF (N): the force the declared model lacks; zero where no force was located.".into(),
        s if s.starts_with("restoring_") => "Restoring force: the identified force against the relative displacement (mm) and velocity (m/s) of the effect's DOFs, with the fitted law (red) and, for a contact or clearance, the gap (grey, dashed).".into(),
        _ => String::new(),
    }
}

/// The figures, each with a caption, in reading order.
fn figures_section(s: &mut String, figs: &[PathBuf]) {
    let _ = writeln!(s, "\n## Figures\n");
    let order = [
        "responses",
        "residual",
        "frf",
        "restoring_",
        "identified_force",
    ];
    let mut pngs: Vec<(usize, String, String)> = figs
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "png"))
        .filter_map(|f| {
            let stem = f.file_stem()?.to_string_lossy().into_owned();
            let rank = order
                .iter()
                .position(|o| stem.starts_with(o))
                .unwrap_or(order.len());
            Some((rank, stem.clone(), format!("{stem}.png")))
        })
        .collect();
    pngs.sort();
    for (_, stem, name) in pngs {
        let _ = writeln!(s, "**{name}**: {}\n\n![{name}]({name})\n", caption(&stem));
    }
}

/// The solver's details, folded away: identification, start states, the
/// rounds of the loop, the trace's ranking, counts and time.
fn appendix(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(
        s,
        "<details>\n<summary>Solver details: how the diagnosis ran</summary>\n"
    );
    let _ = writeln!(s, "Identification: {}.\n", d.identification);
    start_states(s, d);
    loop_section(s, d);
    if let Some(c) = &d.calibration {
        let _ = writeln!(
            s,
            "\nLinear part refined with the effects found: {}.",
            c.refinement
        );
    }
    for f in &d.tolerated_failures {
        let _ = writeln!(
            s,
            "\nWent on past a failure: {} — {} (used instead: {}).",
            f.step, f.error, f.fallback
        );
    }
    let _ = writeln!(s, "\n</details>");
}

/// How the start states of the scored segments were found.
fn start_states(s: &mut String, d: &Diagnosis) {
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
        let _ = writeln!(s, "Start states of the segments ({}).", starts.join("; "));
    }
}

/// The rounds of the loop, the first trace's ranking, the cost.
fn loop_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "\nRounds of the loop:\n");
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
        let p: Vec<String> = r.parameters.iter().map(|(k, v)| with_unit(k, *v)).collect();
        let _ = writeln!(
            s,
            "| {} | {:.1} % | {:.0} | {} |",
            r.label,
            100.0 * r.residual_explained,
            r.bic_change,
            p.join(", ")
        );
    }
    let _ = writeln!(
        s,
        "\nSub-steps per sample: {} (declared model), {} (final model). Segment simulations: {} (fits, start-state refinement, errors), {} linear (trace). Time: {:.2} s.",
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

/// `text` with its first letter in upper case (a sentence).
fn sentence(text: &str) -> String {
    let mut c = text.chars();
    c.next()
        .map_or(String::new(), |f| f.to_uppercase().chain(c).collect())
}

/// The linear corrections, apart from the effects.
fn linear_corrections(s: &mut String, c: &super::calibrated::CalibrationReport) {
    let _ = writeln!(s, "\n## Linear part: corrections to the declared model\n");
    let on = &c.calibration.records;
    let _ = writeln!(
        s,
        "Springs and modal damping ratios calibrated on {} (relative output error of the linear model {:.2} % → {:.2} %), then refined with the effects found (details in the appendix). {}.\n",
        on.join(", "),
        100.0 * c.calibration.error_before,
        100.0 * c.calibration.error_after,
        sentence(&c.choice)
    );
    let _ = writeln!(
        s,
        "± is one standard error from measurement noise alone (white residual assumed); a correction is significant when it exceeds 3 standard errors and 0.5 %. Damping ratios (zeta) are dimensionless.\n"
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
    if b.screen == 0.0 {
        // [`crate::diagnose::ScreenSettings::dissipative_far`]
        return format!(
            " (below the screen: {}{pre}; a dissipative law with the damping free beside it, fitted whatever the joint linearization predicts while the error is far above the measured noise)",
            b.trace
        );
    }
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
            confirmed,
        } => format!(
            "kept: multiple-shooting error {} → {}{}{}",
            p4(*before),
            p4(*after),
            on_converged(*confirmed),
            why(below)
        ),
        Decision::Withdrawn {
            reason,
            below,
            refit_kept,
            confirmed,
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
            s = format!("{s}{}", on_converged(*confirmed));
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

/// The words for errors scored on start states refined by `iterations`
/// Gauss–Newton iterations to judge a withdrawal (empty when not).
fn on_converged(iterations: Option<usize>) -> String {
    iterations.map_or(String::new(), |n| {
        format!(" (judged on start states refined by {n} Gauss–Newton iterations)")
    })
}

/// How a round's fit ended, with the alternative law when one was tried.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Model;
    use crate::trace::{Candidate, EffectKind, RankedEffect};
    use std::collections::BTreeMap;

    /// Every parameter name an effect of each kind is reported with has a
    /// unit (none falls through to "(SI)").
    #[test]
    fn every_effect_parameter_has_a_unit() {
        let toml = "masses = [1.0, 1.0]\n[[spring]]\ndofs = [1]\nstiffness = 1000.0\n[[spring]]\ndofs = [1, 2]\nstiffness = 1000.0\n[damping]\nkind = \"modal\"\nratio = 0.02\n";
        let kinds = [
            EffectKind::Contact,
            EffectKind::Friction,
            EffectKind::Cubic,
            EffectKind::Stiffness,
            EffectKind::GroundSpring,
            EffectKind::Damping,
            EffectKind::Quadratic,
            EffectKind::QuadraticDamping,
            EffectKind::CubicDamping,
            EffectKind::Clearance,
            EffectKind::RelativeFriction,
        ];
        for kind in kinds {
            let mut model = Model::from_toml_str(toml, "two").unwrap();
            let mut candidate = Candidate::new(kind, vec![0, 1]);
            candidate.spring = Some(1);
            let r = RankedEffect {
                candidate,
                label: kind.name().into(),
                parameters: vec![],
                std_errors: vec![],
                residual_explained: 0.5,
                force_explained: None,
                bic_change: -1.0,
                hidden: vec![],
            };
            let added = super::super::effects::add(&mut model, &r);
            for name in &added.names {
                let sh = shown(name);
                assert_ne!(sh.unit, "(SI)", "{kind:?}: {name}");
                assert!(with_unit(name, 1e-3).ends_with(sh.unit), "{name}");
            }
        }
    }

    fn contact() -> EffectReport {
        let map = |v: &[(&str, f64)]| -> BTreeMap<String, f64> {
            v.iter().map(|(k, x)| (k.to_string(), *x)).collect()
        };
        EffectReport {
            kind: EffectKind::Contact,
            dofs: vec![5, 6],
            label: "contact 5→6".into(),
            parameters: map(&[("gap", 3.9305e-4), ("stiffness", 2.1453e6)]),
            std_errors: [("gap", Some(1.4e-7)), ("stiffness", Some(1.9e3))]
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect(),
            group_estimates: [
                ("gap", vec![3.8155e-4, 3.8033e-4, 3.8172e-4, 3.8249e-4]),
                ("stiffness", vec![2.026e6, 2.005e6, 1.997e6, 2.056e6]),
            ]
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect(),
            traced: BTreeMap::new(),
            undetermined: vec![],
            unobservable: vec![],
            score: super::super::outcome::Score {
                residual_explained: 0.428,
                bic_change: -1.0,
                force_explained: None,
                error_before: Some(0.694),
                error_after: Some(0.0319),
            },
        }
    }

    /// The gap in mm with both ± in mm: the noise one as given, the one
    /// across the record the quarters' standard error combined with their
    /// mean's distance from the value (0.3815 against 0.39305 mm).
    #[test]
    fn parameter_rows_carry_units_and_both_spreads() {
        let e = contact();
        let (mean, se_q) = e.quarters("gap").unwrap();
        approx::assert_relative_eq!(mean, 3.815225e-4, max_relative = 1e-9);
        approx::assert_relative_eq!(se_q, 4.5e-7, max_relative = 0.05);
        let spread = e.spread_error("gap").unwrap();
        approx::assert_relative_eq!(
            spread,
            (mean - 3.9305e-4f64).hypot(se_q),
            max_relative = 1e-12
        );
        let row = parameter_row(&e, "gap", 3.9305e-4, true);
        assert_eq!(
            row,
            "| contact 5→6 | gap | 0.39305 mm | 0.00014 mm | 0.01154 mm | 0.38155, 0.38033, 0.38172, 0.38249 mm |"
        );
        let row = parameter_row(&e, "stiffness", 2.1453e6, false);
        assert!(
            row.starts_with("|  | stiffness | 2.1453e6 N/m | 1.9e3 N/m | 1."),
            "{row}"
        );
        let mut s = String::new();
        offset_note(&mut s, &e);
        assert!(s.contains("gap 0.38152 mm against 0.39305 mm"), "{s}");
        let mut near = e.clone();
        near.parameters.insert("gap".into(), 3.8152e-4);
        near.parameters.insert("stiffness".into(), 2.02e6);
        let mut s = String::new();
        offset_note(&mut s, &near);
        assert!(s.is_empty(), "{s}");
    }

    /// A stop against ground whose gap's standard error (1.6 m) dwarfs
    /// the gap (0.012 mm) is said not to be determined; known to trade
    /// with the rigid-body position it is said not to be observable, with
    /// that cause; a determined gap (the bumper's) gets no sentence.
    #[test]
    fn a_gap_the_noise_could_move_by_more_than_itself_is_not_determined() {
        let mut stop = contact();
        stop.dofs = vec![8];
        stop.label = "contact @8".into();
        stop.parameters.insert("gap".into(), 1.2045e-5);
        stop.std_errors.insert("gap".into(), Some(1.6));
        stop.undetermined = super::super::outcome::undetermined(&stop.parameters, &stop.std_errors);
        assert_eq!(stop.undetermined, vec!["gap".to_string()]);
        let mut s = String::new();
        undetermined_note(&mut s, &stop);
        assert!(s.contains("contact @8: not determined"), "{s}");
        assert!(s.contains("(gap 0.012045 mm ± 1600"), "{s}");
        assert!(!s.contains("rigid body"), "{s}");
        // the same gap known to trade with the rigid-body position
        stop.unobservable = vec!["gap".into()];
        let mut s = String::new();
        undetermined_note(&mut s, &stop);
        assert!(
            s.contains("contact @8: not observable with these sensors"),
            "{s}"
        );
        assert!(
            s.contains("rigid body") && !s.contains("not determined"),
            "{s}"
        );
        let bumper = contact();
        assert!(
            super::super::outcome::undetermined(&bumper.parameters, &bumper.std_errors).is_empty()
        );
        let mut s = String::new();
        undetermined_note(&mut s, &bumper);
        assert!(s.is_empty(), "{s}");
    }

    #[test]
    fn sentences_start_in_upper_case() {
        assert_eq!(
            sentence("multiple-shooting error"),
            "Multiple-shooting error"
        );
        assert_eq!(sentence(""), "");
    }

    #[test]
    fn stiffness_changes_show_in_percent_and_ranking_parameters_in_units() {
        assert_eq!(with_unit("delta", 0.10571), "delta = +10.571 %");
        assert_eq!(with_unit("gap", 3.1569e-4), "gap = 0.31569 mm");
        assert_eq!(with_unit("stiffness", 4.6421e5), "stiffness = 4.6421e5 N/m");
        assert_eq!(with_unit("level", 0.3), "level = 0.30000 N");
    }

    /// The open-loop error per window: exact in the first, as large as the
    /// response (200 %: the sign flipped) in the second.
    #[test]
    fn window_errors_follow_the_drift() {
        let meas = DMatrix::from_fn(2, 8, |c, k| (k + c + 1) as f64);
        let pred = DMatrix::from_fn(
            2,
            8,
            |c, k| if k < 4 { meas[(c, k)] } else { -meas[(c, k)] },
        );
        let w = window_errors(&meas, &pred, 4);
        assert_eq!(w.len(), 2);
        assert!(w[0].abs() < 1e-15);
        approx::assert_relative_eq!(w[1], 2.0, max_relative = 1e-12);
    }
}
