//! Channel units: a record read from a file whose channels carry a `unit`
//! (the HDF5 attribute) is converted to SI (N, m, m/s, m/s²) before use,
//! and an unknown unit is an error naming the channel.
//!
//! Standard gravity g₀ = 9.80665 m/s² (CGPM 1901; ISO 80000-3).

use super::{Channel, Quantity, Record};
use crate::error::{Result, TacitError};

/// Standard gravity, m/s².
pub const G0: f64 = 9.80665;

/// The factor to SI of a unit string for a quantity, or `None` when the
/// unit is not one of that quantity's (spelling variants of `m/s^2`
/// such as `m/s²`, `m/s2`, `m s^-2` are accepted).
pub fn si_factor(quantity: Quantity, unit: &str) -> Option<f64> {
    let u: String = unit
        .trim()
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect::<String>()
        .replace('²', "^2")
        .replace("**", "^")
        .replace(['µ', 'μ'], "u");
    let u = u.as_str();
    match quantity {
        Quantity::Force => match u {
            "N" | "n" => Some(1.0),
            "kN" | "kn" => Some(1e3),
            "mN" => Some(1e-3),
            "lbf" => Some(4.448_221_615_260_5),
            _ => None,
        },
        Quantity::Disp => match u {
            "m" => Some(1.0),
            "mm" => Some(1e-3),
            "um" => Some(1e-6),
            "cm" => Some(1e-2),
            "in" => Some(0.0254),
            _ => None,
        },
        Quantity::Vel => match u {
            "m/s" | "ms^-1" | "m.s^-1" => Some(1.0),
            "mm/s" => Some(1e-3),
            "in/s" => Some(0.0254),
            _ => None,
        },
        Quantity::Accel => match u {
            "m/s^2" | "m/s2" | "ms^-2" | "m.s^-2" => Some(1.0),
            "mm/s^2" | "mm/s2" => Some(1e-3),
            "g" | "g0" | "gn" | "G" => Some(G0),
            "in/s^2" | "in/s2" => Some(0.0254),
            _ => None,
        },
    }
}

/// A conversion made on reading: channel name, unit found, factor to SI.
#[derive(Debug, Clone, PartialEq)]
pub struct Conversion {
    /// Channel name, e.g. `accel_5`.
    pub channel: String,
    /// The unit the file gave.
    pub from: String,
    /// The factor the data were multiplied by.
    pub factor: f64,
}

impl std::fmt::Display for Conversion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let q = super::Quantity::from_prefix(self.channel.split('_').next().unwrap_or(""));
        write!(
            f,
            "{}: converted from {} to {} (×{})",
            self.channel,
            self.from,
            q.map_or("SI", |q| q.si_unit()),
            self.factor
        )
    }
}

/// Convert every channel of `rec` to SI; returns the conversions made.
/// A unit that is not one of the channel's quantity is an error.
pub fn to_si(rec: &mut Record) -> Result<Vec<Conversion>> {
    let mut done = vec![];
    let source = rec.source.clone();
    for c in rec.inputs.iter_mut().chain(rec.outputs.iter_mut()) {
        if let Some(conv) = convert_channel(c).map_err(|m| TacitError::record(&source, m))? {
            done.push(conv);
        }
    }
    Ok(done)
}

fn convert_channel(c: &mut Channel) -> std::result::Result<Option<Conversion>, String> {
    let si = c.quantity.si_unit();
    if c.unit.trim().is_empty() {
        c.unit = si.to_string();
        return Ok(None);
    }
    let factor = si_factor(c.quantity, &c.unit).ok_or_else(|| {
        format!(
            "channel {}: unit {} is not a unit of {} (known: {})",
            c.name(),
            shown(&c.unit),
            c.quantity.prefix(),
            known(c.quantity)
        )
    })?;
    let from = std::mem::replace(&mut c.unit, si.to_string());
    if factor == 1.0 {
        return Ok(None);
    }
    for x in &mut c.data {
        *x *= factor;
    }
    Ok(Some(Conversion {
        channel: c.name(),
        from,
        factor,
    }))
}

/// A unit as written, quoted; one longer than 40 characters is cut
/// there with its length given (a message stays one readable line).
fn shown(unit: &str) -> String {
    let n = unit.chars().count();
    if n <= 40 {
        format!("\"{unit}\"")
    } else {
        let head: String = unit.chars().take(40).collect();
        format!("\"{head}…\" ({n} characters)")
    }
}

fn known(q: Quantity) -> &'static str {
    match q {
        Quantity::Force => "N, kN, mN, lbf",
        Quantity::Disp => "m, mm, cm, um, in",
        Quantity::Vel => "m/s, mm/s, in/s",
        Quantity::Accel => "m/s^2, mm/s^2, g, in/s^2",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(unit: &str, q: Quantity) -> Record {
        Record {
            t0: 0.0,
            fs: 10.0,
            inputs: vec![],
            outputs: vec![Channel {
                unit: unit.into(),
                ..Channel::new(q, 3, vec![1.0, -2.0])
            }],
            truth: None,
            source: "r.h5".into(),
        }
    }

    #[test]
    fn g_and_kn_and_mm_are_converted() {
        let mut r = rec("g", Quantity::Accel);
        let c = to_si(&mut r).unwrap();
        assert_eq!(r.outputs[0].data, vec![G0, -2.0 * G0]);
        assert_eq!(r.outputs[0].unit, "m/s^2");
        assert_eq!(
            c[0].to_string(),
            "accel_3: converted from g to m/s^2 (×9.80665)"
        );
        let mut r = rec("kN", Quantity::Accel);
        let e = to_si(&mut r).unwrap_err().to_string();
        assert!(
            e.contains("accel_3") && e.contains("\"kN\"") && e.contains("r.h5"),
            "{e}"
        );
        let mut r = rec("mm", Quantity::Disp);
        to_si(&mut r).unwrap();
        assert_eq!(r.outputs[0].data, vec![1e-3, -2e-3]);
        assert_eq!(si_factor(Quantity::Force, "kN"), Some(1e3));
        assert_eq!(si_factor(Quantity::Accel, "m/s²"), Some(1.0));
        assert_eq!(si_factor(Quantity::Accel, "m s^-2"), Some(1.0));
    }

    #[test]
    fn si_units_change_nothing() {
        let mut r = rec("m/s^2", Quantity::Accel);
        assert!(to_si(&mut r).unwrap().is_empty());
        assert_eq!(r.outputs[0].data, vec![1.0, -2.0]);
    }
}
