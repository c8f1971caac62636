//! Correlation metrics between a measured signal `m` and a computed one `c`
//! (docs/theory.md, Definitions): relative error, Sprague–Geers magnitude/phase/combined,
//! TRAC.

use serde::Serialize;

/// ‖c − m‖₂ / ‖m‖₂ (NaN when ‖m‖ = 0 and ‖c − m‖ > 0; 0 when both are 0).
pub fn relative_error(c: &[f64], m: &[f64]) -> f64 {
    let (num, den) = sums(c, m);
    ratio(num, den)
}

/// Sums ‖c − m‖², ‖m‖² over the common length.
pub fn sums(c: &[f64], m: &[f64]) -> (f64, f64) {
    c.iter().zip(m).fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - y) * (x - y), b + y * y)
    })
}

/// √(num/den) with the conventions of [`relative_error`].
pub fn ratio(num: f64, den: f64) -> f64 {
    if den > 0.0 {
        (num / den).sqrt()
    } else if num == 0.0 {
        0.0
    } else {
        f64::NAN
    }
}

/// Sprague–Geers metrics.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SpragueGeers {
    /// Magnitude error M = √(Σc²/Σm²) − 1.
    pub magnitude: f64,
    /// Phase error P = arccos(Σmc / √(Σm² Σc²)) / π.
    pub phase: f64,
    /// Combined √(M² + P²).
    pub combined: f64,
}

/// Sprague–Geers magnitude, phase and combined error.
pub fn sprague_geers(c: &[f64], m: &[f64]) -> SpragueGeers {
    let (mut mm, mut cc, mut mc) = (0.0, 0.0, 0.0);
    for (x, y) in c.iter().zip(m) {
        mm += y * y;
        cc += x * x;
        mc += x * y;
    }
    let magnitude = (cc / mm).sqrt() - 1.0;
    let phase = (mc / (mm * cc).sqrt()).clamp(-1.0, 1.0).acos() / std::f64::consts::PI;
    SpragueGeers {
        magnitude,
        phase,
        combined: (magnitude * magnitude + phase * phase).sqrt(),
    }
}

/// TRAC = (Σmc)² / (Σm² Σc²).
pub fn trac(c: &[f64], m: &[f64]) -> f64 {
    let (mut mm, mut cc, mut mc) = (0.0, 0.0, 0.0);
    for (x, y) in c.iter().zip(m) {
        mm += y * y;
        cc += x * x;
        mc += x * y;
    }
    mc * mc / (mm * cc)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_on_known_signals() {
        let m: Vec<f64> = (0..1000).map(|k| (k as f64 * 0.05).sin()).collect();
        let c: Vec<f64> = m.iter().map(|v| 1.1 * v).collect();
        approx::assert_relative_eq!(relative_error(&c, &m), 0.1, max_relative = 1e-12);
        let sg = sprague_geers(&c, &m);
        approx::assert_relative_eq!(sg.magnitude, 0.1, max_relative = 1e-12);
        assert!(sg.phase.abs() < 1e-6);
        approx::assert_relative_eq!(trac(&c, &m), 1.0, max_relative = 1e-12);
        let neg: Vec<f64> = m.iter().map(|v| -v).collect();
        approx::assert_relative_eq!(sprague_geers(&neg, &m).phase, 1.0, max_relative = 1e-9);
        assert_eq!(relative_error(&[0.0], &[0.0]), 0.0);
        assert!(relative_error(&[1.0], &[0.0]).is_nan());
    }
}
