//! libm's `sinf` and `cosf`, bit for bit, without double precision: for the Cortex-M4F,
//! whose FPU has none.
//!
//! libm (musl's algorithm) reduces `x` by a multiple of π/2 held as a double and evaluates
//! a degree-7 (sine) or degree-8 (cosine) polynomial in double precision, then rounds to
//! f32. On the M4F every one of those double operations is a software routine; a call cost
//! about 1,250 instructions, 14 % of a K = 10 calibrated-stop episode on the device even
//! after the ICP stopped recomputing them (README, "Instructions per update"). Here the
//! same reduction and the same polynomials are computed in 64-bit fixed point, about 20
//! bits more precise than libm's double evaluation, and the result is rounded to f32 only
//! when that rounding is certain to be libm's: when the fixed-point value lies farther
//! from the midpoint between two f32 than the two evaluations' combined error bound.
//! Otherwise libm itself is called: for 156 of the 4.4 · 10^9 sines and cosines of the
//! range. So the result is
//! libm's by construction; the tests check it on every f32 the fast path takes (an ignored
//! exhaustive test) and on a random sample in the normal suite.
//!
//! Covered: |x| ≤ 9π/4, where libm reduces with one constant and no table (headings and
//! bearings live here); beyond it, and for NaN and infinities, libm is called.
//!
//! Why the reduction is exact: libm's `x ± k·π/2` in double is exact on this range (the f32
//! `x` and the double constant differ by less than 1 and share the constant's last bit
//! position, so the difference fits in 53 bits), and here it is an exact integer
//! difference in units of 2^-60.

use core::f64::consts::FRAC_PI_2;

// libm's constants (k_sinf.rs, k_cosf.rs, sinf.rs), the same literals (hence more digits than
// an f64 holds).
#[allow(clippy::excessive_precision)]
const S1: f64 = -0.166666666416265235595;
#[allow(clippy::excessive_precision)]
const S2: f64 = 0.0083333293858894631756;
#[allow(clippy::excessive_precision)]
const S3: f64 = -0.000198393348360966317347;
#[allow(clippy::excessive_precision)]
const S4: f64 = 0.0000027183114939898219064;
#[allow(clippy::excessive_precision)]
const C0: f64 = -0.499999997251031003120;
#[allow(clippy::excessive_precision)]
const C1: f64 = 0.0416666233237390631894;
#[allow(clippy::excessive_precision)]
const C2: f64 = -0.00138867637746099294692;
#[allow(clippy::excessive_precision)]
const C3: f64 = 0.0000243904487962774090654;

/// `|v|` of a finite double in fixed point with `frac` fraction bits, truncated.
const fn fixed(v: f64, frac: i32) -> u64 {
    let bits = v.to_bits();
    let e = ((bits >> 52) & 0x7ff) as i32;
    let m = (bits & ((1u64 << 52) - 1)) | (1u64 << 52);
    let shift = e - 1075 + frac;
    if shift >= 0 {
        m << shift
    } else {
        m >> -shift
    }
}

/// Polynomial coefficients' magnitudes in Q62 (the signs are in the formulas).
const S1Q: u64 = fixed(S1, 62);
const S2Q: u64 = fixed(S2, 62);
const S3Q: u64 = fixed(S3, 62);
const S4Q: u64 = fixed(S4, 62);
const C0Q: u64 = fixed(C0, 62);
const C1Q: u64 = fixed(C1, 62);
const C2Q: u64 = fixed(C2, 62);
const C3Q: u64 = fixed(C3, 62);
const ONE_Q: u64 = 1 << 62;
/// `k·π/2` (k = 1..4) as libm's doubles, in Q60 (exact: their last bit is 2^-52 or above).
const PIO2_Q60: [u64; 4] = [
    fixed(FRAC_PI_2, 60),
    fixed(2.0 * FRAC_PI_2, 60),
    fixed(3.0 * FRAC_PI_2, 60),
    fixed(4.0 * FRAC_PI_2, 60),
];

/// `(a · b) >> 62` for `a, b < 2^63`, from 32-bit halves (three 32 × 32 → 64 products on
/// the M4); the dropped low product and carries make it at most 2 below the exact value.
#[inline]
fn mul(a: u64, b: u64) -> u64 {
    let (a1, a0) = (a >> 32, a & 0xffff_ffff);
    let (b1, b0) = (b >> 32, b & 0xffff_ffff);
    ((a1 * b1) << 2) + ((a1 * b0 + a0 * b1) >> 30)
}

/// libm's `k_sinf` polynomial at `y ≥ 0` (Q62, `y < 1`), in Q62.
#[inline]
fn sin_poly(y: u64) -> u64 {
    let z = mul(y, y);
    let w = mul(z, z);
    let s = mul(z, y);
    // y + s·(S1 + z·S2) + s·w·(S3 + z·S4), with S1, S3 < 0 < S2, S4.
    y - mul(s, S1Q) + mul(mul(s, z), S2Q) - mul(mul(s, w), S3Q - mul(z, S4Q))
}

/// libm's `k_cosf` polynomial at `y ≥ 0` (Q62, `y < 1`), in Q62.
#[inline]
fn cos_poly(y: u64) -> u64 {
    let z = mul(y, y);
    let w = mul(z, z);
    // 1 + z·C0 + w·C1 + w·z·(C2 + z·C3), with C0, C2 < 0 < C1, C3.
    ONE_Q - mul(z, C0Q) + mul(w, C1Q) - mul(mul(w, z), C2Q - mul(z, C3Q))
}

/// The f32 nearest to `a` (Q62, > 0) if it is certainly the f32 nearest to libm's double
/// evaluation of the same polynomial, else `None`. Error bound: at most 32 units from this
/// side (a dozen truncating products and the coefficients' last bits), and libm's double
/// evaluation within about 6 of its last-place units of the exact polynomial; allowed: 64
/// units plus 2^-47 of the value, about ten times that.
#[inline]
fn certain_f32(a: u64) -> Option<f32> {
    let p = 63 - a.leading_zeros() as i32;
    let shift = p - 23;
    if shift < 2 {
        return None;
    }
    let mut mant = a >> shift;
    let rem = a & ((1u64 << shift) - 1);
    let half = 1u64 << (shift - 1);
    let err = 64 + (a >> 47);
    if rem.abs_diff(half) <= err {
        return None;
    }
    let mut exp = p - 62 + 127;
    if rem > half {
        mant += 1;
        if mant == 1 << 24 {
            mant >>= 1;
            exp += 1;
        }
    }
    if exp <= 0 {
        return None;
    }
    Some(f32::from_bits(
        ((exp as u32) << 23) | (mant as u32 & 0x7f_ffff),
    ))
}

/// Which polynomial, at which reduced argument, with which sign: libm's branches for
/// |x| ≤ 9π/4, with its oddness and evenness folded in (`k_sinf(-y) = -k_sinf(y)` and
/// `k_cosf(-y) = k_cosf(y)` exactly: negation commutes with rounding).
struct Reduced {
    /// The sine polynomial, else the cosine one.
    sine: bool,
    /// `|y|` in Q62.
    y: u64,
    /// The result's sign is negative.
    negative: bool,
}

/// `|x|` in Q60 (exact for `2^-12 ≤ |x| < 8`), and `|x| - k·π/2` for `k ≥ 1` with its sign.
fn reduce(ax: u32, k: usize) -> (u64, bool) {
    let m = ((ax & 0x7f_ffff) | 0x80_0000) as u64;
    let e = (ax >> 23) as i32 - 150 + 60;
    let xq = m << e;
    let c = PIO2_Q60[k - 1];
    // |y| < 1, so Q60 → Q62 keeps every bit.
    if xq >= c {
        ((xq - c) << 2, false)
    } else {
        ((c - xq) << 2, true)
    }
}

fn q62_of(ax: u32) -> u64 {
    let m = ((ax & 0x7f_ffff) | 0x80_0000) as u64;
    m << ((ax >> 23) as i32 - 150 + 62)
}

fn finish(r: Reduced) -> Option<f32> {
    let v = if r.sine { sin_poly(r.y) } else { cos_poly(r.y) };
    let f = certain_f32(v)?;
    Some(if r.negative { -f } else { f })
}

/// libm's `sinf(x)`, bit for bit.
pub fn sinf(x: f32) -> f32 {
    fast_sinf(x).unwrap_or_else(|| libm::sinf(x))
}

/// libm's `cosf(x)`, bit for bit.
pub fn cosf(x: f32) -> f32 {
    fast_cosf(x).unwrap_or_else(|| libm::cosf(x))
}

/// [`sinf`] where the fixed point is certain, else `None` (libm's to call).
fn fast_sinf(x: f32) -> Option<f32> {
    let bits = x.to_bits();
    let (ax, neg) = (bits & 0x7fff_ffff, bits >> 31 != 0);
    if ax < 0x3980_0000 {
        return Some(x); // |x| < 2^-12 (and ±0, subnormals): libm returns x.
    }
    let r = if ax <= 0x3f49_0fda {
        Reduced {
            sine: true,
            y: q62_of(ax),
            negative: neg,
        }
    } else if ax <= 0x4016_cbe3 {
        // ±k_cosf(|x| - π/2)
        Reduced {
            sine: false,
            y: reduce(ax, 1).0,
            negative: neg,
        }
    } else if ax <= 0x407b_53d1 {
        // sign(x)·k_sinf(π - |x|)
        let (y, below) = reduce(ax, 2);
        Reduced {
            sine: true,
            y,
            negative: neg == below,
        }
    } else if ax <= 0x40af_eddf {
        // -sign(x)·k_cosf(|x| - 3π/2)
        Reduced {
            sine: false,
            y: reduce(ax, 3).0,
            negative: !neg,
        }
    } else if ax <= 0x40e2_31d5 {
        // sign(x)·k_sinf(|x| - 2π)
        let (y, below) = reduce(ax, 4);
        Reduced {
            sine: true,
            y,
            negative: neg != below,
        }
    } else {
        return None;
    };
    finish(r)
}

/// [`cosf`] where the fixed point is certain, else `None`.
fn fast_cosf(x: f32) -> Option<f32> {
    let ax = x.to_bits() & 0x7fff_ffff;
    if ax < 0x3980_0000 {
        return Some(1.0); // |x| < 2^-12: libm returns 1.
    }
    let r = if ax <= 0x3f49_0fda {
        Reduced {
            sine: false,
            y: q62_of(ax),
            negative: false,
        }
    } else if ax <= 0x4016_cbe3 {
        // k_sinf(π/2 - |x|)
        let (y, below) = reduce(ax, 1);
        Reduced {
            sine: true,
            y,
            negative: !below,
        }
    } else if ax <= 0x407b_53d1 {
        // -k_cosf(|x| - π)
        Reduced {
            sine: false,
            y: reduce(ax, 2).0,
            negative: true,
        }
    } else if ax <= 0x40af_eddf {
        // k_sinf(|x| - 3π/2)
        let (y, below) = reduce(ax, 3);
        Reduced {
            sine: true,
            y,
            negative: below,
        }
    } else if ax <= 0x40e2_31d5 {
        // k_cosf(|x| - 2π)
        Reduced {
            sine: false,
            y: reduce(ax, 4).0,
            negative: false,
        }
    } else {
        return None;
    };
    finish(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn same(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// Every f32 bit pattern in `range` (both signs), against libm; returns the count and
    /// how many of the sines and cosines fell back to libm.
    fn check(range: core::ops::Range<u32>) -> (u64, u64) {
        let (mut n, mut fallbacks) = (0, 0);
        for b in range {
            for x in [f32::from_bits(b), -f32::from_bits(b)] {
                assert!(same(sinf(x), libm::sinf(x)), "sinf {:#x}", x.to_bits());
                assert!(same(cosf(x), libm::cosf(x)), "cosf {:#x}", x.to_bits());
                n += 1;
                fallbacks += fast_sinf(x).is_none() as u64 + fast_cosf(x).is_none() as u64;
            }
        }
        (n, fallbacks)
    }

    #[test]
    fn equals_libm_on_a_sample_and_the_edges() {
        // The branch thresholds and their neighbours, the specials, then a stride through
        // every exponent (about 2 × 260 000 arguments).
        for t in [
            0u32,
            1,
            0x0080_0000,
            0x3980_0000,
            0x3f49_0fda,
            0x4016_cbe3,
            0x407b_53d1,
            0x40af_eddf,
            0x40e2_31d5,
            0x7f7f_ffff,
            0x7f80_0000,
            0x7fc0_0000,
        ] {
            check(t.saturating_sub(64)..t.saturating_add(64).min(0x7fc0_0001));
        }
        let mut b = 0u32;
        while b < 0x7f80_0000 {
            check(b..b + 1);
            b += 8191;
        }
        for x in [
            core::f32::consts::PI,
            -core::f32::consts::FRAC_PI_2,
            1e-3,
            40.0,
        ] {
            assert!(same(sinf(x), libm::sinf(x)) && same(cosf(x), libm::cosf(x)));
        }
    }

    /// Every f32 the fast path takes (|x| up to 9π/4, both signs): about 2.2 · 10^9
    /// arguments, 15 s on two cores in release (far longer in a debug build, hence ignored):
    /// `cargo test --release -p activesense-core -- --ignored every_f32`.
    #[test]
    #[ignore]
    fn equals_libm_on_every_f32_up_to_9_pi_over_4() {
        extern crate std;
        let end = 0x40e2_31d6u32;
        let mid = end / 2;
        let halves = [(0, mid), (mid, end)].map(|(a, b)| std::thread::spawn(move || check(a..b)));
        let (n, fallbacks) = halves
            .into_iter()
            .map(|h| h.join().unwrap())
            .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        assert_eq!(n, 2 * end as u64);
        // Within 9π/4 libm is needed only where the two evaluations straddle a rounding
        // midpoint: 156 of the 4.4 · 10^9 sines and cosines.
        std::eprintln!("{n} arguments, {fallbacks} of 2n sines and cosines from libm");
        assert!(fallbacks < n / 100_000, "{fallbacks}");
    }
}
