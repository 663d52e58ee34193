//! `activesense mcu-bench`: the firmware's instructions per on-device event under QEMU
//! (`-icount shift=0`, the firmware's `bench` mode), K = 1 and K = 10, as the markdown tables
//! of `results/mcu-bench/` with the stack's high-water mark and whether the device's targets
//! are met (README, "Instructions per update"). Split from [`super::remote`], whose episode
//! runner it drives.

use super::options::{parse_agent, EpisodeOptions};
use super::remote::spec_for;
use activesense_core::episode::AgentKind;
use activesense_core::protocol::UpdateStats;
use activesense_instrument::link::device::sim_episode;
use activesense_instrument::link::runner::run_one;
use activesense_instrument::link::serial::{self, LinkSpec};
use activesense_instrument::world::plans::TEST_SEEDS;
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// `activesense mcu-bench`.
#[derive(Args, Debug)]
pub struct McuBenchArgs {
    /// Firmware ELF run in qemu-system-arm.
    #[arg(long, default_value = serial::DEFAULT_ELF)]
    pub elf: PathBuf,
    /// Episodes per rotation-bin setting (plan seeds first-seed, first-seed+1, ...).
    #[arg(long, default_value_t = 10)]
    pub episodes: u32,
    /// First plan seed (default: the first test plan).
    #[arg(long, default_value_t = TEST_SEEDS.start)]
    pub first_seed: u32,
    /// Agent: blind-0..2, heuristic-0..3, learnt-int8 (the policy decision column then
    /// counts the int8 network).
    #[arg(long, value_parser = parse_agent, default_value = "heuristic-1")]
    pub agent: AgentKind,
    /// How the episodes are played (default: K = 1 and 10).
    #[command(flatten)]
    pub options: EpisodeOptions,
    /// Reply timeout in milliseconds.
    #[arg(long, default_value_t = 60_000)]
    pub timeout_ms: u64,
}

/// Instruction statistics of one kind of device work over many episodes.
#[derive(Clone, Copy, Debug, Default)]
pub struct InstrStats {
    /// Timed events.
    pub count: u64,
    /// Sum of instructions.
    pub total: u64,
    /// Largest single event.
    pub max: u64,
}

impl InstrStats {
    fn add(&mut self, s: &UpdateStats) {
        self.count += s.updates as u64;
        self.total += s.total_cycles;
        self.max = self.max.max(s.max_cycles as u64);
    }

    fn add_one(&mut self, v: u32) {
        self.count += 1;
        self.total += v as u64;
        self.max = self.max.max(v as u64);
    }

    /// Mean per event (0 without events).
    pub fn mean(&self) -> f64 {
        self.total as f64 / self.count.max(1) as f64
    }

    /// `mean / max` instructions with the 168 MHz time estimate, as a table cell.
    fn cell(&self) -> String {
        if self.count == 0 {
            return "–".into();
        }
        let us = |i: f64| i / MCU_HZ * 1e6;
        format!(
            "{:.0} / {} ({} / {} µs)",
            self.mean(),
            self.max,
            fmt_us(us(self.mean())),
            fmt_us(us(self.max as f64))
        )
    }
}

fn fmt_us(us: f64) -> String {
    if us >= 1000.0 {
        format!("{:.0}", us)
    } else {
        format!("{:.1}", us)
    }
}

/// Core clock of the target STM32F405 (Hz) for the time estimates.
pub const MCU_HZ: f64 = 168e6;

/// The firmware's per-episode instruction counts for one rotation-bin setting.
#[derive(Clone, Copy, Debug, Default)]
pub struct McuBenchRow {
    /// Rotation bins K.
    pub rot_bins: u8,
    /// Episodes run.
    pub episodes: u32,
    /// Updates after a returned measurement (GHT vote).
    pub vote: InstrStats,
    /// Updates after a rotation.
    pub rotation: InstrStats,
    /// Updates after a measurement without return.
    pub no_return: InstrStats,
    /// End-of-episode chain (coarse read-out, registration, recognition).
    pub finish: InstrStats,
    /// The policy's decisions alone (part of every update).
    pub decision: InstrStats,
    /// The device's stack high-water mark after this row's episodes (since boot: the
    /// K = 10 row's covers both).
    pub stack: activesense_core::protocol::StackUsage,
}

/// Runs `a.episodes` episodes for K = 1 and K = 10 against the firmware in QEMU with
/// `-icount shift=0` and the firmware's `bench` mode, and returns the instruction counts.
pub fn mcu_bench(a: &McuBenchArgs) -> Result<Vec<McuBenchRow>> {
    let timeout = Duration::from_millis(a.timeout_ms);
    let qemu_args: Vec<String> = ["-icount", "shift=0", "-append", "bench"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let spec = LinkSpec::Qemu(a.elf.clone());
    let mut link = serial::open_with_qemu_args(&spec, timeout, &qemu_args)
        .with_context(|| format!("starting {} in QEMU", a.elf.display()))?;
    let info = link.client.hello().context("handshake")?;
    if info.capabilities & activesense_core::protocol::CAP_CYCLE_COUNTS == 0 {
        bail!("the firmware reports no cycle counts");
    }
    let mut rows = Vec::new();
    for rot_bins in a.options.rot_bins_or(&[1, 10])? {
        let mut row = McuBenchRow {
            rot_bins,
            ..Default::default()
        };
        for i in 0..a.episodes {
            let seed = a.first_seed.wrapping_add(i);
            let spec = spec_for(seed, a.agent, rot_bins, &a.options)?;
            let mut restarts = 0;
            let run = run_one(&mut link, &|| sim_episode(&spec), false, &mut restarts)
                .with_context(|| format!("K = {rot_bins}, episode on plan {seed}"))?;
            if restarts > 0 {
                bail!("K = {rot_bins}, plan {seed}: the link lost the episode (restarted)");
            }
            let c = run.report.cycles;
            row.episodes += 1;
            row.vote.add(&c.vote);
            row.rotation.add(&c.rotation);
            row.no_return.add(&c.no_return);
            row.finish.add_one(c.finish);
            row.decision.add(&c.decision);
        }
        row.stack = link.client.status().context("status")?.stack;
        rows.push(row);
    }
    // The emulator this command started ends with it.
    let out = link.close().context("stopping the emulator")?;
    if !out.contains("core initialised") {
        bail!("unexpected firmware console output: {out}");
    }
    Ok(rows)
}

/// The markdown table of [`mcu_bench`]'s rows.
pub fn mcu_bench_table(rows: &[McuBenchRow]) -> String {
    let mut s = String::from(
        "| K | episodes | measurement update (GHT vote) | rotation update | no-return update | \
         end of episode (registration) | policy decision |\n|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} |\n",
            r.rot_bins,
            r.episodes,
            r.vote.cell(),
            r.rotation.cell(),
            r.no_return.cell(),
            r.finish.cell(),
            r.decision.cell()
        ));
    }
    s.push_str(&format!(
        "\nCells: mean / max guest instructions per event (updates counted: {}), and in \
         parentheses the time at {:.0} MHz assuming one instruction per cycle (an estimate: \
         the M4F needs more than one cycle for loads, branches, divisions and libm calls).\n",
        rows.iter()
            .map(|r| format!(
                "K={}: {} votes, {} rotations, {} no-returns",
                r.rot_bins, r.vote.count, r.rotation.count, r.no_return.count
            ))
            .collect::<Vec<_>>()
            .join("; "),
        MCU_HZ / 1e6
    ));
    if let Some(st) = rows.last().map(|r| r.stack).filter(|st| st.size > 0) {
        s.push_str(&format!(
            "\nStack: high-water mark {} bytes of the {} between the statics and the top of RAM \
             ({} bytes never touched), over all these episodes (the firmware's painted stack, \
             reported in `Status`).\n",
            st.high_water,
            st.size,
            st.size - st.high_water.min(st.size)
        ));
    }
    s
}

/// Issue 22's targets for every on-device event (measurement update with whatever the stop
/// needs, rotation, no-return, end of episode): mean and worst guest instructions.
pub const EVENT_TARGET_MEAN: f64 = 8e6;
/// See [`EVENT_TARGET_MEAN`].
pub const EVENT_TARGET_MAX: u64 = 40_000_000;

/// One line: whether every event of every row meets [`EVENT_TARGET_MEAN`] and
/// [`EVENT_TARGET_MAX`], naming the events that do not.
pub fn mcu_bench_targets(rows: &[McuBenchRow]) -> String {
    let mut missed = Vec::new();
    for r in rows {
        for (name, st) in [
            ("measurement update", &r.vote),
            ("rotation update", &r.rotation),
            ("no-return update", &r.no_return),
            ("end of episode", &r.finish),
        ] {
            if st.count > 0 && (st.mean() > EVENT_TARGET_MEAN || st.max > EVENT_TARGET_MAX) {
                missed.push(format!(
                    "K={} {name} {:.1} M / {:.1} M",
                    r.rot_bins,
                    st.mean() / 1e6,
                    st.max as f64 / 1e6
                ));
            }
        }
    }
    let target = format!(
        "every event mean ≤ {:.0} M and worst ≤ {:.0} M instructions (the device's budget)",
        EVENT_TARGET_MEAN / 1e6,
        EVENT_TARGET_MAX as f64 / 1e6
    );
    if missed.is_empty() {
        format!("Targets met: {target}.\n")
    } else {
        format!(
            "Targets NOT met: {target}; missed: {}.\n",
            missed.join(", ")
        )
    }
}

/// `activesense mcu-bench`.
pub fn cmd_mcu_bench(a: McuBenchArgs) -> Result<()> {
    let t0 = Instant::now();
    let rows = mcu_bench(&a)?;
    println!(
        "firmware {} under qemu-system-arm -M netduinoplus2 -icount shift=0 (1 TIM2 tick = 1 \
         guest instruction), agent {:?}{}, termination {:?}, plan seeds {}..{}, episode seed {}\n",
        a.elf.display(),
        a.agent,
        match a.options.instrument.instrument {
            activesense_core::episode::InstrumentProfile::EdmScan => String::new(),
            other => format!(" (instrument {})", other.name()),
        },
        a.options.termination,
        a.first_seed,
        a.first_seed.wrapping_add(a.episodes),
        a.options.episode_seed
    );
    print!("{}", mcu_bench_table(&rows));
    print!("\n{}", mcu_bench_targets(&rows));
    eprintln!("mcu-bench: {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}
