//! The figures of a diagnosis report (PNG + SVG): the responses measured
//! and predicted with a zoom on a short window, the residuals, the
//! frequency response before and after, the identified force, and the
//! restoring-force plots with the fitted law and the gap drawn over the
//! data.

use super::Diagnosis;
use crate::correlate::frf::{h1, Frf, FrfSettings, Measurement, Window};
use crate::plot::{self, Figure, Panel, Series, SeriesStyle};
use crate::trace::{Candidate, EffectKind};
use crate::Result;
use nalgebra::DMatrix;
use rayon::prelude::*;
use rustfft::{num_complex::Complex, FftPlanner};
use std::path::{Path, PathBuf};

/// Colour of the measurement (black), drawn over the predictions.
const MEASURED: (u8, u8, u8) = (0, 0, 0);
/// Colour of the declared model's prediction (orange).
const BEFORE: (u8, u8, u8) = (255, 127, 14);
/// Colour of the fitted model's prediction (blue).
const AFTER: (u8, u8, u8) = (31, 119, 180);
/// Colour of a fitted law (red).
const LAW: (u8, u8, u8) = (214, 39, 40);
/// Colour of a gap line (grey).
const GAP: (u8, u8, u8) = (110, 110, 110);
/// Length of the responses' overview window, s.
const OVERVIEW_S: f64 = 0.5;
/// Length of the responses' zoom window, s.
const ZOOM_S: f64 = 0.1;

/// Draw every figure into `dir` (in parallel); returns the paths written.
pub(super) fn write(dir: &Path, d: &Diagnosis) -> Result<Vec<PathBuf>> {
    let cmp = &d.prepared.comparison;
    let ns = cmp.force.ncols();
    let t: Vec<f64> = (0..ns).map(|k| k as f64 / cmp.fs).collect();
    let mut jobs = vec![
        (residual_figure(d, &t), dir.join("residual")),
        (responses_figure(d, &t), dir.join("responses")),
    ];
    if let Some(f) = frf_figure(d) {
        jobs.push((f, dir.join("frf")));
    }
    jobs.push((force_figure(d, &t), dir.join("identified_force")));
    jobs.extend(
        restoring_figures(d)
            .into_iter()
            .enumerate()
            .map(|(i, f)| (f, dir.join(format!("restoring_{}", i + 1)))),
    );
    let saved = jobs
        .par_iter()
        .map(|(fig, path)| plot::save(fig, path))
        .collect::<Result<Vec<_>>>()?;
    Ok(saved.into_iter().flatten().collect())
}

fn row(m: &DMatrix<f64>, r: usize) -> Vec<f64> {
    m.row(r).iter().copied().collect()
}

/// Root mean square of the finite values.
fn rms(x: &[f64]) -> f64 {
    let v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    (v.iter().map(|a| a * a).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// The channel's axis label: its name and SI unit.
fn channel_axis(d: &Diagnosis, c: usize, what: &str) -> String {
    let o = &d.prepared.comparison.observations[c];
    format!("{what} [{}]", o.quantity.si_unit())
}

/// The quantity in words, for axis labels.
fn quantity_word(q: crate::record::Quantity) -> &'static str {
    use crate::record::Quantity;
    match q {
        Quantity::Force => "force",
        Quantity::Disp => "displacement",
        Quantity::Vel => "velocity",
        Quantity::Accel => "acceleration",
    }
}

/// Measured minus the segment predictions before and after, per channel,
/// with each residual's RMS in the legend; beside it the fitted model's
/// residual alone, on its own scale (what is left to explain).
fn residual_figure(d: &Diagnosis, t: &[f64]) -> Figure {
    let cmp = &d.prepared.comparison;
    let meas = cmp.measured();
    let ns = t.len();
    let mut panels = vec![];
    for (c, o) in cmp.observations.iter().enumerate() {
        let unit = o.quantity.si_unit();
        let residual = |name: &str, p: &DMatrix<f64>, colour| {
            let r: Vec<f64> = (0..ns).map(|k| meas[(c, k)] - p[(c, k)]).collect();
            let label = format!("{name} (RMS {:.3} {unit})", rms(&r));
            Series::line(label, t.to_vec(), r).with_colour(colour)
        };
        let before = d
            .predictions
            .0
            .as_ref()
            .map(|p| residual("before", p, BEFORE));
        let after = d
            .predictions
            .1
            .as_ref()
            .map(|p| residual("after", p, AFTER));
        let axis = channel_axis(d, c, "residual");
        let both: Vec<Series> = before.into_iter().chain(after.clone()).collect();
        panels.push(Panel::xy(o.name(), "time [s]", axis.clone(), both));
        if let Some(a) = after {
            let title = format!("{}, after alone", o.name());
            panels.push(Panel::xy(title, "time [s]", axis, vec![a]));
        }
    }
    let columns = if d.predictions.1.is_some() { 2 } else { 1 };
    Figure::new(
        "Residual: measured − segment prediction, before and after",
        panels,
        columns,
    )
}

/// The window `[k0, k1)` of `len` samples centred on the largest
/// |value| of `y` in `[from, to)` (a peak: an impact, when there are any).
fn zoom_window(y: &[f64], (from, to): (usize, usize), len: usize) -> (usize, usize) {
    let to = to.min(y.len());
    let peak = (from..to)
        .max_by(|&a, &b| y[a].abs().total_cmp(&y[b].abs()))
        .unwrap_or(0);
    let k0 = peak
        .saturating_sub(len / 2)
        .min(y.len().saturating_sub(len));
    (k0, (k0 + len).min(y.len()))
}

/// One panel of responses over samples `[k0, k1)`: the predictions as
/// lines under the measurement as black dots.
fn response_panel(d: &Diagnosis, c: usize, t: &[f64], (k0, k1): (usize, usize)) -> Panel {
    let cmp = &d.prepared.comparison;
    let o = &cmp.observations[c];
    let tt = t[k0..k1].to_vec();
    let mut series = vec![];
    for (name, pred, colour, dashed) in [
        ("before (declared)", &d.predictions.0, BEFORE, true),
        ("after (fitted)", &d.predictions.1, AFTER, false),
    ] {
        if let Some(p) = pred {
            let y = row(p, c)[k0..k1].to_vec();
            let s = if dashed {
                Series::dashed(name, tt.clone(), y)
            } else {
                Series::line(name, tt.clone(), y)
            };
            series.push(s.with_colour(colour));
        }
    }
    series.push(Series::points("measured", tt, o.data[k0..k1].to_vec()).with_colour(MEASURED));
    let title = format!("{}, {:.2}–{:.2} s", o.name(), t[k0], t[k1 - 1]);
    Panel::xy(
        title,
        "time [s]",
        channel_axis(d, c, quantity_word(o.quantity)),
        series,
    )
}

/// Per channel, the first half second and a zoom on 0.1 s around its largest
/// peak there: measured (black dots) over the segment predictions.
fn responses_figure(d: &Diagnosis, t: &[f64]) -> Figure {
    let cmp = &d.prepared.comparison;
    let ns = t.len();
    let k1 = ((OVERVIEW_S * cmp.fs) as usize).clamp(2, ns.max(2)).min(ns);
    let zlen = ((ZOOM_S * cmp.fs) as usize).clamp(2, k1.max(2)).min(ns);
    let mut panels = vec![];
    for (c, o) in cmp.observations.iter().enumerate() {
        panels.push(response_panel(d, c, t, (0, k1)));
        // the peak after the first tenth of the window (the start from rest)
        let z = zoom_window(&o.data, (k1 / 10, k1), zlen);
        panels.push(response_panel(d, c, t, z));
    }
    Figure::new(
        "Responses: measured (dots) and segment predictions, with a zoom",
        panels,
        2,
    )
}

/// Welch segment length of the FRF estimate: a power of two near an
/// eighth of the record, 64 to 1024 samples.
fn frf_segment(ns: usize) -> usize {
    let mut n = 64;
    while n * 2 <= (ns / 8).min(1024) {
        n *= 2;
    }
    n
}

/// The lines `[lo, hi)` of a Welch spectrum of `force` (Hann segments of
/// `nseg` samples, half overlapping) within 30 dB of its peak: where the
/// input excites the structure and an FRF estimate means something.
fn input_band(force: &[f64], nseg: usize) -> (usize, usize) {
    let nl = nseg / 2 + 1;
    let win = Window::Hann.values(nseg);
    let fft = FftPlanner::new().plan_fft_forward(nseg);
    let mut g = vec![0.0; nl];
    let mut start = 0;
    while start + nseg <= force.len() {
        let mut buf: Vec<Complex<f64>> = force[start..start + nseg]
            .iter()
            .zip(&win)
            .map(|(v, w)| Complex::new(v * w, 0.0))
            .collect();
        fft.process(&mut buf);
        for (gl, b) in g.iter_mut().zip(&buf) {
            *gl += b.norm_sqr();
        }
        start += nseg / 2;
    }
    let max = g.iter().copied().fold(0.0, f64::max);
    let keep = |l: &usize| max > 0.0 && g[*l] >= 1e-3 * max;
    let lo = (0..nl).find(keep).unwrap_or(0);
    let hi = (0..nl).rev().find(keep).map_or(nl, |h| h + 1);
    (lo, hi)
}

/// The H1 estimates of a diagnosis: of the measurement and of both
/// models' open-loop simulations, from the force at `input` (from 0).
struct Frfs {
    input: usize,
    segment: usize,
    band: (usize, usize),
    measured: Frf,
    before: Option<Frf>,
    after: Option<Frf>,
}

/// H1 from the largest input force to every channel, of the measurement
/// and of both models' open-loop simulations (None without an input
/// force, or when the record is too short).
fn frfs(d: &Diagnosis) -> Option<Frfs> {
    let cmp = &d.prepared.comparison;
    let input = (0..cmp.force.nrows())
        .map(|i| (i, cmp.force.row(i).norm()))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|(_, n)| *n > 0.0)?
        .0;
    let force: Vec<f64> = row(&cmp.force, input);
    let settings = FrfSettings {
        segment: frf_segment(cmp.force.ncols()),
        ..Default::default()
    };
    let outputs: Vec<usize> = cmp.observations.iter().map(|o| o.dof).collect();
    let quantity = cmp.observations.first()?.quantity;
    let estimate = |rows: Vec<Vec<f64>>| {
        let m = [Measurement {
            input: &force,
            outputs: &rows,
        }];
        h1(&m, cmp.fs, input + 1, &outputs, quantity, &settings).ok()
    };
    let model = |p: &Option<DMatrix<f64>>| {
        let p = p.as_ref()?;
        let rows: Vec<Vec<f64>> = (0..p.nrows()).map(|c| row(p, c)).collect();
        rows.iter().flatten().all(|v| v.is_finite()).then_some(())?;
        estimate(rows)
    };
    Some(Frfs {
        input,
        segment: settings.segment,
        band: input_band(&force, settings.segment),
        measured: estimate(cmp.observations.iter().map(|o| o.data.clone()).collect())?,
        before: model(&d.before.open_loop_prediction),
        after: model(&d.after.open_loop_prediction),
    })
}

/// The FRFs of [`frfs`] in dB over the band the force excites, one panel
/// per channel.
fn frf_figure(d: &Diagnosis) -> Option<Figure> {
    let e = frfs(d)?;
    let (lo, hi) = e.band;
    let db = |h: &Frf, c: usize| -> Vec<f64> {
        h.h[c][lo..hi]
            .iter()
            .map(|z| 20.0 * z.norm().max(1e-300).log10())
            .collect()
    };
    let f = e.measured.freq_hz[lo..hi].to_vec();
    let panels = d
        .prepared
        .comparison
        .observations
        .iter()
        .enumerate()
        .map(|(c, o)| {
            let mut series = vec![];
            if let Some(h) = &e.before {
                series.push(
                    Series::dashed("declared model", f.clone(), db(h, c)).with_colour(BEFORE),
                );
            }
            if let Some(h) = &e.after {
                series.push(Series::line("fitted model", f.clone(), db(h, c)).with_colour(AFTER));
            }
            series.push(
                Series::line("measured", f.clone(), db(&e.measured, c)).with_colour(MEASURED),
            );
            let unit = format!("({})/N", o.quantity.si_unit());
            let title = format!("{} / force_{}", o.name(), e.input + 1);
            Panel::xy(
                title,
                "frequency [Hz]",
                format!("|H1| [dB re 1 {unit}]"),
                series,
            )
        })
        .collect();
    let title = format!(
        "FRF (H1, {} averages of {} samples) from the force at DOF {}: measured and open-loop simulations",
        e.measured.averages,
        e.segment,
        e.input + 1
    );
    Some(Figure::new(title, panels, 2))
}

/// The internal force identified at each DOF; a DOF where no force was
/// located is titled so (its force is zero by construction).
fn force_figure(d: &Diagnosis, t: &[f64]) -> Figure {
    let f = &d.prepared.recon.force;
    let panels = (0..f.nrows())
        .map(|i| {
            let y = row(f, i);
            let title = if y.iter().all(|v| *v == 0.0) {
                format!("DOF {}: no force located (zero)", i + 1)
            } else {
                format!("DOF {}", i + 1)
            };
            plot::time_panel(
                &title,
                "f_int [N]",
                t,
                vec![(format!("f{}", i + 1), y, SeriesStyle::Line)],
            )
        })
        .collect();
    Figure::new(
        "Internal force identified from the measurements (left-hand side)",
        panels,
        2,
    )
}

/// Whether a law is a function of the displacement or of the velocity.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum LawAxis {
    /// Relative (or absolute) displacement, m.
    Displacement,
    /// Relative (or absolute) velocity, m/s.
    Velocity,
}

/// A force law, N, of a displacement (m) or velocity (m/s).
pub(super) type Law = Box<dyn Fn(f64) -> f64>;

/// A fitted effect's force law `f(δ)` (N) as the model computes it
/// (`crate::model::elements`), from its parameters `p(name)` (SI; a
/// stiffness change relative to the spring's `nominal` N/m), or None for
/// a change of the modal damping (no single law).
pub(super) fn law(c: &Candidate, p: &dyn Fn(&str) -> f64, nominal: f64) -> Option<(LawAxis, Law)> {
    use LawAxis::{Displacement as D, Velocity as V};
    let (k, g) = (p("stiffness"), p("gap"));
    let vreg = c.vreg;
    Some(match c.kind {
        EffectKind::Contact => (D, Box::new(move |x: f64| k * (x - g).max(0.0))),
        EffectKind::Clearance => (
            D,
            Box::new(move |x: f64| k * (x.abs() - g).max(0.0) * x.signum()),
        ),
        EffectKind::Cubic => {
            let k3 = p("k3");
            (D, Box::new(move |x: f64| k3 * x.powi(3)))
        }
        EffectKind::Quadratic => {
            let k2 = p("k2");
            (D, Box::new(move |x: f64| k2 * x * x))
        }
        EffectKind::GroundSpring => (D, Box::new(move |x: f64| k * x)),
        EffectKind::Stiffness => {
            let dk = p("delta") * nominal;
            (D, Box::new(move |x: f64| dk * x))
        }
        EffectKind::Friction | EffectKind::RelativeFriction => {
            let f = p("level");
            (V, Box::new(move |v: f64| f * (v / vreg).tanh()))
        }
        EffectKind::QuadraticDamping => {
            let c2 = p("c2");
            (V, Box::new(move |v: f64| c2 * v * v.abs()))
        }
        EffectKind::CubicDamping => {
            let c3 = p("c3");
            (V, Box::new(move |v: f64| c3 * v.powi(3)))
        }
        EffectKind::Damping => return None,
    })
}

/// A restoring-force plot to draw: the candidate, its parameters and the
/// nominal stiffness of a changed spring, and the law's legend.
struct Restoring {
    candidate: Candidate,
    parameters: Vec<(String, f64)>,
    nominal: f64,
    label: &'static str,
}

/// The effects found (or the trace's best candidate when none was).
fn restoring_list(d: &Diagnosis) -> Vec<Restoring> {
    if d.effects.is_empty() {
        return d
            .ranking
            .iter()
            .take(1)
            .map(|r| Restoring {
                nominal: r
                    .candidate
                    .spring
                    .and_then(|s| d.model.springs.get(s))
                    .map_or(0.0, |s| s.stiffness),
                candidate: r.candidate.clone(),
                parameters: r.parameters.clone(),
                label: "traced law (not kept)",
            })
            .collect();
    }
    d.effects
        .iter()
        .zip(&d.added)
        .map(|(e, a)| Restoring {
            candidate: a.candidate.clone(),
            parameters: e.parameters.iter().map(|(k, v)| (k.clone(), *v)).collect(),
            nominal: a.nominal,
            label: "fitted law",
        })
        .collect()
}

/// Evenly spaced abscissae over the finite range of `x`.
fn grid_over(x: &[f64], n: usize) -> Vec<f64> {
    let Some((lo, hi)) = extent(x) else {
        return vec![];
    };
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
        .collect()
}

/// The restoring-force plots: identified force against displacement and
/// velocity (pairs: half the difference of the two DOFs' forces), the law
/// drawn over the points, the gap as a vertical line.
fn restoring_figures(d: &Diagnosis) -> Vec<Figure> {
    let prep = &d.prepared;
    let (f, states) = (&prep.recon.force, &prep.recon.states);
    let (n, ns) = (f.nrows(), f.ncols());
    restoring_list(d)
        .into_iter()
        .filter(|r| match r.candidate.kind {
            EffectKind::Friction => r.candidate.dofs.len() == 1,
            _ => r.candidate.dofs.len() <= 2,
        })
        .map(|r| {
            let c = &r.candidate;
            let fy: Vec<f64> = (0..ns)
                .map(|k| match c.dofs.get(1) {
                    Some(&j) => 0.5 * (f[(c.dofs[0], k)] - f[(j, k)]),
                    None => f[(c.dofs[0], k)],
                })
                .collect();
            let dx: Vec<f64> = (0..ns).map(|k| c.delta(states, k)).collect();
            let dv: Vec<f64> = (0..ns).map(|k| c.delta_rate(states, n, k)).collect();
            restoring_figure(&r, (dx, dv, fy))
        })
        .collect()
}

/// The range of the finite values of `x` (None when there are none).
fn extent(x: &[f64]) -> Option<(f64, f64)> {
    let (lo, hi) = x
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    (lo <= hi).then_some((lo, hi))
}

/// The law `f` over the data's abscissae `x` (SI), with the kink of a
/// contact or clearance exactly at its gap `g`, drawn where its force
/// stays within 1.5 × the data's largest |force| `fmax` (a stiff
/// contact's law leaves the data fast); abscissae × `scale`.
fn law_series(
    label: &str,
    f: &Law,
    x: &[f64],
    (gap, fmax): (Option<f64>, f64),
    scale: f64,
) -> Series {
    let mut xs = grid_over(x, 150);
    if let (Some(g), Some((lo, hi))) = (gap, extent(x)) {
        xs.extend([g, -g].into_iter().filter(|v| (lo..=hi).contains(v)));
        xs.sort_by(f64::total_cmp);
    }
    let ys: Vec<f64> = xs
        .iter()
        .map(|&v| f(v))
        .map(|y| if y.abs() <= 1.5 * fmax { y } else { f64::NAN })
        .collect();
    let xs = xs.iter().map(|v| scale * v).collect();
    Series::line(label, xs, ys).with_colour(LAW)
}

/// Dashed vertical lines at the gap `g` m (and at −g for a clearance),
/// drawn in mm over the force range `(lo, hi)`.
fn gap_lines(g: f64, clearance: bool, (lo, hi): (f64, f64)) -> Vec<Series> {
    let g = 1e3 * g;
    let mut out =
        vec![Series::dashed(format!("gap {g:.4} mm"), vec![g, g], vec![lo, hi]).with_colour(GAP)];
    if clearance {
        out.push(Series::dashed("", vec![-g, -g], vec![lo, hi]).with_colour(GAP));
    }
    out
}

/// One restoring-force figure from the data `(δ m, δ̇ m/s, f N)`.
fn restoring_figure(r: &Restoring, (dx, dv, fy): (Vec<f64>, Vec<f64>, Vec<f64>)) -> Figure {
    let c = &r.candidate;
    let what = match c.dofs.get(1) {
        Some(j) => format!("u{} − u{}", c.dofs[0] + 1, j + 1),
        None => format!("u{}", c.dofs[0] + 1),
    };
    let p = |name: &str| {
        r.parameters
            .iter()
            .find(|q| q.0 == name)
            .map_or(f64::NAN, |q| q.1)
    };
    let gapped = matches!(c.kind, EffectKind::Contact | EffectKind::Clearance);
    let gap = Some(p("gap")).filter(|g| gapped && g.is_finite());
    let frange = extent(&fy);
    let fmax = frange.map_or(0.0, |(lo, hi)| lo.abs().max(hi.abs()));
    let mm: Vec<f64> = dx.iter().map(|v| 1e3 * v).collect();
    let mut disp = vec![Series::points("identified", mm, fy.clone()).with_colour(AFTER)];
    let mut vel = vec![Series::points("identified", dv.clone(), fy).with_colour(AFTER)];
    match law(c, &p, r.nominal) {
        Some((LawAxis::Displacement, f)) => {
            disp.push(law_series(r.label, &f, &dx, (gap, fmax), 1e3))
        }
        Some((LawAxis::Velocity, f)) => vel.push(law_series(r.label, &f, &dv, (None, fmax), 1.0)),
        None => {}
    }
    if let (Some(g), Some(fr)) = (gap, frange) {
        disp.extend(gap_lines(g, c.kind == EffectKind::Clearance, fr));
    }
    let p1 = Panel::xy(
        "force vs displacement",
        format!("{what} [mm]"),
        "f_int [N]",
        disp,
    );
    let p2 = Panel::xy(
        "force vs velocity",
        format!("d/dt({what}) [m/s]"),
        "f_int [N]",
        vel,
    );
    Figure::new(format!("Restoring force: {}", c.label()), vec![p1, p2], 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params<'a>(v: &'a [(&'a str, f64)]) -> impl Fn(&str) -> f64 + 'a {
        move |n: &str| v.iter().find(|p| p.0 == n).map_or(f64::NAN, |p| p.1)
    }

    #[test]
    fn contact_and_clearance_laws_open_at_the_gap() {
        let p = [("gap", 4e-4), ("stiffness", 2e6)];
        let c = Candidate::new(EffectKind::Contact, vec![4, 5]);
        let (axis, f) = law(&c, &params(&p), 0.0).unwrap();
        assert_eq!(axis, LawAxis::Displacement);
        assert_eq!(f(3.9e-4), 0.0);
        approx::assert_relative_eq!(f(5e-4), 200.0, max_relative = 1e-12);
        assert_eq!(f(-1e-3), 0.0);
        let c = Candidate::new(EffectKind::Clearance, vec![4, 5]);
        let (_, f) = law(&c, &params(&p), 0.0).unwrap();
        approx::assert_relative_eq!(f(-5e-4), -200.0, max_relative = 1e-12);
        assert_eq!(f(1e-4), 0.0);
    }

    #[test]
    fn stiffness_change_and_friction_laws() {
        let c = Candidate::new(EffectKind::Stiffness, vec![4, 5]);
        let (_, f) = law(&c, &params(&[("delta", 0.1)]), 5e4).unwrap();
        approx::assert_relative_eq!(f(1e-3), 5.0, max_relative = 1e-12);
        let c = Candidate::new(EffectKind::Friction, vec![0]);
        let (axis, f) = law(&c, &params(&[("level", 0.3)]), 0.0).unwrap();
        assert_eq!(axis, LawAxis::Velocity);
        approx::assert_relative_eq!(f(1.0), 0.3, max_relative = 1e-6);
        approx::assert_relative_eq!(f(-1.0), -0.3, max_relative = 1e-6);
        let c = Candidate::new(EffectKind::Damping, vec![0]);
        assert!(law(&c, &params(&[("delta", 0.1)]), 0.0).is_none());
    }

    #[test]
    fn zoom_window_is_centred_on_the_peak_and_stays_inside() {
        let mut y = vec![0.0; 100];
        y[50] = -3.0;
        y[5] = 9.0;
        assert_eq!(zoom_window(&y, (10, 100), 20), (40, 60));
        y[98] = 10.0;
        assert_eq!(zoom_window(&y, (10, 100), 20), (80, 100));
    }

    #[test]
    fn input_band_finds_the_excited_lines() {
        let fs = 512.0;
        let f = crate::signal::random_band(4096, fs, (5.0, 200.0), 20.0, 7).unwrap();
        let (lo, hi) = input_band(&f, 512);
        // lines of 1 Hz: the band's edges within 2 Hz
        assert!((3..=7).contains(&lo), "{lo}");
        assert!((199..=203).contains(&hi), "{hi}");
        assert_eq!(input_band(&[0.0; 1024], 512), (0, 257));
    }

    #[test]
    fn frf_segment_is_a_power_of_two_near_an_eighth() {
        assert_eq!(frf_segment(4096), 512);
        assert_eq!(frf_segment(100_000), 1024);
        assert_eq!(frf_segment(300), 64);
    }
}
