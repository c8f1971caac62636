//! Measure each channel's noise from the record.
//!
//! The lifted smoother ([`super::lifted`]) reconstructs the states and the
//! unknown force along the located directions; what it leaves in each
//! channel is the measurement noise, the part of the noise the force and
//! the states absorb taken away, plus whatever the declared linear part
//! gets wrong. Without reweighting the smoother is a linear map of the
//! data, so the share of white noise it leaves is measured by passing
//! seeded white noise, at the same channel weights, through the same
//! smoother (a reference residual). In each of `bands` frequency bands the
//! residual's power over the reference's is the noise variance there (in
//! units of the assumed one). The channel's noise is the lower quartile
//! of the band ratios, divided by the lower quartile that white noise alone
//! gives ([`quartile_of_white`]): model error confined to fewer than three
//! bands in four does not raise it. A median is raised by what model error
//! spreads over half the bands: the forces of friction on every mass,
//! which the located directions do not take up, are broadband (with the
//! true model declared, 0.3 N of friction on a 1 % record measured 2.74 %
//! with the median, 1.88 % with the quartile). The largest band ratio over
//! the median says how coloured the residual is (Welch 1967 for
//! band-averaged periodograms; the reference replaces a
//! degrees-of-freedom count of the smoother).
//!
//! The record's level is the RMS of the channels' fractions. When it is
//! more than [`super::NoiseSettings::relocate_factor`] from the assumed
//! level it replaces that level in every noise-related threshold of the
//! diagnosis ([`super::NoiseSettings`]), unless it is above the assumed
//! level and coloured (model error, which the trace must still see, holds
//! part of it); closer, the measurement confirms
//! the assumed level, which stays (the stop rules already leave that much
//! room, and the diagnosis of a record whose noise was assumed right does
//! not move with the measurement's own scatter).

use super::lifted::{self, LiftedSettings};
use crate::error::{Result, TacitError};
use crate::linear::SampledModel;
use crate::record::Quantity;
use nalgebra::DMatrix;
use rand_distr::{Distribution, StandardNormal};
use rustfft::{num_complex::Complex, FftPlanner};
use serde::{Deserialize, Serialize};

/// Seed of the reference noise (fixed: the same record gives the same
/// measurement).
const REFERENCE_SEED: u64 = 0x006e_6f69_7365;

/// Band ratio over the median above which a channel's residual is called
/// coloured: model error, not noise, dominates that band.
pub const COLOURED: f64 = 4.0;

/// The noise measured on one channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelNoise {
    /// The channel's name in the record.
    pub channel: String,
    /// Noise standard deviation, in `unit`.
    pub std: f64,
    /// The channel's unit (SI).
    pub unit: String,
    /// `std` as a fraction of the channel's RMS.
    pub fraction: f64,
    /// The largest band's noise variance over the median band's (1 =
    /// white; above [`COLOURED`] the band holds model error).
    pub colour: f64,
    /// That band, Hz.
    pub band_hz: (f64, f64),
}

/// Whether the residual looks like noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum NoiseStatus {
    /// Every channel's band ratios stay below [`COLOURED`].
    White,
    /// The most coloured channel: the linear model misses something in
    /// that band (the level, a lower quartile over bands, stands; it is an
    /// upper bound when more than three bands in four hold model error).
    Coloured {
        /// Channel name.
        channel: String,
        /// Band, Hz.
        band_hz: (f64, f64),
        /// Band variance over the median band's.
        ratio: f64,
    },
}

/// The noise measured on a record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseEstimate {
    /// Per channel.
    pub channels: Vec<ChannelNoise>,
    /// The record's level: RMS of the channels' fractions.
    pub level: f64,
    /// The level assumed before measuring (the channel weights of the
    /// smoother that measured).
    pub assumed: f64,
    /// The level the diagnosis ran at after the measurement: `level` when
    /// far from `assumed`, else `assumed` (module docs).
    pub used: f64,
    /// Frequency bands of the measurement.
    pub bands: usize,
    /// Whether the residual looks like noise.
    pub status: NoiseStatus,
}

impl NoiseEstimate {
    /// One line for reports.
    pub fn summary(&self) -> String {
        let range = self
            .channels
            .iter()
            .map(|c| c.fraction)
            .fold((f64::INFINITY, 0.0_f64), |(lo, hi), f| {
                (lo.min(f), hi.max(f))
            });
        let colour = match &self.status {
            NoiseStatus::White => "the residual is white".to_string(),
            NoiseStatus::Coloured {
                channel,
                band_hz,
                ratio,
            } => format!(
                "the residual is coloured ({channel}: {:.0}–{:.0} Hz at {ratio:.1} × the median band: model error there)",
                band_hz.0, band_hz.1
            ),
        };
        format!(
            "measured noise {:.3} % of RMS (channels {:.3}–{:.3} %); {colour}",
            100.0 * self.level,
            100.0 * range.0,
            100.0 * range.1
        )
    }
}

/// What [`measure`] reads.
pub struct NoiseInput<'a> {
    /// The linear model's sample map.
    pub sampled: &'a SampledModel,
    /// Force directions (n × q; the identity when none were located).
    pub directions: &'a DMatrix<f64>,
    /// Known force at every DOF (n × N).
    pub known_force: &'a DMatrix<f64>,
    /// Measured outputs (p × N).
    pub measured: &'a DMatrix<f64>,
    /// `(quantity, dof0)` of each row of `measured`.
    pub channels: &'a [(Quantity, usize)],
    /// Names of the rows, for the report.
    pub names: &'a [String],
    /// Sample rate, Hz.
    pub fs: f64,
}

/// Measure the noise of every channel (module docs): `lifted` are the
/// smoother's settings (its `noise_fraction` is the assumed level),
/// `bands` the number of frequency bands.
pub fn measure(
    input: &NoiseInput<'_>,
    lifted: &LiftedSettings,
    bands: usize,
) -> Result<NoiseEstimate> {
    let (p, len) = (input.measured.nrows(), input.measured.ncols());
    if len < 2 * bands {
        return Err(TacitError::Setting(format!(
            "noise measurement: {len} samples cannot fill {bands} bands"
        )));
    }
    let s = LiftedSettings {
        reweight_passes: 0,
        ..lifted.clone()
    };
    let assumed = s.noise_fraction;
    let residual = lifted::reconstruct_along(
        input.sampled,
        input.directions,
        input.known_force,
        input.measured,
        input.channels,
        &s,
    )?
    .residual;
    let reference_data = reference_noise(input.measured);
    let zero = DMatrix::zeros(input.known_force.nrows(), len);
    let reference = lifted::reconstruct_along(
        input.sampled,
        input.directions,
        &zero,
        &reference_data,
        input.channels,
        &s,
    )?
    .residual
        * assumed;
    let mut channels = Vec::with_capacity(p);
    for c in 0..p {
        let ratios = band_ratios(&residual, &reference, c, bands);
        let rms = (input.measured.row(c).norm_squared() / len as f64).sqrt();
        channels.push(channel_noise(input, c, &ratios, assumed, rms));
    }
    if channels.iter().any(|c| !c.std.is_finite()) {
        return Err(TacitError::Numerical(
            "noise measurement: the smoother's residual is not finite".into(),
        ));
    }
    let level = (channels.iter().map(|c| c.fraction.powi(2)).sum::<f64>() / p as f64).sqrt();
    let status = status_of(&channels);
    Ok(NoiseEstimate {
        channels,
        level,
        assumed,
        used: assumed,
        bands,
        status,
    })
}

/// The noise of channel `c` from its band ratios.
fn channel_noise(
    input: &NoiseInput<'_>,
    c: usize,
    ratios: &[f64],
    assumed: f64,
    rms: f64,
) -> ChannelNoise {
    let lines = input.measured.ncols() / 2 / ratios.len().max(1);
    let level = quantile(ratios, 0.25) / quartile_of_white(ratios.len(), lines);
    let (colour, band_hz) = worst_band(ratios, input.fs);
    let fraction = assumed * level.sqrt();
    ChannelNoise {
        channel: input
            .names
            .get(c)
            .cloned()
            .unwrap_or_else(|| format!("#{c}")),
        std: fraction * rms,
        unit: input.channels[c].0.si_unit().to_string(),
        fraction,
        colour,
        band_hz,
    }
}

/// The largest of `bands` (equal bands of the one-sided spectrum at `fs`)
/// over their median, and that band in Hz.
fn worst_band(bands: &[f64], fs: f64) -> (f64, (f64, f64)) {
    let med = quantile(bands, 0.5);
    let (worst, &max) = bands
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .unwrap_or((0, &f64::NAN));
    let width = 0.5 * fs / bands.len().max(1) as f64;
    let colour = if med > 0.0 { max / med } else { f64::INFINITY };
    (colour, (worst as f64 * width, (worst + 1) as f64 * width))
}

fn status_of(channels: &[ChannelNoise]) -> NoiseStatus {
    worst_colour(channels.iter().map(|c| (&c.channel, c.colour, c.band_hz)))
}

/// White when every channel's (name, colour, band) has its colour at or
/// below [`COLOURED`], else the most coloured one.
fn worst_colour<'a>(channels: impl Iterator<Item = (&'a String, f64, (f64, f64))>) -> NoiseStatus {
    match channels
        .filter(|c| c.1 > COLOURED)
        .max_by(|a, b| a.1.total_cmp(&b.1))
    {
        None => NoiseStatus::White,
        Some((channel, ratio, band_hz)) => NoiseStatus::Coloured {
            channel: channel.clone(),
            band_hz,
            ratio,
        },
    }
}

/// What a fitted model leaves on one channel ([`remaining`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelRemaining {
    /// The channel's name in the record.
    pub channel: String,
    /// RMS of measured − predicted over the RMS of measured, on the
    /// samples predicted.
    pub fraction: f64,
    /// The largest band's residual power over the median band's (1 =
    /// white; above [`COLOURED`] the band holds model error).
    pub colour: f64,
    /// That band, Hz.
    pub band_hz: (f64, f64),
}

/// What a fitted model leaves of the record: the residual of its segment
/// predictions, per channel, and whether it is white. A white residual at
/// the level of the noise says the model explains the record; a coloured
/// one names the band where it does not. The level is an upper bound of
/// the noise, tighter than [`NoiseEstimate`]'s when the reconstruction's
/// residual is coloured (a force off the located directions).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Remaining {
    /// Per channel.
    pub channels: Vec<ChannelRemaining>,
    /// RMS of the channels' fractions.
    pub level: f64,
    /// Frequency bands of the colour test.
    pub bands: usize,
    /// White, or the most coloured channel.
    pub status: NoiseStatus,
}

impl Remaining {
    /// One line for reports.
    pub fn summary(&self) -> String {
        let (lo, hi) = self
            .channels
            .iter()
            .fold((f64::INFINITY, 0.0_f64), |(lo, hi), c| {
                (lo.min(c.fraction), hi.max(c.fraction))
            });
        let colour = match &self.status {
            NoiseStatus::White => "white: noise".to_string(),
            NoiseStatus::Coloured {
                channel,
                band_hz,
                ratio,
            } => format!(
                "coloured ({channel}: {:.0}–{:.0} Hz at {ratio:.1} × the median band: model error the fitted model leaves there)",
                band_hz.0, band_hz.1
            ),
        };
        format!(
            "{:.3} % of RMS (channels {:.3}–{:.3} %), {colour}",
            100.0 * self.level,
            100.0 * lo,
            100.0 * hi
        )
    }
}

/// What `predicted` (p × N segment predictions, NaN where a sample is not
/// predicted) leaves of `measured` (p × N), per channel named by `names`,
/// with its colour over `bands` frequency bands at `fs` (the samples not
/// predicted count as zero residual). None when fewer than half the
/// samples of a channel are predicted or a channel is zero.
pub fn remaining(
    measured: &DMatrix<f64>,
    predicted: &DMatrix<f64>,
    names: &[String],
    fs: f64,
    bands: usize,
) -> Option<Remaining> {
    let (p, n) = (measured.nrows(), measured.ncols().min(predicted.ncols()));
    if p == 0 || bands == 0 || n < 2 * bands {
        return None;
    }
    let mut channels = Vec::with_capacity(p);
    for c in 0..p {
        let mut r = vec![0.0; n];
        let (mut num, mut den, mut used) = (0.0, 0.0, 0);
        for (k, rk) in r.iter_mut().enumerate() {
            let (m, y) = (measured[(c, k)], predicted[(c, k)]);
            if y.is_finite() && m.is_finite() {
                *rk = m - y;
                num += rk.powi(2);
                den += m * m;
                used += 1;
            }
        }
        if 2 * used < n || den <= 0.0 {
            return None;
        }
        let (colour, band_hz) = worst_band(&band_powers(&r, bands), fs);
        channels.push(ChannelRemaining {
            channel: names.get(c).cloned().unwrap_or_else(|| format!("#{c}")),
            fraction: (num / den).sqrt(),
            colour,
            band_hz,
        });
    }
    let level = (channels.iter().map(|c| c.fraction.powi(2)).sum::<f64>() / p as f64).sqrt();
    let status = worst_colour(channels.iter().map(|c| (&c.channel, c.colour, c.band_hz)));
    Some(Remaining {
        channels,
        level,
        bands,
        status,
    })
}

/// Seeded white noise with exactly each row's RMS of `measured` (so the
/// smoother weighs it as it weighs the data): its weighted standard
/// deviation is `1/assumed`.
fn reference_noise(measured: &DMatrix<f64>) -> DMatrix<f64> {
    let (p, len) = (measured.nrows(), measured.ncols());
    let mut g = crate::signal::rng(REFERENCE_SEED);
    let mut z: DMatrix<f64> = DMatrix::from_fn(p, len, |_, _| StandardNormal.sample(&mut g));
    for c in 0..p {
        let target = (measured.row(c).norm_squared() / len as f64).sqrt();
        let have = (z.row(c).norm_squared() / len as f64).sqrt();
        z.row_mut(c).scale_mut(target / have);
    }
    z
}

/// Per band, the power of row `c` of `residual` over that of `reference`
/// (Hann window, `bands` equal bands of the one-sided spectrum without
/// the mean).
fn band_ratios(
    residual: &DMatrix<f64>,
    reference: &DMatrix<f64>,
    c: usize,
    bands: usize,
) -> Vec<f64> {
    let a = band_powers(&residual.row(c).iter().copied().collect::<Vec<_>>(), bands);
    let b = band_powers(&reference.row(c).iter().copied().collect::<Vec<_>>(), bands);
    a.iter()
        .zip(&b)
        .map(|(x, y)| if *y > 0.0 { x / y } else { f64::INFINITY })
        .collect()
}

/// Power of `x` (Hann-windowed periodogram) summed over `bands` equal
/// bands of lines 1..=N/2.
fn band_powers(x: &[f64], bands: usize) -> Vec<f64> {
    let n = x.len();
    let mean = x.iter().sum::<f64>() / n as f64;
    let mut buf: Vec<Complex<f64>> = x
        .iter()
        .enumerate()
        .map(|(k, v)| {
            let w = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / n as f64).cos();
            Complex::new((v - mean) * w, 0.0)
        })
        .collect();
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    let lines = n / 2;
    let mut out = vec![0.0; bands];
    for (l, z) in buf.iter().enumerate().take(lines + 1).skip(1) {
        let b = ((l - 1) * bands / lines).min(bands - 1);
        out[b] += z.norm_sqr();
    }
    out
}

/// The `q` quantile of the finite values of `x` (linear interpolation
/// between order statistics at position `q (n − 1)`: the median at 0.5,
/// the lower quartile at 0.25); NaN when none.
fn quantile(x: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let at = q * (v.len() - 1) as f64;
    let (i, t) = (at.floor() as usize, at.fract());
    v[i] * (1.0 - t) + v[(i + 1).min(v.len() - 1)] * t
}

/// The expected lower quartile ([`quantile`] at 0.25) of `bands` band ratios
/// of white noise over white noise, each band `lines` lines of a Hann
/// periodogram. Adjacent Hann lines of white noise correlate at −2/3 in
/// amplitude (4/9 in power), lines two apart at 1/6 (1/36), so a band's
/// power has relative variance `(1 + 2·4/9 + 2/36) / lines`; the log of
/// the ratio of two independent bands is near normal with twice that
/// variance, and the quartile's order statistic sits at Blom's normal
/// score (Blom 1958) of its interpolated rank.
pub fn quartile_of_white(bands: usize, lines: usize) -> f64 {
    if bands < 2 || lines == 0 {
        return 1.0;
    }
    let var_band = (1.0 + 2.0 * 4.0 / 9.0 + 2.0 / 36.0) / lines as f64;
    let sd = (2.0 * var_band).sqrt();
    let rank = 0.25 * (bands - 1) as f64 + 1.0;
    let p = (rank - 0.375) / (bands as f64 + 0.25);
    (normal_quantile(p) * sd).exp()
}

/// The standard normal quantile (Acklam's rational approximation, relative
/// error below 1.2e-9).
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Band powers of white noise are equal within their scatter, and a
    /// sine adds to its band only.
    #[test]
    fn band_powers_put_a_sine_in_its_band() {
        let mut g = crate::signal::rng(3);
        let n = 4096;
        let noise: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut g)).collect();
        let white = band_powers(&noise, 16);
        let m = quantile(&white, 0.5);
        assert!(white.iter().all(|w| (w / m - 1.0).abs() < 0.4), "{white:?}");
        // 100 Hz at fs 512: band 100 / 16 = 6
        let sine: Vec<f64> = (0..n)
            .map(|k| noise[k] + 5.0 * (2.0 * std::f64::consts::PI * 100.0 * k as f64 / 512.0).sin())
            .collect();
        let p = band_powers(&sine, 16);
        assert!(p[6] / m > 50.0, "{}", p[6] / m);
        assert!((quantile(&p, 0.5) / m - 1.0).abs() < 0.1);
    }

    /// A prediction that leaves white noise of 2 % of the signal's RMS is
    /// white at 2 %, with gaps (samples not predicted) between segments;
    /// one that also misses a 60 Hz line is coloured in the band of 60 Hz.
    #[test]
    fn what_a_model_leaves_is_white_noise_or_names_its_band() {
        let mut g = crate::signal::rng(5);
        let (n, fs) = (4096, 512.0);
        let signal: Vec<f64> = (0..n)
            .map(|k| (2.0 * std::f64::consts::PI * 20.0 * k as f64 / fs).sin())
            .collect();
        let rms = (0.5_f64).sqrt();
        let measured = DMatrix::from_fn(2, n, |c, k| (1.0 + c as f64) * signal[k]);
        let noise: Vec<f64> = (0..2 * n)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut g);
                0.02 * rms * z
            })
            .collect();
        let predicted = |line: f64| {
            DMatrix::from_fn(2, n, |c, k| {
                if k % 51 == 50 {
                    return f64::NAN;
                }
                let miss = line * (2.0 * std::f64::consts::PI * 60.0 * k as f64 / fs).sin();
                (1.0 + c as f64) * (signal[k] - noise[c * n + k] - miss)
            })
        };
        let names = ["a".to_string(), "b".to_string()];
        let white = remaining(&measured, &predicted(0.0), &names, fs, 16).unwrap();
        assert_eq!(white.status, NoiseStatus::White, "{}", white.summary());
        assert!((white.level / 0.02 - 1.0).abs() < 0.05, "{}", white.level);
        let line = remaining(&measured, &predicted(0.05), &names, fs, 16).unwrap();
        match line.status {
            NoiseStatus::Coloured { band_hz, .. } => assert_eq!(band_hz, (48.0, 64.0)),
            s => panic!("{s:?}"),
        }
        // half the samples predicted: still a verdict; a third: none
        let sparse = DMatrix::from_fn(2, n, |_, k| if k % 2 == 0 { f64::NAN } else { 0.0 });
        assert!(remaining(&measured, &sparse, &names, fs, 16).is_some());
        let sparser = DMatrix::from_fn(2, n, |_, k| if k % 3 == 0 { 0.0 } else { f64::NAN });
        assert!(remaining(&measured, &sparser, &names, fs, 16).is_none());
    }

    /// The quartile of white-noise band ratios over white noise, by
    /// simulation, is what [`quartile_of_white`] says.
    #[test]
    fn the_quartile_of_white_noise_ratios_is_predicted() {
        let mut g = crate::signal::rng(11);
        let (n, bands) = (4096, 16);
        let mut sum = 0.0;
        let trials = 200;
        for _ in 0..trials {
            let mut white =
                || -> Vec<f64> { (0..n).map(|_| StandardNormal.sample(&mut g)).collect() };
            let (a, b) = (band_powers(&white(), bands), band_powers(&white(), bands));
            let r: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x / y).collect();
            sum += quantile(&r, 0.25).ln();
        }
        let measured = (sum / trials as f64).exp();
        let predicted = quartile_of_white(bands, n / 2 / bands);
        assert!(
            (measured / predicted - 1.0).abs() < 0.015,
            "{measured} against {predicted}"
        );
        assert!(predicted < 0.93, "{predicted}");
    }

    #[test]
    fn normal_quantiles() {
        assert!(normal_quantile(0.5).abs() < 1e-12);
        assert!((normal_quantile(0.25) + 0.674_489_750).abs() < 1e-8);
        assert!((normal_quantile(0.975) - 1.959_963_985).abs() < 1e-8);
        assert!((normal_quantile(0.001) + 3.090_232_306).abs() < 1e-7);
    }

    #[test]
    fn lower_quartile_interpolates() {
        assert_eq!(quantile(&[4.0, 1.0, 3.0, 2.0, 5.0], 0.25), 2.0);
        assert_eq!(quantile(&[4.0, 1.0, 2.0, 3.0], 0.25), 1.75);
        assert!(quantile(&[], 0.25).is_nan());
    }

    #[test]
    fn median_of_even_and_odd() {
        assert_eq!(quantile(&[3.0, 1.0, 2.0], 0.5), 2.0);
        assert_eq!(quantile(&[4.0, 1.0, 2.0, 3.0], 0.5), 2.5);
        assert!(quantile(&[], 0.5).is_nan());
    }
}
