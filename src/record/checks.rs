//! Sanity checks of a record before it is diagnosed: a missing or dead
//! force, dead channels, clipped channels (runs of equal extreme values),
//! isolated spikes, offsets and drift of accelerations, and a response
//! scale that disagrees with the model's by a factor near g = 9.81 or
//! 1000 (accelerations in g, force in kN, displacements in mm).
//!
//! Pure functions over the record's numbers: each returns [`Finding`]s
//! naming the channel by its name in the file (`accel_6`), never by an
//! index. A finding of [`Severity::Error`] means the record cannot be
//! diagnosed as it is (no force, a selected channel that holds nothing).

use super::{Channel, Quantity, Record};
use serde::Serialize;

/// How serious a finding is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// The run goes on; the report carries the warning.
    Warning,
    /// The record cannot be used as it is.
    Error,
}

/// What a finding is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// The record holds no force channel.
    NoForce,
    /// A channel's samples are all equal.
    DeadChannel,
    /// Runs of equal values at a channel's extremes.
    Clipped,
    /// Samples far outside the rest of a channel, alone.
    Spike,
    /// An acceleration whose mean is far from zero.
    Offset,
    /// An acceleration with a linear trend.
    Drift,
    /// Mean accelerations that do not balance the mean force over a
    /// rigid-body mode (an accelerometer offset).
    Momentum,
    /// Responses larger or smaller than the model predicts from the force
    /// by a factor near a unit conversion (9.81, 1000).
    Scale,
    /// Values so large that sums of their squares overflow.
    Magnitude,
}

/// Largest magnitude a sample may have: sums of squares over a record
/// (errors, fits, norms) stay within double precision (1.8e308) for up to
/// 1e100 samples of it; no physical quantity in SI units comes near.
pub const MAX_MAGNITUDE: f64 = 1e100;

/// One finding of the checks.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// What it is about.
    pub kind: Kind,
    /// How serious.
    pub severity: Severity,
    /// The channel's name (`accel_6`), when it is about one channel.
    pub channel: Option<String>,
    /// The facts, in words.
    pub message: String,
}

impl std::fmt::Display for Finding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

/// Thresholds of the checks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckSettings {
    /// Least run of equal extreme values counted as clipping, samples.
    pub clip_run: usize,
    /// Share of samples on the rails above which clipping is an error.
    pub clip_error_share: f64,
    /// A spike deviates from the median by more than this many robust
    /// standard deviations (1.4826 × MAD)…
    pub spike_sigmas: f64,
    /// …and by more than this many times its neighbours' deviations.
    pub spike_isolation: f64,
    /// An acceleration mean above this fraction of its standard deviation
    /// is an offset.
    pub offset_share: f64,
    /// An acceleration whose linear trend changes by more than this
    /// fraction of its standard deviation over the record drifts.
    pub drift_share: f64,
    /// A rigid-body momentum balance off by more than this fraction of
    /// the force's RMS flags an offset.
    pub momentum_share: f64,
    /// A scale ratio within this factor of 9.81 or 1000 (or their
    /// inverses) is flagged as a probable unit error.
    pub unit_tolerance: f64,
    /// A scale ratio beyond this factor (either way) is flagged.
    pub scale_limit: f64,
}

impl Default for CheckSettings {
    fn default() -> Self {
        CheckSettings {
            clip_run: 3,
            clip_error_share: 0.25,
            spike_sigmas: 50.0,
            spike_isolation: 10.0,
            offset_share: 0.1,
            drift_share: 0.5,
            momentum_share: 0.01,
            unit_tolerance: 1.6,
            scale_limit: 4.0,
        }
    }
}

/// Every check that needs only the record. `selected`: the output DOFs
/// the run will use (a dead channel there is an error); `None` = all.
pub fn check_record(rec: &Record, selected: Option<&[usize]>, s: &CheckSettings) -> Vec<Finding> {
    let mut out = vec![];
    if rec.inputs.is_empty() {
        out.push(Finding {
            kind: Kind::NoForce,
            severity: Severity::Error,
            channel: None,
            message: "the record has no force channel: the model's response to the test cannot be computed (add the measured force as force_<dof>)".into(),
        });
    }
    for c in &rec.inputs {
        if let Some(f) = dead(c, Severity::Error) {
            out.push(f);
        }
    }
    out.extend(magnitudes(rec));
    for c in &rec.outputs {
        let used = selected.is_none_or(|d| d.contains(&c.dof));
        let sev = if used {
            Severity::Error
        } else {
            Severity::Warning
        };
        if let Some(f) = dead(c, sev) {
            out.push(f);
            continue;
        }
        out.extend(clipped(c, s));
        out.extend(spikes(c, rec.fs, s));
        if c.quantity == Quantity::Accel {
            out.extend(offset_and_drift(c, s));
        }
    }
    for c in &rec.inputs {
        if dead(c, Severity::Error).is_none() {
            out.extend(clipped(c, s));
            out.extend(spikes(c, rec.fs, s));
        }
    }
    out
}

/// The first channel holding a sample above [`MAX_MAGNITUDE`], with a
/// count of the others.
pub fn magnitudes(rec: &Record) -> Option<Finding> {
    let huge: Vec<Finding> = rec
        .inputs
        .iter()
        .chain(&rec.outputs)
        .filter_map(|c| magnitude(c, rec.fs))
        .collect();
    let mut f = huge.first()?.clone();
    if huge.len() > 1 {
        f.message += &format!(" ({} other channels too)", huge.len() - 1);
    }
    Some(f)
}

/// A channel holding a sample above [`MAX_MAGNITUDE`] (an error).
pub fn magnitude(c: &Channel, fs: f64) -> Option<Finding> {
    let (k, x) = c
        .data
        .iter()
        .enumerate()
        .find(|(_, x)| x.abs() > MAX_MAGNITUDE)?;
    Some(Finding {
        kind: Kind::Magnitude,
        severity: Severity::Error,
        channel: Some(c.name()),
        message: format!(
            "channel {} holds {x:.4e} {} at sample {k} (t = {:.4} s): beyond {MAX_MAGNITUDE:e} the sums of squares of its errors and fits overflow double precision; check the channel's units or scale",
            c.name(),
            c.unit,
            k as f64 / fs
        ),
    })
}

/// A channel whose samples are all equal.
pub fn dead(c: &Channel, severity: Severity) -> Option<Finding> {
    let first = *c.data.first()?;
    if c.data.iter().any(|&x| x != first) {
        return None;
    }
    let used = if severity == Severity::Error {
        " and is used by this run"
    } else {
        ""
    };
    Some(Finding {
        kind: Kind::DeadChannel,
        severity,
        channel: Some(c.name()),
        message: format!(
            "channel {} is dead: all {} samples equal {first} {}{used}",
            c.name(),
            c.data.len(),
            c.unit
        ),
    })
}

/// Runs of equal values at the channel's maximum or minimum.
pub fn clipped(c: &Channel, s: &CheckSettings) -> Option<Finding> {
    let (lo, hi) = c
        .data
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let (mut rail, mut longest, mut run) = (0usize, 0usize, 0usize);
    let mut prev = f64::NAN;
    for &x in &c.data {
        if x == hi || x == lo {
            run = if x == prev { run + 1 } else { 1 };
            if run == s.clip_run {
                rail += s.clip_run;
            } else if run > s.clip_run {
                rail += 1;
            }
            longest = longest.max(run);
        } else {
            run = 0;
        }
        prev = x;
    }
    if longest < s.clip_run {
        return None;
    }
    let share = rail as f64 / c.data.len() as f64;
    Some(Finding {
        kind: Kind::Clipped,
        severity: if share >= s.clip_error_share {
            Severity::Error
        } else {
            Severity::Warning
        },
        channel: Some(c.name()),
        message: format!(
            "channel {} looks clipped: {rail} samples ({:.1} %) sit in runs of equal values at its extremes {lo} / {hi} {} (longest run {longest})",
            c.name(),
            100.0 * share,
            c.unit
        ),
    })
}

/// Median of a copy of `x`.
fn median(x: &[f64]) -> f64 {
    let mut v = x.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Isolated samples far from the rest of the channel.
pub fn spikes(c: &Channel, fs: f64, s: &CheckSettings) -> Option<Finding> {
    let n = c.data.len();
    if n < 5 {
        return None;
    }
    let med = median(&c.data);
    let dev: Vec<f64> = c.data.iter().map(|x| (x - med).abs()).collect();
    let sigma = 1.4826 * median(&dev);
    if sigma <= 0.0 {
        return None;
    }
    let found: Vec<usize> = (0..n)
        .filter(|&k| {
            let near = [k.wrapping_sub(1), k + 1]
                .iter()
                .filter_map(|&j| dev.get(j))
                .fold(0.0f64, |a, &b| a.max(b));
            dev[k] > s.spike_sigmas * sigma && dev[k] > s.spike_isolation * near
        })
        .collect();
    let &k = found.first()?;
    Some(Finding {
        kind: Kind::Spike,
        severity: Severity::Warning,
        channel: Some(c.name()),
        message: format!(
            "channel {} has {} isolated spike(s), the first at sample {k} (t = {:.4} s): {} {}, {:.0} times the channel's robust standard deviation",
            c.name(),
            found.len(),
            k as f64 / fs,
            c.data[k],
            c.unit,
            dev[k] / sigma
        ),
    })
}

/// Mean and linear trend of an acceleration (an acceleration that stays
/// bounded in velocity has a mean near zero and no trend).
pub fn offset_and_drift(c: &Channel, s: &CheckSettings) -> Vec<Finding> {
    let n = c.data.len() as f64;
    let mean = c.data.iter().sum::<f64>() / n;
    let var = c.data.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    let std = var.sqrt();
    let mut out = vec![];
    if !(std > 0.0) {
        return out;
    }
    if mean.abs() > s.offset_share * std {
        out.push(Finding {
            kind: Kind::Offset,
            severity: Severity::Warning,
            channel: Some(c.name()),
            message: format!(
                "channel {} has an offset: mean {mean:.4} {} against a standard deviation of {std:.4} (an acceleration that stays bounded averages near zero)",
                c.name(),
                c.unit
            ),
        });
    }
    let kc = (n - 1.0) / 2.0;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (k, x) in c.data.iter().enumerate() {
        let dk = k as f64 - kc;
        sxy += dk * (x - mean);
        sxx += dk * dk;
    }
    let change = (sxy / sxx) * (n - 1.0);
    if change.abs() > s.drift_share * std {
        out.push(Finding {
            kind: Kind::Drift,
            severity: Severity::Warning,
            channel: Some(c.name()),
            message: format!(
                "channel {} drifts: its linear trend changes by {change:.4} {} over the record, {:.2} standard deviations",
                c.name(),
                c.unit,
                change.abs() / std
            ),
        });
    }
    out
}

/// The time mean of the equation of motion projected on a rigid-body
/// mode φ of a structure with no element to ground: `Σᵢ cᵢ āᵢ = Σⱼ φⱼ f̄ⱼ`
/// with `c = φᵀM` (springs, damping and internal elements cancel).
#[derive(Debug, Clone, PartialEq)]
pub struct Balance {
    /// (acceleration channel, coefficient cᵢ in kg, mean āᵢ in m/s²).
    pub terms: Vec<(String, f64, f64)>,
    /// `Σⱼ φⱼ f̄ⱼ`, N.
    pub force_mean: f64,
    /// RMS of `Σⱼ φⱼ fⱼ(t)`, N.
    pub force_rms: f64,
    /// RMS of `Σᵢ cᵢ aᵢ(t)`, N (equal to `force_rms` when the record
    /// balances; far from it when a unit is wrong).
    pub inertia_rms: f64,
}

/// An accelerometer offset seen as a rigid-body momentum balance that
/// does not close: the finding names the channels whose means weigh most.
pub fn momentum(b: &Balance, s: &CheckSettings) -> Option<Finding> {
    let lhs: f64 = b.terms.iter().map(|(_, c, m)| c * m).sum();
    let residual = lhs - b.force_mean;
    let scale = b.force_rms.max(b.inertia_rms);
    if !(scale > 0.0) || residual.abs() <= s.momentum_share * scale {
        return None;
    }
    let mut weigh: Vec<&(String, f64, f64)> = b.terms.iter().collect();
    weigh.sort_by(|x, y| (y.1 * y.2).abs().total_cmp(&(x.1 * x.2).abs()));
    let top: Vec<String> = weigh
        .iter()
        .take(2)
        .map(|(n, c, m)| {
            format!(
                "{n} (mean {m:.4} m/s^2; an offset of {:.4} m/s^2 there explains it)",
                residual / c
            )
        })
        .collect();
    Some(Finding {
        kind: Kind::Momentum,
        severity: Severity::Warning,
        channel: weigh.first().map(|t| t.0.clone()),
        message: format!(
            "the mean accelerations do not balance the mean force over the rigid-body motion: Σ m·ā − F̄ = {residual:.4} N, {:.1} % of the force's RMS; an accelerometer probably has an offset; the largest terms: {}",
            100.0 * residual.abs() / scale,
            top.join(", ")
        ),
    })
}

/// Compare the measured RMS of each response channel with the RMS the
/// model predicts from the measured force: `pairs` holds (channel name,
/// measured RMS, model RMS). One finding for the record when the median
/// ratio is near a unit factor or beyond `scale_limit`.
pub fn scale(pairs: &[(String, f64, f64)], s: &CheckSettings) -> Option<Finding> {
    let ratios: Vec<f64> = pairs
        .iter()
        .filter(|(_, m, p)| *m > 0.0 && *p > 0.0 && m.is_finite() && p.is_finite())
        .map(|(_, m, p)| m / p)
        .collect();
    if ratios.is_empty() {
        return None;
    }
    let r = median(&ratios);
    let near = |f: f64| (r / f).ln().abs() < s.unit_tolerance.ln();
    let hint = if near(1.0 / crate::record::units::G0) {
        Some("the accelerations look like they are in g (set the channel unit to \"g\" or convert to m/s^2)")
    } else if near(crate::record::units::G0) {
        Some("the accelerations look 9.81 times too large (in m/s^2 read as g?), or the force is in kgf")
    } else if near(1e3) {
        Some("the force looks like it is in kN, or the responses in mm (set the unit attribute or convert to N and m)")
    } else if near(1e-3) {
        Some("the force looks 1000 times too large (in mN?), or the responses 1000 times too small")
    } else {
        None
    };
    if hint.is_none() && r < s.scale_limit && r > 1.0 / s.scale_limit {
        return None;
    }
    let names: Vec<&str> = pairs.iter().map(|p| p.0.as_str()).collect();
    Some(Finding {
        kind: Kind::Scale,
        severity: Severity::Warning,
        channel: None,
        message: format!(
            "the measured responses ({}) are {r:.3} times what the model predicts from the measured force (median over channels){}",
            names.join(", "),
            hint.map_or(String::new(), |h| format!(": {h}"))
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        // a deterministic, smooth-enough test signal: sum of sines
        (0..n)
            .map(|k| {
                let t = k as f64 / 512.0;
                (2.0 * std::f64::consts::PI * 23.0 * t + seed as f64).sin()
                    + 0.6 * (2.0 * std::f64::consts::PI * 61.3 * t).sin()
                    + 0.3 * (2.0 * std::f64::consts::PI * 97.1 * t + 1.0).sin()
            })
            .collect()
    }

    fn record() -> Record {
        Record {
            t0: 0.0,
            fs: 512.0,
            inputs: vec![Channel::new(Quantity::Force, 1, noise(2048, 3))],
            outputs: (1..=4)
                .map(|d| Channel::new(Quantity::Accel, d, noise(2048, d as u64)))
                .collect(),
            truth: None,
            source: "r.h5".into(),
        }
    }

    #[test]
    fn clean_record_has_no_finding() {
        let f = check_record(&record(), None, &CheckSettings::default());
        assert!(f.is_empty(), "{f:?}");
    }

    #[test]
    fn huge_values_are_an_error_naming_channel_and_sample() {
        let mut r = record();
        r.outputs[1].data[37] = 2e300;
        let f = check_record(&r, None, &CheckSettings::default());
        let big: Vec<_> = f.iter().filter(|f| f.kind == Kind::Magnitude).collect();
        assert_eq!(big.len(), 1, "{f:?}");
        assert_eq!(big[0].severity, Severity::Error);
        assert_eq!(big[0].channel.as_deref(), Some("accel_2"));
        assert!(big[0].message.contains("2.0000e300") && big[0].message.contains("sample 37"));
    }

    #[test]
    fn dead_channel_is_named_and_an_error_only_when_used() {
        let mut r = record();
        r.outputs[3].data.fill(0.0);
        let f = check_record(&r, None, &CheckSettings::default());
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].channel.as_deref(), Some("accel_4"));
        assert_eq!(f[0].severity, Severity::Error);
        assert!(f[0].message.contains("accel_4 is dead"), "{}", f[0]);
        let f = check_record(&r, Some(&[1, 2]), &CheckSettings::default());
        assert_eq!(f[0].severity, Severity::Warning);
    }

    #[test]
    fn no_force_is_an_error() {
        let mut r = record();
        r.inputs.clear();
        let f = check_record(&r, None, &CheckSettings::default());
        assert_eq!(f[0].kind, Kind::NoForce);
        assert_eq!(f[0].severity, Severity::Error);
    }

    #[test]
    fn clipping_is_measured() {
        let mut r = record();
        for x in &mut r.outputs[1].data {
            *x = x.clamp(-0.5, 0.5);
        }
        let f = check_record(&r, None, &CheckSettings::default());
        assert_eq!(f.len(), 1, "{f:?}");
        assert_eq!(f[0].kind, Kind::Clipped);
        assert_eq!(f[0].channel.as_deref(), Some("accel_2"));
        // clamped at ±0.5 of a ±1.9 signal: most samples are on the rails
        assert_eq!(f[0].severity, Severity::Error, "{}", f[0]);
        let share: f64 =
            r.outputs[1].data.iter().filter(|x| x.abs() == 0.5).count() as f64 / 2048.0;
        assert!(share > 0.25, "{share}");
    }

    #[test]
    fn one_spike_is_found_at_its_sample() {
        let mut r = record();
        r.outputs[2].data[700] = 1e6;
        let f = check_record(&r, None, &CheckSettings::default());
        assert_eq!(f.len(), 1, "{f:?}");
        assert_eq!(f[0].kind, Kind::Spike);
        assert!(f[0].message.contains("sample 700"), "{}", f[0]);
    }

    #[test]
    fn offset_and_drift_are_found() {
        let mut r = record();
        for x in &mut r.outputs[0].data {
            *x += 5.0;
        }
        for (k, x) in r.outputs[1].data.iter_mut().enumerate() {
            *x += 2.0 * k as f64 / 2048.0;
        }
        let f = check_record(&r, None, &CheckSettings::default());
        let kinds: Vec<_> = f
            .iter()
            .map(|f| (f.kind, f.channel.clone().unwrap()))
            .collect();
        assert!(
            kinds.contains(&(Kind::Offset, "accel_1".into())),
            "{kinds:?}"
        );
        assert!(
            kinds.contains(&(Kind::Drift, "accel_2".into())),
            "{kinds:?}"
        );
        assert!(!kinds.iter().any(|k| k.1 == "accel_1" && k.0 == Kind::Drift));
    }

    #[test]
    fn momentum_balance_names_the_offset() {
        let s = CheckSettings::default();
        let mut b = Balance {
            terms: vec![
                ("accel_1".into(), 0.5, 0.01),
                ("accel_2".into(), 0.4, 2.45),
                ("accel_3".into(), 0.4, -2.46),
            ],
            force_mean: 0.0,
            force_rms: 20.0,
            inertia_rms: 20.0,
        };
        assert!(momentum(&b, &s).is_none());
        b.terms[2].2 += 5.0;
        let f = momentum(&b, &s).unwrap();
        assert_eq!(f.channel.as_deref(), Some("accel_3"));
        assert!(f.message.contains("an offset of 5.0025 m/s^2"), "{f}");
    }

    #[test]
    fn scale_flags_units() {
        let s = CheckSettings::default();
        let p = |r: f64| {
            vec![
                ("accel_1".to_string(), r, 1.0),
                ("accel_5".to_string(), r * 1.2, 1.0),
            ]
        };
        assert!(scale(&p(1.0), &s).is_none());
        assert!(scale(&p(0.6), &s).is_none());
        let g = scale(&p(1.0 / 9.81), &s).unwrap();
        assert!(g.message.contains("in g"), "{g}");
        let k = scale(&p(1e-3 * 1.1), &s).unwrap();
        assert!(k.message.contains("in mN?"), "{k}");
        let kn = scale(&p(1e3), &s).unwrap();
        assert!(kn.message.contains("in kN"), "{kn}");
        let far = scale(&p(30.0), &s).unwrap();
        assert!(far.message.contains("33.000 times"), "{far}");
    }
}
