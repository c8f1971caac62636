//! The campaign's summary: one row per record read back from its
//! `report.json`, the spread of every parameter across records, and the
//! writers (CSV, JSON, Markdown).

use crate::diagnose::report::pct;
use crate::error::{Result, TacitError};
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// The SI unit of an effect parameter, by its name in the reports.
pub fn unit(name: &str) -> &'static str {
    match name {
        "gap" => "m",
        "stiffness" | "k" => "N/m",
        "level" => "N",
        "k3" => "N/m^3",
        "k2" => "N/m^2",
        "c2" => "N s^2/m^2",
        "c3" => "N s^3/m^3",
        "delta" => "relative",
        _ => "",
    }
}

/// One fitted parameter of one effect.
#[derive(Debug, Clone, Serialize)]
pub struct ParamValue {
    /// `contact 5→6 gap`.
    pub key: String,
    /// SI value.
    pub value: f64,
    /// Standard error (noise only), when determined.
    pub std_error: Option<f64>,
    /// SI unit.
    pub unit: String,
}

/// One record's line of the summary.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Record name.
    pub name: String,
    /// Group (level, sensor set).
    pub group: String,
    /// What the diagnosis found, in words.
    pub verdict: String,
    /// Labels of the effects found.
    pub effects: Vec<String>,
    /// Their parameters.
    pub parameters: Vec<ParamValue>,
    /// Multiple-shooting relative error of the declared model (fraction).
    pub error_before: Option<f64>,
    /// The same for the fitted model.
    pub error_after: Option<f64>,
    /// Open-loop simulation error before and after (fractions).
    pub simulation_before: Option<f64>,
    /// Open-loop simulation error after.
    pub simulation_after: Option<f64>,
    /// Relative error of the fitted model on the validation record.
    pub validation_after: Option<f64>,
    /// Effect kinds and DOFs, by label (for the joint fit).
    #[serde(skip)]
    pub kinds: BTreeMap<String, (String, Vec<usize>)>,
    /// Integration sub-steps of the fitted model.
    #[serde(skip)]
    pub substeps: usize,
}

/// The spread of one parameter across the records that found it.
#[derive(Debug, Clone, Serialize)]
pub struct Spread {
    /// `contact 5→6 gap`.
    pub key: String,
    /// SI unit.
    pub unit: String,
    /// Records that found it.
    pub records: usize,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (0 for one record).
    pub std: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
}

/// Read one record's `report.json` into its row.
pub fn read_row(path: &Path, name: &str, group: &str) -> Result<Row> {
    let text = std::fs::read_to_string(path).map_err(|e| TacitError::io(path, e))?;
    let r: Value = serde_json::from_str(&text)
        .map_err(|e| TacitError::Setting(format!("{}: {e}", path.display())))?;
    let f = |v: &Value| v.as_f64();
    let mut row = Row {
        name: name.into(),
        group: group.into(),
        verdict: r["verdict"].as_str().unwrap_or("").into(),
        effects: vec![],
        parameters: vec![],
        error_before: f(&r["before"]["relative_error"]),
        error_after: f(&r["after"]["relative_error"]),
        simulation_before: f(&r["before"]["simulation_error"]),
        simulation_after: f(&r["after"]["simulation_error"]),
        validation_after: f(&r["validation"]["after"]["relative_error"]),
        kinds: BTreeMap::new(),
        substeps: r["substeps"][1].as_u64().unwrap_or(10) as usize,
    };
    for e in r["effects"].as_array().into_iter().flatten() {
        let label = e["label"].as_str().unwrap_or("?").to_string();
        let dofs = e["dofs"]
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|d| d.as_u64().map(|d| d as usize))
                    .collect()
            })
            .unwrap_or_default();
        let kind = e["kind"].as_str().unwrap_or("").to_string();
        row.kinds.insert(label.clone(), (kind, dofs));
        for (p, v) in e["parameters"].as_object().into_iter().flatten() {
            row.parameters.push(ParamValue {
                key: format!("{label} {p}"),
                value: v.as_f64().unwrap_or(f64::NAN),
                std_error: e["std_errors"][p].as_f64(),
                unit: unit(p).into(),
            });
        }
        row.effects.push(label);
    }
    Ok(row)
}

/// The spread of every parameter over the rows, in first-seen order.
pub fn spreads(rows: &[Row]) -> Vec<Spread> {
    let mut keys: Vec<(String, String)> = vec![];
    for p in rows.iter().flat_map(|r| &r.parameters) {
        if !keys.iter().any(|k| k.0 == p.key) {
            keys.push((p.key.clone(), p.unit.clone()));
        }
    }
    keys.into_iter()
        .map(|(key, unit)| {
            let v: Vec<f64> = rows
                .iter()
                .flat_map(|r| &r.parameters)
                .filter(|p| p.key == key)
                .map(|p| p.value)
                .collect();
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
            Spread {
                key,
                unit,
                records: v.len(),
                mean,
                std: var.sqrt(),
                min: v.iter().copied().fold(f64::INFINITY, f64::min),
                max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            }
        })
        .collect()
}

/// A parameter value with its unit (gaps in mm).
pub fn with_unit(value: f64, unit: &str) -> String {
    match unit {
        "m" => format!("{:.4} mm", value * 1e3),
        "relative" => format!("{:+.2} %", value * 100.0),
        u => format!("{value:.4e} {u}"),
    }
}

/// The per-record table in Markdown.
pub fn markdown_rows(rows: &[Row]) -> String {
    let mut s = String::from(
        "| record | group | effects found | parameters | error before → after | simulation error before → after | validation after |\n|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let params: Vec<String> = r
            .parameters
            .iter()
            .map(|p| format!("{} = {}", p.key, with_unit(p.value, &p.unit)))
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} → {} | {} → {} | {} |",
            r.name,
            r.group,
            if r.effects.is_empty() {
                "none".into()
            } else {
                r.effects.join(", ")
            },
            params.join("; "),
            pct(r.error_before),
            pct(r.error_after),
            pct(r.simulation_before),
            pct(r.simulation_after),
            r.validation_after.map_or("—".into(), |v| pct(Some(v)))
        );
    }
    s
}

/// The spread table in Markdown.
pub fn markdown_spreads(sp: &[Spread]) -> String {
    let mut s = String::from(
        "| parameter | records | mean | std | relative std | min | max |\n|---|---|---|---|---|---|---|\n",
    );
    for p in sp {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.2} % | {} | {} |",
            p.key,
            p.records,
            with_unit(p.mean, &p.unit),
            with_unit(p.std, &p.unit),
            100.0 * p.std / p.mean.abs(),
            with_unit(p.min, &p.unit),
            with_unit(p.max, &p.unit)
        );
    }
    s
}

/// The per-record table as CSV: one line per record and parameter (a
/// record without effects has one line with empty parameter fields).
pub fn csv(rows: &[Row]) -> Result<String> {
    let mut w = csv::Writer::from_writer(vec![]);
    let e = |e: csv::Error| TacitError::Setting(format!("summary CSV: {e}"));
    w.write_record([
        "record",
        "group",
        "verdict",
        "parameter",
        "value",
        "std_error",
        "unit",
        "error_before",
        "error_after",
        "simulation_before",
        "simulation_after",
        "validation_after",
    ])
    .map_err(e)?;
    let o = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v:.6e}"));
    for r in rows {
        let errs = [
            o(r.error_before),
            o(r.error_after),
            o(r.simulation_before),
            o(r.simulation_after),
            o(r.validation_after),
        ];
        let blank = ParamValue {
            key: String::new(),
            value: f64::NAN,
            std_error: None,
            unit: String::new(),
        };
        let params: Vec<&ParamValue> = if r.parameters.is_empty() {
            vec![&blank]
        } else {
            r.parameters.iter().collect()
        };
        for p in params {
            let value = if p.key.is_empty() {
                String::new()
            } else {
                format!("{:.6e}", p.value)
            };
            let mut line = vec![
                r.name.clone(),
                r.group.clone(),
                r.verdict.clone(),
                p.key.clone(),
                value,
                o(p.std_error),
                p.unit.clone(),
            ];
            line.extend(errs.iter().cloned());
            w.write_record(&line).map_err(e)?;
        }
    }
    let bytes = w
        .into_inner()
        .map_err(|x| TacitError::Setting(format!("summary CSV: {x}")))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, gap: f64) -> Row {
        Row {
            name: name.into(),
            group: String::new(),
            verdict: "found contact 5→6".into(),
            effects: vec!["contact 5→6".into()],
            parameters: vec![ParamValue {
                key: "contact 5→6 gap".into(),
                value: gap,
                std_error: None,
                unit: "m".into(),
            }],
            error_before: Some(0.7),
            error_after: Some(0.01),
            simulation_before: None,
            simulation_after: None,
            validation_after: None,
            kinds: BTreeMap::new(),
            substeps: 40,
        }
    }

    #[test]
    fn spread_of_a_parameter_over_records() {
        let rows = [row("a", 1e-3), row("b", 2e-3), row("c", 3e-3)];
        let s = spreads(&rows);
        assert_eq!(s.len(), 1);
        assert_eq!(s[0].records, 3);
        assert!((s[0].mean - 2e-3).abs() < 1e-15);
        assert!((s[0].std - 1e-3).abs() < 1e-15);
        assert_eq!((s[0].min, s[0].max), (1e-3, 3e-3));
        let md = markdown_rows(&rows);
        assert!(md.contains("contact 5→6 gap = 2.0000 mm"), "{md}");
        assert!(md.contains("70.00 % → 1.00 %"), "{md}");
        let c = csv(&rows).unwrap();
        assert_eq!(c.lines().count(), 4, "{c}");
        assert!(
            c.lines()
                .nth(2)
                .unwrap()
                .starts_with("b,,found contact 5→6,contact 5→6 gap,2.000000e-3,"),
            "{c}"
        );
    }
}
