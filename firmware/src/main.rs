//! activesense instrument-controller firmware (STM32F405, Cortex-M4F).
//!
//! At this stage the firmware boots, exercises the no_std core once (builds and validates
//! a floor-plan model, casts a ray, runs a baseline agent) and reports the result over
//! semihosting, then exits through semihosting so that `qemu-system-arm` returns the
//! status. `cargo xtask qemu-smoke` checks that line. The serial protocol session is
//! layered on top of this in `session`.
#![no_std]
#![no_main]

use activesense_core::agents::{AgentKind, BaselineAgent};
use activesense_core::geometry::{unit, v2};
use activesense_core::FloorPlan;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};

/// Reports a panic over semihosting and exits QEMU with a failure status, so a test
/// harness sees the failure instead of a hung emulator.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("PANIC: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

#[entry]
fn main() -> ! {
    let ok = self_test();
    match ok {
        Ok(range_mm) => {
            hprintln!(
                "activesense-firmware {}: core initialised (self-test range {} mm)",
                env!("CARGO_PKG_VERSION"),
                range_mm
            );
            debug::exit(debug::EXIT_SUCCESS);
        }
        Err(msg) => {
            hprintln!("activesense-firmware: core self-test FAILED: {}", msg);
            debug::exit(debug::EXIT_FAILURE);
        }
    }
    #[allow(clippy::empty_loop)]
    loop {}
}

/// Builds a 4 m x 3 m room, casts one ray from (1, 1) along +x (expect 3 m) and runs the
/// heuristic-1 agent for one period.
fn self_test() -> Result<u32, &'static str> {
    let plan = FloorPlan::new(&[v2(0.0, 0.0), v2(4.0, 0.0), v2(4.0, 3.0), v2(0.0, 3.0)])
        .map_err(|_| "plan rejected")?;
    let hit = plan.ray_cast(v2(1.0, 1.0), unit(0.0)).ok_or("no ray hit")?;
    if libm::fabsf(hit.range - 3.0) > 1e-4 {
        return Err("wrong range");
    }
    let mut agent = BaselineAgent::new(AgentKind::Heuristic1, 0);
    let measures = (0..6)
        .filter(|_| agent.next_action() == activesense_core::agents::Action::Measure)
        .count();
    if measures != 1 {
        return Err("agent period");
    }
    Ok((hit.range * 1000.0) as u32)
}
