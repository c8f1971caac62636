//! Command-line front end: one file per subcommand.

mod campaign;
pub mod check;
mod diagnose;
mod identify;
mod interface;
mod modal;
pub mod out;
pub mod output;
pub mod records;
mod simulate;
mod update;

use clap::{Parser, Subcommand};
use std::path::PathBuf;

/// tacit: find what a linear structural model misses in a vibration test.
#[derive(Debug, Parser)]
#[command(name = "tacit", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Natural frequencies and mode shapes of a model.
    Modal(modal::Args),
    /// Simulate a model under an input and write a record (with its truth).
    Simulate(simulate::Args),
    /// Reconstruct the internal forces a linear model lacks from a record.
    Identify(identify::Args),
    /// Update model parameters so simulated responses match a record.
    Update(update::Args),
    /// Find what the model misses, trace it to an effect, add and fit it, report before/after.
    Diagnose(diagnose::Args),
    /// Diagnose many records against one model, summarize, fit shared parameters.
    Campaign(campaign::Args),
}

/// Run the parsed command.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Modal(a) => modal::run(a),
        Command::Simulate(a) => simulate::run(a),
        Command::Identify(a) => identify::run(a),
        Command::Update(a) => update::run(a),
        Command::Diagnose(a) => diagnose::run(a),
        Command::Campaign(a) => campaign::run(a),
    }
}

/// A list of DOFs (numbered from 1) given as `1,5,6` or `1-8`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DofList(pub Vec<usize>);

impl std::str::FromStr for DofList {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        parse_dofs(s).map(DofList)
    }
}

/// Parse a comma-separated list of DOFs (from 1), e.g. `1,5,6` or `1-8`.
pub fn parse_dofs(s: &str) -> Result<Vec<usize>, String> {
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        if let Some((a, b)) = part.split_once('-') {
            let a: usize = a
                .trim()
                .parse()
                .map_err(|_| format!("bad DOF range '{part}'"))?;
            let b: usize = b
                .trim()
                .parse()
                .map_err(|_| format!("bad DOF range '{part}'"))?;
            if a < 1 || b < a {
                return Err(format!("bad DOF range '{part}'"));
            }
            out.extend(a..=b);
        } else {
            let d: usize = part.parse().map_err(|_| format!("bad DOF '{part}'"))?;
            if d < 1 {
                return Err("DOFs are numbered from 1".into());
            }
            out.push(d);
        }
    }
    if out.is_empty() {
        return Err("empty DOF list".into());
    }
    Ok(out)
}

/// Check every DOF of a list is in the model.
pub fn check_dofs(dofs: &[usize], ndof: usize, what: &str) -> anyhow::Result<()> {
    for &d in dofs {
        if d < 1 || d > ndof {
            anyhow::bail!("{what}: DOF {d} is outside the model (1..={ndof})");
        }
    }
    Ok(())
}

/// Parse `a,b` into a pair of floats.
pub fn parse_pair(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("expected two numbers 'a,b', got '{s}'"))?;
    let a: f64 = a.trim().parse().map_err(|_| format!("bad number '{a}'"))?;
    let b: f64 = b.trim().parse().map_err(|_| format!("bad number '{b}'"))?;
    Ok((a, b))
}

/// Path helper used by several commands.
pub fn with_suffix(path: &std::path::Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!("{stem}{suffix}.{ext}"))
}

/// How to read a record file: `.mat` files need a variable mapping and a rate.
#[derive(Debug, Clone, clap::Args)]
pub struct RecordOpts {
    /// For .mat records: variable=channel pairs, e.g. `V1=force_1,V2=disp_1`
    /// (channel = force, disp, vel or accel, then the DOF from 1, or
    /// `accel:LABEL` at a named point); `VAR[k]=...` takes signal k (from 1)
    /// of a matrix variable: row k of a wide matrix (`Acceleration` 3×N),
    /// column k of a tall one.
    #[arg(long, value_name = "VAR=CHANNEL,...")]
    pub mat_map: Option<String>,
    /// For .mat records: sample rate, Hz, or the name of a scalar variable
    /// of the file holding it (`Fs`).
    #[arg(long, value_name = "HZ|VARIABLE")]
    pub mat_fs: Option<String>,
    /// For .mat records: subtract each channel's mean.
    #[arg(long)]
    pub remove_mean: bool,
}

/// Read a record (HDF5, CSV, or MAT with `opts`); unit conversions are
/// reported on stderr.
pub fn load_record(
    path: &std::path::Path,
    opts: &RecordOpts,
) -> anyhow::Result<tacit::record::Record> {
    use tacit::record::{self, Format, MatChannel, MatMapping, MatRate};
    if record::Format::from_path(path)? != Format::Mat {
        return read_record(path);
    }
    let map = opts.mat_map.as_ref().ok_or_else(|| {
        anyhow::anyhow!(
            "{}: a .mat record needs --mat-map and --mat-fs",
            path.display()
        )
    })?;
    let fs = opts
        .mat_fs
        .as_deref()
        .map(MatRate::parse)
        .ok_or_else(|| anyhow::anyhow!("{}: a .mat record needs --mat-fs", path.display()))?;
    if let MatRate::Hz(hz) = fs {
        check::positive("--mat-fs", hz, 1e9, "sample rate, Hz")?;
    }
    let channels = map
        .split(',')
        .map(|pair| MatChannel::parse(pair).map_err(|e| anyhow::anyhow!("--mat-map: {e}")))
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(record::read_mat(
        path,
        &MatMapping {
            channels,
            fs,
            remove_mean: opts.remove_mean,
        },
    )?)
}

/// [`read_record`] with its channels resolved against `model` (a
/// universal file's node and direction: the node on a lumped model, the
/// point `n<node>:<dir>` on a model with point labels).
pub fn read_record_for(
    path: &std::path::Path,
    model: &tacit::model::Model,
) -> anyhow::Result<tacit::record::Record> {
    let mut rec = read_record(path)?;
    model.resolve_channels(&mut rec)?;
    Ok(rec)
}

/// Read an HDF5 or CSV record; unit conversions are reported on stderr.
pub fn read_record(path: &std::path::Path) -> anyhow::Result<tacit::record::Record> {
    let (rec, conversions) = tacit::record::read_with_conversions(path)?;
    for c in conversions {
        eprintln!("tacit: note: {}: {c}", path.display());
    }
    Ok(rec)
}
