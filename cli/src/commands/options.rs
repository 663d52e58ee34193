//! The options every command that plays an episode shares, declared once: how the episode is
//! played ([`EpisodeOptions`]: the rotation setting, seed, action limit, encoder grid, the
//! stop and its risk) and the simulated sensor ([`SensorArgs`]), with their value parsers.
//! Each command flattens them; a command changes a default with clap's `mut_arg` (the
//! station stops by the calibrated rule) and refuses, in words, an option it cannot honour
//! ([`EpisodeOptions::refuse`]). [`EpisodeOptions::config`] is the one place the core's
//! [`EpisodeConfig`] is built from the command line.

use activesense_core::episode::{
    AgentKind, EpisodeConfig, InstrumentProfile, Termination, DEFAULT_STEPS_PER_TURN,
    EVAL_MAX_ACTIONS,
};
use activesense_core::limits::DEFAULT_STOP_RISK;
use activesense_core::registration::pose_distance::Tolerance;
use activesense_instrument::world::sensor::SensorModel;
use activesense_instrument::world::site::SiteLevel;
use anyhow::{bail, Result};
use clap::Args;

/// The localizer's rotation setting(s): part of [`EpisodeOptions`], and alone where a
/// command sets up a localizer without playing an episode (`bench-localization`).
#[derive(Args, Clone, Debug, Default)]
pub struct RotBinsOption {
    /// Rotation bins of the localizer: 1 = heading known, 10 = heading unknown. Commands
    /// that run both take a comma-separated list (default: 1,10); one episode takes one
    /// (default: 1; `station`: 10).
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u8).range(1..=10))]
    pub rot_bins: Vec<u8>,
}

impl RotBinsOption {
    /// The rotation settings to run (`default` when none was given), each 1 or 10, in the
    /// order given without repeats.
    pub fn list(&self, default: &[u8]) -> Result<Vec<u8>> {
        let mut ks: Vec<u8> = if self.rot_bins.is_empty() {
            default.to_vec()
        } else {
            self.rot_bins.clone()
        };
        if let Some(k) = ks.iter().find(|&&k| k != 1 && k != 10) {
            bail!("--rot-bins must be 1 or 10 (the paper's two settings), got {k}");
        }
        let mut seen = Vec::new();
        ks.retain(|k| {
            let new = !seen.contains(k);
            seen.push(*k);
            new
        });
        Ok(ks)
    }

    /// The one rotation setting of a command that plays one (`default` when none was
    /// given).
    pub fn one(&self, default: u8) -> Result<u8> {
        match self.list(&[default])?.as_slice() {
            [k] => Ok(*k),
            more => bail!(
                "this command plays one rotation setting: give --rot-bins 1 or 10, not {:?}",
                more
            ),
        }
    }
}

/// The instrument the episodes are played on: part of [`EpisodeOptions`], and alone where a
/// command picks the committed policies of an instrument without playing its own episodes.
#[derive(Args, Clone, Debug)]
pub struct InstrumentOption {
    /// The instrument: `edm` (motor and reflectorless EDM only, what GeoCOM total stations
    /// are) or `edm+scan` (the paper's sensor, with the topological camera scan). It picks
    /// the simulated sensor, the committed policies (float and int8) and the stop's tables
    /// that belong to it; a policy made for the other is refused.
    #[arg(long = "instrument", value_name = "PROFILE", default_value = "edm+scan", value_parser = parse_instrument)]
    pub instrument: InstrumentProfile,
}

/// How the episodes of a command are played.
#[derive(Args, Clone, Debug)]
pub struct EpisodeOptions {
    #[command(flatten)]
    pub rot_bins: RotBinsOption,
    #[command(flatten)]
    pub instrument: InstrumentOption,
    /// Episode seed (placement, noise and agent randomness; placement and noise also depend
    /// on the plan).
    #[arg(long, default_value_t = 0)]
    pub episode_seed: u64,
    /// Action limit per episode.
    #[arg(long, default_value_t = EVAL_MAX_ACTIONS, value_parser = clap::value_parser!(u16).range(1..))]
    pub max_actions: u16,
    /// Rotation steps per full turn (rotation step = 360° / this; the encoder grid the
    /// telescope is positioned on).
    #[arg(long, default_value_t = DEFAULT_STEPS_PER_TURN, value_parser = clap::value_parser!(u16).range(2..=3600))]
    pub steps_per_turn: u16,
    /// When an episode stops: on coarse success against the simulated truth (the paper's
    /// rule), by the calibrated stop (no ground truth; it answers with the refined pose), or
    /// only at the action limit.
    #[arg(long, value_parser = termination_parser(), default_value = "oracle")]
    pub termination: Termination,
    /// With --termination confident: the risk of a wrong answer you accept. The stop answers
    /// once the estimated probability that the registration is wrong falls below the
    /// threshold that, on the calibration plans, made the first such stops wrong at most P of
    /// the time (docs/EVALUATION.md, 'Calibrated stop'). The instrument applies the same rule.
    #[arg(long, default_value_t = DEFAULT_STOP_RISK, value_parser = parse_stop_risk, allow_negative_numbers = true)]
    pub stop_risk: f32,
    /// Stop only once the readings determine the pose: the smallest eigenvalue of their
    /// normalised information matrix at the belief argmax must reach this (0 = off; the
    /// instrument applies the same threshold; docs/EVALUATION.md, "Observability").
    #[arg(long, default_value_t = 0.0, value_parser = parse_observability, allow_negative_numbers = true)]
    pub min_observability: f32,
    /// The room the EDM hits, while the instrument is given the plan: `plan` (the room is
    /// exactly its plan), `furnished` (furniture against walls, a column, an open door),
    /// `site` (furnished, plus a wall a few cm off its line, obstacles, glass, people in the
    /// beam) or `mixed` (one of the three per episode, from its seed). Seeded like the
    /// episode (docs/WORLD.md, "Sites").
    #[arg(long, default_value = "plan", value_parser = SiteLevel::parse)]
    pub site: SiteLevel,
}

/// One option of [`EpisodeOptions`], named as on the command line, for
/// [`EpisodeOptions::refuse`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EpisodeOption {
    RotBins,
    EpisodeSeed,
    MaxActions,
    StepsPerTurn,
    StopRisk,
    MinObservability,
    /// `--termination` away from `oracle` (the default of the commands that refuse it).
    Termination,
}

impl EpisodeOption {
    fn flag(self) -> &'static str {
        match self {
            EpisodeOption::RotBins => "--rot-bins",
            EpisodeOption::EpisodeSeed => "--episode-seed",
            EpisodeOption::MaxActions => "--max-actions",
            EpisodeOption::StepsPerTurn => "--steps-per-turn",
            EpisodeOption::StopRisk => "--stop-risk",
            EpisodeOption::MinObservability => "--min-observability",
            EpisodeOption::Termination => "--termination",
        }
    }
}

impl Default for EpisodeOptions {
    /// The options of an empty command line (the defaults are written once, above).
    fn default() -> Self {
        use clap::FromArgMatches;
        let cmd = Self::augment_args(clap::Command::new("episode").no_binary_name(true));
        let m = cmd
            .try_get_matches_from(std::iter::empty::<&str>())
            .expect("the defaults parse");
        Self::from_arg_matches(&m).expect("the defaults parse")
    }
}

impl EpisodeOptions {
    /// The core's episode configuration these options describe (the costs stay the paper's).
    pub fn config(&self) -> EpisodeConfig {
        EpisodeConfig {
            steps_per_turn: self.steps_per_turn,
            max_actions: self.max_actions,
            min_observability: self.min_observability,
            stop_risk: self.stop_risk,
            instrument: self.instrument.instrument,
            ..Default::default()
        }
    }

    /// `sensor` in the room these options name (`--site`).
    pub fn sensor(&self, sensor: SensorModel) -> SensorModel {
        SensorModel {
            site: self.site,
            ..sensor
        }
    }

    /// The rotation settings to run ([`RotBinsOption::list`]).
    pub fn rot_bins_or(&self, default: &[u8]) -> Result<Vec<u8>> {
        self.rot_bins.list(default)
    }

    /// The one rotation setting of a command that plays one ([`RotBinsOption::one`]).
    pub fn one_rot_bins(&self, default: u8) -> Result<u8> {
        self.rot_bins.one(default)
    }

    /// Refuses, in words, any of `options` set away from its default: they mean nothing
    /// to `command` (`why` says what it does instead).
    pub fn refuse(&self, command: &str, options: &[EpisodeOption], why: &str) -> Result<()> {
        let set = |o: EpisodeOption| match o {
            EpisodeOption::RotBins => !self.rot_bins.rot_bins.is_empty(),
            EpisodeOption::EpisodeSeed => self.episode_seed != 0,
            EpisodeOption::MaxActions => self.max_actions != EVAL_MAX_ACTIONS,
            EpisodeOption::StepsPerTurn => self.steps_per_turn != DEFAULT_STEPS_PER_TURN,
            EpisodeOption::StopRisk => self.stop_risk != DEFAULT_STOP_RISK,
            EpisodeOption::MinObservability => self.min_observability != 0.0,
            EpisodeOption::Termination => self.termination != Termination::Oracle,
        };
        if let Some(o) = options.iter().find(|&&o| set(o)) {
            bail!("`{command}` does not take {}: {why}", o.flag());
        }
        Ok(())
    }

    /// Refuses a `--termination` other than `allowed`, in words.
    pub fn require_termination(&self, command: &str, allowed: &[Termination]) -> Result<()> {
        if !allowed.contains(&self.termination) {
            let names: Vec<_> = allowed.iter().map(|t| t.name()).collect();
            bail!(
                "`{command}` stops by --termination {}, not {}",
                names.join(" or "),
                self.termination.name()
            );
        }
        Ok(())
    }
}

/// Sensor options shared by every simulating command.
#[derive(Args, Clone, Debug)]
pub struct SensorArgs {
    /// EDM range noise, standard deviation in metres.
    #[arg(long, default_value_t = 0.01)]
    sigma: f32,
    /// Probability that a measurement is an outlier (uniform random range).
    #[arg(long, default_value_t = 0.05)]
    outliers: f32,
    /// No EDM return beyond this range (m).
    #[arg(long, default_value_t = 50.0)]
    max_range: f32,
    /// No EDM return beyond this incidence angle from the wall normal (degrees).
    #[arg(long, default_value_t = 75.0)]
    max_incidence_deg: f32,
    /// Topological scan false-negative rate per pixel.
    #[arg(long, default_value_t = 0.0)]
    scan_fn: f32,
    /// Topological scan false-positive rate per pixel.
    #[arg(long, default_value_t = 0.0)]
    scan_fp: f32,
}

impl SensorArgs {
    /// The simulated sensor, checked.
    pub fn model(&self) -> Result<SensorModel> {
        let m = SensorModel {
            sigma: self.sigma,
            outlier_prob: self.outliers,
            max_range: self.max_range,
            max_incidence: self.max_incidence_deg.to_radians(),
            scan_false_negative: self.scan_fn,
            scan_false_positive: self.scan_fp,
            site: SiteLevel::Plan,
        };
        m.validate().map_err(anyhow::Error::msg)?;
        Ok(m)
    }
}

/// Command-line parser for `--tolerance METRES,DEGREES` (e.g. `0.05,0.5`).
pub fn parse_tolerance(s: &str) -> Result<Tolerance, String> {
    let bad = || format!("--tolerance wants METRES,DEGREES (e.g. 0.05,0.5), got {s:?}");
    let (m, d) = s.split_once(',').ok_or_else(bad)?;
    let m: f32 = m.trim().parse().map_err(|_| bad())?;
    let d: f32 = d.trim().parse().map_err(|_| bad())?;
    if !(m.is_finite() && d.is_finite() && m > 0.0 && d > 0.0) {
        return Err(format!(
            "--tolerance: both bounds must be positive, got {s:?}"
        ));
    }
    Ok(Tolerance {
        position_m: m,
        heading_rad: d.to_radians(),
    })
}

/// Command-line parser for `--termination`.
pub fn parse_termination(s: &str) -> Result<Termination, String> {
    [
        Termination::Oracle,
        Termination::Confident,
        Termination::ActionLimit,
    ]
    .into_iter()
    .find(|t| t.name() == s)
    .ok_or_else(|| {
        format!("unknown termination '{s}' (expected oracle, confident or action-limit)")
    })
}

/// The `--termination` value parser: the rules are listed with a line each in `--help` and
/// in the error for an unknown one.
pub fn termination_parser() -> impl clap::builder::TypedValueParser<Value = Termination> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new([
        PossibleValue::new("oracle")
            .help("stop on coarse success against the simulated truth (the paper's rule)"),
        PossibleValue::new("confident")
            .help("stop once the estimated risk of a wrong registration is below --stop-risk"),
        PossibleValue::new("action-limit").help("never stop early: run to --max-actions"),
    ])
    .try_map(|s| parse_termination(&s))
}

/// Parses `--min-observability τ`: a number from 0 (off) to 1, NaN refused.
pub fn parse_observability(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!(
            "'{s}' is not an observability threshold (a number from 0 = off to 1; the eigenvalue of readings split evenly between two perpendicular walls is 0.5)"
        )),
    }
}

/// Parses `--stop-risk P`: a finite probability, 0 < P <= 1 (the range the protocol's
/// `EpisodeParams::stop_risk` accepts).
pub fn parse_stop_risk(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 1.0 => Ok(v),
        _ => Err(format!(
            "'{s}' is not a stop risk (a probability P with 0 < P <= 1: the largest accepted chance that the registration is wrong, e.g. 0.01 for 1 %)"
        )),
    }
}

/// Command-line parser for `--instrument`.
pub fn parse_instrument(s: &str) -> Result<InstrumentProfile, String> {
    InstrumentProfile::from_name(s)
        .ok_or_else(|| format!("unknown instrument '{s}' (expected edm or edm+scan)"))
}

/// Command-line parser for `--agent`.
pub fn parse_agent(s: &str) -> Result<AgentKind, String> {
    AgentKind::from_name(s).ok_or_else(|| {
        let names: Vec<_> = AgentKind::ALL
            .iter()
            .chain(&[AgentKind::Learnt, AgentKind::LearntInt8])
            .chain(&AgentKind::GREEDY)
            .map(|a| a.name())
            .collect();
        format!(
            "unknown agent '{s}' (expected one of: {})",
            names.join(", ")
        )
    })
}
