//! Silverbox (measured electronic Duffing oscillator, Wigren & Schoukens
//! 2013): fit a linear m, d, k model to the estimation segment by output
//! error, run the close-the-loop diagnosis on it, and report the open-loop
//! RMS simulation error on the standard test segment before (linear) and
//! after (with the effect found). Reads the data from the shared data set
//! beside the checkout.
//!
//! `cargo run --release --example silverbox_close_the_loop`

use std::path::Path;
use tacit::cases::silverbox;

fn main() -> anyhow::Result<()> {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/data/silverbox/SNLS80mV.mat"
    ));
    let out = Path::new("out/silverbox_close_the_loop");
    let mut settings = silverbox::Settings::default();
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--substeps") {
        settings.substeps = args[i + 1].parse()?;
    }
    if args.iter().any(|a| a == "--full-estimation") {
        settings.estimation = (40650, 127400);
    }
    let r = silverbox::run(path, &settings, Some(out))?;
    println!("{}", r.summary());
    Ok(())
}
