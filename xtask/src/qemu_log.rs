//! `cargo xtask qemu-log`: the firmware's defmt log, decoded on the host.
//!
//! The firmware (feature `log-semihosting`, the default) writes defmt frames to
//! semihosting stderr, which QEMU passes to its own stderr; its plain-text console lines
//! stay on stdout. This task
//! 1. boots the firmware in `smoke` mode, capturing stdout and stderr separately, and
//! 2. serves one short session (`activesense sim --link qemu:ELF --episodes 1
//!    --defmt-out FILE`: hello, plan, one K = 1 episode, shutdown),
//!
//! and decodes both defmt streams with `defmt-decoder` against the ELF's `.defmt` table,
//! printing one readable line per log frame.

use crate::{activesense_cli, build_firmware, root, run, setup, smoke_boot};
use anyhow::{bail, Context, Result};
use defmt_decoder::{DecodeError, Table};
use std::path::Path;

/// Decodes a defmt byte stream; returns the readable lines.
pub fn decode(elf: &Path, bytes: &[u8]) -> Result<Vec<String>> {
    let elf_bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let table = Table::parse(&elf_bytes)
        .context("parsing the ELF's defmt table")?
        .context("the ELF has no .defmt section (was it linked with -Tdefmt.x?)")?;
    let mut decoder = table.new_stream_decoder();
    decoder.received(bytes);
    let mut lines = Vec::new();
    loop {
        match decoder.decode() {
            Ok(frame) => lines.push(frame.display(false).to_string()),
            Err(DecodeError::UnexpectedEof) => break,
            Err(DecodeError::Malformed) => {
                if table.encoding().can_recover() {
                    lines.push("(malformed frame skipped)".into());
                } else {
                    bail!("malformed defmt frame");
                }
            }
        }
    }
    Ok(lines)
}

fn print_decoded(title: &str, elf: &Path, bytes: &[u8]) -> Result<usize> {
    let lines = decode(elf, bytes)?;
    println!(
        "== {title}: {} defmt frames ({} bytes)",
        lines.len(),
        bytes.len()
    );
    for l in &lines {
        println!("{l}");
    }
    Ok(lines.len())
}

/// `cargo xtask qemu-log`.
pub fn run_task() -> Result<()> {
    setup()?;
    let elf = build_firmware()?;

    // 1. Smoke boot.
    let out = smoke_boot(&elf)?;
    if !out.status.success() {
        bail!("firmware exited with {}", out.status);
    }
    println!("== smoke boot: console (semihosting stdout)");
    print!("{}", String::from_utf8_lossy(&out.stdout));
    let n_smoke = print_decoded("smoke boot", &elf, &out.stderr)?;

    // 2. One short session through the host simulator.
    let log = root().join("target").join("qemu-log-session.defmt");
    run(activesense_cli()
        .args(["sim", "--episodes", "1", "--rot-bins", "1", "--link"])
        .arg(format!("qemu:{}", elf.display()))
        .arg("--defmt-out")
        .arg(&log))?;
    let bytes = std::fs::read(&log).with_context(|| format!("reading {}", log.display()))?;
    let n_session = print_decoded("session", &elf, &bytes)?;
    if n_smoke == 0 || n_session == 0 {
        bail!("no defmt frames decoded");
    }
    Ok(())
}
