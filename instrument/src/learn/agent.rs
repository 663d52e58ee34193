//! The learnt policy as an agent: a [`PolicyNet`] behind the core's [`Policy`] seam, so the
//! episode runner, the evaluation and the CLI play it like any baseline. Features come
//! from [`PolicyInput`] (core code, the same the trainer feeds); the action is the argmax
//! of the actor's logits (deterministic, as the int8 policy on the instrument decides), or
//! a draw from the softmax when a seed is given (training).

use super::file::{self, LoadError};
use super::net::{NetShape, PolicyNet, Scratch};
use activesense_core::episode::{Action, InstrumentProfile};
use activesense_core::policy::{Policy, PolicyInput, BELIEF_PLANE, SIDE_FEATURES};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Actor output index → action (the network's fixed action order).
pub const ACTIONS: [Action; 3] = [Action::RotateLeft, Action::RotateRight, Action::Measure];

/// Index of `a` in [`ACTIONS`].
pub fn action_index(a: Action) -> usize {
    match a {
        Action::RotateLeft => 0,
        Action::RotateRight => 1,
        Action::Measure => 2,
    }
}

/// The network shape for `rot_bins` with the core's side features.
pub fn shape_for(rot_bins: u8) -> NetShape {
    NetShape {
        rot_bins: rot_bins as usize,
        side: SIDE_FEATURES,
    }
}

/// Writes the network inputs for `input` into `belief` (`K × BELIEF_PLANE`) and `side`.
pub fn features(input: &PolicyInput<'_>, belief: &mut [f32], side: &mut [f32]) {
    input.write_belief(belief);
    let side: &mut [f32; SIDE_FEATURES] = side
        .try_into()
        .expect("side buffer holds SIDE_FEATURES values");
    input.write_side(side);
}

/// Which parts of the state a policy is shown (the §4.4 ablations). A masked part is
/// written as zeros, in training and in evaluation alike, so the network has the same
/// shape and the same parameter count whatever it is denied.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InputMask {
    /// Everything (the committed policies).
    #[default]
    Full,
    /// No topological scans: the `SCAN_HISTORY × 20` scan features are zero.
    NoScans,
    /// No belief map: the `K × 30 × 30` map is zero (scans, actions, beam, counters only).
    NoBelief,
}

impl InputMask {
    /// Parses `full`, `no-scans`, `no-belief`.
    pub fn from_name(s: &str) -> Option<Self> {
        [InputMask::Full, InputMask::NoScans, InputMask::NoBelief]
            .into_iter()
            .find(|m| m.name() == s)
    }

    /// The name used on the command line and in policy files.
    pub fn name(self) -> &'static str {
        match self {
            InputMask::Full => "full",
            InputMask::NoScans => "no-scans",
            InputMask::NoBelief => "no-belief",
        }
    }

    /// The mask a policy file was trained with (`hyper_params.inputs`; files from before
    /// the ablations have none and saw everything).
    pub fn of_metadata(meta: &serde_json::Value) -> Self {
        meta.get("hyper_params")
            .and_then(|h| h.get("inputs"))
            .and_then(|v| serde_json::from_value(v.clone()).ok())
            .unwrap_or_default()
    }

    /// The instrument a network trained with this mask is for: the scan-blind network is
    /// the EDM-only instrument's, the full one the paper's sensor's; a network denied its
    /// belief map is an ablation, no instrument's.
    pub fn instrument(self) -> Option<InstrumentProfile> {
        match self {
            InputMask::Full => Some(InstrumentProfile::EdmScan),
            InputMask::NoScans => Some(InstrumentProfile::Edm),
            InputMask::NoBelief => None,
        }
    }

    /// Zeroes the denied inputs in place.
    pub fn apply(self, belief: &mut [f32], side: &mut [f32]) {
        match self {
            InputMask::Full => {}
            InputMask::NoScans => {
                let n =
                    activesense_core::policy::SCAN_HISTORY * activesense_core::episode::SCAN_PIXELS;
                side[..n].fill(0.0);
            }
            InputMask::NoBelief => belief.fill(0.0),
        }
    }
}

/// [`features`] with the denied inputs zeroed.
pub fn masked_features(
    input: &PolicyInput<'_>,
    mask: InputMask,
    belief: &mut [f32],
    side: &mut [f32],
) {
    features(input, belief, side);
    mask.apply(belief, side);
}

/// Index of the largest logit (first on ties).
pub fn argmax(logits: &[f32; 3]) -> usize {
    let mut best = 0;
    for i in 1..3 {
        if logits[i] > logits[best] {
            best = i;
        }
    }
    best
}

/// A trained policy for one rotation setting, loaded from its file.
#[derive(Clone, Debug)]
pub struct LearntPolicy {
    /// The network.
    pub net: Arc<PolicyNet>,
    /// Where it came from.
    pub path: PathBuf,
    /// The file's metadata (training command, seed, …).
    pub meta: serde_json::Value,
    /// The inputs it was trained on (and is shown when it plays).
    pub mask: InputMask,
}

impl LearntPolicy {
    /// Loads `path`, checking it is a policy for `rot_bins` with the core's feature layout.
    pub fn load(path: &Path, rot_bins: u8) -> Result<Self, LoadError> {
        let (net, meta) = file::load_expecting(path, rot_bins, SIDE_FEATURES)?;
        Ok(LearntPolicy {
            net: Arc::new(net),
            path: path.to_path_buf(),
            mask: InputMask::of_metadata(&meta),
            meta,
        })
    }

    /// File name and stored checksum, for reports (`k1/policy.policy (crc 1a2b3c4d)`).
    pub fn describe(&self) -> String {
        // The last two path components (`k1/policy.policy`): no machine-specific prefix.
        let parts: Vec<String> = self
            .path
            .components()
            .rev()
            .take(2)
            .map(|c| c.as_os_str().to_string_lossy().into_owned())
            .collect();
        let name = parts.into_iter().rev().collect::<Vec<_>>().join("/");
        let crc = std::fs::read(&self.path)
            .ok()
            .and_then(|b| b.get(b.len().saturating_sub(4)..).map(|t| t.to_vec()))
            .filter(|t| t.len() == 4)
            .map(|t| u32::from_le_bytes([t[0], t[1], t[2], t[3]]));
        match crc {
            Some(c) => format!("{name} (crc {c:08x})"),
            None => name,
        }
    }

    /// A fresh agent playing this policy greedily.
    pub fn agent(&self) -> LearntAgent {
        let mut a = LearntAgent::new(self.net.clone());
        a.mask = self.mask;
        a
    }
}

/// The committed policy file for `rot_bins` of the paper's sensor:
/// `policies/k{K}/policy.policy` at the workspace root (the `--out` directory of its
/// training run, with its log and learning curve).
pub fn default_policy_path(rot_bins: u8) -> PathBuf {
    default_policy_path_for(InstrumentProfile::EdmScan, rot_bins)
}

/// The committed policy file for `rot_bins` on `instrument`: `policies/k{K}/` for the
/// paper's sensor, `policies/edm/k{K}/` for the EDM-only instrument.
pub fn default_policy_path_for(instrument: InstrumentProfile, rot_bins: u8) -> PathBuf {
    let mut p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("policies");
    if instrument == InstrumentProfile::Edm {
        p = p.join("edm");
    }
    p.join(format!("k{rot_bins}")).join("policy.policy")
}

/// A [`Policy`] that runs the float network.
pub struct LearntAgent {
    net: Arc<PolicyNet>,
    scratch: Scratch,
    belief: Vec<f32>,
    side: Vec<f32>,
    /// Inputs zeroed before the network sees them (ablated policies).
    pub mask: InputMask,
    /// Last decision's logits and value (for logs and inspection).
    pub last: Option<([f32; 3], f32)>,
}

impl LearntAgent {
    /// A greedy agent.
    pub fn new(net: Arc<PolicyNet>) -> Self {
        let shape = net.shape;
        LearntAgent {
            scratch: Scratch::new(shape),
            belief: vec![0.0; shape.rot_bins * BELIEF_PLANE],
            side: vec![0.0; SIDE_FEATURES],
            net,
            mask: InputMask::Full,
            last: None,
        }
    }
}

impl Policy for LearntAgent {
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        masked_features(input, self.mask, &mut self.belief, &mut self.side);
        let out = self
            .net
            .forward_with(&self.belief, &self.side, &mut self.scratch);
        self.last = Some((out.logits, out.value));
        ACTIONS[argmax(&out.logits)]
    }
}

/// An int8 policy blob (`docs/policy-blob.md`), validated, with where it came from.
#[derive(Clone, Debug)]
pub struct Int8Policy {
    /// The blob's K.
    pub rot_bins: u8,
    /// The instrument the blob's network was trained for.
    pub instrument: InstrumentProfile,
    /// The bytes.
    pub blob: Arc<Vec<u8>>,
    /// Its origin: a file, or the policy built into the firmware.
    pub origin: String,
}

impl Int8Policy {
    /// Validates `blob` (CRC included).
    pub fn new(blob: Vec<u8>, origin: String) -> anyhow::Result<Self> {
        let parsed = activesense_core::policy::int8::QuantizedPolicy::parse(&blob)
            .map_err(|e| anyhow::anyhow!("{origin} is not a usable int8 policy blob: {e}"))?;
        let (rot_bins, instrument) = (parsed.rot_bins(), parsed.instrument());
        Ok(Int8Policy {
            rot_bins,
            instrument,
            blob: Arc::new(blob),
            origin,
        })
    }

    /// Reads and validates a blob file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let bytes = std::fs::read(path)
            .map_err(|e| anyhow::anyhow!("int8 policy '{}': {e}", path.display()))?;
        Self::new(bytes, format!("int8 policy '{}'", path.display()))
    }

    /// File name (or origin) and CRC, for reports.
    pub fn describe(&self) -> String {
        format!(
            "{} (crc {:08x})",
            self.origin,
            activesense_core::policy::int8::stored_crc(&self.blob).unwrap_or(0)
        )
    }

    /// Runs `f` with an agent playing this blob.
    pub fn with_agent<R>(
        &self,
        f: impl FnOnce(&mut activesense_core::policy::int8::QuantizedAgent<'_>) -> R,
    ) -> R {
        // Validated in `new`, so parsing again cannot fail.
        let policy = activesense_core::policy::int8::QuantizedPolicy::parse(&self.blob)
            .expect("validated blob");
        let mut agent = Box::new(activesense_core::policy::int8::QuantizedAgent::new(policy));
        f(&mut agent)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn greedy_agent_takes_the_argmax() {
        assert_eq!(argmax(&[0.1, 0.3, 0.2]), 1);
        assert_eq!(argmax(&[0.5, 0.5, 0.2]), 0);
        assert_eq!(ACTIONS[action_index(Action::Measure)], Action::Measure);
    }
}
