//! Four `f64` lanes computed side by side, so the lobe fit's sample loops read as scalar
//! formulas and run as vector code: [`F4`] is a plain array (each operation a loop over the
//! lanes: the baseline build, and the reference), [`Avx4`] one AVX register (the build for
//! processors with AVX2). Comparisons give masks and [`Lanes::select`] blends by them: no
//! branches. The logarithm and the exponential are polynomials ([`Lanes::ln`],
//! [`Lanes::exp`]): libm's scalar calls would stop the vectorisation. Every operation is
//! IEEE-exact lane by lane in both, in the same order: identical results.
//!
//! Written by hand (measured: the lobe fit is ~90% of the estimator's time on dense rigs, and
//! the compiler does not vectorise the scalar formulas by itself, libm calls included).

use std::ops::{Add, BitAnd, Div, Mul, Neg, Sub};

/// Number of lanes.
pub(super) const LANES: usize = 4;

/// Four `f64` lanes and the operations the sample loops use.
pub(super) trait Lanes:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
{
    /// A lane mask (all bits set where true).
    type Mask: Copy + BitAnd<Output = Self::Mask>;

    /// The same value in every lane.
    fn splat(v: f64) -> Self;
    /// Lanes `i..i + LANES` of a column (whose length is a whole number of blocks).
    fn load(column: &[f64], i: usize) -> Self;
    /// Writes the lanes to `out[..LANES]`.
    fn store(self, out: &mut [f64]);
    fn sqrt(self) -> Self;
    /// `if self > other { self } else { other }`.
    fn max(self, other: Self) -> Self;
    /// `if self < other { self } else { other }`.
    fn min(self, other: Self) -> Self;
    /// `self > other` (false where either is NaN).
    fn gt(self, other: Self) -> Self::Mask;
    /// `if mask { yes } else { no }`, lane by lane.
    fn select(mask: Self::Mask, yes: Self, no: Self) -> Self;
    /// `2^n` where `t = n + 1.5 2^52` holds the integer `n` in its low bits.
    fn pow2_shifted(t: Self) -> Self;
    /// For positive normal lanes: the binary exponent `e` (as a float) and the mantissa
    /// `m` in [1, 2), `self = m 2^e`.
    fn split(self) -> (Self, Self);

    /// The lanes' sum, in a fixed order.
    #[inline(always)]
    fn sum(self) -> f64 {
        let mut a = [0.0; LANES];
        self.store(&mut a);
        (a[0] + a[1]) + (a[2] + a[3])
    }

    /// `e^x` for `x` in [-708, 708] (clamped there) to about one unit in the last place:
    /// `x = n ln 2 + r` with `|r| <= ln 2 / 2`, `e^r` by its Taylor series to `r^13` (the
    /// remainder is below 1e-17), `2^n` from the exponent bits.
    #[inline(always)]
    fn exp(self) -> Self {
        let x = self.max(Self::splat(-708.0)).min(Self::splat(708.0));
        let t = x * std::f64::consts::LOG2_E + SHIFTER;
        let n = t - SHIFTER;
        let r = x - n * LN2_HI - n * LN2_LO;
        let mut p = Self::splat(1.0 / 6_227_020_800.0);
        for c in EXP_TAYLOR {
            p = p * r + c;
        }
        p * Self::pow2_shifted(t)
    }

    /// `ln x` for positive normal `x` to about one unit in the last place: `x = m 2^e` with
    /// `m` in [sqrt(1/2), sqrt(2)), `ln m = 2 atanh(s)`, `s = (m - 1) / (m + 1)`, by its series
    /// to `s^21` (`|s| < 0.172`: the remainder is below 1e-18).
    #[inline(always)]
    fn ln(self) -> Self {
        let (e, m) = self.split();
        let big = m.gt(Self::splat(std::f64::consts::SQRT_2));
        let m = Self::select(big, m * 0.5, m);
        let e = Self::select(big, e + 1.0, e);
        let f = m - 1.0;
        let s = f / (f + 2.0);
        let z = s * s;
        let mut p = Self::splat(1.0 / 21.0);
        for c in LN_SERIES {
            p = p * z + c;
        }
        e * LN2_HI + (s * 2.0 * p + e * LN2_LO)
    }
}

/// Adding 1.5 2^52 rounds a float to an integer held in the low bits of the sum.
const SHIFTER: f64 = 6_755_399_441_055_744.0;

/// `2^52`: its bits or'ed with a 52-bit integer give `2^52 + integer`.
const TWO_52: f64 = 4_503_599_627_370_496.0;

/// The mantissa bits of an `f64`, and the exponent bits of 1.0.
const MANTISSA: u64 = 0x000f_ffff_ffff_ffff;
const ONE_EXPONENT: u64 = 0x3ff0_0000_0000_0000;

/// `ln 2` in two parts: the first with trailing zero bits, so `n ln2_hi` is exact.
const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);

/// Taylor coefficients of `e^r` from `r^12` down to `r^0` (`r^13`'s starts the Horner loop).
const EXP_TAYLOR: [f64; 13] = [
    1.0 / 479_001_600.0,
    1.0 / 39_916_800.0,
    1.0 / 3_628_800.0,
    1.0 / 362_880.0,
    1.0 / 40_320.0,
    1.0 / 5_040.0,
    1.0 / 720.0,
    1.0 / 120.0,
    1.0 / 24.0,
    1.0 / 6.0,
    0.5,
    1.0,
    1.0,
];

/// Coefficients `1 / (2k + 1)` of the `atanh` series from `k = 9` down to 0 (`k = 10` starts
/// the Horner loop).
const LN_SERIES: [f64; 10] = [
    1.0 / 19.0,
    1.0 / 17.0,
    1.0 / 15.0,
    1.0 / 13.0,
    1.0 / 11.0,
    1.0 / 9.0,
    1.0 / 7.0,
    1.0 / 5.0,
    1.0 / 3.0,
    1.0,
];

/// Four lanes as a plain array: the baseline build.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct F4(pub(super) [f64; LANES]);

/// A mask of [`F4`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct M4([u64; LANES]);

impl F4 {
    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> F4 {
        F4(self.0.map(f))
    }

    #[inline(always)]
    fn zip(self, other: F4, f: impl Fn(f64, f64) -> f64) -> F4 {
        F4(std::array::from_fn(|k| f(self.0[k], other.0[k])))
    }

    #[inline(always)]
    fn bits(self, f: impl Fn(u64) -> u64) -> F4 {
        self.map(|x| f64::from_bits(f(x.to_bits())))
    }
}

impl Lanes for F4 {
    type Mask = M4;

    #[inline(always)]
    fn splat(v: f64) -> Self {
        F4([v; LANES])
    }

    #[inline(always)]
    fn load(column: &[f64], i: usize) -> Self {
        F4(column[i..i + LANES]
            .try_into()
            .expect("columns are padded to whole blocks"))
    }

    #[inline(always)]
    fn store(self, out: &mut [f64]) {
        out[..LANES].copy_from_slice(&self.0);
    }

    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(f64::sqrt)
    }

    #[inline(always)]
    fn max(self, other: Self) -> Self {
        self.zip(other, |a, b| if a > b { a } else { b })
    }

    #[inline(always)]
    fn min(self, other: Self) -> Self {
        self.zip(other, |a, b| if a < b { a } else { b })
    }

    #[inline(always)]
    fn gt(self, other: Self) -> M4 {
        M4(std::array::from_fn(|k| {
            if self.0[k] > other.0[k] {
                u64::MAX
            } else {
                0
            }
        }))
    }

    #[inline(always)]
    fn select(mask: M4, yes: Self, no: Self) -> Self {
        F4(std::array::from_fn(|k| {
            f64::from_bits((yes.0[k].to_bits() & mask.0[k]) | (no.0[k].to_bits() & !mask.0[k]))
        }))
    }

    #[inline(always)]
    fn pow2_shifted(t: Self) -> Self {
        t.bits(|b| {
            b.wrapping_sub(SHIFTER.to_bits())
                .wrapping_add(1023)
                .wrapping_shl(52)
        })
    }

    #[inline(always)]
    fn split(self) -> (Self, Self) {
        let e = self.bits(|b| (b >> 52) | TWO_52.to_bits()) - (TWO_52 + 1023.0);
        let m = self.bits(|b| (b & MANTISSA) | ONE_EXPONENT);
        (e, m)
    }
}

impl BitAnd for M4 {
    type Output = M4;
    #[inline(always)]
    fn bitand(self, other: M4) -> M4 {
        M4(std::array::from_fn(|k| self.0[k] & other.0[k]))
    }
}

impl Neg for F4 {
    type Output = F4;
    #[inline(always)]
    fn neg(self) -> F4 {
        self.map(|a| -a)
    }
}

macro_rules! array_ops {
    ($($trait:ident $method:ident $op:tt),*) => {$(
        impl $trait for F4 {
            type Output = F4;
            #[inline(always)]
            fn $method(self, other: F4) -> F4 {
                self.zip(other, |a, b| a $op b)
            }
        }
        impl $trait<f64> for F4 {
            type Output = F4;
            #[inline(always)]
            fn $method(self, other: f64) -> F4 {
                self.map(|a| a $op other)
            }
        }
    )*};
}

array_ops!(Add add +, Sub sub -, Mul mul *, Div div /);

#[cfg(target_arch = "x86_64")]
pub(super) use avx::Avx4;

#[cfg(target_arch = "x86_64")]
mod avx {
    //! Four lanes in one AVX register, for the kernels compiled with AVX2.
    //!
    //! Soundness: values of [`Avx4`] are created only inside the `#[target_feature(enable =
    //! "avx2")]` kernels, which run only after `is_x86_feature_detected!("avx2")`; every
    //! method is `#[inline(always)]`, so its intrinsics are inlined there.

    use super::{Lanes, LANES, MANTISSA, ONE_EXPONENT, SHIFTER, TWO_52};
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, Div, Mul, Neg, Sub};

    /// Four lanes in an AVX register.
    #[derive(Clone, Copy)]
    pub(in crate::frames::lobe) struct Avx4(__m256d);

    /// A mask of [`Avx4`].
    #[derive(Clone, Copy)]
    pub(in crate::frames::lobe) struct MaskAvx(__m256d);

    /// Runs AVX intrinsics; see the module's soundness note.
    macro_rules! avx {
        ($e:expr) => {
            // SAFETY: Avx4 values exist only in code that runs on processors with AVX2 (the
            // module's soundness note); the pointers of loads and stores come from slices
            // checked to hold LANES values.
            unsafe { $e }
        };
    }

    impl Lanes for Avx4 {
        type Mask = MaskAvx;

        #[inline(always)]
        fn splat(v: f64) -> Self {
            Avx4(avx!(_mm256_set1_pd(v)))
        }

        #[inline(always)]
        fn load(column: &[f64], i: usize) -> Self {
            let lanes = &column[i..i + LANES];
            Avx4(avx!(_mm256_loadu_pd(lanes.as_ptr())))
        }

        #[inline(always)]
        fn store(self, out: &mut [f64]) {
            let lanes = &mut out[..LANES];
            avx!(_mm256_storeu_pd(lanes.as_mut_ptr(), self.0))
        }

        #[inline(always)]
        fn sqrt(self) -> Self {
            Avx4(avx!(_mm256_sqrt_pd(self.0)))
        }

        #[inline(always)]
        fn max(self, other: Self) -> Self {
            // max_pd(a, b) is `a > b ? a : b`, as F4's.
            Avx4(avx!(_mm256_max_pd(self.0, other.0)))
        }

        #[inline(always)]
        fn min(self, other: Self) -> Self {
            Avx4(avx!(_mm256_min_pd(self.0, other.0)))
        }

        #[inline(always)]
        fn gt(self, other: Self) -> MaskAvx {
            MaskAvx(avx!(_mm256_cmp_pd::<_CMP_GT_OQ>(self.0, other.0)))
        }

        #[inline(always)]
        fn select(mask: MaskAvx, yes: Self, no: Self) -> Self {
            Avx4(avx!(_mm256_blendv_pd(no.0, yes.0, mask.0)))
        }

        #[inline(always)]
        fn pow2_shifted(t: Self) -> Self {
            avx!({
                let n = _mm256_sub_epi64(
                    _mm256_castpd_si256(t.0),
                    _mm256_set1_epi64x(SHIFTER.to_bits() as i64),
                );
                let e = _mm256_add_epi64(n, _mm256_set1_epi64x(1023));
                Avx4(_mm256_castsi256_pd(_mm256_slli_epi64::<52>(e)))
            })
        }

        #[inline(always)]
        fn split(self) -> (Self, Self) {
            avx!({
                let b = _mm256_castpd_si256(self.0);
                let e = _mm256_or_si256(
                    _mm256_srli_epi64::<52>(b),
                    _mm256_set1_epi64x(TWO_52.to_bits() as i64),
                );
                let e = Avx4(_mm256_castsi256_pd(e)) - (TWO_52 + 1023.0);
                let m = _mm256_or_si256(
                    _mm256_and_si256(b, _mm256_set1_epi64x(MANTISSA as i64)),
                    _mm256_set1_epi64x(ONE_EXPONENT as i64),
                );
                (e, Avx4(_mm256_castsi256_pd(m)))
            })
        }
    }

    impl BitAnd for MaskAvx {
        type Output = MaskAvx;
        #[inline(always)]
        fn bitand(self, other: MaskAvx) -> MaskAvx {
            MaskAvx(avx!(_mm256_and_pd(self.0, other.0)))
        }
    }

    impl Neg for Avx4 {
        type Output = Avx4;
        #[inline(always)]
        fn neg(self) -> Avx4 {
            Avx4(avx!(_mm256_xor_pd(self.0, _mm256_set1_pd(-0.0))))
        }
    }

    macro_rules! avx_ops {
        ($($trait:ident $method:ident $intrinsic:ident),*) => {$(
            impl $trait for Avx4 {
                type Output = Avx4;
                #[inline(always)]
                fn $method(self, other: Avx4) -> Avx4 {
                    Avx4(avx!($intrinsic(self.0, other.0)))
                }
            }
            impl $trait<f64> for Avx4 {
                type Output = Avx4;
                #[inline(always)]
                fn $method(self, other: f64) -> Avx4 {
                    Avx4(avx!($intrinsic(self.0, _mm256_set1_pd(other))))
                }
            }
        )*};
    }

    avx_ops!(Add add _mm256_add_pd, Sub sub _mm256_sub_pd, Mul mul _mm256_mul_pd, Div div _mm256_div_pd);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn first<V: Lanes>(v: V) -> f64 {
        let mut a = [0.0; LANES];
        v.store(&mut a);
        a[0]
    }

    fn exp_and_ln<V: Lanes>() {
        let mut worst: f64 = 0.0;
        for i in 0..20_000 {
            let x = -700.0 + 1400.0 * (i as f64 + 0.37) / 20_000.0;
            let (a, b) = (first(V::splat(x).exp()), x.exp());
            worst = worst.max(((a - b) / b).abs());
        }
        assert!(worst < 4e-16, "exp: {worst:e}");
        let mut worst: f64 = 0.0;
        for i in 0..20_000 {
            let x = 10f64.powf(-300.0 + 600.0 * (i as f64 + 0.37) / 20_000.0);
            let (a, b) = (first(V::splat(x).ln()), x.ln());
            worst = worst.max((a - b).abs() / b.abs().max(1.0));
        }
        assert!(worst < 4e-16, "ln: {worst:e}");
        // Near 1, where ln is small: absolute error.
        for i in 0..2_000 {
            let x = 0.9 + 0.2 * i as f64 / 2_000.0;
            assert!((first(V::splat(x).ln()) - x.ln()).abs() < 3e-17, "{x}");
        }
    }

    #[test]
    fn exp_and_ln_match_the_standard_library() {
        exp_and_ln::<F4>();
    }

    #[test]
    fn select_and_masks_pick_lane_by_lane() {
        let a = F4([1.0, -2.0, 3.0, f64::NAN]);
        let m = a.gt(F4::splat(0.0));
        let picked = F4::select(m, a, F4::splat(9.0));
        assert_eq!(&picked.0[..3], &[1.0, 9.0, 3.0]);
        // NaN compares false.
        assert_eq!(picked.0[3], 9.0);
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx_lanes_match_the_array_lanes_bit_for_bit() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        #[target_feature(enable = "avx2")]
        fn through<V: Lanes>(x: &[f64]) -> Vec<f64> {
            let mut out = vec![0.0; x.len() * 6];
            for i in (0..x.len()).step_by(LANES) {
                let v = V::load(x, i);
                let w = V::load(x, (i + LANES) % x.len());
                let results = [
                    v.exp(),
                    (v * v + 1e-300).ln(),
                    (v * v).sqrt() / (w + 0.5),
                    V::select(v.gt(w), -v, w - 2.0),
                    v.max(w).min(V::splat(0.25)),
                    V::splat((v * w).sum()),
                ];
                for (k, r) in results.into_iter().enumerate() {
                    r.store(&mut out[(k * x.len() + i)..]);
                }
            }
            out
        }
        let x: Vec<f64> = (0..64)
            .map(|i| ((i * 37 % 64) as f64 - 30.0) * 0.731)
            .collect();
        // SAFETY: the processor supports AVX2 (checked above).
        let (a, b) = unsafe { (through::<F4>(&x), through::<Avx4>(&x)) };
        assert!(a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()));
        // SAFETY: as above.
        unsafe { exp_and_ln_avx() };
        #[target_feature(enable = "avx2")]
        fn exp_and_ln_avx() {
            exp_and_ln::<Avx4>();
        }
    }
}
