//! The instrument's episode controller: validates `StartEpisode` parameters against the
//! loaded plan and the policies it carries, passes them straight to an [`EpisodeRunner`],
//! chooses every action (a baseline agent or the int8 policy), times each update, and
//! reports the episode ([`EpisodeReport`]). It knows nothing of frames or request ids
//! ([`crate::device::session`] does).

use crate::episode::{
    Action, AgentKind, EpisodeParams, InstrumentProfile, Observation, ParamError,
};
use crate::pipeline::runner::{Booked, EpisodeRunner};
use crate::pipeline::PipelineError;
use crate::policy::int8::{QuantizedPolicy, Scratch as QScratch, ScratchAgent};
use crate::policy::BaselineAgent;
use crate::protocol::*;
use crate::world::floorplan::FloorPlan;
use crate::world::geometry::v2;

/// What the controller wants next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// Perform `action` (the `step`-th of the episode) and report the observation.
    Act {
        /// 0-based action index.
        step: u16,
        /// The action.
        action: Action,
    },
    /// The episode is over.
    Done(EpisodeReport),
}

/// Bytes of the RAM slot an uploaded int8 policy lives in (a K = 10 blob of the
/// `conv8-4-fc32` network is 16,220 bytes).
pub const POLICY_SLOT_BYTES: usize = 16 * 1024;

/// Who decides in the running episode.
enum DeviceAgent {
    Baseline(BaselineAgent),
    /// The int8 policy from the upload slot or from the built-in blob at this index.
    Int8(Option<usize>),
}

/// An upload in progress (staged in the idle localizer's memory).
#[derive(Clone, Copy)]
struct Upload {
    rot_bins: u8,
    len: u32,
    crc: u32,
    received: u32,
}

struct Running {
    agent: DeviceAgent,
    pending: Option<Action>,
    trace: TraceHash,
    cycles: EpisodeCycles,
    update_start: u32,
    /// What the update being timed did (set by `observe`).
    update_kind: Booked,
}

/// The device's decision maker for one plan and one episode at a time.
pub struct Controller {
    plan: Option<FloorPlan>,
    running: Option<Running>,
    cycles: UpdateStats,
    clock: Option<fn() -> u32>,
    pub(super) runner: EpisodeRunner,
    /// int8 policies in flash, validated when an episode asks for one.
    builtin: &'static [&'static [u8]],
    /// The uploaded policy (`slot_len` bytes; 0 = none) and its K.
    slot: [u8; POLICY_SLOT_BYTES],
    slot_len: usize,
    slot_rot_bins: u8,
    /// The instrument the uploaded blob is for.
    slot_instrument: InstrumentProfile,
    upload: Option<Upload>,
    /// Activations of the int8 policy.
    scratch: QScratch,
}

impl Controller {
    /// An idle controller. `clock` (a free-running cycle counter) enables per-update
    /// cycle statistics; `policies` are the int8 blobs built into the firmware.
    pub const fn new(clock: Option<fn() -> u32>, policies: &'static [&'static [u8]]) -> Self {
        Controller {
            plan: None,
            running: None,
            cycles: UpdateStats {
                updates: 0,
                total_cycles: 0,
                max_cycles: 0,
            },
            clock,
            runner: EpisodeRunner::new_empty(),
            builtin: policies,
            slot: [0; POLICY_SLOT_BYTES],
            slot_len: 0,
            slot_rot_bins: 0,
            slot_instrument: InstrumentProfile::EdmScan,
            upload: None,
            scratch: QScratch::new(),
        }
    }

    /// The policy serving `rot_bins` on `instrument`: the uploaded one if it is for this K
    /// and instrument, else the first sound built-in one (`None` index = the upload slot). A
    /// blob for another instrument never serves.
    fn policy_for(
        &self,
        instrument: InstrumentProfile,
        rot_bins: u8,
    ) -> Option<(Option<usize>, &[u8])> {
        if self.slot_len > 0 && self.slot_rot_bins == rot_bins && self.slot_instrument == instrument
        {
            return Some((None, &self.slot[..self.slot_len]));
        }
        self.builtin.iter().enumerate().find_map(|(i, b)| {
            QuantizedPolicy::parse(b)
                .ok()
                .filter(|p| p.rot_bins() == rot_bins && p.instrument() == instrument)
                .map(|_| (Some(i), *b))
        })
    }

    /// Which policy serves `rot_bins` on the paper's sensor (the protocol's `PolicyInfo`
    /// names K only).
    pub fn policy_info(&self, rot_bins: u8) -> PolicyInfo {
        match self.policy_for(InstrumentProfile::EdmScan, rot_bins) {
            Some((src, bytes)) => PolicyInfo {
                rot_bins,
                source: if src.is_none() {
                    PolicySource::Uploaded
                } else {
                    PolicySource::BuiltIn
                },
                len: bytes.len() as u32,
                crc: crate::policy::int8::stored_crc(bytes).unwrap_or(0),
            },
            None => PolicyInfo {
                rot_bins,
                source: PolicySource::None,
                len: 0,
                crc: 0,
            },
        }
    }

    /// True when some policy (built-in or uploaded) is on board.
    pub fn has_policies(&self) -> bool {
        !self.builtin.is_empty() || self.slot_len > 0
    }

    /// Starts a policy upload (between episodes only).
    pub fn policy_begin(&mut self, rot_bins: u8, len: u32, crc: u32) -> Result<(), WireError> {
        if self.running.is_some() {
            return Err(WireError::UnexpectedRequest);
        }
        let capacity = POLICY_SLOT_BYTES as u32;
        if len as usize > POLICY_SLOT_BYTES
            || len as usize > self.runner.idle_storage().len()
            || rot_bins == 0
            || rot_bins > MAX_ROT_BINS
        {
            return Err(WireError::Policy(PolicyError::TooLarge { capacity }));
        }
        self.upload = Some(Upload {
            rot_bins,
            len,
            crc,
            received: 0,
        });
        Ok(())
    }

    /// Stages the next chunk of the upload.
    pub fn policy_chunk(&mut self, offset: u32, data: &[u8]) -> Result<(), WireError> {
        let up = self
            .upload
            .as_mut()
            .ok_or(WireError::Policy(PolicyError::NoUpload))?;
        if offset != up.received {
            return Err(WireError::Policy(PolicyError::ChunkOffset {
                expected: up.received,
            }));
        }
        let end = offset as usize + data.len();
        if end > up.len as usize {
            return Err(WireError::Policy(PolicyError::Overrun));
        }
        let staging = self.runner.idle_storage();
        staging
            .get_mut(offset as usize..end)
            .ok_or(WireError::Policy(PolicyError::Overrun))?
            .copy_from_slice(data);
        up.received = end as u32;
        Ok(())
    }

    /// Checks the staged blob and puts it in service; a bad one changes nothing.
    pub fn policy_commit(&mut self) -> Result<PolicyInfo, WireError> {
        let up = self
            .upload
            .take()
            .ok_or(WireError::Policy(PolicyError::NoUpload))?;
        if up.received != up.len {
            return Err(WireError::Policy(PolicyError::Incomplete {
                received: up.received,
            }));
        }
        let len = up.len as usize;
        let staging = self.runner.idle_storage();
        let blob = staging
            .get(..len)
            .ok_or(WireError::Policy(PolicyError::Overrun))?;
        // The announced CRC is the blob's own (over all but its last 4 bytes); `parse`
        // below checks that the blob agrees with itself.
        let body = blob.get(..len.saturating_sub(4)).unwrap_or(&[]);
        if crate::protocol::crc32(body) != up.crc {
            return Err(WireError::Policy(PolicyError::Checksum));
        }
        let parsed =
            QuantizedPolicy::parse(blob).map_err(|e| WireError::Policy(PolicyError::Invalid(e)))?;
        let (found, instrument) = (parsed.rot_bins(), parsed.instrument());
        if found != up.rot_bins {
            return Err(WireError::Policy(PolicyError::WrongRotBins { found }));
        }
        self.slot[..len].copy_from_slice(blob);
        self.slot_len = len;
        self.slot_rot_bins = found;
        self.slot_instrument = instrument;
        Ok(self.policy_info(found))
    }

    fn now(&self) -> u32 {
        self.clock.map(|c| c()).unwrap_or(0)
    }

    /// Installs a validated plan (aborts any episode).
    pub fn load_plan(&mut self, plan: FloorPlan) {
        self.running = None;
        self.plan = Some(plan);
    }

    /// The loaded plan.
    pub fn plan(&self) -> Option<&FloorPlan> {
        self.plan.as_ref()
    }

    /// Drops plan, episode, statistics and any uploaded policy.
    pub fn reset(&mut self) {
        self.plan = None;
        self.running = None;
        self.cycles = UpdateStats::default();
        self.upload = None;
        self.slot_len = 0;
    }

    /// True while an episode runs.
    pub fn is_running(&self) -> bool {
        self.running.is_some()
    }

    /// Actions taken in the running episode.
    pub fn episode_actions(&self) -> u16 {
        self.running
            .as_ref()
            .map(|_| self.runner.state().actions)
            .unwrap_or(0)
    }

    /// The latest topological scan of the running episode (the initial one before the
    /// first observation).
    pub fn last_scan(&self) -> Option<u32> {
        self.running
            .as_ref()
            .and_then(|_| self.runner.history().scan(0))
    }

    /// Cycle statistics since power-on / reset.
    pub fn cycles(&self) -> UpdateStats {
        self.cycles
    }

    /// Ranges voted in the running (or last) episode; the registration keeps every one
    /// of them.
    pub fn measurement_count(&self) -> usize {
        self.runner.pipeline().observations().len()
    }

    /// Validates `p` against the loaded plan and the policies the device carries:
    /// [`EpisodeParams::check_limits`], the agent, [`EpisodeParams::check_poses`], then
    /// the ground truth inside the plan (in this order, so the first defect is reported).
    pub fn check_params(&self, p: &EpisodeParams) -> Result<(), WireError> {
        let plan = self.plan.as_ref().ok_or(WireError::NoPlan)?;
        let bad = |e| Err(WireError::InvalidParams(e));
        if let Err(e) = p.check_limits() {
            return bad(e);
        }
        match p.agent {
            // The float network and the greedy benchmarks live on the host only.
            AgentKind::Learnt | AgentKind::Oigm | AgentKind::OigmCost | AgentKind::Eem => {
                return bad(ParamError::AgentUnavailable)
            }
            AgentKind::LearntInt8 if self.policy_for(p.config.instrument, p.rot_bins).is_none() => {
                return bad(ParamError::AgentUnavailable)
            }
            _ => {}
        }
        if let Err(e) = p.check_poses() {
            return bad(e);
        }
        if let Some(gt) = p.ground_truth {
            if !plan.contains(v2(gt.x, gt.y)) {
                return bad(ParamError::GroundTruthOutside);
            }
        }
        Ok(())
    }

    /// Starts an episode (replacing any running one): the received parameters go
    /// straight to the runner (the host's stop rule included, carried since protocol v4,
    /// so the instrument stops exactly where the host's episode runner would).
    pub fn start(&mut self, p: &EpisodeParams) -> Result<(), WireError> {
        self.check_params(p)?;
        self.running = None;
        // An episode takes the localizer's memory back from a staged upload.
        self.upload = None;
        let agent = if p.agent == AgentKind::LearntInt8 {
            DeviceAgent::Int8(
                self.policy_for(p.config.instrument, p.rot_bins)
                    .ok_or(WireError::InvalidParams(ParamError::AgentUnavailable))?
                    .0,
            )
        } else {
            DeviceAgent::Baseline(BaselineAgent::new(p.agent, p.seed))
        };
        let plan = self.plan.as_ref().ok_or(WireError::NoPlan)?;
        self.runner.start(plan, p).map_err(|e| {
            WireError::InvalidParams(match e {
                PipelineError::KnownHeadingRequired => ParamError::KnownHeadingRequired,
                PipelineError::GroundTruthRequired => ParamError::GroundTruthRequired,
                PipelineError::Localizer(_) => ParamError::PlanNotLocalizable,
            })
        })?;
        self.running = Some(Running {
            agent,
            pending: None,
            trace: TraceHash::new(),
            cycles: EpisodeCycles::default(),
            update_start: self.now(),
            update_kind: Booked::Rotation,
        });
        Ok(())
    }

    fn report(runner: &EpisodeRunner, r: &Running, end: EpisodeEnd) -> EpisodeReport {
        let state = runner.state();
        EpisodeReport {
            recognised: None,
            end,
            actions: state.actions,
            measurements: state.measurements,
            rotations: state.rotations,
            no_returns: runner.no_returns(),
            cost: state.cost,
            bearing_index: state.bearing_index,
            trace_hash: r.trace.value(),
            coarse: None,
            refined: None,
            stop_risk: None,
            answer_readings: 0,
            cycles: r.cycles,
        }
    }

    /// The next action request, or the end of the episode (which clears it). Repeats the
    /// pending request until it is observed. Without a running episode: `None`.
    ///
    /// **Timing.** One update spans from the start of [`Controller::observe`] to the end
    /// of the decision here (booking the observation, the GHT vote and termination check
    /// for a returned range, choosing the next action); the end-of-episode chain
    /// ([`Pipeline::finish`](crate::pipeline::Pipeline::finish): coarse read-out,
    /// registration, recognition) is timed separately into [`EpisodeCycles::finish`].
    pub fn next_step(&mut self) -> Option<Step> {
        let clock = self.clock;
        let now = || clock.map(|c| c()).unwrap_or(0);
        let r = self.running.as_mut()?;
        if let Some(action) = r.pending {
            return Some(Step::Act {
                step: self.runner.state().actions,
                action,
            });
        }
        let t_decide = now();
        let decided = match &mut r.agent {
            DeviceAgent::Baseline(a) => self.runner.decide(a),
            DeviceAgent::Int8(src) => {
                let bytes: &[u8] = match *src {
                    None => &self.slot[..self.slot_len],
                    Some(i) => self.builtin.get(i).copied().unwrap_or(&[]),
                };
                // Validated (with its CRC) when the episode started or the upload was
                // committed; the structure is re-checked, never trusted blindly.
                match QuantizedPolicy::parse_verified(bytes) {
                    Ok(policy) => self.runner.decide(&mut ScratchAgent {
                        policy,
                        scratch: &mut self.scratch,
                    }),
                    Err(_) => None,
                }
            }
        };
        if decided.is_some() {
            r.cycles.decision.record(now().wrapping_sub(t_decide));
        }
        let step = decided.map(|action| {
            r.pending = Some(action);
            Step::Act {
                step: self.runner.state().actions,
                action,
            }
        });
        let cycles = now().wrapping_sub(r.update_start);
        if self.runner.state().actions > 0 {
            match r.update_kind {
                Booked::Vote => r.cycles.vote.record(cycles),
                Booked::Rotation => r.cycles.rotation.record(cycles),
                Booked::NoReturn => r.cycles.no_return.record(cycles),
            }
            self.cycles.record(cycles);
        }
        match step {
            Some(s) => Some(s),
            None => {
                let end = if self.runner.stop().is_some() {
                    EpisodeEnd::Localized
                } else {
                    EpisodeEnd::ActionLimit
                };
                let mut rep = Self::report(&self.runner, r, end);
                self.running = None;
                if let Some(plan) = self.plan.as_ref() {
                    let t0 = now();
                    let result = self.runner.finish(plan);
                    rep.cycles.finish = now().wrapping_sub(t0);
                    rep.coarse = result.coarse;
                    rep.refined = result.refined.map(|x| x.pose);
                    rep.recognised = result.recognised;
                    rep.stop_risk = result.stop_risk;
                    rep.answer_readings = result.answer_readings;
                }
                Some(Step::Done(rep))
            }
        }
    }

    /// Books the instrument's answer to action request `step`.
    pub fn observe(&mut self, step: u16, obs: &Observation) -> Result<(), WireError> {
        let now = self.now();
        let r = self.running.as_mut().ok_or(WireError::UnexpectedRequest)?;
        let action = match r.pending {
            Some(a) if step == self.runner.state().actions => a,
            _ => {
                return Err(WireError::StepMismatch {
                    expected: self.runner.state().actions,
                })
            }
        };
        r.update_kind = self
            .runner
            .observe(action, obs)
            .map_err(WireError::InvalidObservation)?;
        r.update_start = now;
        r.pending = None;
        r.trace.push(action, obs);
        Ok(())
    }

    /// Aborts the running episode, returning its report so far.
    pub fn abort(&mut self) -> Option<EpisodeReport> {
        let r = self.running.take()?;
        Some(Self::report(&self.runner, &r, EpisodeEnd::Aborted))
    }
}
