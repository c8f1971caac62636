//! Figures of an update (data only; rendering is [`crate::plot::save`]):
//! the measured channels (solid) against the model's (dashed), one panel
//! per channel, as the paper's Figs 5 and 6.

use super::problem::Problem;
use crate::plot::{self, Figure, SeriesStyle};

/// Test (solid) against model (dashed) for every observation of `problem`;
/// `t` holds the sample times and `predicted` one vector per observation
/// (e.g. from [`super::predict`]).
pub fn responses(problem: &Problem, t: &[f64], predicted: &[Vec<f64>], title: &str) -> Figure {
    let panels = problem
        .observations
        .iter()
        .zip(predicted)
        .map(|(o, y)| {
            plot::time_panel(
                &format!("{} at DOF {}", o.quantity.prefix(), o.dof),
                &format!("{} [{}]", o.quantity.prefix(), o.quantity.si_unit()),
                t,
                vec![
                    ("test".into(), o.data.clone(), SeriesStyle::Line),
                    ("model".into(), y.clone(), SeriesStyle::DashedLine),
                ],
            )
        })
        .collect();
    Figure::new(title, panels, 1)
}
