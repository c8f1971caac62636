//! Presentation of correlation results: text tables in the layout of the
//! paper's Tables 1–3 and figure data (MAC matrix, stabilisation diagram,
//! adjustment bars as in Figs 2–3) for [`crate::plot::save`].

use super::fit::{FitResult, StabPole};
use super::frf::Frf;
use super::mac::Correlation;
use super::residue::UpdateResult;
use super::testmodes::TestModes;
use crate::plot::{Figure, Panel, Series};

/// A row of a paper table: test Hz, model Hz, error %, MAC %.
pub type PaperRow = (f64, f64, f64, f64);

/// Correlation table (paper Tables 2–3): test frequency, model frequency,
/// frequency error, MAC; `paper` optionally gives the paper's rows, printed
/// beside.
pub fn correlation_table(corr: &Correlation, paper: Option<&[PaperRow]>) -> String {
    let mut s = format!(
        "{:>5} {:>6} {:>10} {:>10} {:>8} {:>7}",
        "test", "model", "test Hz", "model Hz", "error %", "MAC %"
    );
    if paper.is_some() {
        s.push_str(&format!(
            "   | paper: {:>7} {:>7} {:>7} {:>6}",
            "test Hz", "FE Hz", "err %", "MAC %"
        ));
    }
    s.push('\n');
    for (i, p) in corr.pairs.iter().enumerate() {
        s.push_str(&format!(
            "{:>5} {:>6} {:>10.2} {:>10.2} {:>8.2} {:>7.2}",
            p.test_mode,
            p.model_mode,
            p.test_hz,
            p.model_hz,
            p.freq_error_pct,
            100.0 * p.mac
        ));
        if let Some(row) = paper.and_then(|r| r.get(i)) {
            s.push_str(&format!(
                "   |        {:>7.1} {:>7.1} {:>7.1} {:>6.1}",
                row.0, row.1, row.2, row.3
            ));
        }
        s.push('\n');
    }
    for u in &corr.unpaired {
        s.push_str(&format!(
            "{u:>5} {:>6}  (no model mode with a MAC above the threshold)\n",
            "-"
        ));
    }
    s.push_str(&format!(
        "mean |error| {:.2} %, smallest MAC {:.2} %, DOFs {:?}\n",
        corr.mean_abs_freq_error_pct(),
        100.0 * corr.min_mac(),
        corr.dofs
    ));
    s
}

/// Identified modes (paper Table 1): frequency and damping of each mode of
/// one or more sets side by side.
pub fn modes_table(sets: &[(&str, &TestModes)]) -> String {
    let mut s = String::from("mode");
    for (name, _) in sets {
        s.push_str(&format!(" | {name:^24}"));
    }
    s.push_str("\n    ");
    for _ in sets {
        s.push_str(&format!(" | {:>12} {:>11}", "freq Hz", "damping %"));
    }
    s.push('\n');
    let rows = sets.iter().map(|(_, t)| t.modes.len()).max().unwrap_or(0);
    for r in 0..rows {
        s.push_str(&format!("{:>4}", r + 1));
        for (_, t) in sets {
            match t.modes.get(r) {
                Some(m) => s.push_str(&format!(
                    " | {:>12.2} {:>11.2}",
                    m.frequency_hz,
                    100.0 * m.damping
                )),
                None => s.push_str(&format!(" | {:>12} {:>11}", "-", "-")),
            }
        }
        s.push('\n');
    }
    s
}

/// Spring adjustments (paper Figs 2–3) as a table: one column per result.
pub fn adjustment_table(results: &[(&str, &UpdateResult)]) -> String {
    let mut s = format!("{:>8}", "spring");
    for (name, _) in results {
        s.push_str(&format!(" {name:>22}"));
    }
    s.push('\n');
    let labels = results
        .first()
        .map(|r| r.1.labels.clone())
        .unwrap_or_default();
    for (i, l) in labels.iter().enumerate() {
        s.push_str(&format!("{l:>8}"));
        for (_, r) in results {
            let v = r.change.get(i).copied().unwrap_or(f64::NAN);
            s.push_str(&format!(" {:>21.2}%", 100.0 * v));
        }
        s.push('\n');
    }
    for (title, f) in [
        (
            "evals",
            &(|r: &UpdateResult| r.evaluations.to_string()) as &dyn Fn(&UpdateResult) -> String,
        ),
        ("status", &|r: &UpdateResult| r.status.to_string()),
        ("cond.", &|r: &UpdateResult| {
            format!("{:.1e}", r.condition())
        }),
        ("resid.", &|r: &UpdateResult| {
            format!("{:.1e}->{:.1e}", r.residual_initial, r.residual_final)
        }),
    ] {
        s.push_str(&format!("{title:>8}"));
        for (_, r) in results {
            let t: String = f(r).chars().take(22).collect();
            s.push_str(&format!(" {t:>22}"));
        }
        s.push('\n');
    }
    s
}

/// The MAC matrix as a figure (test modes down, flexible model modes
/// across).
pub fn mac_figure(title: &str, corr: &Correlation, test_name: &str, model_name: &str) -> Figure {
    let rows = (1..=corr.mac.len()).map(|i| format!("T{i}")).collect();
    let cols = (1..=corr.model_hz.len()).map(|i| format!("A{i}")).collect();
    let panel = Panel::matrix(
        format!("MAC at DOFs {:?}", corr.dofs),
        format!("model modes ({model_name})"),
        format!("test modes ({test_name})"),
        corr.mac.clone(),
        rows,
        cols,
    );
    let mut fig = Figure::single(title, panel);
    fig.width = 760;
    fig.height = 660;
    fig
}

/// Bars of the stiffness adjustment per spring, %, one group per result
/// (paper Figs 2–3).
pub fn adjustment_figure(title: &str, results: &[(String, &UpdateResult)]) -> Figure {
    let labels = results
        .first()
        .map(|r| r.1.labels.clone())
        .unwrap_or_default();
    let groups: Vec<(String, Vec<f64>)> = results
        .iter()
        .map(|(n, r)| (n.clone(), r.change_pct()))
        .collect();
    crate::plot::bar_chart(title, &labels, &groups, "stiffness adjustment [%]")
}

/// FRF magnitudes (log10) above the stabilisation diagram.
pub fn stabilisation_figure(
    title: &str,
    frf: &Frf,
    fit: &FitResult,
    band_hz: (f64, f64),
) -> Figure {
    let lines: Vec<usize> = (0..frf.freq_hz.len())
        .filter(|&l| frf.freq_hz[l] >= band_hz.0 && frf.freq_hz[l] <= band_hz.1)
        .collect();
    let x: Vec<f64> = lines.iter().map(|&l| frf.freq_hz[l]).collect();
    let series = frf
        .h
        .iter()
        .zip(&frf.output_dofs)
        .map(|(h, d)| {
            Series::line(
                format!("DOF {d}"),
                x.clone(),
                lines
                    .iter()
                    .map(|&l| h[l].norm().max(1e-300).log10())
                    .collect(),
            )
        })
        .collect();
    let top = Panel::xy(
        format!("H1 accelerance, {} averages", frf.averages),
        "frequency [Hz]",
        "log10 |H| [(m/s²)/N]",
        series,
    );
    let (st, un): (Vec<&StabPole>, Vec<&StabPole>) = fit.poles.iter().partition(|p| p.stable);
    let pts = |v: &[&StabPole]| -> (Vec<f64>, Vec<f64>) {
        (
            v.iter().map(|p| p.freq_hz).collect(),
            v.iter().map(|p| p.order as f64).collect(),
        )
    };
    let (xs, ys) = pts(&st);
    let (xu, yu) = pts(&un);
    let mut series = vec![
        Series::points("stable", xs, ys),
        Series::points("not stable", xu, yu),
    ];
    let lo = fit.poles.iter().map(|p| p.order).min().unwrap_or(0) as f64;
    let hi = fit.poles.iter().map(|p| p.order).max().unwrap_or(1) as f64;
    for (i, m) in fit.modes.iter().enumerate() {
        let label = if i == 0 { "identified" } else { "" };
        series.push(Series::dashed(label, vec![m.frequency_hz; 2], vec![lo, hi]));
    }
    let bottom = Panel::xy(
        "stabilisation diagram (LSCF)",
        "frequency [Hz]",
        "model order",
        series,
    );
    Figure::new(title, vec![top, bottom], 1)
}
