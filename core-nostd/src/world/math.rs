//! Scalar maths through `libm`.
//!
//! Every transcendental and square root in the crate goes through these wrappers so
//! that the host build and the Cortex-M4F build call the same pure-Rust routines and
//! round identically (determinism requirement: same episode, same actions).

use core::f32::consts::PI;

/// 2π as f32.
pub const TAU: f32 = 2.0 * PI;

/// Square root (correctly rounded in both libm and hardware). The M4F's FPU computes it
/// in one instruction (`fpu::sqrt`); elsewhere libm's routine gives the same bits.
#[inline]
pub fn sqrt(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        fpu::sqrt(x)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

/// `VSQRT.F32` on the Cortex-M4F's single-precision FPU. IEEE 754 requires a correctly
/// rounded square root, and libm's `sqrtf` (the host's) is one too, so the bits are the
/// same for every non-NaN input; the firmware's `dsp-selftest` compares the two on the
/// device. libm's routine is a bit-by-bit software loop of about 36 instructions plus the
/// call, and the ICP's correspondences take one per pair: 3 % of a K = 10 episode's
/// instructions under the calibrated stop (README, "Instructions per update"). Stable Rust has no `sqrt` in `core`, and its `asm!` offers the S registers
/// only with the double-precision `vfp2` feature, which this single-precision FPU lacks;
/// so the instruction is a two-instruction leaf function in `global_asm!` (hard-float
/// AAPCS: argument and result in `s0`), and the call is the core's second `unsafe` block
/// (`docs/ARCHITECTURE.md`, "unsafe").
#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
#[allow(unsafe_code)]
pub mod fpu {
    core::arch::global_asm!(
        ".section .text.activesense_vsqrtf,\"ax\",%progbits",
        ".fpu fpv4-sp-d16",
        ".global activesense_vsqrtf",
        ".type activesense_vsqrtf,%function",
        ".thumb_func",
        "activesense_vsqrtf:",
        "vsqrt.f32 s0, s0",
        "bx lr",
        ".size activesense_vsqrtf, . - activesense_vsqrtf",
    );

    extern "C" {
        fn activesense_vsqrtf(x: f32) -> f32;
    }

    /// `VSQRT.F32` of `x`.
    #[inline]
    pub fn sqrt(x: f32) -> f32 {
        // SAFETY: a leaf of two instructions on `s0` and `lr` only (no memory, no stack),
        // called with the hard-float ABI the target uses; the runtime enables the FPU
        // before `main`.
        unsafe { activesense_vsqrtf(x) }
    }
}
/// Sine: libm's `sinf`, bit for bit. On the M4F (no double-precision FPU) computed in
/// fixed point by [`super::trig::sinf`], about a tenth of libm's instructions there.
#[inline]
pub fn sin(x: f32) -> f32 {
    #[cfg(target_arch = "arm")]
    {
        super::trig::sinf(x)
    }
    #[cfg(not(target_arch = "arm"))]
    {
        libm::sinf(x)
    }
}
/// Cosine: libm's `cosf`, bit for bit (on the M4F by [`super::trig::cosf`]).
#[inline]
pub fn cos(x: f32) -> f32 {
    #[cfg(target_arch = "arm")]
    {
        super::trig::cosf(x)
    }
    #[cfg(not(target_arch = "arm"))]
    {
        libm::cosf(x)
    }
}
/// Two-argument arc tangent.
#[inline]
pub fn atan2(y: f32, x: f32) -> f32 {
    libm::atan2f(y, x)
}
/// Arc cosine, argument clamped into [-1, 1] first.
#[inline]
pub fn acos(x: f32) -> f32 {
    libm::acosf(x.clamp(-1.0, 1.0))
}
/// Natural logarithm.
#[inline]
pub fn ln(x: f32) -> f32 {
    libm::logf(x)
}
/// Exponential.
#[inline]
pub fn exp(x: f32) -> f32 {
    libm::expf(x)
}
/// Absolute value.
#[inline]
pub fn abs(x: f32) -> f32 {
    libm::fabsf(x)
}
/// Round down.
#[inline]
pub fn floor(x: f32) -> f32 {
    libm::floorf(x)
}
/// Round half away from zero.
#[inline]
pub fn round(x: f32) -> f32 {
    libm::roundf(x)
}

/// Wraps an angle into [-π, π).
#[inline]
pub fn wrap_angle(a: f32) -> f32 {
    let mut r = a - TAU * floor((a + PI) / TAU);
    // Guard the rounding edge: floor can leave r == π.
    if r >= PI {
        r -= TAU;
    }
    if r < -PI {
        r += TAU;
    }
    r
}

/// Wraps an angle into [0, 2π).
#[inline]
pub fn wrap_positive(a: f32) -> f32 {
    let r = a - TAU * floor(a / TAU);
    if r >= TAU {
        r - TAU
    } else {
        r
    }
}

/// SplitMix64 finaliser (Steele, Lea & Flood 2014): decorrelates nearby seeds. The one
/// seed-derivation function of the project: the core derives the registration seed from
/// the agent seed with it, the host its world and agent streams.
pub const fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_angle_range() {
        for i in -100..100 {
            let a = i as f32 * 0.37;
            let w = wrap_angle(a);
            assert!((-PI..PI).contains(&w), "{a} -> {w}");
            assert!(abs(sin(a) - sin(w)) < 1e-4 && abs(cos(a) - cos(w)) < 1e-4);
            let p = wrap_positive(a);
            assert!((0.0..TAU).contains(&p), "{a} -> {p}");
        }
    }
}
