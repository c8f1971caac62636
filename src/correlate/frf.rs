//! Frequency response functions by the H1 estimator with Welch averaging.
//!
//! Each record is cut into segments of `segment` samples overlapping by
//! `overlap` (a fraction), each segment has its mean removed and is
//! multiplied by a window `w`, then transformed (FFT, `rustfft`). Over all
//! segments of all records the cross- and auto-spectra are averaged,
//!
//! $$ G_{xf}(f) = \sum_s X_s(f) F_s^*(f), \qquad G_{ff}(f) = \sum_s |F_s(f)|^2, $$
//!
//! and the H1 estimate and the ordinary coherence are
//!
//! $$ H_1(f) = G_{xf} / G_{ff}, \qquad \gamma^2 = |G_{xf}|^2 / (G_{ff} G_{xx}). $$
//!
//! H1 is unbiased by noise on the outputs (the accelerometers), which is the
//! usual situation of a shaker test (Bendat & Piersol, *Random Data*, §9.2).
//! With accelerations as outputs it is the accelerance (m/s² per N).

use crate::error::{Result, TacitError};
use crate::record::{Quantity, Record};
use rustfft::{num_complex::Complex, FftPlanner};
use serde::Serialize;

/// Segment window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Window {
    /// Hann (raised cosine); the default for random excitation.
    #[default]
    Hann,
    /// No window (for transients that die out within a segment).
    Rectangular,
}

impl Window {
    /// The window's values for a segment of `n` samples (periodic form).
    pub fn values(self, n: usize) -> Vec<f64> {
        match self {
            Window::Rectangular => vec![1.0; n],
            Window::Hann => (0..n)
                .map(|i| 0.5 * (1.0 - (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos()))
                .collect(),
        }
    }
}

/// Settings of the H1 estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrfSettings {
    /// Samples per segment (>= 16; default 2048, i.e. 4 s and 0.25 Hz
    /// lines at 512 Hz, fine enough for the 1 %-damped first mode of the
    /// testbed at 22 Hz). Shorter: more averages, coarser lines.
    pub segment: usize,
    /// Overlap of consecutive segments as a fraction in [0, 0.95]
    /// (default 0.5).
    pub overlap: f64,
    /// Window (default Hann).
    pub window: Window,
}

impl Default for FrfSettings {
    fn default() -> Self {
        FrfSettings {
            segment: 2048,
            overlap: 0.5,
            window: Window::Hann,
        }
    }
}

impl FrfSettings {
    /// Check the settings; the error repeats the rule.
    pub fn validate(&self) -> Result<()> {
        if self.segment < 16 {
            return Err(TacitError::Setting(format!(
                "FRF segment = {} samples: must be >= 16",
                self.segment
            )));
        }
        if !(0.0..=0.95).contains(&self.overlap) {
            return Err(TacitError::Setting(format!(
                "FRF overlap = {}: must be in [0, 0.95]",
                self.overlap
            )));
        }
        Ok(())
    }
}

/// FRFs from one input to several outputs.
#[derive(Debug, Clone, Serialize)]
pub struct Frf {
    /// Frequency of each line, Hz (0 … fs/2).
    pub freq_hz: Vec<f64>,
    /// DOF (from 1) of the input force.
    pub input_dof: usize,
    /// DOF (from 1) of each output.
    pub output_dofs: Vec<usize>,
    /// What the outputs measure (the FRF is receptance, mobility or
    /// accelerance accordingly).
    pub quantity: Quantity,
    /// H1, `h[output][line]`.
    #[serde(skip)]
    pub h: Vec<Vec<Complex<f64>>>,
    /// Ordinary coherence, `coherence[output][line]`, in [0, 1].
    pub coherence: Vec<Vec<f64>>,
    /// Number of segments averaged.
    pub averages: usize,
    /// Sample rate, Hz.
    pub fs: f64,
}

impl Frf {
    /// Index of the output at `dof`, if any.
    pub fn output_index(&self, dof: usize) -> Option<usize> {
        self.output_dofs.iter().position(|&d| d == dof)
    }
}

/// One measured input history and the output histories that go with it.
#[derive(Debug, Clone, Copy)]
pub struct Measurement<'a> {
    /// Force at the input DOF.
    pub input: &'a [f64],
    /// One history per output, in the order of the output DOFs.
    pub outputs: &'a [Vec<f64>],
}

fn check_measurements(
    measurements: &[Measurement<'_>],
    output_dofs: &[usize],
    nseg: usize,
) -> Result<()> {
    if measurements.is_empty() {
        return Err(TacitError::Setting("H1 needs at least one record".into()));
    }
    for (r, m) in measurements.iter().enumerate() {
        if m.outputs.len() != output_dofs.len() {
            return Err(TacitError::Setting(format!(
                "record {}: {} output histories for {} output DOFs",
                r + 1,
                m.outputs.len(),
                output_dofs.len()
            )));
        }
        if m.input.len() < nseg {
            return Err(TacitError::Setting(format!(
                "record {}: {} samples, shorter than one FRF segment ({nseg})",
                r + 1,
                m.input.len()
            )));
        }
        for (o, y) in m.outputs.iter().enumerate() {
            if y.len() != m.input.len() {
                return Err(TacitError::Setting(format!(
                    "record {}: output at DOF {} has {} samples, the input {}",
                    r + 1,
                    output_dofs[o],
                    y.len(),
                    m.input.len()
                )));
            }
        }
    }
    Ok(())
}

/// H1 estimate from one or more measurements (e.g. five records of the same
/// test), all at rate `fs`, averaged together.
pub fn h1(
    measurements: &[Measurement<'_>],
    fs: f64,
    input_dof: usize,
    output_dofs: &[usize],
    quantity: Quantity,
    settings: &FrfSettings,
) -> Result<Frf> {
    settings.validate()?;
    if !(fs.is_finite() && fs > 0.0) {
        return Err(TacitError::Setting(format!(
            "sample rate {fs} Hz must be > 0"
        )));
    }
    let nseg = settings.segment;
    check_measurements(measurements, output_dofs, nseg)?;
    let no = output_dofs.len();
    let nl = nseg / 2 + 1;
    let win = settings.window.values(nseg);
    let step = ((nseg as f64) * (1.0 - settings.overlap)).round().max(1.0) as usize;
    let fft = FftPlanner::new().plan_fft_forward(nseg);
    let mut gff = vec![0.0; nl];
    let mut gxf = vec![vec![Complex::new(0.0, 0.0); nl]; no];
    let mut gxx = vec![vec![0.0; nl]; no];
    let mut averages = 0;
    let spectrum = |x: &[f64]| -> Vec<Complex<f64>> {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let mut buf: Vec<Complex<f64>> = x
            .iter()
            .zip(&win)
            .map(|(v, w)| Complex::new((v - mean) * w, 0.0))
            .collect();
        fft.process(&mut buf);
        buf.truncate(nl);
        buf
    };
    for m in measurements {
        let mut start = 0;
        while start + nseg <= m.input.len() {
            let f = spectrum(&m.input[start..start + nseg]);
            for (g, c) in gff.iter_mut().zip(&f) {
                *g += c.norm_sqr();
            }
            for o in 0..no {
                let x = spectrum(&m.outputs[o][start..start + nseg]);
                for l in 0..nl {
                    gxf[o][l] += x[l] * f[l].conj();
                    gxx[o][l] += x[l].norm_sqr();
                }
            }
            averages += 1;
            start += step;
        }
    }
    let h = gxf
        .iter()
        .map(|g| {
            g.iter()
                .zip(&gff)
                .map(|(c, p)| {
                    if *p > 0.0 {
                        c / p
                    } else {
                        Complex::new(0.0, 0.0)
                    }
                })
                .collect()
        })
        .collect();
    let coherence = (0..no)
        .map(|o| {
            (0..nl)
                .map(|l| {
                    let den = gff[l] * gxx[o][l];
                    if den > 0.0 {
                        (gxf[o][l].norm_sqr() / den).clamp(0.0, 1.0)
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    Ok(Frf {
        freq_hz: (0..nl).map(|l| l as f64 * fs / nseg as f64).collect(),
        input_dof,
        output_dofs: output_dofs.to_vec(),
        quantity,
        h,
        coherence,
        averages,
        fs,
    })
}

fn record_name(i: usize, r: &Record) -> std::path::PathBuf {
    if r.source.as_os_str().is_empty() {
        std::path::PathBuf::from(format!("<record {}>", i + 1))
    } else {
        r.source.clone()
    }
}

/// H1 from records: the input is the force channel at `input_dof` (or the
/// only force channel when `None`), the outputs are the `quantity` channels
/// at `sensors`. Every record must have the same rate and those channels;
/// errors name the record (by its file, or its position) and the channel.
pub fn h1_records(
    records: &[Record],
    input_dof: Option<usize>,
    sensors: &[usize],
    quantity: Quantity,
    settings: &FrfSettings,
) -> Result<Frf> {
    let first = records
        .first()
        .ok_or_else(|| TacitError::Setting("H1 needs at least one record".into()))?;
    if sensors.is_empty() {
        return Err(TacitError::Setting("H1 needs at least one sensor".into()));
    }
    let input_dof = match input_dof {
        Some(d) => d,
        None => match first.inputs.as_slice() {
            [c] => c.dof,
            [] => {
                return Err(TacitError::record(
                    record_name(0, first),
                    "no input force channel",
                ))
            }
            _ => {
                return Err(TacitError::record(
                    record_name(0, first),
                    format!(
                        "{} input channels: say which DOF is the input",
                        first.inputs.len()
                    ),
                ))
            }
        },
    };
    let mut outs: Vec<Vec<Vec<f64>>> = Vec::with_capacity(records.len());
    let mut ins: Vec<&[f64]> = Vec::with_capacity(records.len());
    for (i, r) in records.iter().enumerate() {
        if (r.fs - first.fs).abs() > 1e-9 * first.fs {
            return Err(TacitError::record(
                record_name(i, r),
                format!(
                    "sample rate {} Hz differs from the first record's {} Hz",
                    r.fs, first.fs
                ),
            ));
        }
        let f = r
            .inputs
            .iter()
            .find(|c| c.dof == input_dof)
            .ok_or_else(|| {
                TacitError::record(
                    record_name(i, r),
                    format!("no force channel at DOF {input_dof}"),
                )
            })?;
        ins.push(&f.data);
        let mut o = Vec::with_capacity(sensors.len());
        for &d in sensors {
            let c = r.output(quantity, d).ok_or_else(|| {
                TacitError::record(
                    record_name(i, r),
                    format!("no channel {}_{d} (sensor DOF {d})", quantity.prefix()),
                )
            })?;
            o.push(c.data.clone());
        }
        outs.push(o);
    }
    let ms: Vec<Measurement<'_>> = ins
        .iter()
        .zip(&outs)
        .map(|(i, o)| Measurement {
            input: i,
            outputs: o,
        })
        .collect();
    h1(&ms, first.fs, input_dof, sensors, quantity, settings)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// y = 3 f gives H1 = 3 and coherence 1 at every line carrying input
    /// power.
    #[test]
    fn gain_is_recovered() {
        let f = crate::signal::random_band(4096, 512.0, (5.0, 200.0), 1.0, 3).unwrap();
        let y = vec![f.iter().map(|v| 3.0 * v).collect::<Vec<_>>()];
        let m = [Measurement {
            input: &f,
            outputs: &y,
        }];
        let s = FrfSettings {
            segment: 1024,
            ..Default::default()
        };
        let frf = h1(&m, 512.0, 1, &[2], Quantity::Accel, &s).unwrap();
        assert_eq!(frf.averages, 7);
        let l = frf.freq_hz.iter().position(|&x| x >= 50.0).unwrap();
        approx::assert_relative_eq!(frf.h[0][l].re, 3.0, max_relative = 1e-9);
        assert!(frf.h[0][l].im.abs() < 1e-9);
        approx::assert_relative_eq!(frf.coherence[0][l], 1.0, max_relative = 1e-9);
    }

    #[test]
    fn bad_input_is_named() {
        let f = vec![0.0; 100];
        let y = vec![vec![0.0; 99]];
        let m = [Measurement {
            input: &f,
            outputs: &y,
        }];
        let s = FrfSettings {
            segment: 64,
            ..Default::default()
        };
        let e = h1(&m, 512.0, 1, &[4], Quantity::Accel, &s)
            .unwrap_err()
            .to_string();
        assert!(e.contains("DOF 4") && e.contains("99"), "{e}");
        let s = FrfSettings {
            overlap: 1.0,
            ..Default::default()
        };
        assert!(s.validate().unwrap_err().to_string().contains("overlap"));
    }
}
