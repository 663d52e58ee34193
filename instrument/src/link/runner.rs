//! Running one episode on a device over the link, as `sim`, `serial run` and `mcu-bench`
//! do: restart it from its seeds when the link lost it beyond the client's re-sends,
//! check its trace fingerprint and (`--verify`) replay it in-process, and end the session
//! (leave the device serving, or `--shutdown`).

use crate::link::device::SimInstrument;
use crate::link::error::LinkError;
use crate::link::serial::{self, EpisodeRun, Link, LinkSpec};
use activesense_core::device::instrument::run_local;
use activesense_core::device::Controller;
use activesense_core::protocol::{EpisodeParams, EpisodeReport};
use activesense_core::FloorPlan;
use anyhow::{bail, Context, Result};
use std::time::Duration;

/// Runs the same episode in-process (reference for `--verify` and the HIL tests).
pub fn reference_run(
    plan: &FloorPlan,
    params: &EpisodeParams,
    instrument: &mut SimInstrument,
) -> Result<EpisodeRun> {
    let mut ctl = Box::new(Controller::new(
        None,
        &activesense_core::policy::builtin::POLICIES,
    ));
    let mut steps = Vec::new();
    let report = run_local(&mut ctl, plan, params, instrument, |a, o| {
        steps.push((a, *o))
    })
    .map_err(|e| anyhow::anyhow!("in-process reference run failed: {e:?}"))?;
    Ok(EpisodeRun { steps, report })
}

/// True when two runs agree bit for bit (cycle statistics excluded: they measure the
/// machine, not the episode).
pub fn same_run(a: &EpisodeRun, b: &EpisodeRun) -> bool {
    let bits = |r: &EpisodeRun| {
        r.steps
            .iter()
            .map(|(act, o)| (*act, o.range.map(f32::to_bits), o.scan))
            .collect::<Vec<_>>()
    };
    let strip = |r: &EpisodeReport| EpisodeReport {
        cycles: Default::default(),
        ..*r
    };
    bits(a) == bits(b)
        && strip(&a.report) == strip(&b.report)
        && a.report.cost.to_bits() == b.report.cost.to_bits()
}

/// Most times one episode is restarted from its seeds after the link lost it.
pub const MAX_RESTARTS: u32 = 3;

/// True for failures after which the episode can be run again from its seeds: the line
/// lost or garbled frames beyond the client's re-sends, or the device dropped the session
/// (it abandons an episode whose host went silent). A refusal of the plan or the
/// parameters would only repeat, and a closed or broken link cannot be retried.
pub fn restartable(e: &LinkError) -> bool {
    use activesense_core::protocol::WireError as W;
    match e {
        LinkError::Timeout | LinkError::GaveUp { .. } | LinkError::BadFrame(_) => true,
        LinkError::Unexpected(_) => true,
        LinkError::Device(w) => matches!(
            w,
            W::NoSession
                | W::OutOfSequence { .. }
                | W::StepMismatch { .. }
                | W::UnexpectedRequest
                | W::Framing
                | W::Crc
                | W::Decode
                | W::Oversized
        ),
        _ => false,
    }
}

/// An episode's plan, parameters and simulated instrument, built from its seeds: calling
/// it again gives the same episode (a restart, the `--verify` reference).
pub type EpisodeMaker<'a> = &'a dyn Fn() -> (FloorPlan, EpisodeParams, SimInstrument);

/// Runs one episode on the device; after a restartable link failure ([`restartable`]) it
/// re-opens the session and runs the episode again from its seeds (same seeds, same
/// actions), at most [`MAX_RESTARTS`] times, counting them in `restarts`.
pub fn run_one(
    link: &mut Link,
    mk: EpisodeMaker<'_>,
    verify: bool,
    restarts: &mut u32,
) -> Result<EpisodeRun> {
    let mut attempt = 0;
    let run = loop {
        let (plan, params, mut inst) = mk();
        let r = link
            .client
            .load_plan(&plan)
            .and_then(|_| link.client.run_episode(&params, &mut inst));
        match r {
            Ok(run) => break run,
            Err(e) if attempt < MAX_RESTARTS && restartable(&e) => {
                attempt += 1;
                *restarts += 1;
                eprintln!(
                    "warning: {e}; restarting the episode from its seeds ({attempt} of {MAX_RESTARTS})"
                );
                link.client
                    .hello()
                    .context("re-opening the session for a restart")?;
            }
            Err(e) => return Err(e).context("running the episode"),
        }
    };
    if run.trace_hash() != run.report.trace_hash {
        bail!(
            "trace fingerprint mismatch: host {:08x}, device {:08x}",
            run.trace_hash(),
            run.report.trace_hash
        );
    }
    if verify {
        let (p, prm, mut i) = mk();
        let local = reference_run(&p, &prm, &mut i)?;
        if !same_run(&run, &local) {
            bail!("device run differs from the in-process run");
        }
    }
    Ok(run)
}

/// Opens `spec`; `--timeout-ms`, when given, fixes the reply time-out, else it follows
/// the device's announcement.
pub fn open_link(spec: &LinkSpec, qemu_args: &[String], timeout_ms: Option<u64>) -> Result<Link> {
    let floor = timeout_ms.map_or(serial::HANDSHAKE_TIMEOUT, Duration::from_millis);
    let mut link = serial::open_with_qemu_args(spec, floor, qemu_args)
        .with_context(|| format!("opening {spec}"))?;
    if timeout_ms.is_some() {
        link.client.set_reply_timeout(floor, false);
    }
    Ok(link)
}

/// The host's side of the link summary: what it took to get the frames through.
pub fn print_link_counters(link: &Link, restarts: u32) {
    println!(
        "link (host): {}, {} episode restarts; reply time-out {} ms",
        link.client.counters().summary(),
        restarts,
        link.client.reply_timeout().as_millis()
    );
}

/// Ends a command's session: `Shutdown` with `--shutdown`, else leave the device serving.
pub fn end_session(link: Link, shutdown: bool) -> Result<(String, Vec<u8>)> {
    if shutdown {
        link.shutdown_with_stderr()
            .context("shutting the device down")
    } else {
        link.close_with_stderr().context("closing the link")
    }
}
