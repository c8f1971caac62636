//! The `tacit` command line. Parses arguments (clap), calls the library,
//! writes files; all numerics live in the library.

// `!(x > 0.0)` also rejects NaN; used on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod cli;

use clap::Parser;

fn main() {
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => {}
        Err(e) => {
            eprintln!("tacit: error: {e:#}");
            std::process::exit(1);
        }
    }
}
