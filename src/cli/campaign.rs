//! `tacit campaign`: many records diagnosed against one model, in
//! parallel, resumable, summarized, with one set of effect parameters
//! fitted to all of them (docs/cli.md).

use super::out::outln;
use super::DofList;
use anyhow::{bail, Context};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use tacit::campaign::{joint, summary, Entry, Manifest};
use tacit::model::Model;

/// Arguments of `tacit campaign`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A campaign manifest (TOML, docs/cli.md) or a directory whose .h5 and
    /// .csv records are diagnosed (name order).
    input: PathBuf,
    /// Declared model (TOML): needed with a directory; replaces the
    /// manifest's.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Sensor DOFs, numbered from 1 (default: the manifest's, or every
    /// output channel).
    #[arg(long, value_name = "DOFS")]
    sensors: Option<DofList>,
    /// Records diagnosed at once, 1 to 256 (default: the number of cores).
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
    /// Skip the joint fit of the shared effect.
    #[arg(long)]
    no_joint: bool,
    /// Output directory: records/NAME/ per record, campaign.md, .csv,
    /// .json. A record whose report is already there is not diagnosed
    /// again.
    #[arg(short, long)]
    output: PathBuf,
    /// Diagnose every record again.
    #[arg(long)]
    force: bool,
}

/// The manifest with the command line's overrides.
fn manifest(a: &Args) -> anyhow::Result<Manifest> {
    let mut m = if a.input.is_dir() {
        let model = a.model.as_ref().with_context(|| {
            format!(
                "{}: a directory of records needs --model",
                a.input.display()
            )
        })?;
        Manifest::from_dir(&a.input, model)?
    } else {
        Manifest::from_file(&a.input)?
    };
    if let Some(p) = &a.model {
        m.model = p.clone();
    }
    if let Some(s) = &a.sensors {
        m.sensors = Some(s.0.clone());
    }
    if a.no_joint {
        m.joint.off = true;
    }
    Ok(m)
}

/// Make (or reopen) the output directory; with `force` the records done
/// before are removed. A directory that holds something else is refused.
fn open_output(out: &Path, m: &Manifest, force: bool) -> anyhow::Result<PathBuf> {
    let marker = out.join("campaign-manifest.toml");
    // records/ alone: reports written by per-record jobs (a Slurm array)
    let busy = std::fs::read_dir(out)
        .is_ok_and(|mut d| d.any(|e| e.is_ok_and(|e| e.file_name() != "records")));
    if busy && !marker.exists() {
        bail!(
            "{}: not empty and not a campaign's output; choose another directory",
            out.display()
        );
    }
    let records = out.join("records");
    if force && records.exists() {
        std::fs::remove_dir_all(&records)
            .with_context(|| format!("{}: cannot remove", records.display()))?;
    }
    std::fs::create_dir_all(&records)
        .with_context(|| format!("{}: cannot create", records.display()))?;
    for e in std::fs::read_dir(&records)?.flatten() {
        if e.path().extension().is_some_and(|x| x == "partial") {
            std::fs::remove_dir_all(e.path())?;
        }
    }
    tacit::io::write_string(&marker, &toml::to_string(m)?)?;
    Ok(records)
}

/// The progress bar: drawn on a terminal, hidden when piped.
fn bar(len: usize) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(len as u64);
    if let Ok(s) = ProgressStyle::with_template(
        "campaign {bar:30} {pos}/{len} records {elapsed} (eta {eta}) {msg}",
    ) {
        b.set_style(s);
    }
    b
}

/// Diagnose the records not done yet, in parallel; the failures by name.
fn diagnose_all(
    m: &Manifest,
    model: &Model,
    records: &Path,
    jobs: usize,
) -> anyhow::Result<Vec<(String, String)>> {
    let settings = m.diagnose_settings()?;
    let linear = m
        .linear_records
        .iter()
        .map(|p| tacit::record::read(p))
        .collect::<tacit::Result<Vec<_>>>()?;
    let todo: Vec<&Entry> = m
        .records
        .iter()
        .filter(|e| !records.join(&e.name).join("report.json").exists())
        .collect();
    let done = m.records.len() - todo.len();
    if done > 0 {
        eprintln!(
            "tacit: {done} record(s) already diagnosed in {}: kept",
            records.display()
        );
    }
    let pb = bar(todo.len());
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build()?;
    let failed = pool.install(|| {
        todo.par_iter()
            .filter_map(|e| {
                let part = records.join(format!("{}.partial", e.name));
                let r = tacit::campaign::run_record(m, e, model, &linear, &settings, &part)
                    .map_err(anyhow::Error::from)
                    .and_then(|_| Ok(std::fs::rename(&part, records.join(&e.name))?));
                pb.inc(1);
                pb.set_message(e.name.clone());
                r.err().map(|err| {
                    let _ = std::fs::remove_dir_all(&part);
                    (e.name.clone(), super::out::error_message(&err))
                })
            })
            .collect::<Vec<_>>()
    });
    pb.finish_and_clear();
    Ok(failed)
}

/// Run `tacit campaign`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let m = manifest(&a)?;
    let jobs = a.jobs.unwrap_or_else(rayon::current_num_threads);
    super::check::count("--jobs", jobs, 1, 256, "records diagnosed at once")?;
    let model = Model::from_file(&m.model)?;
    if let Some(s) = &m.sensors {
        super::check_dofs(s, model.ndof(), "sensors")?;
    }
    let t0 = std::time::Instant::now();
    let records = open_output(&a.output, &m, a.force)?;
    let failed = diagnose_all(&m, &model, &records, jobs)?;
    let diagnose_s = t0.elapsed().as_secs_f64();
    for (name, msg) in &failed {
        eprintln!("tacit: warning: record {name}: {msg}");
    }
    let rows: Vec<summary::Row> = m
        .records
        .iter()
        .filter(|e| !failed.iter().any(|f| f.0 == e.name))
        .map(|e| {
            summary::read_row(
                &records.join(&e.name).join("report.json"),
                &e.name,
                &e.group,
            )
        })
        .collect::<tacit::Result<_>>()?;
    let spreads = summary::spreads(&rows);
    let t1 = std::time::Instant::now();
    let joint = if m.joint.off {
        None
    } else {
        joint_fit(&m, &model, &rows, &records)
    };
    let timings = (diagnose_s, t1.elapsed().as_secs_f64());
    write_summary(&a.output, &rows, &spreads, &joint, &failed, jobs, timings)?;
    if !failed.is_empty() {
        bail!(
            "{} of {} records failed (listed in {}); run again to retry them",
            failed.len(),
            m.records.len(),
            a.output.join("campaign.md").display()
        );
    }
    Ok(())
}

/// The effect to share: the manifest's, or the one found in most records.
fn shared_effect(m: &Manifest, rows: &[summary::Row]) -> Option<(String, String, Vec<usize>)> {
    let mut counts: Vec<(String, usize)> = vec![];
    for l in rows.iter().flat_map(|r| &r.effects) {
        match counts.iter_mut().find(|c| &c.0 == l) {
            Some(c) => c.1 += 1,
            None => counts.push((l.clone(), 1)),
        }
    }
    let label = match &m.joint.effect {
        Some(l) => l.clone(),
        None => counts.iter().max_by_key(|c| c.1)?.0.clone(),
    };
    let (kind, dofs) = rows.iter().find_map(|r| r.kinds.get(&label))?.clone();
    Some((label, kind, dofs))
}

/// The joint fit (None, with a message, when it cannot run).
fn joint_fit(
    m: &Manifest,
    model: &Model,
    rows: &[summary::Row],
    records: &Path,
) -> Option<Result<joint::JointFit, String>> {
    let (label, kind, dofs) = shared_effect(m, rows)?;
    let with: Vec<&summary::Row> = rows.iter().filter(|r| r.effects.contains(&label)).collect();
    if with.len() < 2 {
        return Some(Err(format!(
            "{label} was found in {} record(s): nothing to share",
            with.len()
        )));
    }
    let run = || -> tacit::Result<joint::JointFit> {
        let settings = m.diagnose_settings()?;
        let recs = with
            .iter()
            .map(|r| {
                let e = m
                    .records
                    .iter()
                    .find(|e| e.name == r.name)
                    .expect("row of an entry");
                Ok((e, tacit::record::read(&e.path)?))
            })
            .collect::<tacit::Result<Vec<_>>>()?;
        let diagnosed = with
            .iter()
            .zip(&recs)
            .map(|(r, (e, rec))| {
                Ok(joint::Diagnosed {
                    name: r.name.clone(),
                    record: rec,
                    sensors: m.sensors_of(e),
                    fitted: Model::from_file(&records.join(&r.name).join("model-fitted.toml"))?,
                    substeps: r.substeps,
                })
            })
            .collect::<tacit::Result<Vec<_>>>()?;
        joint::fit_diagnosed(model, (&label, &kind, &dofs), &diagnosed, &settings)
    };
    Some(run().map_err(|e| e.to_string()))
}

/// campaign.md, campaign.csv, campaign.json; the Markdown on stdout.
fn write_summary(
    out: &Path,
    rows: &[summary::Row],
    spreads: &[summary::Spread],
    joint: &Option<Result<joint::JointFit, String>>,
    failed: &[(String, String)],
    jobs: usize,
    (diagnose_s, joint_s): (f64, f64),
) -> anyhow::Result<()> {
    let mut md = format!(
        "# Campaign: {} record(s)\n\nDiagnosed with {jobs} job(s) in {diagnose_s:.1} s (records kept from an earlier run included at no cost); joint fit {joint_s:.1} s. Errors are multiple-shooting relative errors (fractions of the measured signal); ± are noise-only standard errors in the records' reports.\n\n## Per record\n\n{}",
        rows.len(),
        summary::markdown_rows(rows)
    );
    if !failed.is_empty() {
        md.push_str("\n## Failed records\n\n");
        for (n, msg) in failed {
            md.push_str(&format!("- {n}: {msg}\n"));
        }
    }
    md.push_str(&format!(
        "\n## Spread across records\n\n{}",
        summary::markdown_spreads(spreads)
    ));
    md.push_str(&joint_markdown(joint));
    tacit::io::write_string(&out.join("campaign.md"), &md)?;
    tacit::io::write_string(&out.join("campaign.csv"), &summary::csv(rows)?)?;
    let joint_json = match joint {
        Some(Ok(j)) => serde_json::to_value(j)?,
        Some(Err(msg)) => serde_json::json!({ "error": msg }),
        None => serde_json::Value::Null,
    };
    tacit::io::write_json(
        &out.join("campaign.json"),
        &serde_json::json!({
            "tacit_version": env!("CARGO_PKG_VERSION"),
            "records": rows,
            "spreads": spreads,
            "joint": joint_json,
            "failed": failed,
            "jobs": jobs,
            "timings": { "diagnose_s": diagnose_s, "joint_s": joint_s },
        }),
    )?;
    if let Some(Ok(j)) = joint {
        tacit::io::write_string(&out.join("model-joint.toml"), &j.model.to_toml_string())?;
    }
    outln!("{md}");
    Ok(())
}

/// The joint fit in Markdown.
fn joint_markdown(joint: &Option<Result<joint::JointFit, String>>) -> String {
    let j = match joint {
        None => return "\n## Joint fit\n\nnot run (no effect found, or switched off)\n".into(),
        Some(Err(msg)) => return format!("\n## Joint fit\n\nnot done: {msg}\n"),
        Some(Ok(j)) => j,
    };
    let mut s = format!(
        "\n## Joint fit: {} shared by {} records\n\n{} iterations, {:.1} s, {}; model with the shared parameters: model-joint.toml\n\n| parameter | shared value | ± (noise only) | per-record values |\n|---|---|---|---|\n",
        j.effect,
        j.records.len(),
        j.iterations,
        j.elapsed_s,
        j.termination
    );
    for p in &j.parameters {
        let per: Vec<String> = p
            .per_record
            .iter()
            .map(|v| summary::with_unit(*v, &p.unit))
            .collect();
        s.push_str(&format!(
            "| {} | {}{} | {} | {} |\n",
            p.name,
            summary::with_unit(p.value, &p.unit),
            if p.at_bound { " (at a bound)" } else { "" },
            p.std.map_or("—".into(), |v| format!("{v:.2e} {}", p.unit)),
            per.join(", ")
        ));
    }
    s.push_str("\n| record | error, own fit | error, shared parameters |\n|---|---|---|\n");
    for r in &j.records {
        s.push_str(&format!(
            "| {} | {} | {} |\n",
            r.name,
            tacit::diagnose::report::pct(r.own),
            tacit::diagnose::report::pct(r.joint)
        ));
    }
    s
}
