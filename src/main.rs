//! The `tacit` command line. Parses arguments (clap), calls the library,
//! writes files; all numerics live in the library.

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
