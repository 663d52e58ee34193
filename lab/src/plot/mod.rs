//! Every chart of the lab, drawn with `plotters`' SVG backend from plain numbers: this module
//! never imports the evaluation or the trainer, they pass their data in. Ticks fall on 1-2-5
//! values, each panel's legend sits inside it, and every axis says its unit.
//!
//! Here: the generic multi-panel line chart [`line_panels`] and the budget chart
//! (recognition rate and pose error against the measurement budget, one line per agent,
//! [`budget_svg`]). [`charts`] holds the evaluation's other charts (utility curves,
//! reliability diagram, extra measurements) and [`curve`] the trainer's learning curve. The
//! plan and episode scene is the instrument's (`activesense_instrument::plot::svg`), drawn
//! by hand: a floor plan is polygons, not axes.
//!
//! Why `plotters` without a font backend: its naive text metrics need no font files, so
//! the committed SVGs are the same bytes on every machine (the browser draws the text).

pub mod charts;
pub mod curve;

pub use charts::{
    extra_svg, reliability_svg, utility_svg, ExtraLine, ReliabilityLine, UtilityLine,
};

use plotters::prelude::*;

const COLOURS: [RGBColor; 12] = [
    RGBColor(0x1b, 0x9e, 0x77),
    RGBColor(0xd9, 0x5f, 0x02),
    RGBColor(0x75, 0x70, 0xb3),
    RGBColor(0xe7, 0x29, 0x8a),
    RGBColor(0x66, 0xa6, 0x1e),
    RGBColor(0xe6, 0xab, 0x02),
    RGBColor(0xa6, 0x76, 0x1d),
    RGBColor(0x66, 0x66, 0x66),
    RGBColor(0x1f, 0x78, 0xb4),
    RGBColor(0xb1, 0x59, 0x28),
    RGBColor(0x6a, 0x3d, 0x9a),
    RGBColor(0x00, 0x00, 0x00),
];
/// One panel's size in pixels.
const PANEL_W: u32 = 520;
const PANEL_H: u32 = 340;
/// Room for the chart's title.
const TITLE_H: u32 = 40;

/// One agent and rotation setting of the budget chart: recognition rate and mean pose error
/// of the recognised episodes within budgets `1..=max_budget` measurements.
pub struct BudgetLine<'a> {
    /// Agent name (as in the legend order `agents`).
    pub agent: &'a str,
    /// Rotation bins.
    pub rot_bins: u8,
    /// Recognition rate within each budget.
    pub recognition: &'a [f64],
    /// Mean pose error of the recognised within each budget (`None`: none recognised yet).
    pub pose_error: &'a [Option<f64>],
}

/// A line's points: `(x, y)`, `None` for a gap.
type Points = Vec<(f64, Option<f64>)>;

/// Renders the budget plot over `plans` plans for every rotation setting in `settings`,
/// budgets `1..=max_budget`, agents in legend order `agents`: per setting, the recognition
/// rate and the mean pose error of the recognised against the budget.
pub fn budget_svg(
    plans: u32,
    max_budget: usize,
    settings: &[u8],
    agents: &[String],
    lines: &[BudgetLine<'_>],
) -> String {
    // Shared pose-error scale: the 90th percentile of the plotted means, rounded up to a
    // 1-2-5 value, so one agent with a huge error does not flatten the others (lines above
    // the scale are clipped at the top edge).
    let mut all: Vec<f64> = lines
        .iter()
        .flat_map(|r| r.pose_error.iter().flatten().copied())
        .collect();
    all.sort_by(f64::total_cmp);
    let emax = all.get(all.len() * 9 / 10).copied().unwrap_or(0.0);
    let emax = [0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0]
        .into_iter()
        .find(|v| *v >= emax)
        .unwrap_or(10.0);
    let budgets = |values: &mut dyn Iterator<Item = Option<f64>>| -> Points {
        values
            .enumerate()
            .map(|(i, v)| (i as f64 + 1.0, v))
            .collect()
    };
    let mut panels = Vec::new();
    for &k in settings {
        let tag = if k == 1 {
            "1 rotation bin".to_string()
        } else {
            format!("{k} rotation bins")
        };
        let of = |f: &dyn Fn(&BudgetLine<'_>) -> Points| -> Vec<Series> {
            agents
                .iter()
                .filter_map(|name| {
                    let r = lines.iter().find(|r| r.agent == name && r.rot_bins == k)?;
                    Some(Series {
                        name: name.clone(),
                        points: f(r),
                    })
                })
                .collect()
        };
        panels.push(LinePanel {
            title: format!("recognition rate — {tag}"),
            xlabel: "measurement budget (ranges)".into(),
            ylabel: "recognised within budget (fraction)".into(),
            x: (1.0, max_budget as f64),
            y: (0.0, 1.0),
            series: of(&|r| budgets(&mut r.recognition.iter().map(|v| Some(*v)))),
        });
        panels.push(LinePanel {
            title: format!("pose error — {tag}"),
            xlabel: "measurement budget (ranges)".into(),
            ylabel: "mean pose error of recognised (m)".into(),
            x: (1.0, max_budget as f64),
            y: (0.0, emax),
            series: of(&|r| budgets(&mut r.pose_error.iter().copied())),
        });
    }
    line_panels(
        &format!("Recognition and pose error within a measurement budget ({plans} plans)"),
        &panels,
        2,
    )
}

/// One line of a [`line_panels`] chart: a name and its points (`None` leaves a gap).
pub struct Series {
    /// Legend label.
    pub name: String,
    /// (x, y) points in x order.
    pub points: Vec<(f64, Option<f64>)>,
}

/// One panel of a [`line_panels`] chart.
pub struct LinePanel {
    /// Title above the panel.
    pub title: String,
    /// Label of the x axis.
    pub xlabel: String,
    /// Label of the y axis.
    pub ylabel: String,
    /// x range.
    pub x: (f64, f64),
    /// y range (values outside are clipped to the edge).
    pub y: (f64, f64),
    /// The lines, in legend order (the same names in every panel get the same colour).
    pub series: Vec<Series>,
}

/// Renders panels side by side (`columns` per row), each with its legend inside: the
/// utility-vs-cost curves, the frontier, the learning curve and the extra-measurement plot.
/// A name has the same colour in every panel.
pub fn line_panels(title: &str, panels: &[LinePanel], columns: usize) -> String {
    let columns = columns.max(1);
    let rows = panels.len().div_ceil(columns).max(1);
    let mut names: Vec<&str> = Vec::new();
    for p in panels {
        for sr in &p.series {
            if !names.contains(&sr.name.as_str()) {
                names.push(&sr.name);
            }
        }
    }
    let size = (PANEL_W * columns as u32, TITLE_H + PANEL_H * rows as u32);
    let mut s = String::new();
    let drawn = draw_panels(&mut s, size, title, panels, columns, rows, &names);
    if let Err(e) = drawn {
        // Drawing into a string does not fail on its own; say so in the picture if it does.
        s = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}"><text x="10" y="20">{}: {}</text></svg>"#,
            size.0,
            size.1,
            xml(title),
            xml(&e.to_string())
        );
    }
    if !s.ends_with('\n') {
        s.push('\n');
    }
    s
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

fn draw_panels(
    s: &mut String,
    size: (u32, u32),
    title: &str,
    panels: &[LinePanel],
    columns: usize,
    rows: usize,
    names: &[&str],
) -> DrawResult {
    let root = SVGBackend::with_string(s, size).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 17).into_font().style(FontStyle::Bold))?;
    for (p, area) in panels.iter().zip(root.split_evenly((rows, columns))) {
        draw_panel(&area, p, names)?;
    }
    root.present()?;
    Ok(())
}

fn draw_panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    p: &LinePanel,
    names: &[&str],
) -> DrawResult {
    let (xa, xb) = (p.x.0, if p.x.1 > p.x.0 { p.x.1 } else { p.x.0 + 1.0 });
    let (ya, yb) = (p.y.0, if p.y.1 > p.y.0 { p.y.1 } else { p.y.0 + 1.0 });
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, ("sans-serif", 14))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(xa..xb, ya..yb)?;
    chart
        .configure_mesh()
        .x_desc(&p.xlabel)
        .y_desc(&p.ylabel)
        .x_labels(6)
        .y_labels(6)
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .light_line_style(WHITE)
        .bold_line_style(BLACK.mix(0.12))
        .label_style(("sans-serif", 11))
        .axis_desc_style(("sans-serif", 12))
        .draw()?;
    let clip = |y: f64| y.clamp(ya, yb);
    for sr in &p.series {
        let ci = names.iter().position(|n| *n == sr.name).unwrap_or(0);
        let c = COLOURS[ci % COLOURS.len()];
        // One line per gap-free run; a lone point is a dot. The legend entry comes once.
        let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for &(x, y) in &sr.points {
            match y {
                Some(y) if y.is_finite() && x.is_finite() => {
                    runs.last_mut().expect("one run").push((x, clip(y)))
                }
                _ => runs.push(Vec::new()),
            }
        }
        let mut labelled = false;
        for run in runs.into_iter().filter(|r| !r.is_empty()) {
            let style = c.stroke_width(2);
            let drawn = if run.len() > 1 {
                chart.draw_series(LineSeries::new(run, style))?
            } else {
                chart.draw_series(run.into_iter().map(|pt| Circle::new(pt, 3, c.filled())))?
            };
            if !labelled {
                drawn.label(sr.name.as_str()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(3))
                });
                labelled = true;
            }
        }
    }
    if !p.series.is_empty() {
        chart
            .configure_series_labels()
            .position(legend_corner(p, ya, yb))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font(("sans-serif", 11))
            .draw()?;
    }
    Ok(())
}

/// The corner of the panel the lines leave freest at its right edge: the legend goes low
/// when the lines end high, high otherwise.
fn legend_corner(p: &LinePanel, ya: f64, yb: f64) -> SeriesLabelPosition {
    // Markers (two-point lines such as the end of the warm start) do not count.
    let lines: Vec<&Series> = p.series.iter().filter(|sr| sr.points.len() > 2).collect();
    let lines = if lines.is_empty() {
        p.series.iter().collect()
    } else {
        lines
    };
    let ends: Vec<f64> = lines
        .into_iter()
        .filter_map(|sr| {
            sr.points
                .iter()
                .rev()
                .find_map(|&(_, y)| y.filter(|y| y.is_finite()))
        })
        .map(|y| (y - ya) / (yb - ya))
        .collect();
    let mean = ends.iter().sum::<f64>() / ends.len().max(1) as f64;
    if mean > 0.5 {
        SeriesLabelPosition::LowerRight
    } else {
        SeriesLabelPosition::UpperRight
    }
}

/// A tick label: as few digits as the 1-2-5 value needs; thousands and millions as k and M.
fn tick(v: f64) -> String {
    if v.abs() >= 1e6 {
        return format!("{}M", tick(v / 1e6));
    }
    if v.abs() >= 1e4 {
        return format!("{}k", tick(v / 1e3));
    }
    let t = format!("{v:.6}");
    let t = t.trim_end_matches('0').trim_end_matches('.');
    if t == "-0" {
        "0".into()
    } else {
        t.into()
    }
}

fn xml(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
