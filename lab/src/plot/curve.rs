//! The trainer's learning curve (`curve.svg`, written by [`crate::learn::train`]): a few
//! logged quantities against environment steps, one panel each, with the end of the
//! imitation warm start marked. A [`line_panels`] chart drawn from plain numbers.

use super::{line_panels, LinePanel, Series};

/// One panel of the learning curve: its title and one value per logged update.
pub struct CurvePanel<'a> {
    /// Title above the panel (also its y label).
    pub title: &'a str,
    /// The quantity at each logged update, in log order.
    pub values: Vec<f64>,
}

/// The learning curve titled `title`: each panel's values against `steps` (environment
/// steps of each logged update), with a vertical line at `imitation_until` (the last
/// imitation update's steps) when there was a warm start.
pub fn learning_curve_svg(
    title: &str,
    steps: &[f64],
    panels: &[CurvePanel<'_>],
    imitation_until: Option<f64>,
) -> String {
    let xmax = steps.last().copied().unwrap_or(1.0).max(1.0);
    let panels: Vec<LinePanel> = panels
        .iter()
        .map(|p| {
            let (mut lo, mut hi) = p
                .values
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &y| {
                    (a.min(y), b.max(y))
                });
            if !lo.is_finite() {
                (lo, hi) = (0.0, 1.0);
            }
            if hi - lo < 1e-6 {
                hi = lo + 1.0;
            }
            let mut series = vec![Series {
                name: "training".into(),
                points: steps
                    .iter()
                    .zip(&p.values)
                    .map(|(&x, &y)| (x, Some(y)))
                    .collect(),
            }];
            if let Some(x) = imitation_until {
                series.push(Series {
                    name: "end of the imitation warm start".into(),
                    points: vec![(x, Some(lo)), (x, Some(hi))],
                });
            }
            LinePanel {
                title: p.title.to_string(),
                xlabel: format!("environment steps (max {xmax:.0})"),
                ylabel: p.title.to_string(),
                x: (0.0, xmax),
                y: (lo, hi),
                series,
            }
        })
        .collect();
    line_panels(title, &panels, 1)
}
