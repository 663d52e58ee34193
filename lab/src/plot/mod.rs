//! Every picture the crate draws, as hand-written SVG (a few line charts and a floor-plan
//! do not justify a plotting dependency), from plain numbers: this module never imports the
//! evaluation or the trainer, they pass their data in.
//!
//! Here: the budget chart (recognition rate and pose error against the measurement budget,
//! one line per agent, one row of two panels per rotation setting, [`budget_svg`]) and the
//! generic multi-panel line chart [`line_panels`] with its shared legend. [`charts`] holds
//! the evaluation's other charts (utility curves, reliability diagram, extra
//! measurements) and [`curve`] the trainer's learning curve. The plan and episode scene is
//! the instrument's (`activesense_instrument::plot::svg`).

pub mod charts;
pub mod curve;

pub use charts::{
    extra_svg, reliability_svg, utility_svg, ExtraLine, ReliabilityLine, UtilityLine,
};

use std::fmt::Write;

const COLOURS: [&str; 12] = [
    "#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02", "#a6761d", "#666666",
    "#1f78b4", "#b15928", "#6a3d9a", "#000000",
];
const PANEL_W: f64 = 420.0;
const PANEL_H: f64 = 260.0;
const LEFT: f64 = 70.0;
const TOP: f64 = 60.0;
const GAP_X: f64 = 110.0;
const GAP_Y: f64 = 90.0;

struct Panel {
    x0: f64,
    y0: f64,
    ymax: f64,
    max_budget: usize,
}

impl Panel {
    fn px(&self, budget: f64, y: f64) -> (f64, f64) {
        let x = self.x0 + (budget - 1.0) / (self.max_budget as f64 - 1.0) * PANEL_W;
        let y = self.y0 + PANEL_H - (y / self.ymax).clamp(0.0, 1.0) * PANEL_H;
        (x, y)
    }
}

fn axes(
    s: &mut String,
    p: &Panel,
    title: &str,
    ylabel: &str,
    yticks: &[f64],
    fmt: &dyn Fn(f64) -> String,
) {
    let _ = writeln!(
        s,
        r##"<rect x="{:.1}" y="{:.1}" width="{PANEL_W}" height="{PANEL_H}" fill="none" stroke="#444"/>"##,
        p.x0, p.y0
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" font-weight="bold" text-anchor="middle">{title}</text>"#,
        p.x0 + PANEL_W / 2.0,
        p.y0 - 10.0
    );
    for &t in yticks {
        let (_, y) = p.px(1.0, t);
        let _ = writeln!(
            s,
            r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end" font-size="11">{}</text>"##,
            p.x0,
            p.x0 + PANEL_W,
            p.x0 - 6.0,
            y + 4.0,
            fmt(t)
        );
    }
    for b in (0..=p.max_budget).step_by(5).skip(1).chain([1]) {
        let (x, y) = p.px(b as f64, 0.0);
        let _ = writeln!(
            s,
            r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle" font-size="11">{b}</text>"#,
            y + 16.0
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="12">measurement budget</text>"#,
        p.x0 + PANEL_W / 2.0,
        p.y0 + PANEL_H + 34.0
    );
    let _ = writeln!(
        s,
        r#"<text transform="translate({:.1},{:.1}) rotate(-90)" text-anchor="middle" font-size="12">{ylabel}</text>"#,
        p.x0 - 48.0,
        p.y0 + PANEL_H / 2.0
    );
}

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

/// Renders the budget plot over `plans` plans for every rotation setting in `settings`,
/// budgets `1..=max_budget`, agents in legend order `agents`.
pub fn budget_svg(
    plans: u32,
    max_budget: usize,
    settings: &[u8],
    agents: &[String],
    lines: &[BudgetLine<'_>],
) -> String {
    let width = LEFT + 2.0 * PANEL_W + GAP_X + 170.0;
    let height = TOP + settings.len() as f64 * (PANEL_H + GAP_Y) + 20.0;
    let mut s = svg_head(
        width,
        height,
        &format!("Recognition and pose error within a measurement budget ({plans} plans)"),
    );
    // Shared pose-error scale: the 90th percentile of the plotted means, rounded up to a
    // nice value, so one agent with a huge error does not flatten the others (lines above
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
    for (row, &k) in settings.iter().enumerate() {
        let y0 = TOP + 20.0 + row as f64 * (PANEL_H + GAP_Y);
        let rec = Panel {
            x0: LEFT,
            y0,
            ymax: 1.0,
            max_budget,
        };
        let err = Panel {
            x0: LEFT + PANEL_W + GAP_X,
            y0,
            ymax: emax,
            max_budget,
        };
        let tag = if k == 1 {
            "1 rotation bin".to_string()
        } else {
            format!("{k} rotation bins")
        };
        axes(
            &mut s,
            &rec,
            &format!("recognition rate — {tag}"),
            "recognised within budget",
            &[0.0, 0.25, 0.5, 0.75, 1.0],
            &|v| format!("{v:.2}"),
        );
        axes(
            &mut s,
            &err,
            &format!("pose error — {tag}"),
            "mean pose error of recognised (m)",
            &[0.0, emax / 4.0, emax / 2.0, 3.0 * emax / 4.0, emax],
            &|v| format!("{v:.3}"),
        );
        for (ai, name) in agents.iter().enumerate() {
            let Some(r) = lines.iter().find(|r| r.agent == name && r.rot_bins == k) else {
                continue;
            };
            let c = COLOURS[ai % COLOURS.len()];
            let pts: Vec<String> = r
                .recognition
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    let (x, y) = rec.px(i as f64 + 1.0, *v);
                    format!("{x:.1},{y:.1}")
                })
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{c}" stroke-width="2"/>"#,
                pts.join(" ")
            );
            // Pose-error line: only where some episode was recognised within the budget.
            let mut seg: Vec<String> = Vec::new();
            for (i, v) in r.pose_error.iter().enumerate() {
                if let Some(v) = v {
                    let (x, y) = err.px(i as f64 + 1.0, *v);
                    seg.push(format!("{x:.1},{y:.1}"));
                }
            }
            if !seg.is_empty() {
                let _ = writeln!(
                    s,
                    r#"<polyline points="{}" fill="none" stroke="{c}" stroke-width="2"/>"#,
                    seg.join(" ")
                );
            }
        }
    }
    legend(&mut s, LEFT + 2.0 * PANEL_W + GAP_X + 20.0, agents);
    s.push_str("</svg>\n");
    s
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

/// Renders panels side by side (`columns` per row) with one shared legend: the utility-vs-
/// cost curves and the extra-measurement plot.
pub fn line_panels(title: &str, panels: &[LinePanel], columns: usize) -> String {
    let columns = columns.max(1);
    let rows = panels.len().div_ceil(columns);
    let mut names: Vec<&str> = Vec::new();
    for p in panels {
        for sr in &p.series {
            if !names.contains(&sr.name.as_str()) {
                names.push(&sr.name);
            }
        }
    }
    // Room on the right for the legend's longest label.
    let longest = names.iter().map(|n| n.chars().count()).max().unwrap_or(0) as f64;
    let width = (LEFT + columns as f64 * (PANEL_W + GAP_X) - GAP_X + 60.0 + 7.5 * longest)
        .max(LEFT + columns as f64 * (PANEL_W + GAP_X) + 80.0);
    let height =
        (TOP + rows as f64 * (PANEL_H + GAP_Y) + 20.0).max(TOP + 40.0 + 20.0 * names.len() as f64);
    let mut s = svg_head(width, height, title);
    for (i, p) in panels.iter().enumerate() {
        let x0 = LEFT + (i % columns) as f64 * (PANEL_W + GAP_X);
        let y0 = TOP + 20.0 + (i / columns) as f64 * (PANEL_H + GAP_Y);
        let (xa, xb) = (p.x.0, if p.x.1 > p.x.0 { p.x.1 } else { p.x.0 + 1.0 });
        let (ya, yb) = (p.y.0, if p.y.1 > p.y.0 { p.y.1 } else { p.y.0 + 1.0 });
        let px = |x: f64, y: f64| {
            (
                x0 + (x - xa) / (xb - xa) * PANEL_W,
                y0 + PANEL_H - ((y - ya) / (yb - ya)).clamp(0.0, 1.0) * PANEL_H,
            )
        };
        let _ = writeln!(
            s,
            r##"<rect x="{x0:.1}" y="{y0:.1}" width="{PANEL_W}" height="{PANEL_H}" fill="none" stroke="#444"/>"##
        );
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-weight="bold" text-anchor="middle">{}</text>"#,
            x0 + PANEL_W / 2.0,
            y0 - 10.0,
            xml(&p.title)
        );
        for k in 0..=4 {
            let yv = ya + (yb - ya) * k as f64 / 4.0;
            let (_, y) = px(xa, yv);
            let _ = writeln!(
                s,
                r##"<line x1="{x0:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end" font-size="11">{}</text>"##,
                x0 + PANEL_W,
                x0 - 6.0,
                y + 4.0,
                tick(yv)
            );
            let xv = xa + (xb - xa) * k as f64 / 4.0;
            let (x, y) = px(xv, ya);
            let _ = writeln!(
                s,
                r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle" font-size="11">{}</text>"#,
                y + 16.0,
                tick(xv)
            );
        }
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="12">{}</text>"#,
            x0 + PANEL_W / 2.0,
            y0 + PANEL_H + 34.0,
            xml(&p.xlabel)
        );
        let _ = writeln!(
            s,
            r#"<text transform="translate({:.1},{:.1}) rotate(-90)" text-anchor="middle" font-size="12">{}</text>"#,
            x0 - 48.0,
            y0 + PANEL_H / 2.0,
            xml(&p.ylabel)
        );
        for sr in &p.series {
            let ci = names.iter().position(|n| *n == sr.name).unwrap_or(0);
            let c = COLOURS[ci % COLOURS.len()];
            // One polyline per gap-free run.
            let mut run: Vec<String> = Vec::new();
            let flush = |run: &mut Vec<String>, s: &mut String| {
                if run.len() > 1 {
                    let _ = writeln!(
                        s,
                        r#"<polyline points="{}" fill="none" stroke="{c}" stroke-width="2"/>"#,
                        run.join(" ")
                    );
                } else if let Some(pt) = run.first() {
                    let mut xy = pt.split(',');
                    let (x, y) = (xy.next().unwrap_or("0"), xy.next().unwrap_or("0"));
                    let _ = writeln!(s, r#"<circle cx="{x}" cy="{y}" r="2.5" fill="{c}"/>"#);
                }
                run.clear();
            };
            for &(x, y) in &sr.points {
                match y {
                    Some(y) if y.is_finite() => {
                        let (x, y) = px(x, y);
                        run.push(format!("{x:.1},{y:.1}"));
                    }
                    _ => flush(&mut run, &mut s),
                }
            }
            flush(&mut run, &mut s);
        }
    }
    legend(
        &mut s,
        LEFT + columns as f64 * (PANEL_W + GAP_X) - GAP_X + 20.0,
        &names,
    );
    let _ = writeln!(s, "</svg>");
    s
}

/// The opening of a chart: the `<svg>` element of `width` × `height`, a white background
/// and the bold title line.
fn svg_head(width: f64, height: f64, title: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="sans-serif" font-size="13">"#
    );
    let _ = writeln!(s, r##"<rect width="100%" height="100%" fill="#fff"/>"##);
    let _ = writeln!(
        s,
        r#"<text x="{LEFT}" y="24" font-size="16" font-weight="bold">{}</text>"#,
        xml(title)
    );
    s
}

/// The shared legend at `lx`: one coloured line and name per series, in colour order.
fn legend<S: AsRef<str>>(s: &mut String, lx: f64, names: &[S]) {
    for (i, name) in names.iter().enumerate() {
        let y = TOP + 30.0 + i as f64 * 20.0;
        let c = COLOURS[i % COLOURS.len()];
        let _ = writeln!(
            s,
            r#"<line x1="{lx:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{c}" stroke-width="3"/><text x="{:.1}" y="{:.1}">{}</text>"#,
            lx + 24.0,
            lx + 30.0,
            y + 4.0,
            xml(name.as_ref())
        );
    }
}

fn tick(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v.abs() >= 10.0 {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.1}")
    } else if v.abs() >= 0.1 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

fn xml(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
