//! A vectorisable `exp` for kernel matrices: every RBF evaluation is one `exp` of a
//! non-positive argument, and calling libm per element dominated kernel construction.

crate::simd::widest_vectors! {
    /// `exp(x)` for every element, in place, accurate to about 2 ulp for x in [-708, 0] and exact
    /// 0 below (the RBF's range). The loop has no calls or branches so the compiler vectorises it;
    /// on x86-64 it runs the widest instruction set the CPU offers (chosen at run time, so the
    /// wheel still runs on any x86-64).
    pub fn exp_nonpositive_in_place(xs: &mut [f64]) = exp_slice;
}

#[inline(always)]
fn exp_slice(xs: &mut [f64]) {
    for x in xs.iter_mut() {
        *x = exp_nonpositive(*x);
    }
}

#[inline(always)]
pub fn exp_nonpositive(x: f64) -> f64 {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    // ln 2 split so that k * LN2_HI is exact for |k| < 2^11 (Cody–Waite reduction).
    const LN2_HI: f64 = 6.931_471_803_691_238_164_9e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_700_02e-10;
    let xc = x.clamp(-708.0, 0.0);
    // Round to nearest by adding and removing 1.5 * 2^52 (f64::round is a libm call on
    // baseline x86-64 and would stop vectorisation).
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    let shifted = xc * LOG2E + SHIFTER;
    let k = shifted - SHIFTER;
    let r = (xc - k * LN2_HI) - k * LN2_LO; // |r| <= ln2 / 2
                                            // Taylor series to r^13: truncation error below 2^-60 relative on |r| <= 0.347.
    let mut p = 1.0 / 6_227_020_800.0;
    p = p * r + 1.0 / 479_001_600.0;
    p = p * r + 1.0 / 39_916_800.0;
    p = p * r + 1.0 / 3_628_800.0;
    p = p * r + 1.0 / 362_880.0;
    p = p * r + 1.0 / 40_320.0;
    p = p * r + 1.0 / 5_040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    // Scale by 2^k through the exponent bits; k >= -1022 keeps the result normal. The integer
    // k sits in the low bits of `shifted` (its mantissa), so no float-to-int conversion (which
    // baseline x86-64 cannot vectorise) is needed.
    let k_bits = shifted.to_bits().wrapping_sub(SHIFTER.to_bits());
    let scale = f64::from_bits(k_bits.wrapping_add(1023) << 52);
    let y = p * scale;
    if x < -708.0 {
        0.0
    } else {
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_std_exp_to_a_few_ulp() {
        let mut worst: f64 = 0.0;
        let mut x = -708.0;
        while x <= 0.0 {
            let got = exp_nonpositive(x);
            let want = x.exp();
            worst = worst.max(((got - want) / want).abs());
            x += 0.0137;
        }
        assert!(worst < 5e-16, "worst relative error {worst}");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-800.0), 0.0);
        assert_eq!(exp_nonpositive(f64::NEG_INFINITY), 0.0);
    }

    #[test]
    fn slice_version_agrees() {
        let mut v: Vec<f64> = (0..1000).map(|i| -(i as f64) * 0.05).collect();
        let want: Vec<f64> = v.iter().map(|x| x.exp()).collect();
        exp_nonpositive_in_place(&mut v);
        for (a, b) in v.iter().zip(&want) {
            assert!(((a - b) / b).abs() < 5e-16);
        }
    }
}
