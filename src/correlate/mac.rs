//! Modal assurance criterion, mode pairing and frequency error
//! (paper §2, Tables 2–3).
//!
//! $$ \mathrm{MAC}(\phi_t, \phi_a) = \frac{(\phi_t^\top \phi_a)^2}{(\phi_t^\top \phi_t)(\phi_a^\top \phi_a)} $$
//!
//! compares a test shape with a model shape at the measured DOFs; it is 1
//! for parallel shapes and 0 for orthogonal ones, and ignores scale and
//! sign (Allemang & Brown 1982). The frequency error of a pair is
//! `(f_model − f_test) / f_test`, the sign convention of the paper's
//! Table 2 (21.8 Hz model vs 22.3 Hz test → −2.3 %).

use super::testmodes::TestModes;
use crate::error::{Result, TacitError};
use crate::modal::Modes;
use nalgebra::DMatrix;
use serde::Serialize;

/// MAC of two shapes of the same length. A zero shape has no direction:
/// its MAC with anything is 0.
pub fn mac(a: &[f64], b: &[f64]) -> Result<f64> {
    if a.len() != b.len() {
        return Err(TacitError::Setting(format!(
            "MAC: shapes of different lengths ({} and {} DOFs)",
            a.len(),
            b.len()
        )));
    }
    let ab: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let aa: f64 = a.iter().map(|x| x * x).sum();
    let bb: f64 = b.iter().map(|x| x * x).sum();
    if aa == 0.0 || bb == 0.0 {
        return Ok(0.0);
    }
    Ok((ab * ab / (aa * bb)).clamp(0.0, 1.0))
}

/// MAC matrix between the columns of `a` (rows = DOFs) and of `b`:
/// `out[i][j] = MAC(a_i, b_j)`.
pub fn mac_matrix(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<Vec<Vec<f64>>> {
    if a.nrows() != b.nrows() {
        return Err(TacitError::Setting(format!(
            "MAC: shapes of different lengths ({} and {} DOFs)",
            a.nrows(),
            b.nrows()
        )));
    }
    let col = |m: &DMatrix<f64>, j: usize| -> Vec<f64> { m.column(j).iter().copied().collect() };
    (0..a.ncols())
        .map(|i| {
            (0..b.ncols())
                .map(|j| mac(&col(a, i), &col(b, j)))
                .collect()
        })
        .collect()
}

/// How test modes are paired with model modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Pairing {
    /// Largest MAC first, each model mode used once (default).
    #[default]
    Mac,
    /// Test mode r with flexible model mode r.
    Order,
}

/// Settings of a correlation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CorrelationSettings {
    /// Pairing rule (default [`Pairing::Mac`]).
    pub pairing: Pairing,
    /// Pairs with a MAC below this are not made (in [0, 1]; default 0.3);
    /// the test mode is then reported unpaired.
    pub min_mac: f64,
}

impl Default for CorrelationSettings {
    fn default() -> Self {
        CorrelationSettings {
            pairing: Pairing::Mac,
            min_mac: 0.3,
        }
    }
}

/// One paired test/model mode (a row of the paper's Table 2).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairRow {
    /// Test mode, from 1.
    pub test_mode: usize,
    /// Flexible model mode, from 1 (rigid-body modes are not counted).
    pub model_mode: usize,
    /// Test frequency, Hz.
    pub test_hz: f64,
    /// Model frequency, Hz.
    pub model_hz: f64,
    /// (model − test) / test, %.
    pub freq_error_pct: f64,
    /// MAC at the measured DOFs, in [0, 1].
    pub mac: f64,
}

/// Test-analysis correlation.
#[derive(Debug, Clone, Serialize)]
pub struct Correlation {
    /// Measured DOFs the MAC was computed on.
    pub dofs: Vec<usize>,
    /// Flexible model frequencies, Hz.
    pub model_hz: Vec<f64>,
    /// MAC matrix, test modes × flexible model modes.
    pub mac: Vec<Vec<f64>>,
    /// Paired modes in test-mode order.
    pub pairs: Vec<PairRow>,
    /// Test modes (from 1) left unpaired.
    pub unpaired: Vec<usize>,
}

impl Correlation {
    /// Mean absolute frequency error of the pairs, % (NaN without pairs).
    pub fn mean_abs_freq_error_pct(&self) -> f64 {
        if self.pairs.is_empty() {
            return f64::NAN;
        }
        self.pairs
            .iter()
            .map(|p| p.freq_error_pct.abs())
            .sum::<f64>()
            / self.pairs.len() as f64
    }
    /// Largest absolute frequency error of the pairs, %.
    pub fn max_abs_freq_error_pct(&self) -> f64 {
        self.pairs
            .iter()
            .map(|p| p.freq_error_pct.abs())
            .fold(f64::NAN, f64::max)
    }
    /// Smallest MAC of the pairs (NaN without pairs).
    pub fn min_mac(&self) -> f64 {
        self.pairs.iter().map(|p| p.mac).fold(f64::NAN, f64::min)
    }
}

/// Model shapes of the flexible modes at the given DOFs (DOFs × modes) and
/// their frequencies, Hz.
pub fn flexible_at(modes: &Modes, dofs: &[usize]) -> Result<(DMatrix<f64>, Vec<f64>)> {
    let n = modes.shapes.nrows();
    for &d in dofs {
        if d < 1 || d > n {
            return Err(TacitError::Setting(format!(
                "DOF {d} is not in the model (1..={n})"
            )));
        }
    }
    let flex: Vec<usize> = (0..modes.rigid.len())
        .filter(|&r| !modes.rigid[r])
        .collect();
    let m = DMatrix::from_fn(dofs.len(), flex.len(), |i, j| {
        modes.shapes[(dofs[i] - 1, flex[j])]
    });
    Ok((m, flex.iter().map(|&r| modes.freq_hz[r]).collect()))
}

/// Correlate test modes with the flexible model modes at the test DOFs.
pub fn correlate(
    test: &TestModes,
    modes: &Modes,
    settings: &CorrelationSettings,
) -> Result<Correlation> {
    if !(0.0..=1.0).contains(&settings.min_mac) {
        return Err(TacitError::Setting(format!(
            "min_mac = {}: must be in [0, 1]",
            settings.min_mac
        )));
    }
    test.validate(modes.shapes.nrows(), &test.name)?;
    let (phi, model_hz) = flexible_at(modes, &test.dofs)?;
    let mac = mac_matrix(&test.shape_matrix(), &phi)?;
    let pair = pair_modes(&mac, settings);
    let mut pairs = Vec::new();
    let mut unpaired = Vec::new();
    for (i, p) in pair.iter().enumerate() {
        match p {
            Some(j) => {
                let ft = test.modes[i].frequency_hz;
                pairs.push(PairRow {
                    test_mode: i + 1,
                    model_mode: j + 1,
                    test_hz: ft,
                    model_hz: model_hz[*j],
                    freq_error_pct: 100.0 * (model_hz[*j] - ft) / ft,
                    mac: mac[i][*j],
                });
            }
            None => unpaired.push(i + 1),
        }
    }
    Ok(Correlation {
        dofs: test.dofs.clone(),
        model_hz,
        mac,
        pairs,
        unpaired,
    })
}

/// Pairing from a MAC matrix (test × model): the model mode of each test
/// mode, or `None`.
pub fn pair_modes(mac: &[Vec<f64>], settings: &CorrelationSettings) -> Vec<Option<usize>> {
    let nt = mac.len();
    let nm = mac.first().map_or(0, |r| r.len());
    let mut pair: Vec<Option<usize>> = vec![None; nt];
    match settings.pairing {
        Pairing::Order => {
            for (r, p) in pair.iter_mut().enumerate().take(nm) {
                if mac[r][r] >= settings.min_mac {
                    *p = Some(r);
                }
            }
        }
        Pairing::Mac => {
            let mut cand: Vec<(f64, usize, usize)> = (0..nt)
                .flat_map(|i| (0..nm).map(move |j| (i, j)))
                .map(|(i, j)| (mac[i][j], i, j))
                .filter(|c| c.0 >= settings.min_mac)
                .collect();
            cand.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
            let mut used = vec![false; nm];
            for (_, i, j) in cand {
                if pair[i].is_none() && !used[j] {
                    pair[i] = Some(j);
                    used[j] = true;
                }
            }
        }
    }
    pair
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mac_basics() {
        let a = [1.0, 2.0, -1.0];
        approx::assert_relative_eq!(mac(&a, &a).unwrap(), 1.0, epsilon = 1e-15);
        approx::assert_relative_eq!(mac(&a, &[-2.0, -4.0, 2.0]).unwrap(), 1.0, epsilon = 1e-15);
        assert_eq!(mac(&a, &[1.0, 0.0, 1.0]).unwrap(), 0.0);
        assert_eq!(mac(&a, &[0.0; 3]).unwrap(), 0.0);
        let e = mac(&a, &[1.0, 2.0]).unwrap_err().to_string();
        assert!(e.contains("3 and 2"), "{e}");
    }

    #[test]
    fn pairing_prefers_the_largest_mac() {
        let m = vec![vec![0.9, 0.95], vec![0.2, 0.97]];
        let p = pair_modes(&m, &CorrelationSettings::default());
        assert_eq!(p, vec![Some(0), Some(1)]);
        let m = vec![vec![0.1, 0.2]];
        assert_eq!(pair_modes(&m, &CorrelationSettings::default()), vec![None]);
    }
}
