//! `activesense` — the command-line front end of the simulator, evaluation harness and
//! instrument driver. Run `activesense --help` for the list of commands. This file is the
//! clap tree only (commands, their help text, the dispatch); every command's body and its
//! options live in [`activesense::commands`].

use activesense::commands::{self as cli, command_line};
use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Register a known floor-plan against a room with as few EDM measurements as possible.
///
/// activesense is the reference implementation of "Learning Effective Sparse Sampling
/// Strategies using Deep Active Sensing". This tool generates floor-plans, runs simulated
/// sampling episodes, evaluates agents and drives a real or emulated instrument.
#[derive(Parser)]
#[command(name = "activesense", version, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate one floor-plan from its seed and draw it (outline, visual centre, agent disc, agent).
    Plan(cli::plan::PlanArgs),
    /// Run one simulated episode with a baseline or the learnt agent and print its step log.
    Episode(cli::episode::EpisodeArgs),
    /// Train the learnt sampling policy (advantage actor-critic with GAE, paper §3.1) on
    /// generated training plans; writes the policy file, its learning curve and logs.
    Train(cli::train::TrainArgs),
    /// Run episodes on the instrument controller (QEMU, serial, TCP or loopback) while the host plays its sensors.
    Sim(cli::remote::SimArgs),
    /// Set up a Leica total station in the plan's frame over GeoCOM: drive it with the core
    /// decision chain (policy, localizer, calibrated stop), print the answer and, with
    /// --set-station, write the station and orientation to it (docs/GEOCOM.md).
    Station(cli::station::StationArgs),
    /// A GeoCOM instrument simulator playing a plan's room over TCP or a pty, with faults
    /// injected on request (docs/GEOCOM.md).
    GeocomSim(cli::station::GeocomSimArgs),
    /// Talk to an instrument controller on a serial port.
    Serial(cli::remote::SerialArgs),
    /// Count the firmware's instructions per update and per registration under QEMU
    /// (-icount shift=0); prints a markdown table (see `cargo xtask mcu-bench`).
    McuBench(cli::mcu_bench::McuBenchArgs),
    /// Summarise a seed range of generated plans (shapes, vertex counts, extents) as a table.
    Dataset(cli::dataset::DatasetArgs),
    /// Evaluate agents on the test plans (the paper's Table 4): writes results.json,
    /// results.md, timing.json, budget.svg and the utility-vs-cost curves utility-k{K}.svg
    /// into --out (or, with --extra-measurements, the pose error past the minimal set).
    Eval(cli::eval::EvalArgs),
    /// Measure sparse-registration accuracy from coarse poses on the test plans.
    BenchRegistration(cli::bench_registration::BenchRegistrationArgs),
    /// Benchmark the GHT localizer against the classical grid localizer (cost, memory, recognition).
    BenchLocalization(cli::bench_localization::BenchLocalizationArgs),
    /// The int8 policy for the instrument: quantise a float policy into a blob
    /// (docs/policy-blob.md), measure how often it acts as the float one, upload it to an
    /// instrument, or ask an instrument which policy it runs.
    #[command(subcommand)]
    Policy(PolicyCommand),
    /// The inspection tool (paper §3.5): a self-contained web page to step through a
    /// learnt-agent trajectory (episode --agent learnt --json FILE) with a guided
    /// back-propagation overlay, or (--aggregate) the Fig.-4 analysis over many episodes.
    Inspect(cli::inspect::InspectArgs),
    /// How honest the answer's printed precision is (how often the truth lies within 2σ)
    /// and how often answers are ambiguous, over simulated episodes on generated plans or
    /// your rooms (--plans-from).
    AnswerCoverage(cli::answer_coverage::AnswerCoverageArgs),
    /// Fit the calibrated stop (--termination confident, --stop-risk): run episodes on
    /// calibration plans, fit P(wrong registration) from the belief and the readings, and
    /// write the models the core compiles (core-nostd/src/stop/calibration.rs) with a
    /// held-out check (results/calibration/).
    Calibrate(cli::calibrate::CalibrateArgs),
}

#[derive(Subcommand)]
enum PolicyCommand {
    /// Post-training int8 quantisation of a float policy file, calibrated on greedy episodes
    /// on training plans; writes the blob the firmware runs.
    Quantize(cli::policy::QuantizeArgs),
    /// Float vs int8 on the test plans: argmax agreement per state and whole-episode
    /// outcomes of each; prints a table, writes JSON.
    Agreement(cli::policy::AgreementArgs),
    /// Upload an int8 policy into the instrument's RAM slot, replacing the one serving its
    /// K without reflashing (a corrupt or mismatched blob is refused; the old one serves on).
    Upload(cli::policy::PolicyUploadArgs),
    /// Show which policy serves K = 1 and K = 10 on the instrument (built-in or uploaded).
    Info(cli::policy::PolicyInfoArgs),
}

/// True for a panic of `println!` whose reader went away (`activesense episode | head -1`).
fn is_broken_pipe(info: &std::panic::PanicHookInfo<'_>) -> bool {
    let msg = info
        .payload()
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| info.payload().downcast_ref::<&str>().copied())
        .unwrap_or("");
    msg.starts_with("failed printing to stdout") && msg.contains("Broken pipe")
}

fn main() -> ExitCode {
    // A closed stdout is the reader saying it has seen enough (`| head`): stop quietly
    // with status 0, as the classic Unix filters do, instead of a panic (status 101).
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if is_broken_pipe(info) {
            std::process::exit(0);
        }
        default_hook(info)
    }));
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Plan(a) => cli::plan::run(a),
        Command::Episode(a) => cli::episode::run(a),
        Command::Train(a) => cli::train::run(a),
        Command::Dataset(a) => cli::dataset::run(a),
        Command::Eval(a) => cli::eval::run(a),
        Command::AnswerCoverage(a) => cli::answer_coverage::run(a),
        Command::Calibrate(a) => cli::calibrate::cmd_calibrate(a),
        Command::BenchRegistration(a) => cli::bench_registration::run(a),
        Command::BenchLocalization(a) => cli::bench_localization::run(a),
        Command::Station(a) => cli::station::run(a),
        Command::GeocomSim(a) => cli::station::run_sim(a),
        Command::Sim(a) => cli::remote::cmd_sim(a),
        Command::Serial(a) => cli::remote::cmd_serial(a),
        Command::McuBench(a) => cli::mcu_bench::cmd_mcu_bench(a),
        Command::Policy(PolicyCommand::Quantize(a)) => cli::policy::quantize(a),
        Command::Policy(PolicyCommand::Agreement(a)) => cli::policy::agreement(a),
        Command::Policy(PolicyCommand::Upload(a)) => cli::policy::upload(a),
        Command::Policy(PolicyCommand::Info(a)) => cli::policy::info(a),
        Command::Inspect(a) => cli::inspect::cmd_inspect(a, &command_line()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // A command that writes with `writeln!` sees the closed pipe as an error: the same.
        Err(e)
            if e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>()
                    .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            }) =>
        {
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
