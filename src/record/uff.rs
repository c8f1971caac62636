//! Records in the universal file format, dataset 58 (function at a nodal
//! DOF), ASCII: the time histories acquisition systems export.
//!
//! A universal file is a sequence of datasets, each between two lines
//! holding `-1` (right-justified in six columns), its number on the line
//! after the first. Datasets other than 58 (units 164, nodes 2411, …) are
//! skipped. A dataset 58 holds (SDRC / Siemens I-deas universal file
//! format, dataset 58):
//!
//! - records 1–5: free text (ID lines, date);
//! - record 6, `2(I5,I10),2(1X,10A1,I10,I4)`: function type (1 = time
//!   response), function id, version, load case, response entity name,
//!   response node, response direction (±1, ±2, ±3 = ±X, ±Y, ±Z; ±4…±6
//!   rotations), reference entity, node and direction;
//! - record 7, `3I10,3E13.5`: ordinate data type (2 = real single, 4 = real
//!   double; 5, 6 complex), number of points, abscissa spacing (1 = even),
//!   abscissa minimum, increment, z value;
//! - records 8–11, `I10,3I5,2(1X,20A1)`: the abscissa, ordinate (numerator),
//!   ordinate denominator and z-axis characteristics: specific data type
//!   (17 = time; 8 = displacement, 11 = velocity, 12 = acceleration,
//!   13 = excitation force, 9 = reaction force), exponents of length,
//!   force and temperature, axis label, axis units label;
//! - record 12: the ordinates, `6E13.5` per line (single) or `4E20.12`
//!   (double) for even spacing.
//!
//! Each dataset becomes one channel: a force (types 9, 13) is an input,
//! the rest outputs. A channel carries both its node and its direction:
//! on a lumped model the node number is the DOF (numbered from 1) and the
//! channel is named `accel_<node>`; on a model from matrices it is the
//! point `n<node>:<dir>` (`n12:uy`; directions 1–6 are `ux`, `uy`, `uz`,
//! `rx`, `ry`, `rz`), resolved against the model's `[points]`
//! ([`crate::model::Model::resolve_channels`]). A negative direction
//! negates the data (the model's DOFs point along +X, +Y or +Z). The unit is the ordinate's axis units label
//! (`g`, `m/s^2`, `mm`, `kN`, …, converted to SI after reading,
//! [`super::units`]); without a label the data are taken as SI. Every
//! channel must have the time base of the first: even spacing, the same
//! start, increment and length. The sample rate is `1 / increment`; an
//! increment written with six significant digits (`E13.5`) is rounded to
//! the nearest whole rate in Hz when within 1e-5 of it.
//!
//! Binary files (dataset `58b`) are refused with a message: export ASCII.

use super::{Channel, Quantity, Record};
use crate::error::{Result, TacitError};
use std::path::Path;

/// Read an ASCII universal file's datasets 58 into a record (units as
/// written; [`super::read`] converts them to SI and validates).
pub fn read(path: &Path) -> Result<Record> {
    let bytes = std::fs::read(path).map_err(|e| TacitError::io(path, e))?;
    let text = String::from_utf8_lossy(&bytes);
    parse(&text, path)
}

/// One dataset 58 as read.
struct Dataset {
    node: i64,
    dir: i64,
    quantity: Quantity,
    unit: String,
    start: f64,
    step: f64,
    data: Vec<f64>,
}

/// Parse the text of a universal file.
pub fn parse(text: &str, path: &Path) -> Result<Record> {
    let lines: Vec<&str> = text.lines().collect();
    let mut sets = vec![];
    let mut i = 0;
    while i < lines.len() {
        if lines[i].trim() != "-1" {
            i += 1;
            continue;
        }
        let kind = lines.get(i + 1).map_or("", |l| l.trim());
        let end = (i + 2..lines.len())
            .find(|&k| lines[k].trim() == "-1")
            .ok_or_else(|| {
                TacitError::record(
                    path,
                    format!("line {}: dataset {kind} has no closing -1", i + 1),
                )
            })?;
        let id = kind.split_whitespace().next().unwrap_or("");
        if id == "58b" {
            return Err(TacitError::record(
                path,
                format!(
                    "line {}: binary dataset 58b is not read: export the universal file as ASCII",
                    i + 2
                ),
            ));
        }
        if id == "58" {
            let n = sets.len() + 1;
            sets.push(dataset(&lines[i + 2..end], i + 3, n, path)?);
        }
        i = end + 1;
    }
    record(sets, path)
}

/// Columns `a..b` of a fixed-format line (shorter lines give less).
fn cols(line: &str, a: usize, b: usize) -> &str {
    let n = line.len();
    line.get(a.min(n)..b.min(n)).unwrap_or("").trim()
}

/// Parse one dataset 58 (`body` = records 1–12; `first` its first line
/// number, `n` its index from 1, for messages).
fn dataset(body: &[&str], first: usize, n: usize, path: &Path) -> Result<Dataset> {
    let fail = |rec: usize, what: String| {
        TacitError::record(
            path,
            format!(
                "dataset 58 number {n}, record {rec} (line {}): {what}",
                first + rec - 1
            ),
        )
    };
    if body.len() < 12 {
        return Err(fail(
            body.len().max(1),
            "the dataset ends before its data (record 12)".into(),
        ));
    }
    let int = |rec: usize, s: &str, what: &str| -> Result<i64> {
        s.parse::<i64>()
            .map_err(|_| fail(rec, format!("{what} \"{s}\" is not an integer")))
    };
    let r6 = body[5];
    let ftype = int(6, cols(r6, 0, 5), "function type")?;
    if ftype != 1 {
        return Err(fail(
            6,
            format!("function type {ftype} is not a time response (1)"),
        ));
    }
    let node = int(6, cols(r6, 41, 51), "response node")?;
    let dir = int(6, cols(r6, 51, 55), "response direction")?;
    let r7: Vec<&str> = body[6].split_whitespace().collect();
    let num = |k: usize, what: &str| -> Result<f64> {
        r7.get(k)
            .and_then(|s| s.replace(['D', 'd'], "E").parse::<f64>().ok())
            .ok_or_else(|| fail(7, format!("{what} is missing or not a number")))
    };
    let otype = num(0, "ordinate data type")? as i64;
    let count = num(1, "number of points")? as usize;
    let even = num(2, "abscissa spacing")? as i64;
    let (start, step) = (num(3, "abscissa minimum")?, num(4, "abscissa increment")?);
    let width = match otype {
        2 => 13,
        4 => 20,
        5 | 6 => {
            return Err(fail(
                7,
                "complex ordinates (a spectrum or an FRF?): a record holds real time histories"
                    .into(),
            ))
        }
        t => {
            return Err(fail(
                7,
                format!("ordinate data type {t}: give 2 (real single) or 4 (real double)"),
            ))
        }
    };
    if even != 1 {
        return Err(fail(
            7,
            "uneven abscissa spacing: a record needs evenly spaced samples".into(),
        ));
    }
    if !(step > 0.0 && step.is_finite()) {
        return Err(fail(7, format!("abscissa increment {step} must be > 0")));
    }
    let r9 = body[8];
    let spec = int(9, cols(r9, 0, 10), "ordinate data type")?;
    let quantity = match spec {
        8 => Quantity::Disp,
        11 => Quantity::Vel,
        12 => Quantity::Accel,
        9 | 13 => Quantity::Force,
        s => return Err(fail(9, format!("ordinate type {s} is not a force (9, 13), displacement (8), velocity (11) or acceleration (12)"))),
    };
    let unit = cols(r9, 47, 67).to_string();
    let data = values(&body[11..], width, count)
        .map_err(|(k, s)| fail(12 + k, format!("\"{s}\" is not a number")))?;
    if data.len() != count {
        return Err(fail(
            12,
            format!("{} values for the {count} points of record 7", data.len()),
        ));
    }
    Ok(Dataset {
        node,
        dir,
        quantity,
        unit,
        start,
        step,
        data,
    })
}

/// The ordinates: fixed-width fields of `width` columns; a line whose
/// fields do not parse at that width is read by whitespace instead. Err:
/// (line offset, text) of a value that does not parse.
fn values(
    lines: &[&str],
    width: usize,
    count: usize,
) -> std::result::Result<Vec<f64>, (usize, String)> {
    let mut out = Vec::with_capacity(count);
    let parse = |s: &str| s.trim().replace(['D', 'd'], "E").parse::<f64>().ok();
    for (k, line) in lines.iter().enumerate() {
        let fixed: Option<Vec<f64>> = (0..line.len().div_ceil(width))
            .map(|j| cols(line, j * width, (j + 1) * width))
            .filter(|s| !s.is_empty())
            .map(parse)
            .collect();
        match fixed {
            Some(v) => out.extend(v),
            None => {
                for s in line.split_whitespace() {
                    out.push(parse(s).ok_or((k, s.to_string()))?);
                }
            }
        }
    }
    Ok(out)
}

/// The channels on one time base.
fn record(sets: Vec<Dataset>, path: &Path) -> Result<Record> {
    let first = sets
        .first()
        .ok_or_else(|| TacitError::record(path, "no dataset 58 (time history) in the file"))?;
    let (start, step, len) = (first.start, first.step, first.data.len());
    let mut rec = Record {
        t0: start,
        fs: rate(step),
        inputs: vec![],
        outputs: vec![],
        truth: None,
        source: path.to_path_buf(),
    };
    for (k, s) in sets.iter().enumerate() {
        let same = (s.step - step).abs() <= 1e-9 * step
            && (s.start - start).abs() <= 1e-6 * step
            && s.data.len() == len;
        if !same {
            return Err(TacitError::record(
                path,
                format!(
                    "dataset 58 number {}: time base {} points from {} s by {} s differs from the first's ({len} from {start} s by {step} s)",
                    k + 1, s.data.len(), s.start, s.step
                ),
            ));
        }
        if s.node < 1 || !(1..=6).contains(&s.dir.abs()) {
            return Err(TacitError::record(
                path,
                format!("dataset 58 number {}: node {} direction {}: nodes are DOFs from 1, directions ±1 to ±6", k + 1, s.node, s.dir),
            ));
        }
        let sign = if s.dir < 0 { -1.0 } else { 1.0 };
        let mut c = Channel {
            point: Some(point_label(s.node, s.dir)),
            ..Channel::new(
                s.quantity,
                s.node as usize,
                s.data.iter().map(|v| sign * v).collect(),
            )
        };
        if !s.unit.is_empty() && !s.unit.eq_ignore_ascii_case("none") {
            c.unit = s.unit.clone();
        }
        if s.quantity == Quantity::Force {
            rec.inputs.push(c);
        } else {
            rec.outputs.push(c);
        }
    }
    Ok(rec)
}

/// The point label of a node and direction: `n<node>:<ux|uy|uz|rx|ry|rz>`
/// (the sign of the direction is taken into the data).
pub fn point_label(node: i64, dir: i64) -> String {
    const DIRS: [&str; 6] = ["ux", "uy", "uz", "rx", "ry", "rz"];
    format!(
        "n{node}:{}",
        DIRS[(dir.unsigned_abs() as usize).clamp(1, 6) - 1]
    )
}

/// `1 / step`, rounded to a whole rate when within 1e-5 of one.
fn rate(step: f64) -> f64 {
    let fs = 1.0 / step;
    if (fs - fs.round()).abs() <= 1e-5 * fs {
        fs.round()
    } else {
        fs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dataset 58 written by hand in the fixed formats (6E13.5 data).
    fn ds(node: i64, dir: i64, spec: i64, unit: &str, data: &[f64]) -> String {
        let mut s = String::from("    -1\n    58\nid1\nid2\n25-Nov-26 12:00:00\nid4\nid5\n");
        s += &format!(
            "{:5}{:10}{:5}{:10} {:<10}{:10}{:4} {:<10}{:10}{:4}\n",
            1, 1, 0, 0, "NONE", node, dir, "NONE", 1, 1
        );
        s += &format!(
            "{:10}{:10}{:10}{:13.5E}{:13.5E}{:13.5E}\n",
            2,
            data.len(),
            1,
            0.0,
            1.0 / 512.0,
            0.0
        );
        s += &format!(
            "{:10}{:5}{:5}{:5} {:<20} {:<20}\n",
            17, 0, 0, 0, "Time", "s"
        );
        s += &format!(
            "{:10}{:5}{:5}{:5} {:<20} {:<20}\n",
            spec, 1, 0, 0, "Response", unit
        );
        s += &format!(
            "{:10}{:5}{:5}{:5} {:<20} {:<20}\n",
            0, 0, 0, 0, "NONE", "NONE"
        );
        s += &format!(
            "{:10}{:5}{:5}{:5} {:<20} {:<20}\n",
            0, 0, 0, 0, "NONE", "NONE"
        );
        for chunk in data.chunks(6) {
            for v in chunk {
                s += &format!("{v:13.5E}");
            }
            s += "\n";
        }
        s + "    -1\n"
    }

    #[test]
    fn hand_written_force_and_accelerations_in_g() {
        let f = [1.0, -2.5, 3.25, 0.0, 1e-3, -7.0, 2.0];
        let a = [0.5, 0.25, -0.125, 1.0, 2.0, -3.0, 4.0];
        let mut text = String::from("    -1\n   164\n         1SI\n    -1\n");
        text += &ds(1, 1, 13, "N", &f);
        text += &ds(5, -1, 12, "g", &a);
        let p = Path::new("hand.uff");
        let mut rec = parse(&text, p).unwrap();
        assert_eq!(rec.fs, 512.0);
        assert_eq!(rec.inputs.len(), 1);
        assert_eq!(rec.inputs[0].dof, 1);
        assert_eq!(rec.inputs[0].data, f.to_vec());
        // -X: negated; g converted to m/s² by the units module
        super::super::units::to_si(&mut rec).unwrap();
        let o = &rec.outputs[0];
        assert_eq!((o.quantity, o.dof), (Quantity::Accel, 5));
        assert_eq!(o.point.as_deref(), Some("n5:ux"));
        assert_eq!(point_label(12, -2), "n12:uy");
        assert_eq!(point_label(3, 6), "n3:rz");
        for (x, y) in o.data.iter().zip(a) {
            assert!((x + y * 9.80665).abs() < 1e-12, "{x} {y}");
        }
        rec.validate(None).unwrap();
    }

    #[test]
    fn bad_datasets_are_named() {
        let p = Path::new("bad.uff");
        let frf = ds(1, 1, 12, "g", &[1.0, 2.0]).replace(
            "\n         2         2         1",
            "\n         6         2         1",
        );
        let e = parse(&frf, p).unwrap_err().to_string();
        assert!(e.contains("record 7") && e.contains("complex"), "{e}");
        let strain = ds(1, 1, 3, "", &[1.0, 2.0]);
        let e = parse(&strain, p).unwrap_err().to_string();
        assert!(e.contains("ordinate type 3"), "{e}");
        let short = ds(1, 1, 12, "g", &[1.0, 2.0, 3.0])
            .replace("         3         1", "         4         1");
        let e = parse(&short, p).unwrap_err().to_string();
        assert!(e.contains("3 values for the 4 points"), "{e}");
        let bin = "    -1\n   58b     2     1\nxx\n    -1\n";
        assert!(parse(bin, p).unwrap_err().to_string().contains("ASCII"));
        let two = ds(1, 1, 13, "N", &[1.0, 2.0]) + &ds(2, 1, 12, "g", &[1.0, 2.0, 3.0]);
        let e = parse(&two, p).unwrap_err().to_string();
        assert!(e.contains("number 2") && e.contains("time base"), "{e}");
        assert!(parse("nothing\n", p)
            .unwrap_err()
            .to_string()
            .contains("no dataset 58"));
    }
}
