//! Reproduces Table 4 of Hemez & Doebling (§6.1): time-domain updating of
//! the 4-DOF chain with a cubic spring, four implementations (GLS with
//! model reduction on displacements, on displacements and velocities; PCD
//! full order and reduced on displacements), on noise-free data and with
//! 1 % noise, printed beside the paper's values; then the four optimizers
//! on one column.
//!
//! Run: `cargo run --release --example table4_cubic_updating`
//! (optional argument: the seed of the noise, default 11).

use tacit::cases::table4;
use tacit::update::{self, FitResult, FitSettings, Optimizer};

const ROWS: [&str; 5] = ["k1", "k2", "k3", "k4", "cubic"];

fn main() -> tacit::Result<()> {
    let seed: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(11);
    for noise in [0.0, 0.01] {
        let case = table4::case(noise, seed)?;
        let mut results = Vec::new();
        for col in table4::columns() {
            let problem = table4::problem(&case, &col)?;
            results.push(update::fit(&problem, &FitSettings::default())?);
        }
        print_table(noise, seed, &results);
    }
    println!("\nOptimizers on column 3 (PCD, FM, D), noise-free:");
    let case = table4::case(0.0, seed)?;
    let col = table4::columns()[2];
    for opt in [
        Optimizer::Lm,
        Optimizer::Gn,
        Optimizer::Bfgs,
        Optimizer::Simplex,
    ] {
        let problem = table4::problem(&case, &col)?;
        let r = update::fit(&problem, &FitSettings::with(opt))?;
        println!(
            "  {:8} {}  {:3} iterations {:5} simulations {:7.3} s  {:?}",
            format!("{opt:?}"),
            fmt_row(&r.percent_changes()),
            r.iterations,
            r.simulations,
            r.elapsed_s,
            r.termination
        );
    }
    Ok(())
}

fn fmt_row(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:+7.2}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn print_table(noise: f64, seed: u64, results: &[FitResult]) {
    let cols = table4::columns();
    println!(
        "\nTable 4, noise {:.0} % (seed {seed}); changes in %, truth k3 -15, cubic +25; ours | paper",
        noise * 100.0
    );
    print!("{:6}", "");
    for c in &cols {
        print!("| {:^22}", c.label);
    }
    println!();
    for (row, name) in ROWS.iter().enumerate() {
        print!("{name:6}");
        for (c, r) in results.iter().enumerate() {
            print!(
                "| {:+7.2} ({:+6.1})     ",
                r.percent_changes()[row],
                table4::PAPER[c][row]
            );
        }
        println!();
    }
    for (c, r) in results.iter().enumerate() {
        let id = r.identifiability.as_ref();
        let worst = id
            .map(|i| {
                i.parameters
                    .iter()
                    .map(|p| p.std_scaled * 100.0)
                    .fold(0.0, f64::max)
            })
            .unwrap_or(f64::NAN);
        println!(
            "  {:12} error {:.4} -> {:.5}; {} it, {} sims, {:.3} s; {:?}; reduction error {}; max std at 1 % noise {:.2} points; {}",
            cols[c].label,
            r.errors_before.as_ref().map_or(f64::NAN, |e| e.overall),
            r.errors_after.as_ref().map_or(f64::NAN, |e| e.overall),
            r.iterations,
            r.simulations,
            r.elapsed_s,
            r.termination,
            r.reduction_error
                .map_or("-".to_string(), |e| format!("{:.4}", e)),
            worst,
            id.map_or("no identifiability report", |i| i.verdict.as_str())
        );
    }
}
