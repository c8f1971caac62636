//! Input signals for simulation (band-limited random, sine sweep, impulse),
//! measurement noise, and conversions between records and matrices.
//!
//! Every random signal comes from a ChaCha8 generator seeded by the caller:
//! the same seed gives the same samples on every machine.

use crate::error::{Result, TacitError};
use crate::record::Record;
use nalgebra::DMatrix;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rustfft::{num_complex::Complex, FftPlanner};

/// Channel weights `1 / (fraction · RMS)` of each row of `y` (a channel
/// over samples), the one rule every weighted fit uses (the noise assumed
/// a fraction of each channel's RMS); None for a channel whose RMS is 0.
pub fn channel_weights(y: &DMatrix<f64>, fraction: f64) -> Vec<Option<f64>> {
    (0..y.nrows())
        .map(|r| {
            let rms = (y.row(r).norm_squared() / y.ncols().max(1) as f64).sqrt();
            (rms > 0.0).then(|| 1.0 / (fraction * rms))
        })
        .collect()
}

/// A seeded generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Samples of the force ramp that brings a random input up from rest.
pub const RAMP_SAMPLES: usize = 8;

/// Band-limited Gaussian random signal: white noise, filtered in the
/// frequency domain to `[f_lo, f_hi]` Hz (bins outside set to zero), scaled
/// to `rms`, then ramped up over the first [`RAMP_SAMPLES`] samples (a
/// half-cosine) so a simulation can start from rest.
pub fn random_band(n: usize, fs: f64, band: (f64, f64), rms: f64, seed: u64) -> Result<Vec<f64>> {
    let (lo, hi) = band;
    if !(lo >= 0.0 && hi > lo && hi <= fs / 2.0 + 1e-9) {
        return Err(TacitError::Setting(format!(
            "band {lo}..{hi} Hz must satisfy 0 <= low < high <= fs/2 = {}",
            fs / 2.0
        )));
    }
    if n < 2 {
        return Err(TacitError::Setting(
            "a random input needs >= 2 samples".into(),
        ));
    }
    let mut g = rng(seed);
    let mut buf: Vec<Complex<f64>> = (0..n)
        .map(|_| Complex::new(StandardNormal.sample(&mut g), 0.0))
        .collect();
    let mut planner = FftPlanner::new();
    planner.plan_fft_forward(n).process(&mut buf);
    let df = fs / n as f64;
    for (i, c) in buf.iter_mut().enumerate() {
        let f = if i <= n / 2 { i as f64 } else { (n - i) as f64 } * df;
        if f < lo || f > hi {
            *c = Complex::new(0.0, 0.0);
        }
    }
    planner.plan_fft_inverse(n).process(&mut buf);
    let mut x: Vec<f64> = buf.iter().map(|c| c.re).collect();
    let r = rms_of(&x);
    if r == 0.0 {
        return Err(TacitError::Setting(format!(
            "band {lo}..{hi} Hz holds no frequency bin at {n} samples and {fs} Hz"
        )));
    }
    x.iter_mut().for_each(|v| *v *= rms / r);
    for (i, v) in x.iter_mut().take(RAMP_SAMPLES).enumerate() {
        *v *= 0.5 * (1.0 - (std::f64::consts::PI * i as f64 / RAMP_SAMPLES as f64).cos());
    }
    Ok(x)
}

/// Linear sine sweep from `f0` to `f1` Hz over the record, amplitude `amp`,
/// starting at zero force with zero phase.
pub fn sine_sweep(n: usize, fs: f64, f0: f64, f1: f64, amp: f64) -> Result<Vec<f64>> {
    if !(f0 > 0.0 && f1 > 0.0 && f0.max(f1) <= fs / 2.0) {
        return Err(TacitError::Setting(format!(
            "sweep {f0}..{f1} Hz must be within (0, fs/2 = {}]",
            fs / 2.0
        )));
    }
    let dur = n as f64 / fs;
    Ok((0..n)
        .map(|k| {
            let t = k as f64 / fs;
            let phase = 2.0 * std::f64::consts::PI * (f0 * t + 0.5 * (f1 - f0) * t * t / dur);
            amp * phase.sin()
        })
        .collect())
}

/// Half-sine impulse of peak `amp` lasting `width` samples, starting at
/// sample 1 (sample 0 is zero: the structure starts at rest).
pub fn impulse(n: usize, amp: f64, width: usize) -> Result<Vec<f64>> {
    if width < 1 || width + 1 >= n {
        return Err(TacitError::Setting(format!(
            "impulse width {width} samples must be >= 1 and shorter than the record ({n})"
        )));
    }
    let mut x = vec![0.0; n];
    for (i, v) in x.iter_mut().enumerate().skip(1).take(width) {
        *v = amp * (std::f64::consts::PI * i as f64 / (width + 1) as f64).sin();
    }
    Ok(x)
}

/// Root mean square.
pub fn rms_of(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// RMS of each signal in each frequency band (Hz; `[lo, hi)`), from its
/// discrete Fourier transform at rate `fs` (Parseval: the squares of the
/// bands sum to the square of the whole RMS).
pub fn band_rms(signals: &[Vec<f64>], fs: f64, bands: &[(f64, f64)]) -> Vec<Vec<f64>> {
    let mut planner = FftPlanner::<f64>::new();
    signals
        .iter()
        .map(|x| {
            let n = x.len();
            let mut buf: Vec<Complex<f64>> = x.iter().map(|&v| Complex::new(v, 0.0)).collect();
            planner.plan_fft_forward(n).process(&mut buf);
            let mut ss = vec![0.0; bands.len()];
            for (k, c) in buf.iter().enumerate() {
                // bin k and its mirror n − k share the frequency
                let f = k.min(n - k) as f64 * fs / n as f64;
                if let Some(b) = bands.iter().position(|&(lo, hi)| f >= lo && f < hi) {
                    ss[b] += c.norm_sqr();
                }
            }
            ss.iter().map(|s| (s / (n * n) as f64).sqrt()).collect()
        })
        .collect()
}

/// Add Gaussian noise with standard deviation `fraction` × RMS of `x`.
pub fn add_noise(x: &mut [f64], fraction: f64, g: &mut ChaCha8Rng) {
    if fraction <= 0.0 {
        return;
    }
    let s = fraction * rms_of(x);
    for v in x.iter_mut() {
        let e: f64 = StandardNormal.sample(g);
        *v += s * e;
    }
}

/// External force at the model DOFs as a DOF × sample matrix.
pub fn force_matrix(rec: &Record, ndof: usize) -> DMatrix<f64> {
    let n = rec.len();
    let mut f = DMatrix::zeros(ndof, n);
    for c in &rec.inputs {
        if c.dof >= 1 && c.dof <= ndof {
            for (k, v) in c.data.iter().enumerate() {
                f[(c.dof - 1, k)] += v;
            }
        }
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random_band_has_rms_band_and_is_reproducible() {
        let x = random_band(4096, 512.0, (5.0, 200.0), 20.0, 7).unwrap();
        let y = random_band(4096, 512.0, (5.0, 200.0), 20.0, 7).unwrap();
        assert_eq!(x, y);
        let z = random_band(4096, 512.0, (5.0, 200.0), 20.0, 8).unwrap();
        assert_ne!(x, z);
        // RMS after the ramp is within 1 % of the target
        approx::assert_relative_eq!(rms_of(&x), 20.0, max_relative = 0.01);
        assert_eq!(x[0], 0.0);
        // no energy above 200 Hz (apart from the ramp's leakage)
        let mut buf: Vec<Complex<f64>> = x[RAMP_SAMPLES..]
            .iter()
            .map(|&v| Complex::new(v, 0.0))
            .collect();
        let n = buf.len();
        FftPlanner::new().plan_fft_forward(n).process(&mut buf);
        let df = 512.0 / n as f64;
        let (mut inb, mut out) = (0.0, 0.0);
        for (i, c) in buf.iter().enumerate().take(n / 2) {
            let f = i as f64 * df;
            if (5.0..=200.0).contains(&f) {
                inb += c.norm_sqr();
            } else if f > 220.0 {
                out += c.norm_sqr();
            }
        }
        assert!(out / inb < 1e-3, "out-of-band fraction {}", out / inb);
        assert!(random_band(100, 512.0, (5.0, 300.0), 1.0, 1).is_err());
    }

    #[test]
    fn noise_fraction_of_rms() {
        let mut x: Vec<f64> = (0..20000).map(|k| (k as f64 * 0.1).sin()).collect();
        let clean = x.clone();
        add_noise(&mut x, 0.05, &mut rng(3));
        let e: Vec<f64> = x.iter().zip(&clean).map(|(a, b)| a - b).collect();
        approx::assert_relative_eq!(rms_of(&e) / rms_of(&clean), 0.05, max_relative = 0.03);
    }

    #[test]
    fn sweep_and_impulse() {
        let s = sine_sweep(1000, 512.0, 5.0, 100.0, 2.0).unwrap();
        assert_eq!(s[0], 0.0);
        assert!(s.iter().all(|v| v.abs() <= 2.0));
        let p = impulse(100, 50.0, 5).unwrap();
        assert_eq!(p[0], 0.0);
        approx::assert_relative_eq!(p[3], 50.0);
        assert!(impulse(5, 1.0, 10).is_err());
    }

    #[test]
    fn band_rms_puts_each_sine_in_its_band_and_keeps_the_total() {
        let fs = 400.0;
        // 0.05 Hz bins: both lines on a bin
        let n = 8000;
        // 7 Hz (torsion band) amplitude 2, 12 Hz amplitude 1, offset 0.5
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                0.5 + 2.0 * (2.0 * std::f64::consts::PI * 7.0 * t).sin()
                    + (2.0 * std::f64::consts::PI * 12.0 * t).cos()
            })
            .collect();
        let b = band_rms(std::slice::from_ref(&x), fs, &crate::cases::f16::BANDS_HZ);
        let b = &b[0];
        approx::assert_relative_eq!(b[3], 2.0 / 2f64.sqrt(), max_relative = 1e-9);
        approx::assert_relative_eq!(b[4], 1.0 / 2f64.sqrt(), max_relative = 1e-9);
        approx::assert_relative_eq!(b[0], 0.5, max_relative = 1e-9);
        assert!(b[1] < 1e-9 && b[2] < 1e-9 && b[5] < 1e-9, "{b:?}");
        let total: f64 = b.iter().map(|v| v * v).sum::<f64>().sqrt();
        approx::assert_relative_eq!(total, rms_of(&x), max_relative = 1e-12);
    }
}
