//! `activesense policy …`: post-training int8 quantisation of a float policy (`quantize`),
//! float-vs-int8 agreement on the test plans (`agreement`), and, over a link to an
//! instrument, uploading an int8 policy (`upload`) and asking which one serves (`info`).

use super::options::{InstrumentOption, RotBinsOption};
use super::write_file;
use activesense_instrument::agents::Policies;
use activesense_instrument::link::runner::open_link;
use activesense_instrument::link::serial::{self, LinkSpec};
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct QuantizeArgs {
    /// Float policy file (activesense train output).
    #[arg(long)]
    policy: PathBuf,
    /// Where to write the int8 blob.
    #[arg(long)]
    out: PathBuf,
    /// Greedy episodes on training plans whose states calibrate the activation ranges.
    #[arg(long, default_value_t = activesense_lab::learn::quantize::DEFAULT_CALIBRATION_EPISODES)]
    calibration_episodes: usize,
    /// Seed of the calibration plans and placements.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

#[derive(Args)]
pub struct AgreementArgs {
    // --rot-bins (default here: 1,10); the episodes are the evaluation's defaults.
    #[command(flatten)]
    rot_bins: RotBinsOption,
    // --instrument: whose committed policies and episodes.
    #[command(flatten)]
    instrument: InstrumentOption,
    /// Test plans per setting (seeds from 1000000 on).
    #[arg(long, default_value_t = 200)]
    plans: usize,
    /// Float policy file(s), each for the K its header names; default: the committed
    /// policies/k{K}/policy.policy.
    #[arg(long)]
    policy: Vec<PathBuf>,
    /// int8 blob(s) to check, each for the K it names; default: quantised on the fly.
    #[arg(long)]
    int8: Vec<PathBuf>,
    /// Calibration episodes when quantising on the fly.
    #[arg(long, default_value_t = activesense_lab::learn::quantize::DEFAULT_CALIBRATION_EPISODES)]
    calibration_episodes: usize,
    /// Calibration seed when quantising on the fly.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Write the report as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

pub fn quantize(a: QuantizeArgs) -> Result<()> {
    use activesense_instrument::learn::file;
    use activesense_lab::learn::quantize;
    let (net, meta) = file::load(&a.policy).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mask = activesense_instrument::learn::agent::InputMask::of_metadata(&meta);
    // A network trained without scans is the EDM-only instrument's: it has no camera, so
    // the int8 network reads the same zeros the float one was trained on.
    let Some(instrument) = mask.instrument() else {
        bail!(
            "{} is an ablation trained on '{}' inputs, no instrument's policy: only policies trained on every input (the paper's sensor) or without scans (the EDM-only instrument) can be quantised",
            a.policy.display(),
            mask.name()
        );
    };
    let (blob, r) = quantize::quantize_calibrated(&net, instrument, a.calibration_episodes, a.seed);
    std::fs::write(&a.out, &blob).with_context(|| format!("cannot write {}", a.out.display()))?;
    println!(
        "calibrated on {} states of {} training episodes (seed {}); wrote {} ({} bytes, K = {}, --instrument {})",
        r.states,
        a.calibration_episodes,
        a.seed,
        a.out.display(),
        blob.len(),
        net.shape.rot_bins,
        instrument.name()
    );
    Ok(())
}

/// Reads an int8 blob, naming the file in every error.
fn read_blob(path: &Path) -> Result<(u8, Vec<u8>)> {
    use activesense_core::policy::int8::QuantizedPolicy;
    let bytes = std::fs::read(path).with_context(|| format!("cannot read '{}'", path.display()))?;
    let k = QuantizedPolicy::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("'{}' is not a usable int8 policy blob: {e}", path.display()))?
        .rot_bins();
    Ok((k, bytes))
}

pub fn agreement(a: AgreementArgs) -> Result<()> {
    use activesense_lab::learn::quantize;
    let rot_bins = a.rot_bins.list(&[1, 10])?;
    let instrument = a.instrument.instrument;
    let policies = Policies::load_for(instrument, &a.policy, &rot_bins)?;
    let mut blobs = Vec::new();
    for path in &a.int8 {
        blobs.push((read_blob(path)?, path.clone()));
    }
    let mut reports = Vec::new();
    println!("| K | plans | states | action agreement | identical episodes | success float / int8 | mean actions float / int8 | max logit error | blob |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for &k in &rot_bins {
        let p = policies
            .for_rot_bins(k)
            .ok_or_else(|| anyhow::anyhow!("no float policy for K = {k}"))?;
        let blob = match blobs.iter().find(|((bk, _), _)| *bk == k) {
            Some(((_, b), _)) => b.clone(),
            None => {
                quantize::quantize_calibrated(&p.net, instrument, a.calibration_episodes, a.seed).0
            }
        };
        let r = quantize::agreement(&p.net, &blob, a.plans).map_err(|e| {
            anyhow::anyhow!("int8 blob for K = {k} does not fit {}: {e}", p.describe())
        })?;
        println!(
            "| {} | {} | {} | {:.4} | {} / {} | {:.3} / {:.3} | {:.1} / {:.1} | {:.4} | {} B, crc {:08x} |",
            r.rot_bins,
            r.plans,
            r.states,
            r.action_agreement,
            r.identical_episodes,
            r.plans,
            r.float.success_rate,
            r.int8.success_rate,
            r.float.mean_actions,
            r.int8.mean_actions,
            r.max_logit_error,
            r.blob_bytes,
            r.blob_crc
        );
        reports.push(serde_json::json!({ "policy": p.describe(), "agreement": r }));
    }
    if let Some(path) = &a.json {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
        }
        write_file(path, &serde_json::to_string_pretty(&reports)?)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// `activesense policy upload`.
#[derive(Args, Debug)]
pub struct PolicyUploadArgs {
    // clap's help text: the brackets are optional parts, not rustdoc links.
    #[allow(rustdoc::broken_intra_doc_links)]
    /// loopback | qemu[:ELF] | tcp:HOST:PORT | serial:PATH[@BAUD]
    #[arg(long)]
    pub link: LinkSpec,
    /// The int8 policy blob (`activesense policy quantize` output).
    #[arg(long)]
    pub int8: PathBuf,
    /// Reply time-out in milliseconds (default: what the device announces as its slowest
    /// reply, plus half again).
    #[arg(long)]
    pub timeout_ms: Option<u64>,
    /// Power the instrument off afterwards (protocol `Shutdown`). Without it the instrument
    /// keeps serving, with the uploaded policy in its RAM.
    #[arg(long)]
    pub shutdown: bool,
}

/// `activesense policy info`.
#[derive(Args, Debug)]
pub struct PolicyInfoArgs {
    // clap's help text: the brackets are optional parts, not rustdoc links.
    #[allow(rustdoc::broken_intra_doc_links)]
    /// loopback | qemu[:ELF] | tcp:HOST:PORT | serial:PATH[@BAUD]
    #[arg(long)]
    pub link: LinkSpec,
    /// Reply time-out in milliseconds (default: what the device announces as its slowest
    /// reply, plus half again).
    #[arg(long)]
    pub timeout_ms: Option<u64>,
    /// Power the instrument off afterwards (protocol `Shutdown`). Without it the instrument
    /// keeps serving, with the uploaded policy in its RAM.
    #[arg(long)]
    pub shutdown: bool,
}

fn print_policy(i: &activesense_core::protocol::PolicyInfo) {
    println!(
        "K = {:>2}: {:?}{}",
        i.rot_bins,
        i.source,
        if i.len > 0 {
            format!(" ({} bytes, crc {:08x})", i.len, i.crc)
        } else {
            String::new()
        }
    );
}

/// Uploads an int8 policy into the instrument's RAM slot (it serves its K until power-off
/// or `Reset`; the built-in policy serves again after that). The device refuses a blob
/// that is corrupt or for another K and keeps the policy it had.
pub fn upload(a: PolicyUploadArgs) -> Result<()> {
    let blob = std::fs::read(&a.int8)
        .with_context(|| format!("cannot read int8 policy '{}'", a.int8.display()))?;
    // Check locally first: a clear message beats a device error code.
    let k = activesense_core::policy::int8::QuantizedPolicy::parse(&blob)
        .map_err(|e| {
            anyhow::anyhow!(
                "'{}' is not a usable int8 policy blob: {e}",
                a.int8.display()
            )
        })?
        .rot_bins();
    let mut link = open_link(&a.link, &[], a.timeout_ms)?;
    let info = link.client.hello().context("handshake")?;
    if info.capabilities & activesense_core::protocol::CAP_POLICY_UPLOAD == 0 {
        bail!(
            "the device ({}) does not accept policy uploads",
            info.firmware
        );
    }
    let bar = indicatif::ProgressBar::new(blob.len() as u64);
    let installed = link
        .client
        .upload_policy(k, &blob, |n| bar.set_position(n as u64))
        .with_context(|| format!("uploading '{}'", a.int8.display()))?;
    bar.finish_and_clear();
    println!("uploaded {} ({} bytes)", a.int8.display(), blob.len());
    print_policy(&installed);
    end_session(link, a.shutdown)
}

/// Prints which policy serves K = 1 and K = 10 on the instrument.
pub fn info(a: PolicyInfoArgs) -> Result<()> {
    let mut link = open_link(&a.link, &[], a.timeout_ms)?;
    let info = link.client.hello().context("handshake")?;
    println!("device: {} (protocol v{})", info.firmware, info.protocol);
    for k in [1u8, 10] {
        print_policy(&link.client.policy_info(k)?);
    }
    end_session(link, a.shutdown)
}

/// `Shutdown` with `--shutdown`; else the session ends and the instrument keeps serving
/// (a `loopback`/`qemu` device this command started ends with it).
fn end_session(link: serial::Link, shutdown: bool) -> Result<()> {
    if shutdown {
        link.shutdown().context("shutting the device down")?;
        println!("device shut down");
    } else {
        link.close().context("closing the link")?;
    }
    Ok(())
}
