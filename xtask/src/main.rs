//! `cargo xtask` — project automation in Rust instead of shell scripts (the
//! rust-embedded / RTIC way): installing the tools CI needs, building the firmware,
//! booting it under QEMU, and running the whole test suite.
//!
//! ```text
//! cargo xtask ci           # the whole test suite, installing what it needs (what .ci/run calls)
//! cargo xtask setup        # only the installs: thumbv7em-none-eabihf target, qemu-system-arm, chromium
//! cargo xtask firmware     # build the firmware ELF (profile `firmware`)
//! cargo xtask qemu-smoke   # boot the firmware in qemu-system-arm -M netduinoplus2, expect exit 0
//! cargo xtask flash [--no-run] # build the board firmware (features board + log-rtt) and run it on an STM32F405 with probe-rs
//! cargo xtask mcu-bench [--episodes N] [--agent NAME] [--termination T] [--instrument P]  # instructions per update / decision / registration (QEMU -icount)
//! cargo xtask qemu-log     # the firmware's defmt log (smoke boot + one session), decoded
//! cargo xtask soak [--episodes N]  # N episodes in one QEMU session, each bit-identical to the host
//! cargo xtask reproduce [--list] [--only A,B] [--skip A,B] [--resume] [--check]  # every committed artifact
//! ```

mod fuzz;
// The emulator's command line, shared with the host's `qemu` link (why by path: see the file).
#[path = "../../instrument/src/link/qemu_cmd.rs"]
#[allow(dead_code)] // xtask boots with USART1 on null only
mod qemu_cmd;
mod qemu_log;
mod reproduce;
mod size;

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const TARGET: &str = "thumbv7em-none-eabihf";
const FIRMWARE_PROFILE: &str = "firmware";
const FIRMWARE_BIN: &str = "activesense-firmware";
/// The line the firmware prints over semihosting once the core has initialised.
const SMOKE_LINE: &str = "core initialised";

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("ci") => ci(),
        Some("setup") => setup(),
        Some("firmware") => build_firmware().map(|p| println!("{}", p.display())),
        Some("flash") => flash(&args[1..]),
        Some("qemu-smoke") => qemu_smoke(),
        Some("size") => build_firmware().and_then(|elf| size::report(&elf)),
        Some("fuzz") => fuzz::run(&args[1..]),
        Some("mcu-bench") => mcu_bench(&args[1..]),
        Some("qemu-log") => qemu_log::run_task(),
        Some("soak") => soak(&args[1..]),
        Some("reproduce") => reproduce::run(&args[1..]),
        Some("help") | Some("--help") | Some("-h") | None => {
            print_help();
            Ok(())
        }
        Some(other) => {
            print_help();
            Err(anyhow::anyhow!("unknown xtask '{other}'"))
        }
    };
    if let Err(e) = result {
        eprintln!("xtask error: {e:#}");
        std::process::exit(1);
    }
}

fn print_help() {
    println!(
        "cargo xtask <task>\n\n\
         tasks:\n  \
         ci          whole test suite (installs the thumb target, qemu-system-arm and chromium if missing)\n  \
         setup       install the thumbv7em-none-eabihf target, qemu-system-arm and chromium if missing\n  \
         firmware    build the firmware ELF and print its path\n  \
         qemu-smoke  boot the firmware under qemu-system-arm -M netduinoplus2 and check its boot line\n  \
         flash [--no-run]\n              \
         build the board firmware (Olimex STM32-H405: features board + log-rtt) and flash and\n              \
         run it with `probe-rs run --chip STM32F405RGTx` (defmt over RTT); --no-run only builds\n  \
         qemu-log    decode the firmware's defmt log (smoke boot and one short session)\n  \
         soak [--episodes N]\n              \
         N consecutive episodes (default 500) in one QEMU session of the firmware, both K,\n              \
         heuristic-1 and learnt-int8, oracle and confident stop, each bit-identical to the host\n  \
         size        firmware flash / static RAM against the budgets (512 KiB / 96 KiB)\n  \
         fuzz [SECS] run the cargo-fuzz targets `session` and `policy_blob` for SECS seconds each (default 60)\n  \
         mcu-bench [--episodes N] [--agent NAME] [--termination T]\n              \
         instructions per GHT update, rotation and registration on the Cortex-M4 under\n              \
         QEMU -icount shift=0, K = 1 and K = 10, N episodes each (default 20)\n  \
         reproduce [--list] [--only A,B] [--skip A,B] [--resume] [--check]\n              \
         regenerate every committed artifact in dependency order (policies, blobs, results,\n              \
         calibration, inspection, MCU tables, sizes), each directory with a manifest.json;\n              \
         --check regenerates the cheap ones into target/ and compares them byte for byte"
    );
}

/// The workspace root (xtask lives one level below it).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn cargo() -> Command {
    let mut c = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.current_dir(root());
    c
}

/// `cargo run --quiet -p activesense --bin activesense --`: the host CLI, for tasks that
/// drive the firmware through it.
pub fn activesense_cli() -> Command {
    let mut c = cargo();
    c.args([
        "run",
        "--quiet",
        "-p",
        "activesense",
        "--bin",
        "activesense",
        "--",
    ]);
    c
}

fn run(cmd: &mut Command) -> Result<()> {
    eprintln!("xtask: running {cmd:?}");
    let status = cmd
        .status()
        .with_context(|| format!("cannot start {cmd:?}"))?;
    if !status.success() {
        bail!("{cmd:?} failed with {status}");
    }
    Ok(())
}

fn have(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .stdout(Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}

/// Installs the thumbv7em-none-eabihf target if rustup lacks it.
fn setup_target() -> Result<()> {
    let installed = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .output()
        .context("rustup is required")?;
    if !String::from_utf8_lossy(&installed.stdout)
        .lines()
        .any(|l| l.trim() == TARGET)
    {
        run(Command::new("rustup").args(["target", "add", TARGET]))?;
    }
    Ok(())
}

/// Installs what a fresh machine lacks. Idempotent and quiet when all is present.
fn setup() -> Result<()> {
    setup_target()?;
    // qemu-system-arm runs the firmware; chromium runs the inspection page's browser test
    // (cli/tests/inspect_browser.rs). Both from the distribution's packages.
    let missing: Vec<&str> = [
        ("qemu-system-arm", "qemu-system-arm"),
        ("chromium", "chromium"),
    ]
    .into_iter()
    .filter(|(program, _)| !have(program))
    .map(|(_, package)| package)
    .collect();
    if !missing.is_empty() {
        let sudo = if Command::new("id")
            .arg("-u")
            .output()
            .map(|o| o.stdout != b"0\n")
            .unwrap_or(true)
        {
            "sudo "
        } else {
            ""
        };
        // The installer's chatter goes to stderr: a step whose stdout is its artifact
        // (`mcu-bench > results/mcu-bench/….md`) once got apt's lines in its table.
        run(Command::new("sh").args([
            "-c",
            &format!(
                "({sudo}apt-get update -qq && DEBIAN_FRONTEND=noninteractive {sudo}apt-get install -y -qq {}) 1>&2",
                missing.join(" ")
            ),
        ]))?;
    }
    Ok(())
}

/// Cargo's target directory: `CARGO_TARGET_DIR` if set, else `target/` of the workspace.
fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(|d| root().join(d))
        .unwrap_or_else(|| root().join("target"))
}

/// The chip probe-rs flashes (the Olimex STM32-H405's STM32F405RGT6).
const PROBE_CHIP: &str = "STM32F405RGTx";

/// The board build: `cargo build -p activesense-firmware --release --target
/// thumbv7em-none-eabihf --features board` (feature `board` brings `log-rtt`, and takes
/// precedence over the default `qemu`). Returns the ELF path.
fn build_board_firmware() -> Result<PathBuf> {
    run(cargo().args(BOARD_BUILD))?;
    let elf = target_dir().join(TARGET).join("release").join(FIRMWARE_BIN);
    if !elf.exists() {
        bail!("board firmware ELF not found at {}", elf.display());
    }
    Ok(elf)
}

/// `cargo build` arguments of the board firmware (also a CI step).
const BOARD_BUILD: [&str; 8] = [
    "build",
    "-p",
    "activesense-firmware",
    "--release",
    "--target",
    TARGET,
    "--features",
    "board",
];

/// `cargo xtask flash [--no-run]`: builds the board firmware and runs `probe-rs run --chip
/// STM32F405RGTx <elf>`, which flashes it over SWD, resets the chip and prints its defmt
/// log (RTT) until Ctrl-C. docs/firmware.md, "Bring-up", has the steps before this.
fn flash(args: &[String]) -> Result<()> {
    let mut no_run = false;
    for a in args {
        match a.as_str() {
            "--no-run" => no_run = true,
            other => bail!("flash: unknown argument '{other}'"),
        }
    }
    setup_target()?;
    let elf = build_board_firmware()?;
    println!("flash: board firmware {}", elf.display());
    if no_run {
        return Ok(());
    }
    if !have("probe-rs") {
        bail!(
            "probe-rs is not installed (it flashes the board over SWD and prints the defmt log).\n\
             Install it with `cargo install probe-rs-tools --locked` (or see https://probe.rs),\n\
             connect the debug probe to the board's SWD pins, then run `cargo xtask flash` again.\n\
             The ELF is built: {}",
            elf.display()
        );
    }
    run(Command::new("probe-rs")
        .args(["run", "--chip", PROBE_CHIP])
        .arg(&elf))
}

/// Builds the firmware and returns the ELF path.
fn build_firmware() -> Result<PathBuf> {
    run(cargo().args([
        "build",
        "-p",
        "activesense-firmware",
        "--target",
        TARGET,
        "--profile",
        FIRMWARE_PROFILE,
    ]))?;
    let elf = target_dir()
        .join(TARGET)
        .join(FIRMWARE_PROFILE)
        .join(FIRMWARE_BIN);
    if !elf.exists() {
        bail!("firmware ELF not found at {}", elf.display());
    }
    Ok(elf)
}

/// Boots `elf` under QEMU in smoke mode (the firmware exits after its boot line instead of
/// serving USART1) and waits, bounded, for it to exit. Returns its captured output: stdout is
/// the plain console, stderr the binary defmt frames (and QEMU's own diagnostics).
pub fn smoke_boot(elf: &Path) -> Result<std::process::Output> {
    let mut cmd = qemu_cmd::qemu_command("qemu-system-arm", elf, qemu_cmd::QemuSerial::Null);
    cmd.args(["-append", "smoke"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    eprintln!("xtask: running {cmd:?}");
    let mut child = cmd.spawn().context("cannot start qemu-system-arm")?;
    let started = Instant::now();
    // The smoke boot writes a few hundred bytes: the pipes cannot fill up meanwhile.
    while child.try_wait()?.is_none() {
        if started.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            bail!("firmware did not exit within 60 s under QEMU");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(child.wait_with_output()?)
}

/// Boots the firmware, waits (bounded) for it to exit, and checks the boot line and status.
fn qemu_smoke() -> Result<()> {
    setup()?;
    let elf = build_firmware()?;
    let started = Instant::now();
    let out = smoke_boot(&elf)?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    print!("{stdout}");
    match qemu_log::decode(&elf, &out.stderr) {
        Ok(lines) => lines.iter().for_each(|l| println!("defmt: {l}")),
        Err(_) => eprint!("{}", String::from_utf8_lossy(&out.stderr)),
    }
    if !out.status.success() {
        bail!("firmware exited with {}", out.status);
    }
    if !stdout.contains(SMOKE_LINE) {
        bail!("firmware did not print '{SMOKE_LINE}'");
    }
    println!("qemu-smoke: ok ({:.1} s)", started.elapsed().as_secs_f32());
    Ok(())
}

/// `cargo xtask mcu-bench [--episodes N] [--agent NAME] [--termination T]`: builds the firmware and runs N simulated
/// episodes per rotation-bin setting against it under `qemu-system-arm -icount shift=0`
/// (`activesense mcu-bench`, which prints the markdown table). Deterministic: the same
/// command gives the same numbers.
fn mcu_bench(args: &[String]) -> Result<()> {
    let mut episodes = 20u32;
    let mut agent = "heuristic-1".to_string();
    let mut termination = "oracle".to_string();
    let mut instrument = "edm+scan".to_string();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--instrument" => {
                instrument = it
                    .next()
                    .context("--instrument needs edm or edm+scan")?
                    .clone()
            }
            "--episodes" => {
                episodes = it
                    .next()
                    .context("--episodes needs a number")?
                    .parse()
                    .context("--episodes needs a number")?
            }
            "--agent" => agent = it.next().context("--agent needs a name")?.clone(),
            "--termination" => {
                termination = it
                    .next()
                    .context("--termination needs oracle, confident or action-limit")?
                    .clone()
            }
            other => bail!("mcu-bench: unknown argument '{other}'"),
        }
    }
    setup()?;
    let elf = build_firmware()?;
    // Relative to the workspace (the CLI runs there), so the table's header line is the same
    // on every checkout (`results/mcu-bench/`).
    let elf = elf
        .strip_prefix(root())
        .map(Path::to_path_buf)
        .unwrap_or(elf);
    run(activesense_cli()
        .args([
            "mcu-bench",
            "--episodes",
            &episodes.to_string(),
            "--agent",
            &agent,
            "--termination",
            &termination,
            "--instrument",
            &instrument,
            "--elf",
        ])
        .arg(&elf))
}

/// `cargo xtask soak [--episodes N]`: the soak test (`tests/tests/soak.rs`) with N episodes
/// (default 500) in one QEMU session; CI runs its 8-episode default.
fn soak(args: &[String]) -> Result<()> {
    let mut episodes = 500u32;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--episodes" => {
                episodes = it
                    .next()
                    .context("--episodes needs a number")?
                    .parse()
                    .context("--episodes needs a number")?
            }
            other => bail!("soak: unknown argument '{other}'"),
        }
    }
    setup()?;
    let started = Instant::now();
    run(cargo()
        .args([
            "test",
            "-p",
            "activesense-tests",
            "--test",
            "soak",
            "--",
            "--nocapture",
        ])
        .env("ACTIVESENSE_SOAK_EPISODES", episodes.to_string()))?;
    println!(
        "soak: {episodes} episodes ok ({:.0} s)",
        started.elapsed().as_secs_f32()
    );
    Ok(())
}

/// The whole test suite: installs, formatting, the MCU build of the core, the firmware under
/// QEMU, and every host test (the integration tests include the QEMU hardware-in-the-loop
/// run, which uses the firmware built here).
fn ci() -> Result<()> {
    let t0 = Instant::now();
    // One full build per run: incremental caches would only cost disk (1.8 GB on a fresh
    // clone), and CI machines have run out of it.
    std::env::set_var("CARGO_INCREMENTAL", "0");
    setup()?;
    run(cargo().args(["fmt", "--all", "--check"]))?;
    run(cargo().args([
        "clippy",
        "--workspace",
        "--exclude",
        "activesense-firmware",
        "--all-targets",
        "--",
        "-D",
        "warnings",
    ]))?;
    run(cargo().args([
        "clippy",
        "-p",
        "activesense-firmware",
        "--target",
        TARGET,
        "--",
        "-D",
        "warnings",
    ]))?;
    // The hardware variant (defmt over RTT) must keep compiling too.
    run(cargo().args([
        "clippy",
        "-p",
        "activesense-firmware",
        "--target",
        TARGET,
        "--no-default-features",
        "--features",
        "log-rtt",
        "--",
        "-D",
        "warnings",
    ]))?;
    // The board build (Olimex STM32-H405: HSE + PLL, the instrument on USART2 and PB0/PB1,
    // defmt over RTT) must keep compiling and linking, and stay lint-free.
    run(cargo().args([
        "clippy",
        "-p",
        "activesense-firmware",
        "--target",
        TARGET,
        "--features",
        "board",
        "--",
        "-D",
        "warnings",
    ]))?;
    build_board_firmware()?;
    run(cargo().args(["build", "-p", "activesense-core", "--target", TARGET]))?;
    qemu_smoke()?;
    // The inspection page's browser test must run here, not skip (setup installed chromium).
    let (passed, failed, ignored) = test_counted(
        cargo()
            .args(["test", "--workspace", "--exclude", "activesense-firmware"])
            .env("ACTIVESENSE_REQUIRE_BROWSER", "1"),
    )?;
    // The defmt log decodes on the host (smoke boot and one session).
    qemu_log::run_task()?;
    // Every cheap committed artifact still comes out of the code: the int8 blobs, the first
    // plans of every committed evaluation, the size table and the first updates of every
    // committed learning curve (the seeds behind the policies and all six ablations).
    reproduce::run(&["--check".into()])?;
    println!("xtask ci: all green in {:.0} s", t0.elapsed().as_secs_f32());
    // The plain closing line CI readers look for.
    println!("ci: {passed} passed, {failed} failed, {ignored} skipped");
    Ok(())
}

/// Runs a `cargo test` command, echoing its output, and totals the "test result" lines.
fn test_counted(cmd: &mut Command) -> Result<(u64, u64, u64)> {
    use std::io::{BufRead, BufReader};
    eprintln!("xtask: running {cmd:?}");
    let mut child = cmd
        .stdout(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot start {cmd:?}"))?;
    let (mut passed, mut failed, mut ignored) = (0, 0, 0);
    let stdout = child.stdout.take().context("no stdout")?;
    for line in BufReader::new(stdout).lines() {
        let line = line?;
        println!("{line}");
        if let Some(rest) = line.strip_prefix("test result: ") {
            for part in rest.split([';', '.']) {
                let mut it = part.split_whitespace();
                if let (Some(n), Some(what)) = (it.next(), it.next()) {
                    let n: u64 = n.parse().unwrap_or(0);
                    match what {
                        "passed" => passed += n,
                        "failed" => failed += n,
                        "ignored" => ignored += n,
                        _ => {}
                    }
                }
            }
        }
    }
    let status = child.wait()?;
    if !status.success() {
        println!("ci: {passed} passed, {failed} failed, {ignored} skipped");
        bail!("{cmd:?} failed with {status}");
    }
    if passed == 0 {
        bail!("cargo test ran no test");
    }
    Ok((passed, failed, ignored))
}

/// The board's clock plan (`firmware/src/clock_plan.rs`, the same file the firmware
/// builds) against RM0090, the STM32F405 reference manual.
#[cfg(test)]
#[path = "../../firmware/src/clock_plan.rs"]
mod clock_plan;

#[cfg(test)]
mod clock_plan_tests {
    use super::clock_plan::*;

    /// RM0090 §6.3.2's limits on the main PLL, and the two outputs exactly.
    fn check_rm0090(hse: u32, p: Pll) {
        assert!((2..=63).contains(&p.m), "M {p:?}");
        assert!((50..=432).contains(&p.n), "N {p:?}");
        assert!([2, 4, 6, 8].contains(&p.p), "P {p:?}");
        assert!((2..=15).contains(&p.q), "Q {p:?}");
        assert!(
            (1_000_000..=2_000_000).contains(&p.vco_in(hse)),
            "VCO in {p:?}"
        );
        assert!(
            (100_000_000..=432_000_000).contains(&p.vco_out(hse)),
            "VCO out {p:?}"
        );
        // f(VCO clock) = f(PLL clock input) × (PLLN / PLLM); f(PLL general clock output) =
        // f(VCO clock) / PLLP; f(USB OTG FS, SDIO, RNG clock output) = f(VCO clock) / PLLQ.
        assert_eq!(
            hse as u64 * p.n as u64 / p.m as u64 / p.p as u64,
            168_000_000
        );
        assert_eq!(
            hse as u64 * p.n as u64 / p.m as u64 / p.q as u64,
            48_000_000
        );
    }

    #[test]
    fn pll_for_an_8_mhz_crystal() {
        // The Olimex STM32-H405: VCO in 2 MHz (RM0090's recommendation), VCO 336 MHz.
        let p = pll(8_000_000, 168_000_000);
        assert_eq!(
            p,
            Pll {
                m: 4,
                n: 168,
                p: 2,
                q: 7
            }
        );
        check_rm0090(8_000_000, p);
        assert_eq!(BOARD_HSE_HZ, 8_000_000);
        assert_eq!(BOARD_PLL, p);
    }

    #[test]
    fn pll_for_a_12_mhz_crystal() {
        // E.g. the Adafruit Feather STM32F405's crystal.
        let p = pll(12_000_000, 168_000_000);
        assert_eq!(
            p,
            Pll {
                m: 6,
                n: 168,
                p: 2,
                q: 7
            }
        );
        check_rm0090(12_000_000, p);
    }

    #[test]
    fn pll_for_other_crystals_meets_rm0090() {
        for mhz in [4, 16, 24, 25] {
            check_rm0090(mhz * 1_000_000, pll(mhz * 1_000_000, 168_000_000));
        }
        // 25 MHz divides to 2 MHz no better than 48 MHz does: M = 25, VCO in 1 MHz.
        assert_eq!(
            pll(25_000_000, 168_000_000),
            Pll {
                m: 25,
                n: 336,
                p: 2,
                q: 7
            }
        );
        // A PLL that misses the outputs is caught by the checks above.
        let r = std::panic::catch_unwind(|| {
            check_rm0090(
                8_000_000,
                Pll {
                    m: 4,
                    n: 168,
                    p: 2,
                    q: 8,
                },
            )
        });
        assert!(r.is_err());
    }

    #[test]
    fn usart1_divisor_matches_rm0090() {
        // RM0090's baud-rate table at f(PCLK) = 84 MHz, oversampling by 16: 115.2 KBps
        // is programmed as USARTDIV 45.5625 (error 0.02 %): mantissa 45 = 0x2D, fraction
        // 0.5625 × 16 = 9, so USART_BRR = 0x2D9.
        assert_eq!(PCLK2_HZ, 84_000_000);
        assert_eq!(HOST_BAUD, 115_200);
        assert_eq!(HOST_BRR, 0x2D9);
        assert_eq!(HOST_BRR >> 4, 45);
        assert_eq!(HOST_BRR & 0xF, 9);
        // Tx/Rx baud = f(PCK) / (8 × (2 − OVER8) × USARTDIV), OVER8 = 0.
        let baud = PCLK2_HZ as f64 / (16.0 * (HOST_BRR as f64 / 16.0));
        assert!((baud / 115_200.0 - 1.0).abs() < 0.0003, "{baud}");
        assert_eq!(baud_of(PCLK2_HZ, HOST_BRR), 115_226); // +0.02 %, as RM0090 lists
                                                          // The same rate from the reset clock (HSI 16 MHz, the emulated build): 8.6875.
        assert_eq!(brr_over16(16_000_000, 115_200), 0x8B);
    }

    #[test]
    fn usart2_divisor_is_within_tolerance() {
        assert_eq!(PCLK1_HZ, 42_000_000);
        // 42 MHz / (16 × 19200) = 136.72: BRR 2188 = 0x88C (USARTDIV 136.75).
        assert_eq!(EDM_BRR, brr_over16(42_000_000, EDM_BAUD));
        let err = (PCLK1_HZ as f64 / EDM_BRR as f64) / EDM_BAUD as f64 - 1.0;
        assert!(err.abs() < 0.001, "{err}");
    }
}
