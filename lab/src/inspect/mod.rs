//! The inspection tool (paper §3.5, Fig. 4, §5.1): record what the learnt policy saw and
//! computed at every step of an episode, and turn that state trajectory into one
//! self-contained web page to step through it, with a guided-back-propagation view
//! (Springenberg et al. 2014) of which parts of the state drove each chosen action.
//!
//! - [`record_episode`]: plays the float policy greedily (the same actions as
//!   [`activesense_instrument::learn::agent::LearntAgent`]) and stores, per step, the belief map (all rotation
//!   channels), the side features (scans, action history, beam, step, measurements), the
//!   logits, action probabilities and value, and the guided-back-propagation maps of the
//!   chosen action's logit over the belief and the side features
//!   ([`activesense_instrument::learn::net::PolicyNet::guided_backprop`]).
//! - [`load_trajectory`]: reads a trajectory JSON written by `activesense episode --json`,
//!   refusing another format version or a broken file with one line naming the file.
//! - [`render_page`]: the HTML page (inline CSS and JavaScript written in this repository,
//!   `page.html`, `page.css`, `page.js`; no network access).
//! - [`aggregate`]: the Fig.-4 analysis over many test-plan episodes.

pub mod aggregate;

use activesense_core::episode::Action;
use activesense_core::localization::grid::GridSpec;
use activesense_core::policy::{Policy, PolicyInput, BELIEF_SIDE, SIDE_FEATURES};
use activesense_instrument::episode::{
    run_episode_with, EpisodeSpec, InspectionHeader, StepInspection, Trajectory, TRAJECTORY_FORMAT,
};
use activesense_instrument::learn::agent::{
    argmax, masked_features, InputMask, LearntPolicy, ACTIONS,
};
use activesense_instrument::learn::net::{softmax, PolicyNet};
use anyhow::{bail, Context, Result};
use std::path::Path;

/// A greedy float-policy agent that records a [`StepInspection`] per decision.
pub struct InspectingAgent<'a> {
    net: &'a PolicyNet,
    belief: Vec<f32>,
    side: Vec<f32>,
    /// One record per decision, in order.
    pub records: Vec<StepInspection>,
    /// The localizer's grid, seen at the first decision.
    pub grid: Option<GridSpec>,
    /// Inputs zeroed before the network sees them (an ablated policy's mask).
    pub mask: InputMask,
}

impl<'a> InspectingAgent<'a> {
    pub fn new(net: &'a PolicyNet) -> Self {
        InspectingAgent {
            net,
            belief: vec![0.0; net.shape.belief_len()],
            side: vec![0.0; SIDE_FEATURES],
            records: Vec::new(),
            grid: None,
            mask: InputMask::Full,
        }
    }
}

impl Policy for InspectingAgent<'_> {
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        if self.grid.is_none() {
            self.grid = Some(*input.localizer.grid());
        }
        masked_features(input, self.mask, &mut self.belief, &mut self.side);
        let out = self.net.forward(&self.belief, &self.side);
        let a = argmax(&out.logits);
        let (gbp_belief, gbp_side) = self.net.guided_backprop(&self.belief, &self.side, a);
        self.records.push(StepInspection {
            belief: self.belief.clone(),
            side: self.side.clone(),
            logits: out.logits,
            probs: softmax(&out.logits),
            value: out.value,
            gbp_belief,
            gbp_side,
        });
        ACTIONS[a]
    }
}

/// Runs `spec` with the float `policy` (greedy, as `--agent learnt` plays) and returns the
/// trajectory with the inspection data on every step.
pub fn record_episode(spec: &EpisodeSpec, policy: &LearntPolicy) -> Trajectory {
    let mut agent = InspectingAgent::new(&policy.net);
    agent.mask = policy.mask;
    let mut t = run_episode_with(spec, &mut agent);
    debug_assert_eq!(agent.records.len(), t.steps.len());
    for (step, rec) in t.steps.iter_mut().zip(agent.records) {
        step.inspect = Some(rec);
    }
    t.inspection = agent.grid.map(|grid| InspectionHeader {
        policy: policy.describe(),
        grid,
        belief_side: BELIEF_SIDE,
    });
    t
}

/// Reads a trajectory JSON for inspection. Every failure is one line naming the file: not
/// readable, not JSON, no or another format version, not a trajectory, or one without the
/// inspection data (a baseline agent's), or with inconsistent array sizes.
pub fn load_trajectory(path: &Path) -> Result<Trajectory> {
    let name = path.display();
    let text = std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("'{name}': {e}"))?;
    let value: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("'{name}' is not a trajectory (not valid JSON: {e})"))?;
    let Some(obj) = value.as_object() else {
        bail!("'{name}' is not a trajectory (the JSON is not an object)");
    };
    match obj.get("format") {
        None if obj.contains_key("steps") => bail!(
            "'{name}' is a trajectory without a format version (written before format {TRAJECTORY_FORMAT}); record it again with `activesense episode --agent learnt --json FILE`"
        ),
        None => bail!("'{name}' is not a trajectory (no format version, no steps)"),
        Some(v) if v.as_u64() == Some(u64::from(TRAJECTORY_FORMAT)) => {}
        Some(v) => bail!(
            "'{name}' is trajectory format {v}, this activesense reads format {TRAJECTORY_FORMAT}; record it again with `activesense episode --agent learnt --json FILE`"
        ),
    }
    let t: Trajectory = serde_json::from_value(value)
        .map_err(|e| anyhow::anyhow!("'{name}' is a broken trajectory: {e}"))?;
    let Some(h) = &t.inspection else {
        bail!(
            "'{name}' has no inspection data ({} agent); record a learnt-agent episode: `activesense episode --agent learnt --json FILE`",
            t.spec.agent.name()
        );
    };
    let k = h.grid.rot_bins as usize;
    let plane = h.belief_side * h.belief_side;
    if h.belief_side != BELIEF_SIDE || k == 0 || k != t.spec.rot_bins as usize {
        bail!("'{name}' is a broken trajectory: belief map {0}x{0} with {k} channels does not match K = {1}", h.belief_side, t.spec.rot_bins);
    }
    for s in &t.steps {
        let Some(i) = &s.inspect else {
            bail!(
                "'{name}' is a broken trajectory: step {} has no inspection data",
                s.step
            );
        };
        let ok = i.belief.len() == k * plane
            && i.gbp_belief.len() == k * plane
            && i.side.len() == SIDE_FEATURES
            && i.gbp_side.len() == SIDE_FEATURES
            && i.belief
                .iter()
                .chain(&i.gbp_belief)
                .chain(&i.side)
                .chain(&i.gbp_side)
                .all(|v| v.is_finite());
        if !ok {
            bail!(
                "'{name}' is a broken trajectory: step {} has inspection arrays of the wrong size or non-finite values",
                s.step
            );
        }
    }
    if t.steps.is_empty() {
        bail!("'{name}' is a broken trajectory: no steps");
    }
    Ok(t)
}

const PAGE_HTML: &str = include_str!("page.html");
const PAGE_CSS: &str = include_str!("page.css");
const PAGE_JS: &str = include_str!("page.js");

/// The self-contained inspection page for `t` (which must carry inspection data; see
/// [`load_trajectory`]): the trajectory embedded as JSON, the page's CSS and JavaScript
/// inline. The same trajectory gives the same bytes.
pub fn render_page(t: &Trajectory, source: &str) -> Result<String> {
    let mut value = serde_json::to_value(t).context("serialising the trajectory")?;
    // The door walls as indices: the plan's `openings` is a 64-bit mask, and JavaScript's
    // numbers hold 53 bits exactly, so a door on a wall above index 52 would be lost there.
    let doors: Vec<usize> = (0..t.plan.len())
        .filter(|&i| t.plan.is_opening(i))
        .collect();
    if let Some(plan) = value.get_mut("plan").and_then(|p| p.as_object_mut()) {
        plan.insert("doors".into(), serde_json::json!(doors));
    }
    let data = serde_json::to_string(&value).context("serialising the trajectory")?;
    // Inside <script> only "</" could end the element early; "<\/" is the same JSON string.
    let data = data.replace("</", "<\\/");
    let title = format!(
        "activesense inspect: {} {} K={} ({})",
        t.spec.plan_label(),
        t.spec.agent.name(),
        t.spec.rot_bins,
        source
    );
    Ok(PAGE_HTML
        .replace("{{TITLE}}", &html_escape(&title))
        .replace("{{CSS}}", PAGE_CSS)
        .replace("{{JS}}", PAGE_JS)
        .replace("{{DATA}}", &data))
}

/// Escapes text for HTML element content.
pub fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// `activesense inspect TRAJECTORY --out PAGE`.
pub fn write_page(trajectory: &Path, out: &Path) -> Result<()> {
    let t = load_trajectory(trajectory)?;
    let source = trajectory
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let page = render_page(&t, &source)?;
    std::fs::write(out, page).with_context(|| format!("cannot write {}", out.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use activesense_core::episode::AgentKind;
    use activesense_instrument::agents::{run_agent_episode, Policies};
    use activesense_instrument::learn::agent::default_policy_path;
    use activesense_instrument::world::plans;

    fn scratch(name: &str) -> std::path::PathBuf {
        let d =
            std::env::temp_dir().join(format!("activesense-inspect-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// The page names the door walls by index: a door on wall 60 of a 62-wall room is
    /// bit 60 of the plan's `openings`, which a JavaScript number cannot hold.
    #[test]
    fn the_page_lists_door_walls_past_the_53_bits_of_a_javascript_number() {
        let policy = LearntPolicy::load(&default_policy_path(1), 1).unwrap();
        let spec = EpisodeSpec::new(plans::TEST_SEEDS.start + 5, AgentKind::Learnt);
        let mut t = record_episode(&spec, &policy);
        let n = 62;
        let ring: Vec<[f32; 2]> = (0..n)
            .map(|i| {
                let a = std::f32::consts::TAU * i as f32 / n as f32;
                [10.0 * a.cos(), 10.0 * a.sin()]
            })
            .collect();
        let openings = (1u64 << 1) | (1u64 << 60);
        t.plan = activesense_core::FloorPlan::from_parts(&ring, &[], openings).unwrap();
        let page = render_page(&t, "doors.json").unwrap();
        assert!(
            page.contains("\"doors\":[1,60]"),
            "door walls listed by index"
        );
    }

    #[test]
    fn recorded_episode_plays_like_the_learnt_agent_and_carries_consistent_maps() {
        let policy = LearntPolicy::load(&default_policy_path(1), 1).unwrap();
        let mut spec = EpisodeSpec::new(plans::TEST_SEEDS.start + 5, AgentKind::Learnt);
        spec.episode_seed = 2;
        let t = record_episode(&spec, &policy);
        let policies = Policies::load(&[], &[1]).unwrap();
        let plain = run_agent_episode(&spec, &policies).unwrap();
        let actions = |t: &Trajectory| t.steps.iter().map(|s| s.action).collect::<Vec<_>>();
        assert_eq!(actions(&t), actions(&plain), "recording changes no action");
        assert!(plain.steps.iter().all(|s| s.inspect.is_none()));
        assert!(t.steps.len() >= 2);
        for s in &t.steps {
            let i = s.inspect.as_ref().unwrap();
            // The chosen action is the most probable, and its map is the guided one.
            let a = activesense_instrument::learn::agent::action_index(s.action);
            assert_eq!(argmax(&i.logits), a);
            assert!((i.probs.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            let (gb, gs) = policy.net.guided_backprop(&i.belief, &i.side, a);
            assert_eq!(gb, i.gbp_belief);
            assert_eq!(gs, i.gbp_side);
        }
        // Deterministic: the same page twice; and the page round-trips through a file.
        let dir = scratch("roundtrip");
        let f = dir.join("run.json");
        std::fs::write(&f, serde_json::to_string(&t).unwrap()).unwrap();
        let back = load_trajectory(&f).unwrap();
        assert_eq!(
            render_page(&back, "run.json").unwrap(),
            render_page(&t, "run.json").unwrap()
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn wrong_files_are_one_line_errors_naming_the_file() {
        let dir = scratch("errors");
        let policy = LearntPolicy::load(&default_policy_path(1), 1).unwrap();
        let spec = EpisodeSpec::new(plans::TEST_SEEDS.start + 1, AgentKind::Learnt);
        let good = serde_json::to_value(record_episode(&spec, &policy)).unwrap();
        let check = |name: &str, text: String, want: &str| {
            let f = dir.join(name);
            std::fs::write(&f, text).unwrap();
            let e = format!("{:#}", load_trajectory(&f).unwrap_err());
            assert!(e.contains(name) && e.contains(want), "{name}: {e}");
            assert!(!e.contains('\n'), "{name}: not one line: {e}");
        };
        check("missing.json", String::new(), "not valid JSON");
        check("list.json", "[1, 2]".into(), "not an object");
        let mut v = good.clone();
        v["format"] = 1.into();
        check("old.json", v.to_string(), "format 1");
        let mut v = good.clone();
        v.as_object_mut().unwrap().remove("format");
        check(
            "unversioned.json",
            v.to_string(),
            "without a format version",
        );
        let mut v = good.clone();
        v["steps"][0]["inspect"]["belief"] = serde_json::json!([0.5]);
        check("short.json", v.to_string(), "wrong size");
        let mut v = good.clone();
        v["steps"][0]["action"] = "Jump".into();
        check("action.json", v.to_string(), "broken trajectory");
        let text = good.to_string();
        check(
            "truncated.json",
            text[..text.len() / 2].into(),
            "not valid JSON",
        );
        let base = activesense_instrument::episode::run_episode(&EpisodeSpec::new(
            plans::TEST_SEEDS.start,
            AgentKind::Heuristic1,
        ));
        check(
            "baseline.json",
            serde_json::to_string(&base).unwrap(),
            "no inspection data",
        );
        let e = format!(
            "{:#}",
            load_trajectory(&dir.join("absent.json")).unwrap_err()
        );
        assert!(e.contains("absent.json"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
