//! `tacit modal`: natural frequencies and mode shapes.

use std::path::PathBuf;
use tacit::model::Model;

/// Arguments of `tacit modal`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file (TOML).
    #[arg(long)]
    model: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(serde::Serialize)]
struct ModeOut {
    mode: usize,
    frequency_hz: f64,
    rigid: bool,
    shape: Vec<f64>,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let model = Model::from_file(&a.model)?;
    let modes = tacit::modal::solve(&model.mass_matrix(), &model.stiffness_matrix())?;
    let n = model.ndof();
    let out: Vec<ModeOut> = (0..n)
        .map(|r| {
            let col = modes.shapes.column(r);
            let scale = col.amax().max(f64::MIN_POSITIVE);
            ModeOut {
                mode: r + 1,
                frequency_hz: modes.freq_hz[r],
                rigid: modes.rigid[r],
                shape: col.iter().map(|x| x / scale).collect(),
            }
        })
        .collect();
    if a.json {
        #[derive(serde::Serialize)]
        struct Doc<'a> {
            model: &'a str,
            ndof: usize,
            modes: &'a [ModeOut],
        }
        let doc = Doc {
            model: &model.name,
            ndof: n,
            modes: &out,
        };
        println!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(());
    }
    println!(
        "model {} ({} DOFs), undamped modes, shapes scaled to max |φ| = 1",
        model.name, n
    );
    print!("{:>4} {:>10}  ", "mode", "freq (Hz)");
    for d in 1..=n {
        print!("{:>7}", format!("dof{d}"));
    }
    println!();
    for m in &out {
        let f = if m.rigid {
            "rigid".to_string()
        } else {
            format!("{:.3}", m.frequency_hz)
        };
        print!("{:>4} {:>10}  ", m.mode, f);
        for x in &m.shape {
            print!("{x:>7.3}");
        }
        println!();
    }
    Ok(())
}
