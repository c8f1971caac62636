//! Up-front checks of command-line values: every numeric option in a
//! stated range, with a message naming the option, and the memory a run
//! needs compared with what the machine has before anything is allocated.

use anyhow::{bail, Result};

/// Most integration sub-steps per sample any command accepts.
pub const MAX_SUBSTEPS: usize = tacit::integrate::newmark::MAX_SUBSTEPS;
/// Most points of an α grid.
pub const MAX_GRID: usize = 200;
/// Most samples a simulated record may hold.
pub const MAX_SAMPLES: usize = 100_000_000;

/// `value` is finite and in `[lo, hi]`.
pub fn in_range(option: &str, value: f64, lo: f64, hi: f64, what: &str) -> Result<()> {
    if !(value.is_finite() && value >= lo && value <= hi) {
        bail!("{option} {value} is outside [{lo}, {hi}] ({what})");
    }
    Ok(())
}

/// `value` is finite and > 0 (at most `hi`).
pub fn positive(option: &str, value: f64, hi: f64, what: &str) -> Result<()> {
    if !(value.is_finite() && value > 0.0 && value <= hi) {
        bail!("{option} {value} must be > 0 and at most {hi} ({what})");
    }
    Ok(())
}

/// An integer option in `lo..=hi`.
pub fn count(option: &str, value: usize, lo: usize, hi: usize, what: &str) -> Result<()> {
    if value < lo || value > hi {
        bail!("{option} {value} is outside {lo}..={hi} ({what})");
    }
    Ok(())
}

/// `--substeps`: 1..=[`MAX_SUBSTEPS`].
pub fn substeps(value: usize) -> Result<()> {
    count(
        "--substeps",
        value,
        1,
        MAX_SUBSTEPS,
        "integration sub-steps per sample; 40 resolve a 490 Hz contact sampled at 512 Hz",
    )
}

/// A band `lo,hi` in Hz below the Nyquist frequency of `fs`.
pub fn band(option: &str, band: (f64, f64), fs: f64) -> Result<()> {
    let (lo, hi) = band;
    let nyquist = fs / 2.0;
    if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo) {
        bail!("{option} {lo},{hi}: give low,high in Hz with 0 <= low < high");
    }
    if hi > nyquist {
        bail!("{option} {lo},{hi}: the high end is above the Nyquist frequency {nyquist} Hz of the sample rate {fs} Hz");
    }
    Ok(())
}

/// Refuse a run whose estimated memory exceeds what the machine has.
/// `estimate` is in bytes (saturating arithmetic: an overflow is "too
/// much"); `what` says what the estimate is made of.
pub fn memory(estimate: f64, what: &str) -> Result<()> {
    let Some(avail) = tacit::io::available_memory() else {
        return Ok(());
    };
    check_memory(estimate, avail, what)
}

fn check_memory(estimate: f64, avail: u64, what: &str) -> Result<()> {
    if !(estimate.is_finite() && estimate <= avail as f64) {
        bail!(
            "this run needs about {} of memory ({what}); the machine has {} available",
            human_bytes(estimate),
            human_bytes(avail as f64)
        );
    }
    Ok(())
}

/// Bytes as `1.2 GB`.
pub fn human_bytes(b: f64) -> String {
    if !b.is_finite() {
        return "more than can be counted".into();
    }
    let units = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut v = b;
    let mut i = 0;
    while v >= 1000.0 && i + 1 < units.len() {
        v /= 1000.0;
        i += 1;
    }
    if i + 1 == units.len() && v >= 1000.0 {
        return format!("{b:.1e} B");
    }
    format!("{v:.1} {}", units[i])
}

/// Memory of an integration, bytes: the sample map the Newmark integrator
/// builds (`substeps × 5 n` values per contact pair and a `3 n × 5 n`
/// block), the states at every sample (u, v, a, f_int and the force: `5 n`
/// values per sample) and the record with its truth (`6 n` more).
pub fn integration_bytes(ndof: usize, pairs: usize, substeps: usize, samples: usize) -> f64 {
    let n = ndof as f64;
    let map = (pairs as f64 * substeps as f64 * 5.0 * n + 15.0 * n * n) * 8.0;
    let states = samples as f64 * 11.0 * n * 8.0;
    map + states
}

/// The numeric options of `tacit diagnose` that need no record.
pub fn diagnose_options(
    segment: f64,
    max_effects: usize,
    substeps_per_sample: usize,
) -> Result<()> {
    positive("--segment", segment, 1e6, "segment length, s")?;
    if max_effects == 0 {
        bail!("--max-effects 0 would search for nothing: give 1..=10 (the most effects to add)");
    }
    count(
        "--max-effects",
        max_effects,
        1,
        10,
        "the most effects to add",
    )?;
    substeps(substeps_per_sample)
}

/// `--segment` seconds against a record: at least 8 samples per segment
/// and at least two segments in the record.
pub fn segment_in_record(segment: f64, fs: f64, samples: usize) -> Result<()> {
    let k = segment * fs;
    let (lo, hi) = (8.0, (samples / 2) as f64);
    if !(k >= lo && k <= hi) {
        bail!(
            "--segment {segment} s is {} samples at {fs} Hz; give {:.6} to {:.6} s (8 samples to half the record's {samples})",
            if k.abs() >= 0.01 { format!("{k:.3}") } else { format!("{k:.3e}") },
            lo / fs,
            hi / fs
        );
    }
    Ok(())
}

/// Memory of a diagnosis, bytes: the lifted smoother's state
/// covariances (`(2n)²` per sample, four sets), and one integration per
/// worker thread with the contact pairs of every DOF pair at the larger of
/// `substeps` and 40 sub-steps.
pub fn diagnose_bytes(ndof: usize, substeps: usize, samples: usize) -> f64 {
    let n = ndof as f64;
    let smoother = samples as f64 * 4.0 * (2.0 * n).powi(2) * 8.0;
    let threads = std::thread::available_parallelism().map_or(1, |t| t.get()) as f64;
    let pairs = ndof * (ndof + 1) / 2;
    smoother + threads * integration_bytes(ndof, pairs, substeps.max(40), samples)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_name_the_option() {
        let e = substeps(1_000_000_000).unwrap_err().to_string();
        assert!(
            e.contains("--substeps 1000000000") && e.contains("1..=1000"),
            "{e}"
        );
        assert!(substeps(40).is_ok());
        let e = positive("--segment", f64::INFINITY, 1e3, "s").unwrap_err();
        assert!(e.to_string().contains("--segment inf"));
        assert!(positive("--segment", 0.1, 1e3, "s").is_ok());
        assert!(in_range("--noise", f64::NAN, 0.0, 1.0, "fraction").is_err());
    }

    #[test]
    fn diagnose_segment_and_effects() {
        let e = diagnose_options(0.1, 0, 10).unwrap_err().to_string();
        assert!(e.contains("--max-effects 0"), "{e}");
        assert!(diagnose_options(f64::INFINITY, 3, 10).is_err());
        assert!(diagnose_options(0.1, 3, 10).is_ok());
        let e = segment_in_record(1e-9, 512.0, 4096)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--segment 0.000000001 s") && e.contains("0.015625 to 4.000000 s"),
            "{e}"
        );
        assert!(segment_in_record(0.1, 512.0, 4096).is_ok());
    }

    #[test]
    fn band_is_checked_against_nyquist() {
        assert!(band("--band", (5.0, 200.0), 512.0).is_ok());
        let e = band("--band", (5.0, 300.0), 512.0).unwrap_err().to_string();
        assert!(e.contains("Nyquist frequency 256 Hz"), "{e}");
        assert!(band("--band", (50.0, 5.0), 512.0).is_err());
    }

    #[test]
    fn memory_estimate_is_refused_above_what_is_available() {
        let text = "MemTotal: 100 kB\nMemFree: 10 kB\nMemAvailable:   2048 kB\n";
        assert_eq!(tacit::io::parse_meminfo(text), Some(2048 * 1024));
        let e = check_memory(3e6, 2048 * 1024, "test")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("3.0 MB") && e.contains("2.1 MB available"),
            "{e}"
        );
        assert!(check_memory(1e6, 2048 * 1024, "test").is_ok());
        assert!(check_memory(f64::INFINITY, 2048 * 1024, "test").is_err());
        // the 1e9 sub-step simulation of the 8-DOF model with one contact:
        // 320 GB, as the allocation that aborted it
        let b = integration_bytes(8, 1, 1_000_000_000, 16);
        assert!((b / 3.2e11 - 1.0).abs() < 1e-3, "{b}");
    }
}
