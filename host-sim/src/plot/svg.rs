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

    // Outline.
    let pts: Vec<String> = plan
        .vertices()
        .map(|v| {
            let (x, y) = f.px(v);
            format!("{x:.1},{y:.1}")
        })
        .collect();
    let _ = writeln!(
        s,
        r##"<polygon points="{}" fill="#f4f1ea" stroke="#222" stroke-width="3"/>"##,
        pts.join(" ")
    );
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

    if let Some(t) = scene.trajectory {
        let a = t.truth.translation();
        for st in t.steps.iter().filter(|st| st.range.is_some()) {
            let r = st.range.unwrap_or(0.0);
            let end = a + unit(st.world_bearing) * r;
            let (x0, y0) = f.px(a);
            let (x1, y1) = f.px(end);
            let colour = match st.range_kind {
                Some(RangeKind::Outlier) => "#e76f51",
                _ => "#e9c46a",
            };
            let _ = writeln!(
                s,
                r#"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="{colour}" stroke-width="1.5"/><circle cx="{x1:.1}" cy="{y1:.1}" r="3" fill="{colour}"/>"#
            );
        }
    }

    for (pose, colour, label) in [
        (scene.agent, "#c1121f", "agent"),
        (scene.estimate, "#6a4c93", "estimate"),
    ] {
        if let Some(p) = pose {
            let a = p.translation();
            let (x, y) = f.px(a);
            let tip = a + unit(p.theta) * (28.0 / scale);
            let (tx, ty) = f.px(tip);
            let _ = writeln!(
                s,
                r#"<line x1="{x:.1}" y1="{y:.1}" x2="{tx:.1}" y2="{ty:.1}" stroke="{colour}" stroke-width="3"/><circle cx="{x:.1}" cy="{y:.1}" r="6" fill="{colour}"/><text x="{:.1}" y="{:.1}" fill="{colour}">{label}</text>"#,
                x + 9.0,
                y - 9.0
            );
        }
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
        ("#c1121f", "● agent, heading"),
        ("#e9c46a", "— measurement"),
        ("#e76f51", "— outlier"),
    ];
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
}
