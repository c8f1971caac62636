//! Silverbox (measured electronic Duffing-type oscillator, Wigren &
//! Schoukens 2013) through the calibrated diagnosis, as `tacit diagnose`
//! runs it (the same library function, model file and settings file; the
//! command is in docs/silverbox.md): estimation on samples 40650–127400,
//! open-loop RMS error on the arrow test segment 100–40575 with its first
//! 50 samples not scored, before (the calibrated linear model) and after
//! (the effects found, every parameter refined by the open-loop error).
//! Reads the data from the shared data set beside the checkout; writes the
//! report to out/silverbox_close_the_loop.
//!
//! `cargo run --release --example silverbox_close_the_loop`

use std::path::Path;
use tacit::cases::silverbox;

fn main() -> anyhow::Result<()> {
    let Some(path) = tacit::record::shared_data("silverbox/SNLS80mV.mat") else {
        return Ok(());
    };
    let out = Path::new("out/silverbox_close_the_loop");
    let r = silverbox::run(&path, &silverbox::Settings::default(), Some(out))?;
    println!("{}", r.summary());
    Ok(())
}
