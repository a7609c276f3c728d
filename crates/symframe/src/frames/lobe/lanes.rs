//! Sixteen `f64` lanes computed side by side, so the lobe fit's sample loops read as scalar
//! formulas and run as vector code: [`F64x16`] is a plain array (each operation a loop over the
//! lanes: the baseline build, and the reference), [`Avx2`] four AVX registers (processors with
//! AVX2 and FMA), [`Avx512`] two AVX-512 registers (processors with AVX-512F). Comparisons give
//! masks and [`Lanes::select`] blends by them: no branches. The logarithm and the exponential
//! are polynomials ([`Lanes::ln`], [`Lanes::exp`]): libm's scalar calls would stop the
//! vectorisation. Every operation is IEEE-exact lane by lane in all three (the fused
//! multiply-add rounded once in each), in the same order: identical results.
//!
//! Written by hand: the lobe fit is most of the estimator's time on dense rigs, and the
//! compiler does not vectorise the scalar formulas by itself, libm calls included. Sixteen lanes
//! rather than one register's four or eight: each block is a long chain of dependent operations
//! (the polynomials), and several registers side by side keep the processor's units busy
//! (docs/performance.md, "The default estimator with the lobe fit", "Sixteen lanes").

use std::ops::{Add, BitAnd, Div, Mul, Neg, Sub};

/// Number of lanes.
pub(super) const LANES: usize = 16;

/// [`LANES`] `f64` lanes and the operations the sample loops use.
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
    /// `self * a + b` rounded once (a fused multiply-add).
    fn mul_add(self, a: Self, b: Self) -> Self;
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
        // Pairwise, in a fixed order: the same in every build.
        let mut n = LANES;
        while n > 1 {
            n /= 2;
            for k in 0..n {
                a[k] = a[2 * k] + a[2 * k + 1];
            }
        }
        a[0]
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
            p = p.mul_add(r, Self::splat(c));
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
            p = p.mul_add(z, Self::splat(c));
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

/// The lanes as a plain array: the baseline build.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct F64x16(pub(super) [f64; LANES]);

/// A mask of [`F64x16`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct M16([u64; LANES]);

impl F64x16 {
    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> F64x16 {
        F64x16(self.0.map(f))
    }

    #[inline(always)]
    fn zip(self, other: F64x16, f: impl Fn(f64, f64) -> f64) -> F64x16 {
        F64x16(std::array::from_fn(|k| f(self.0[k], other.0[k])))
    }

    #[inline(always)]
    fn bits(self, f: impl Fn(u64) -> u64) -> F64x16 {
        self.map(|x| f64::from_bits(f(x.to_bits())))
    }
}

impl Lanes for F64x16 {
    type Mask = M16;

    #[inline(always)]
    fn splat(v: f64) -> Self {
        F64x16([v; LANES])
    }

    #[inline(always)]
    fn load(column: &[f64], i: usize) -> Self {
        F64x16(
            column[i..i + LANES]
                .try_into()
                .expect("columns are padded to whole blocks"),
        )
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
    fn mul_add(self, a: Self, b: Self) -> Self {
        F64x16(std::array::from_fn(|k| self.0[k].mul_add(a.0[k], b.0[k])))
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
    fn gt(self, other: Self) -> M16 {
        M16(std::array::from_fn(|k| {
            if self.0[k] > other.0[k] {
                u64::MAX
            } else {
                0
            }
        }))
    }

    #[inline(always)]
    fn select(mask: M16, yes: Self, no: Self) -> Self {
        F64x16(std::array::from_fn(|k| {
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

impl BitAnd for M16 {
    type Output = M16;
    #[inline(always)]
    fn bitand(self, other: M16) -> M16 {
        M16(std::array::from_fn(|k| self.0[k] & other.0[k]))
    }
}

impl Neg for F64x16 {
    type Output = F64x16;
    #[inline(always)]
    fn neg(self) -> F64x16 {
        self.map(|a| -a)
    }
}

macro_rules! array_ops {
    ($($trait:ident $method:ident $op:tt),*) => {$(
        impl $trait for F64x16 {
            type Output = F64x16;
            #[inline(always)]
            fn $method(self, other: F64x16) -> F64x16 {
                self.zip(other, |a, b| a $op b)
            }
        }
        impl $trait<f64> for F64x16 {
            type Output = F64x16;
            #[inline(always)]
            fn $method(self, other: f64) -> F64x16 {
                self.map(|a| a $op other)
            }
        }
    )*};
}

array_ops!(Add add +, Sub sub -, Mul mul *, Div div /);

#[cfg(target_arch = "x86_64")]
pub(super) use avx::{Avx2, Avx512};

#[cfg(target_arch = "x86_64")]
mod avx {
    //! The lanes in four AVX registers ([`Avx2`], for the kernels compiled with AVX2 and FMA)
    //! or in two AVX-512 registers ([`Avx512`], for those compiled with AVX-512F).
    //!
    //! Soundness: values of these types are created only inside the `#[target_feature]`
    //! kernels of their instruction set, which run only after `is_x86_feature_detected!` says
    //! the processor has it; every method is `#[inline(always)]`, so its intrinsics are
    //! inlined there.

    use super::{Lanes, LANES, MANTISSA, ONE_EXPONENT, SHIFTER, TWO_52};
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, Div, Mul, Neg, Sub};

    /// Runs SIMD intrinsics; see the module's soundness note.
    macro_rules! simd {
        ($e:expr) => {
            // SAFETY: values of these types exist only in code that runs on processors with
            // the instruction set (the module's soundness note); the pointers of loads and
            // stores come from slices checked to hold LANES values.
            unsafe { $e }
        };
    }

    /// The lanes in four AVX registers.
    #[derive(Clone, Copy)]
    pub(in crate::frames::lobe) struct Avx2([__m256d; 4]);

    impl Avx2 {
        /// `f` on each register.
        #[inline(always)]
        fn each(self, f: impl Fn(__m256d) -> __m256d) -> Self {
            let a = self.0;
            Avx2([f(a[0]), f(a[1]), f(a[2]), f(a[3])])
        }
        /// `f` on each register of `self` and the same of `o`.
        #[inline(always)]
        fn pair(self, o: Self, f: impl Fn(__m256d, __m256d) -> __m256d) -> Self {
            let (a, b) = (self.0, o.0);
            Avx2([f(a[0], b[0]), f(a[1], b[1]), f(a[2], b[2]), f(a[3], b[3])])
        }
    }
    /// A mask of [`Avx2`].
    #[derive(Clone, Copy)]
    pub(in crate::frames::lobe) struct MaskAvx2([__m256d; 4]);

    impl BitAnd for MaskAvx2 {
        type Output = MaskAvx2;
        #[inline(always)]
        fn bitand(self, o: MaskAvx2) -> MaskAvx2 {
            MaskAvx2(
                Avx2(self.0)
                    .pair(Avx2(o.0), |a, b| simd!(_mm256_and_pd(a, b)))
                    .0,
            )
        }
    }

    impl Lanes for Avx2 {
        type Mask = MaskAvx2;
        #[inline(always)]
        fn splat(v: f64) -> Self {
            let r = simd!(_mm256_set1_pd(v));
            Avx2([r; 4])
        }
        #[inline(always)]
        fn load(column: &[f64], i: usize) -> Self {
            let l = &column[i..i + LANES];
            simd!(Avx2([
                _mm256_loadu_pd(l.as_ptr()),
                _mm256_loadu_pd(l.as_ptr().add(4)),
                _mm256_loadu_pd(l.as_ptr().add(8)),
                _mm256_loadu_pd(l.as_ptr().add(12))
            ]))
        }
        #[inline(always)]
        fn store(self, out: &mut [f64]) {
            let l = &mut out[..LANES];
            simd!({
                for k in 0..4 {
                    _mm256_storeu_pd(l.as_mut_ptr().add(4 * k), self.0[k]);
                }
            })
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            self.each(|a| simd!(_mm256_sqrt_pd(a)))
        }
        #[inline(always)]
        fn mul_add(self, a: Self, b: Self) -> Self {
            let (x, y, z) = (self.0, a.0, b.0);
            simd!(Avx2([
                _mm256_fmadd_pd(x[0], y[0], z[0]),
                _mm256_fmadd_pd(x[1], y[1], z[1]),
                _mm256_fmadd_pd(x[2], y[2], z[2]),
                _mm256_fmadd_pd(x[3], y[3], z[3])
            ]))
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            self.pair(o, |a, b| simd!(_mm256_max_pd(a, b)))
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            self.pair(o, |a, b| simd!(_mm256_min_pd(a, b)))
        }
        #[inline(always)]
        fn gt(self, o: Self) -> MaskAvx2 {
            MaskAvx2(
                self.pair(o, |a, b| simd!(_mm256_cmp_pd::<_CMP_GT_OQ>(a, b)))
                    .0,
            )
        }
        #[inline(always)]
        fn select(m: MaskAvx2, yes: Self, no: Self) -> Self {
            let (m, y, n) = (m.0, yes.0, no.0);
            simd!(Avx2([
                _mm256_blendv_pd(n[0], y[0], m[0]),
                _mm256_blendv_pd(n[1], y[1], m[1]),
                _mm256_blendv_pd(n[2], y[2], m[2]),
                _mm256_blendv_pd(n[3], y[3], m[3])
            ]))
        }
        #[inline(always)]
        fn pow2_shifted(t: Self) -> Self {
            t.each(|t| {
                simd!({
                    let n = _mm256_sub_epi64(
                        _mm256_castpd_si256(t),
                        _mm256_set1_epi64x(SHIFTER.to_bits() as i64),
                    );
                    let e = _mm256_add_epi64(n, _mm256_set1_epi64x(1023));
                    _mm256_castsi256_pd(_mm256_slli_epi64::<52>(e))
                })
            })
        }
        #[inline(always)]
        fn split(self) -> (Self, Self) {
            let e = self.each(|x| {
                simd!(_mm256_castsi256_pd(_mm256_or_si256(
                    _mm256_srli_epi64::<52>(_mm256_castpd_si256(x)),
                    _mm256_set1_epi64x(TWO_52.to_bits() as i64)
                )))
            }) - (TWO_52 + 1023.0);
            let m = self.each(|x| {
                simd!(_mm256_castsi256_pd(_mm256_or_si256(
                    _mm256_and_si256(_mm256_castpd_si256(x), _mm256_set1_epi64x(MANTISSA as i64)),
                    _mm256_set1_epi64x(ONE_EXPONENT as i64)
                )))
            });
            (e, m)
        }
    }
    impl Neg for Avx2 {
        type Output = Avx2;
        #[inline(always)]
        fn neg(self) -> Avx2 {
            self.each(|a| simd!(_mm256_xor_pd(a, _mm256_set1_pd(-0.0))))
        }
    }

    /// The lanes in two AVX-512 registers.
    #[derive(Clone, Copy)]
    pub(in crate::frames::lobe) struct Avx512(__m512d, __m512d);

    impl Avx512 {
        /// `f` on each register.
        #[inline(always)]
        fn each(self, f: impl Fn(__m512d) -> __m512d) -> Self {
            Avx512(f(self.0), f(self.1))
        }
        /// `f` on each register of `self` and the same of `o`.
        #[inline(always)]
        fn pair(self, o: Self, f: impl Fn(__m512d, __m512d) -> __m512d) -> Self {
            Avx512(f(self.0, o.0), f(self.1, o.1))
        }
    }
    /// A mask of [`Avx512`].
    #[derive(Clone, Copy)]
    pub(in crate::frames::lobe) struct MaskAvx512(__mmask8, __mmask8);

    impl BitAnd for MaskAvx512 {
        type Output = MaskAvx512;
        #[inline(always)]
        fn bitand(self, o: MaskAvx512) -> MaskAvx512 {
            MaskAvx512(self.0 & o.0, self.1 & o.1)
        }
    }

    impl Lanes for Avx512 {
        type Mask = MaskAvx512;
        #[inline(always)]
        fn splat(v: f64) -> Self {
            let r = simd!(_mm512_set1_pd(v));
            Avx512(r, r)
        }
        #[inline(always)]
        fn load(column: &[f64], i: usize) -> Self {
            let lanes = &column[i..i + LANES];
            simd!(Avx512(
                _mm512_loadu_pd(lanes.as_ptr()),
                _mm512_loadu_pd(lanes.as_ptr().add(8))
            ))
        }
        #[inline(always)]
        fn store(self, out: &mut [f64]) {
            let lanes = &mut out[..LANES];
            simd!({
                _mm512_storeu_pd(lanes.as_mut_ptr(), self.0);
                _mm512_storeu_pd(lanes.as_mut_ptr().add(8), self.1)
            })
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            self.each(|a| simd!(_mm512_sqrt_pd(a)))
        }
        #[inline(always)]
        fn mul_add(self, a: Self, b: Self) -> Self {
            simd!(Avx512(
                _mm512_fmadd_pd(self.0, a.0, b.0),
                _mm512_fmadd_pd(self.1, a.1, b.1)
            ))
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            self.pair(o, |a, b| simd!(_mm512_max_pd(a, b)))
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            self.pair(o, |a, b| simd!(_mm512_min_pd(a, b)))
        }
        #[inline(always)]
        fn gt(self, o: Self) -> MaskAvx512 {
            simd!(MaskAvx512(
                _mm512_cmp_pd_mask::<_CMP_GT_OQ>(self.0, o.0),
                _mm512_cmp_pd_mask::<_CMP_GT_OQ>(self.1, o.1)
            ))
        }
        #[inline(always)]
        fn select(m: MaskAvx512, yes: Self, no: Self) -> Self {
            simd!(Avx512(
                _mm512_mask_blend_pd(m.0, no.0, yes.0),
                _mm512_mask_blend_pd(m.1, no.1, yes.1)
            ))
        }
        #[inline(always)]
        fn pow2_shifted(t: Self) -> Self {
            t.each(|t| {
                simd!({
                    let n = _mm512_sub_epi64(
                        _mm512_castpd_si512(t),
                        _mm512_set1_epi64(SHIFTER.to_bits() as i64),
                    );
                    let e = _mm512_add_epi64(n, _mm512_set1_epi64(1023));
                    _mm512_castsi512_pd(_mm512_slli_epi64::<52>(e))
                })
            })
        }
        #[inline(always)]
        fn split(self) -> (Self, Self) {
            let e = self.each(|x| {
                simd!(_mm512_castsi512_pd(_mm512_or_si512(
                    _mm512_srli_epi64::<52>(_mm512_castpd_si512(x)),
                    _mm512_set1_epi64(TWO_52.to_bits() as i64)
                )))
            }) - (TWO_52 + 1023.0);
            let m = self.each(|x| {
                simd!(_mm512_castsi512_pd(_mm512_or_si512(
                    _mm512_and_si512(_mm512_castpd_si512(x), _mm512_set1_epi64(MANTISSA as i64)),
                    _mm512_set1_epi64(ONE_EXPONENT as i64)
                )))
            });
            (e, m)
        }
    }
    impl Neg for Avx512 {
        type Output = Avx512;
        #[inline(always)]
        fn neg(self) -> Avx512 {
            self.each(|a| {
                simd!(_mm512_castsi512_pd(_mm512_xor_si512(
                    _mm512_castpd_si512(a),
                    _mm512_set1_epi64(i64::MIN)
                )))
            })
        }
    }

    macro_rules! simd_ops {
        ($($trait:ident $method:ident $avx:ident $avx512:ident),*) => {$(
            impl $trait for Avx2 {
                type Output = Avx2;
                #[inline(always)]
                fn $method(self, other: Avx2) -> Avx2 {
                    self.pair(other, |a, b| simd!($avx(a, b)))
                }
            }
            impl $trait<f64> for Avx2 {
                type Output = Avx2;
                #[inline(always)]
                fn $method(self, other: f64) -> Avx2 {
                    let b = simd!(_mm256_set1_pd(other));
                    self.each(|a| simd!($avx(a, b)))
                }
            }
            impl $trait for Avx512 {
                type Output = Avx512;
                #[inline(always)]
                fn $method(self, other: Avx512) -> Avx512 {
                    self.pair(other, |a, b| simd!($avx512(a, b)))
                }
            }
            impl $trait<f64> for Avx512 {
                type Output = Avx512;
                #[inline(always)]
                fn $method(self, other: f64) -> Avx512 {
                    let b = simd!(_mm512_set1_pd(other));
                    self.each(|a| simd!($avx512(a, b)))
                }
            }
        )*};
    }

    simd_ops!(
        Add add _mm256_add_pd _mm512_add_pd,
        Sub sub _mm256_sub_pd _mm512_sub_pd,
        Mul mul _mm256_mul_pd _mm512_mul_pd,
        Div div _mm256_div_pd _mm512_div_pd
    );
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
        exp_and_ln::<F64x16>();
    }

    #[test]
    fn select_and_masks_pick_lane_by_lane() {
        let mut a = F64x16::splat(5.0);
        a.0[..4].copy_from_slice(&[1.0, -2.0, 3.0, f64::NAN]);
        let m = a.gt(F64x16::splat(0.0));
        let picked = F64x16::select(m, a, F64x16::splat(9.0));
        assert_eq!(&picked.0[..3], &[1.0, 9.0, 3.0]);
        // NaN compares false.
        assert_eq!(picked.0[3], 9.0);
    }

    /// Every operation on awkward values, through lanes of type `V`.
    #[inline(always)]
    fn through<V: Lanes>(x: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; x.len() * 7];
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
                v.mul_add(w, V::splat(1.0 / 3.0)),
            ];
            for (k, r) in results.into_iter().enumerate() {
                r.store(&mut out[(k * x.len() + i)..]);
            }
        }
        out
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_simd_lanes_match_the_array_lanes_bit_for_bit() {
        use std::arch::is_x86_feature_detected as has;
        #[target_feature(enable = "avx2,fma")]
        fn avx2(x: &[f64]) -> Vec<f64> {
            exp_and_ln::<Avx2>();
            through::<Avx2>(x)
        }
        #[target_feature(enable = "avx512f")]
        fn avx512(x: &[f64]) -> Vec<f64> {
            exp_and_ln::<Avx512>();
            through::<Avx512>(x)
        }
        let x: Vec<f64> = (0..64)
            .map(|i| ((i * 37 % 64) as f64 - 30.0) * 0.731)
            .chain([f64::NAN, f64::INFINITY, -0.0, 1e-310])
            .chain((0..12).map(|i| i as f64))
            .collect();
        let bits = |v: Vec<f64>| v.into_iter().map(f64::to_bits).collect::<Vec<_>>();
        let baseline = bits(through::<F64x16>(&x));
        if has!("avx2") && has!("fma") {
            // SAFETY: the processor supports AVX2 and FMA (checked just above).
            assert_eq!(bits(unsafe { avx2(&x) }), baseline);
        }
        if has!("avx512f") {
            // SAFETY: the processor supports AVX-512F (checked just above).
            assert_eq!(bits(unsafe { avx512(&x) }), baseline);
        }
    }
}
