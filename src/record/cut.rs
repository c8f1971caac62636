//! Parts of a record chosen on the command line, and the force of a
//! band-limited acquisition made fit for tacit's integrators.
//!
//! A benchmark gives its estimation and test data as sample ranges of one
//! file (the Silverbox: estimation on samples 40650–127400, test on
//! 100–40575); [`SampleRange`] cuts them out. Every simulation in tacit
//! (the Newmark integrator, the sampled model of the identification and
//! of the calibration) takes the force as linear between samples. A
//! measured force is band-limited instead: the piecewise-linear force
//! through its samples has the spectrum `F(f) sinc²(f/fs)` in the band
//! (and images above Nyquist), 31 % low at a third of the sample rate.
//! [`Record::with_band_limited_force`] divides the force channels'
//! spectrum by `sinc²(f/fs)`, so that the piecewise-linear force through
//! the new samples has the measured samples' spectrum below Nyquist.

use super::Record;
use crate::error::{Result, TacitError};
use rustfft::{num_complex::Complex, FftPlanner};

/// Samples `start..end` of a record (0-based, `end` excluded).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SampleRange {
    /// First sample kept.
    pub start: usize,
    /// One past the last sample kept.
    pub end: usize,
}

impl SampleRange {
    /// Parse `START..END` (0-based, END excluded, START < END); the error
    /// repeats the value and the rule.
    pub fn parse(s: &str) -> std::result::Result<SampleRange, String> {
        let rule =
            "give START..END, whole samples from 0, END excluded, START < END (e.g. 40650..127400)";
        let (a, b) = s
            .trim()
            .split_once("..")
            .ok_or_else(|| format!("'{s}': {rule}"))?;
        let num = |t: &str| {
            t.trim()
                .parse::<usize>()
                .map_err(|_| format!("'{s}': {rule}"))
        };
        let (start, end) = (num(a)?, num(b)?);
        if start >= end {
            return Err(format!("'{s}': START must be below END; {rule}"));
        }
        Ok(SampleRange { start, end })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.end - self.start
    }

    /// Always false (a range holds at least one sample).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The samples of `rec` in this range (a new record whose `t0` is the
    /// time of `start`); an error naming the record and its length when
    /// the range is not within it.
    pub fn cut(&self, rec: &Record) -> Result<Record> {
        let n = rec.len();
        if self.end > n {
            return Err(TacitError::record(
                rec.source.clone(),
                format!(
                    "samples {}..{} are not within the record's {n} samples (0..{n})",
                    self.start, self.end
                ),
            ));
        }
        rec.slice(self.start, self.end)
    }
}

impl std::fmt::Display for SampleRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}..{}", self.start, self.end)
    }
}

/// `x` with its spectrum divided by `sinc²(f/fs)` (`sinc(x) = sin πx / πx`;
/// the discrete Fourier transform of the whole signal, the mean kept):
/// the samples whose piecewise-linear interpolation has, below the
/// Nyquist frequency, the spectrum of the band-limited signal through
/// `x`. The gain is 1.45 at a third of the sample rate and 2.47 at
/// Nyquist. The transform treats `x` as periodic: a jump between its last
/// and first sample rings near both ends.
pub fn compensate_linear_interpolation(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return x.to_vec();
    }
    let mut planner = FftPlanner::<f64>::new();
    let mut buf: Vec<Complex<f64>> = x.iter().map(|&v| Complex::new(v, 0.0)).collect();
    planner.plan_fft_forward(n).process(&mut buf);
    for (k, z) in buf.iter_mut().enumerate().skip(1) {
        let r = k.min(n - k) as f64 / n as f64;
        let s = (std::f64::consts::PI * r).sin() / (std::f64::consts::PI * r);
        *z /= s * s;
    }
    planner.plan_fft_inverse(n).process(&mut buf);
    buf.iter().map(|z| z.re / n as f64).collect()
}

impl Record {
    /// The record with every force channel compensated for the linear
    /// interpolation between samples ([`compensate_linear_interpolation`];
    /// module docs): for a force measured by a band-limited (anti-aliased)
    /// acquisition. Apply it to the whole file before cutting, so that the
    /// ringing of the ends stays out of the ranges used.
    pub fn with_band_limited_force(&self) -> Record {
        let mut r = self.clone();
        for c in &mut r.inputs {
            c.data = compensate_linear_interpolation(&c.data);
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{Channel, Quantity};

    #[test]
    fn ranges_parse_and_refuse_with_the_rule() {
        assert_eq!(
            SampleRange::parse("40650..127400").unwrap(),
            SampleRange {
                start: 40650,
                end: 127400
            }
        );
        for bad in ["100", "5..5", "9..3", "a..7", "-1..4", "1..2..3"] {
            let e = SampleRange::parse(bad).unwrap_err();
            assert!(e.contains(bad) && e.contains("START..END"), "{e}");
        }
    }

    #[test]
    fn a_range_beyond_the_record_is_an_error_naming_it() {
        let rec = Record {
            t0: 0.0,
            fs: 10.0,
            inputs: vec![Channel::new(Quantity::Force, 1, vec![0.0; 50])],
            outputs: vec![],
            truth: None,
            source: "rec.mat".into(),
        };
        let cut = SampleRange::parse("10..20").unwrap().cut(&rec).unwrap();
        assert_eq!(cut.len(), 10);
        assert!((cut.t0 - 1.0).abs() < 1e-12);
        let e = SampleRange::parse("10..51").unwrap().cut(&rec).unwrap_err();
        let m = e.to_string();
        assert!(
            m.contains("rec.mat") && m.contains("10..51") && m.contains("50"),
            "{m}"
        );
    }

    /// A sine at a third of the sample rate: the piecewise-linear
    /// interpolant of the compensated samples has the sine's amplitude in
    /// its mean power at the sine's frequency (projected on the sine,
    /// integrated exactly over whole periods).
    #[test]
    fn compensated_samples_interpolate_to_the_band_limited_sine() {
        let (n, cycles) = (600, 200.0);
        let w = 2.0 * std::f64::consts::PI * cycles / n as f64;
        let x: Vec<f64> = (0..n).map(|k| (w * k as f64).sin()).collect();
        let amplitude = |s: &[f64]| {
            // projection of the piecewise-linear interpolant on sin(w t)
            let fine = 50;
            let mut acc = 0.0;
            for k in 0..n {
                let (a, b) = (s[k], s[(k + 1) % n]);
                for j in 0..fine {
                    let f = (j as f64 + 0.5) / fine as f64;
                    acc += (a + (b - a) * f) * (w * (k as f64 + f)).sin();
                }
            }
            2.0 * acc / (n * fine) as f64
        };
        let plain = amplitude(&x);
        let comp = amplitude(&compensate_linear_interpolation(&x));
        assert!(
            (plain - 0.6839).abs() < 0.01,
            "linear interpolation: {plain}"
        );
        assert!((comp - 1.0).abs() < 2e-3, "compensated: {comp}");
    }
}
