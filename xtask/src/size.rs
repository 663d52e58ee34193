//! `cargo xtask size`: flash and static RAM of the firmware ELF, checked against the
//! budgets (flash ≤ 512 KiB, static RAM ≤ 96 KiB). Reads the ELF32 section headers
//! directly (no binutils needed): flash = allocated sections placed in FLASH plus the
//! load image of initialised RAM data; static RAM = allocated sections placed in RAM
//! (`.data`, `.bss`, `.uninit`; the stack is the remainder and is not counted).

use anyhow::{bail, Context, Result};
use std::path::Path;

/// Flash budget (bytes).
pub const FLASH_BUDGET: u64 = 512 * 1024;
/// Static RAM budget (bytes).
pub const RAM_BUDGET: u64 = 96 * 1024;
const FLASH: std::ops::Range<u64> = 0x0800_0000..0x0810_0000;
const RAM: std::ops::Range<u64> = 0x2000_0000..0x2002_0000;
const SHF_ALLOC: u32 = 0x2;
const SHT_NOBITS: u32 = 8;

/// Per-section and total sizes.
pub struct Sizes {
    /// (name, address, size, in_flash, in_ram, nobits)
    pub sections: Vec<(String, u64, u64, bool, bool)>,
    /// Flash bytes.
    pub flash: u64,
    /// Static RAM bytes.
    pub ram: u64,
}

fn u16_at(b: &[u8], o: usize) -> Result<u16> {
    Ok(u16::from_le_bytes(
        b.get(o..o + 2).context("truncated ELF")?.try_into()?,
    ))
}
fn u32_at(b: &[u8], o: usize) -> Result<u32> {
    Ok(u32::from_le_bytes(
        b.get(o..o + 4).context("truncated ELF")?.try_into()?,
    ))
}

/// Measures an ELF32 little-endian file.
pub fn measure(elf: &Path) -> Result<Sizes> {
    let b = std::fs::read(elf).with_context(|| format!("cannot read {}", elf.display()))?;
    if b.get(0..4) != Some(b"\x7fELF") || b.get(4) != Some(&1) || b.get(5) != Some(&1) {
        bail!("{} is not a little-endian ELF32 file", elf.display());
    }
    let shoff = u32_at(&b, 0x20)? as usize;
    let shentsize = u16_at(&b, 0x2E)? as usize;
    let shnum = u16_at(&b, 0x30)? as usize;
    let shstrndx = u16_at(&b, 0x32)? as usize;
    let strtab_off = u32_at(&b, shoff + shstrndx * shentsize + 0x10)? as usize;
    let mut s = Sizes {
        sections: Vec::new(),
        flash: 0,
        ram: 0,
    };
    for i in 0..shnum {
        let h = shoff + i * shentsize;
        let name_off = u32_at(&b, h)? as usize;
        let ty = u32_at(&b, h + 4)?;
        let flags = u32_at(&b, h + 8)?;
        let addr = u32_at(&b, h + 0x0C)? as u64;
        let size = u32_at(&b, h + 0x14)? as u64;
        if flags & SHF_ALLOC == 0 || size == 0 {
            continue;
        }
        let name_bytes = &b[strtab_off + name_off..];
        let end = name_bytes.iter().position(|&c| c == 0).unwrap_or(0);
        let name = String::from_utf8_lossy(&name_bytes[..end]).into_owned();
        let in_flash = FLASH.contains(&addr);
        let in_ram = RAM.contains(&addr);
        if in_flash {
            s.flash += size;
        }
        if in_ram {
            s.ram += size;
            if ty != SHT_NOBITS {
                // Initialised data: its load image lives in flash too.
                s.flash += size;
            }
        }
        s.sections.push((name, addr, size, in_flash, in_ram));
    }
    Ok(s)
}

/// The size table of `elf` (what `cargo xtask size` prints and `results/size.md` holds), and
/// the sizes it shows.
pub fn table(elf: &Path) -> Result<(String, Sizes)> {
    use std::fmt::Write as _;
    let s = measure(elf)?;
    let mut out = String::new();
    // Relative to the workspace, so that the table is the same file on every checkout
    // (`results/size.md`, compared by `cargo xtask reproduce --check`).
    let shown = elf.strip_prefix(crate::root()).unwrap_or(elf);
    writeln!(out, "{}", shown.display())?;
    writeln!(
        out,
        "{:<16} {:>10} {:>9}  region",
        "section", "address", "bytes"
    )?;
    for (name, addr, size, f, r) in &s.sections {
        let region = if *f {
            "FLASH"
        } else if *r {
            "RAM"
        } else {
            "-"
        };
        writeln!(out, "{name:<16} {addr:#010x} {size:>9}  {region}")?;
    }
    writeln!(
        out,
        "flash: {} bytes ({:.1} KiB) of {} KiB budget",
        s.flash,
        s.flash as f64 / 1024.0,
        FLASH_BUDGET / 1024
    )?;
    writeln!(
        out,
        "static RAM: {} bytes ({:.1} KiB) of {} KiB budget",
        s.ram,
        s.ram as f64 / 1024.0,
        RAM_BUDGET / 1024
    )?;
    {
        use activesense_core::device::POLICY_SLOT_BYTES;
        use activesense_core::policy::{builtin, int8};
        let blobs: usize = builtin::POLICIES.iter().map(|b| b.len()).sum();
        writeln!(
            out,
            "of which the learnt policies: flash {} bytes (int8 blobs, EDM + scan K = 1: {}, K = 10: {}; \
             EDM only K = 1: {}, K = 10: {}); RAM {} bytes (int8 activations {} + upload slot {})",
            blobs,
            builtin::K1.len(),
            builtin::K10.len(),
            builtin::EDM_K1.len(),
            builtin::EDM_K10.len(),
            int8::SCRATCH_BYTES + POLICY_SLOT_BYTES,
            int8::SCRATCH_BYTES,
            POLICY_SLOT_BYTES
        )?;
    }
    Ok((out, s))
}

/// Prints the table and fails when a budget is exceeded.
pub fn report(elf: &Path) -> Result<()> {
    let (text, s) = table(elf)?;
    print!("{text}");
    if s.flash > FLASH_BUDGET {
        bail!("flash budget exceeded");
    }
    if s.ram > RAM_BUDGET {
        bail!("static RAM budget exceeded");
    }
    Ok(())
}
