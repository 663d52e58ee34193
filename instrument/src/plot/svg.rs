//! SVG pictures of a plan and, optionally, an episode: outline with wall indices, perimeter
//! centroid (the model origin), visual centre, placement disc, the agent with its heading,
//! the measurement beams, a scale bar and a legend. Written by hand (no dependency): the
//! format is plain XML and the picture has a dozen element kinds.

use crate::episode::Trajectory;
use crate::world::sensor::RangeKind;
use crate::world::Placement;
use activesense_core::world::geometry::{unit, v2, Vec2};
use activesense_core::{FloorPlan, Pose2};
use std::fmt::Write;

/// What to draw besides the outline.
#[derive(Default)]
pub struct Scene<'a> {
    /// Title line.
    pub title: String,
    /// Visual centre and placement disc.
    pub placement: Option<Placement>,
    /// Agent (ground truth).
    pub agent: Option<Pose2>,
    /// An episode whose measurement beams to draw.
    pub trajectory: Option<&'a Trajectory>,
    /// An estimated pose to draw beside the truth.
    pub estimate: Option<Pose2>,
}

const WIDTH: f32 = 900.0;
const MARGIN: f32 = 60.0;

struct Frame {
    lo: Vec2,
    hi: Vec2,
    scale: f32,
}

impl Frame {
    fn px(&self, p: Vec2) -> (f32, f32) {
        (
            MARGIN + (p.x - self.lo.x) * self.scale,
            MARGIN + (self.hi.y - p.y) * self.scale,
        )
    }
}

/// Renders `plan` (model frame) and `scene` into an SVG document.
pub fn render(plan: &FloorPlan, scene: &Scene) -> String {
    let (lo, hi) = plan.bounds();
    let ext = hi - lo;
    let scale = (WIDTH - 2.0 * MARGIN) / ext.x.max(ext.y);
    let f = Frame { lo, hi, scale };
    let h = ext.y * scale + 2.0 * MARGIN + 70.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{h:.0}" viewBox="0 0 {WIDTH} {h:.0}" font-family="sans-serif" font-size="13">"#
    );
    let _ = writeln!(s, r##"<rect width="100%" height="100%" fill="#ffffff"/>"##);
    let _ = writeln!(
        s,
        r#"<text x="{MARGIN}" y="28" font-size="16" font-weight="bold">{}</text>"#,
        xml(&scene.title)
    );

    // Outline, then the columns (walls around an unfilled hole), then the doors (the wall
    // blanked out, a dashed line across the gap).
    let ring_points = |r: usize| -> String {
        plan.ring(r)
            .map(|i| {
                let (x, y) = f.px(plan.vertex(i));
                format!("{x:.1},{y:.1}")
            })
            .collect::<Vec<String>>()
            .join(" ")
    };
    let _ = writeln!(
        s,
        r##"<polygon points="{}" fill="#f4f1ea" stroke="#222" stroke-width="3"/>"##,
        ring_points(0)
    );
    for r in 1..plan.ring_count() {
        let _ = writeln!(
            s,
            r##"<polygon points="{}" fill="#ffffff" stroke="#222" stroke-width="3"/>"##,
            ring_points(r)
        );
    }
    for i in (0..plan.len()).filter(|&i| plan.is_opening(i)) {
        let (a, b) = plan.wall(i);
        let ((x0, y0), (x1, y1)) = (f.px(a), f.px(b));
        let _ = writeln!(
            s,
            r##"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="#ffffff" stroke-width="5"/><line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="#222" stroke-width="1.5" stroke-dasharray="4 3"/>"##
        );
    }
    for i in 0..plan.len() {
        let (a, b) = plan.wall(i);
        let mid = (a + b) * 0.5 + plan.outward_normal(i) * (14.0 / scale);
        let (x, y) = f.px(mid);
        let _ = writeln!(
            s,
            r##"<text x="{x:.1}" y="{y:.1}" fill="#888" font-size="10" text-anchor="middle">w{i}</text>"##
        );
        let (vx, vy) = f.px(a);
        let _ = writeln!(
            s,
            r##"<circle cx="{vx:.1}" cy="{vy:.1}" r="3" fill="#222"/>"##
        );
    }

    // Model origin (perimeter centroid).
    let (cx, cy) = f.px(plan.perimeter_centroid());
    let _ = writeln!(
        s,
        r##"<path d="M{:.1},{cy:.1}h14M{cx:.1},{:.1}v14" stroke="#1f5fbf" stroke-width="2"/>"##,
        cx - 7.0,
        cy - 7.0
    );

    if let Some(p) = scene.placement {
        let c = v2(p.visual_centre[0], p.visual_centre[1]);
        let (x, y) = f.px(c);
        let _ = writeln!(
            s,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="{:.1}" fill="#2a9d8f" fill-opacity="0.12" stroke="#2a9d8f" stroke-dasharray="6 4"/>"##,
            p.radius * scale
        );
        let _ = writeln!(
            s,
            r##"<path d="M{:.1},{:.1}l10,10M{:.1},{:.1}l-10,10" stroke="#2a9d8f" stroke-width="2"/>"##,
            x - 5.0,
            y - 5.0,
            x + 5.0,
            y - 5.0
        );
    }

    if let Some(site) = scene.trajectory.and_then(|t| t.site.as_ref()) {
        draw_site(&mut s, &f, site);
    }

    if let Some(t) = scene.trajectory {
        let a = t.truth.translation();
        for st in t.steps.iter().filter(|st| st.range.is_some()) {
            let r = st.range.unwrap_or(0.0);
            let end = a + unit(st.world_bearing) * r;
            let (x0, y0) = f.px(a);
            let (x1, y1) = f.px(end);
            let colour = match st.range_kind {
                Some(RangeKind::Outlier) => "#e76f51",
                Some(RangeKind::Clutter) | Some(RangeKind::Behind) => SITE_COLOUR,
                _ => "#e9c46a",
            };
            let _ = writeln!(
                s,
                r#"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="{colour}" stroke-width="1.5"/><circle cx="{x1:.1}" cy="{y1:.1}" r="3" fill="{colour}"/>"#
            );
        }
    }

    // Agent and estimate: markers first, then the labels, each on the side away from the
    // other pose, so that they never overlap however close the two are.
    let marks: Vec<(Pose2, &str, &str)> = [
        (scene.agent, "#c1121f", "agent"),
        (scene.estimate, "#6a4c93", "estimate"),
    ]
    .into_iter()
    .filter_map(|(p, c, l)| p.map(|p| (p, c, l)))
    .collect();
    for (p, colour, _) in &marks {
        let a = p.translation();
        let (x, y) = f.px(a);
        let tip = a + unit(p.theta) * (28.0 / scale);
        let (tx, ty) = f.px(tip);
        let _ = writeln!(
            s,
            r#"<line x1="{x:.1}" y1="{y:.1}" x2="{tx:.1}" y2="{ty:.1}" stroke="{colour}" stroke-width="3"/><circle cx="{x:.1}" cy="{y:.1}" r="6" fill="{colour}"/>"#
        );
    }
    let px: Vec<(f32, f32)> = marks
        .iter()
        .map(|(p, _, _)| f.px(p.translation()))
        .collect();
    for (k, (_, colour, label)) in marks.iter().enumerate() {
        let dir = if marks.len() == 2 {
            let (o, q) = (px[k], px[1 - k]);
            let (dx, dy) = (o.0 - q.0, o.1 - q.1);
            let n = (dx * dx + dy * dy).sqrt();
            if n < 1.0 {
                // Same spot: agent label above, estimate below.
                if k == 0 {
                    (0.0, -1.0)
                } else {
                    (0.0, 1.0)
                }
            } else {
                (dx / n, dy / n)
            }
        } else {
            (
                std::f32::consts::FRAC_1_SQRT_2,
                -std::f32::consts::FRAC_1_SQRT_2,
            )
        };
        let (x, y, anchor) = label_at(px[k], dir);
        let _ = writeln!(
            s,
            r#"<text x="{x:.1}" y="{y:.1}" fill="{colour}" text-anchor="{anchor}">{label}</text>"#
        );
    }

    // Scale bar: the largest "nice" length below a quarter of the drawing.
    let bar_m = [0.5f32, 1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .rev()
        .find(|l| l * scale <= 0.25 * (WIDTH - 2.0 * MARGIN))
        .unwrap_or(0.5);
    let by = h - 50.0;
    let bw = bar_m * scale;
    let _ = writeln!(
        s,
        r##"<path d="M{MARGIN},{by}h{bw:.1}M{MARGIN},{:.1}v10M{:.1},{:.1}v10" stroke="#000" stroke-width="2"/><text x="{:.1}" y="{:.1}" text-anchor="middle">{bar_m} m</text>"##,
        by - 5.0,
        MARGIN + bw,
        by - 5.0,
        MARGIN + bw / 2.0,
        by + 20.0
    );

    // Legend.
    let lx = MARGIN + bw + 30.0;
    let items = [
        ("#1f5fbf", "+ perimeter centroid (model origin)"),
        ("#2a9d8f", "× visual centre, placement disc"),
        ("#c1121f", "● agent (truth), heading"),
        ("#6a4c93", "● estimate (refined), heading"),
        ("#e9c46a", "— measurement"),
        ("#e76f51", "— outlier"),
    ];
    let site_item = [(SITE_COLOUR, "■ site, not on the plan; — reading off it")];
    let drawn_site = scene.trajectory.is_some_and(|t| t.site.is_some());
    let items: Vec<(&str, &str)> = items
        .into_iter()
        .chain(site_item.into_iter().filter(|_| drawn_site))
        .collect();
    for (i, (c, t)) in items.iter().enumerate() {
        let x = lx + (i % 3) as f32 * 250.0;
        let y = by - 4.0 + (i / 3) as f32 * 18.0;
        let _ = writeln!(
            s,
            r#"<text x="{x:.1}" y="{y:.1}" fill="{c}">{}</text>"#,
            xml(t)
        );
    }
    s.push_str("</svg>\n");
    s
}

/// Colour of what the site has and the plan does not (furniture, columns, obstacles, doors,
/// glass, a wall as built) and of the readings off it.
const SITE_COLOUR: &str = "#8338ec";

/// Draws the site over the plan: obstacles filled, openings and a moved wall as lines.
fn draw_site(s: &mut String, f: &Frame, site: &crate::world::site::Site) {
    for o in &site.obstacles {
        let pts: Vec<String> = o
            .corners
            .iter()
            .map(|c| {
                let (x, y) = f.px(v2(c[0], c[1]));
                format!("{x:.1},{y:.1}")
            })
            .collect();
        let _ = writeln!(
            s,
            r#"<polygon points="{}" fill="{SITE_COLOUR}" fill-opacity="0.25" stroke="{SITE_COLOUR}" stroke-width="1.5"/>"#,
            pts.join(" ")
        );
    }
    for o in &site.openings {
        let (a, b) = site.as_built.wall(o.wall);
        let (x0, y0) = f.px(a + (b - a) * o.from);
        let (x1, y1) = f.px(a + (b - a) * o.to);
        let dash = if o.depth_behind.is_some() {
            ""
        } else {
            r#" stroke-dasharray="3 3""#
        };
        let _ = writeln!(
            s,
            r##"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="#ffffff" stroke-width="5"/><line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="{SITE_COLOUR}" stroke-width="2"{dash}/>"##
        );
    }
    if let Some((i, _)) = site.moved_wall {
        let (a, b) = site.as_built.wall(i);
        let ((x0, y0), (x1, y1)) = (f.px(a), f.px(b));
        let _ = writeln!(
            s,
            r#"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="{SITE_COLOUR}" stroke-width="2" stroke-dasharray="8 3"/>"#
        );
    }
}

/// Where a marker's label goes: 16 px from the marker centre along `dir` (pixels, y down),
/// anchored so that the text extends away from the marker.
fn label_at(p: (f32, f32), dir: (f32, f32)) -> (f32, f32, &'static str) {
    let anchor = if dir.0 > 0.38 {
        "start"
    } else if dir.0 < -0.38 {
        "end"
    } else {
        "middle"
    };
    // Text sits on its baseline: below the marker it needs its height (13 px) more.
    let y = p.1 + 16.0 * dir.1 + if dir.1 > 0.38 { 12.0 } else { 4.0 };
    (p.0 + 16.0 * dir.0, y, anchor)
}

/// The pixel box a label of `chars` characters occupies (13 px sans-serif, ≈ 7 px a
/// character) at `(x, y, anchor)`: `(left, top, right, bottom)`.
#[cfg(test)]
fn label_box(x: f32, y: f32, anchor: &str, chars: usize) -> (f32, f32, f32, f32) {
    let w = 7.0 * chars as f32;
    let left = match anchor {
        "start" => x,
        "end" => x - w,
        _ => x - w / 2.0,
    };
    (left, y - 11.0, left + w, y + 3.0)
}

fn xml(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::placement;
    use crate::world::plans;

    #[test]
    fn renders_well_formed_svg() {
        let plan = plans::generate(plans::TEST_SEEDS.start);
        let svg = render(
            &plan,
            &Scene {
                title: "seed <1000000> & co".into(),
                placement: Some(placement(&plan)),
                agent: Some(Pose2::new(0.0, 0.0, 1.0)),
                ..Default::default()
            },
        );
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("&lt;1000000&gt; &amp; co"));
        assert_eq!(svg.matches("<polygon").count(), 1);
        assert!(svg.contains(" m</text>"), "scale bar label");
    }

    #[test]
    fn agent_and_estimate_labels_never_overlap() {
        let plan = plans::generate(plans::TEST_SEEDS.start);
        // The estimate on the agent, a hair off, and at a few pixels in every direction.
        let mut offsets = vec![(0.0, 0.0), (0.001, 0.0)];
        for k in 0..16 {
            let a = k as f32 * std::f32::consts::TAU / 16.0;
            for r in [0.02f32, 0.1, 0.3] {
                offsets.push((r * a.cos(), r * a.sin()));
            }
        }
        for (dx, dy) in offsets {
            let agent = Pose2::new(0.3, -0.2, 1.0);
            let est = Pose2::new(0.3 + dx, -0.2 + dy, 1.1);
            let svg = render(
                &plan,
                &Scene {
                    agent: Some(agent),
                    estimate: Some(est),
                    ..Default::default()
                },
            );
            let label = |name: &str| {
                let line = svg
                    .lines()
                    .find(|l| l.contains(&format!(">{name}</text>")))
                    .unwrap_or_else(|| panic!("no {name} label"));
                let attr = |a: &str| {
                    let i = line.find(&format!(" {a}=\"")).unwrap() + a.len() + 3;
                    line[i..].split('"').next().unwrap().to_string()
                };
                let (x, y) = (attr("x").parse().unwrap(), attr("y").parse().unwrap());
                label_box(x, y, &attr("text-anchor"), name.len())
            };
            let (a, e) = (label("agent"), label("estimate"));
            let apart = a.2 <= e.0 || e.2 <= a.0 || a.3 <= e.1 || e.3 <= a.1;
            assert!(apart, "offset ({dx}, {dy}): agent {a:?} estimate {e:?}");
        }
        // The legend names the estimate.
        let svg = render(&plan, &Scene::default());
        assert!(svg.contains("estimate (refined)"));
    }
}
