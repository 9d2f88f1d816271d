//! Runtime CPU dispatch for the hot per-pixel kernels (the blur and the sRGB encoding).
//!
//! A default build targets baseline x86-64 (SSE2: four `f32` lanes, no fused multiply-add).
//! Almost every x86-64 machine in use has AVX2 and FMA (eight lanes, one rounding per
//! multiply-add), so the kernels are compiled twice, once for each, and the wider one is
//! chosen at run time when the processor has it — no `-C target-cpu` needed.
//!
//! The kernels are ordinary safe, generic Rust (`#[inline(always)]`, loops over small
//! fixed-size arrays that the compiler vectorises); [`Isa::run`] compiles a closure that
//! calls them inside a function with the AVX2 and FMA target features enabled. The only
//! `unsafe` of the crate is the call of that function, here, after checking that the
//! processor has the features. Kernels take a `const FMA: bool` to use [`madd`] with a
//! fused multiply-add only where the instruction exists (elsewhere `f32::mul_add` would
//! be a slow library call); results of the two paths differ only in rounding, which the
//! kernels' tests bound.
#![allow(unsafe_code)]

/// An instruction-set level the kernels are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Isa {
    /// The build's target (baseline x86-64: SSE2), separate multiply and add.
    Baseline,
    /// AVX2 with fused multiply-add (x86-64 only, when the processor has both).
    Avx2Fma,
}

impl Isa {
    /// The level the kernels use: the best this processor supports, unless the
    /// environment variable `VISADAPT_SIMD` is `baseline` (for comparisons; read once).
    pub(crate) fn detect() -> Isa {
        static CHOSEN: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
        *CHOSEN.get_or_init(|| {
            if std::env::var_os("VISADAPT_SIMD").is_some_and(|v| v == "baseline") {
                Isa::Baseline
            } else {
                Isa::best()
            }
        })
    }

    /// The best level this processor supports.
    fn best() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Isa::Avx2Fma;
            }
        }
        Isa::Baseline
    }

    /// Every level this processor can run (for tests comparing the paths).
    #[cfg(test)]
    pub(crate) fn all_available() -> Vec<Isa> {
        let mut v = vec![Isa::Baseline];
        if Isa::best() == Isa::Avx2Fma {
            v.push(Isa::Avx2Fma);
        }
        v
    }

    /// Run `f` compiled for this level. `f` should call `#[inline(always)]` kernels so
    /// that they are compiled inside the target-feature function.
    ///
    /// # Panics
    /// If the level is not supported by this processor.
    #[inline]
    pub(crate) fn run<R>(self, f: impl FnOnce() -> R) -> R {
        match self {
            Isa::Baseline => f(),
            Isa::Avx2Fma => {
                #[cfg(target_arch = "x86_64")]
                {
                    assert!(
                        Isa::best() == Isa::Avx2Fma,
                        "AVX2/FMA kernels requested on a processor without them"
                    );
                    // SAFETY: `with_avx2_fma` only requires the processor to support
                    // AVX2 and FMA, which was checked on the line above.
                    unsafe { with_avx2_fma(f) }
                }
                #[cfg(not(target_arch = "x86_64"))]
                {
                    unreachable!("AVX2/FMA is x86-64 only")
                }
            }
        }
    }
}

/// `f` compiled with AVX2 and FMA enabled (it is inlined here).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn with_avx2_fma<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// `a·b + c`, fused (one rounding) when `FMA`.
#[inline(always)]
pub(crate) fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_levels_compute_the_same_sum() {
        let v: Vec<f32> = (0..1000).map(|i| i as f32 * 0.5).collect();
        for isa in Isa::all_available() {
            let s: f32 = isa.run(|| v.iter().sum());
            assert_eq!(s, 249_750.0, "{isa:?}");
        }
        assert_eq!(madd::<true>(2.0, 3.0, 1.0), 7.0);
        assert_eq!(madd::<false>(2.0, 3.0, 1.0), 7.0);
        // One rounding instead of two: (1 + 2⁻¹²)² − 1 − 2⁻¹¹ = 2⁻²⁴ exactly.
        let a = 1.0 + f32::EPSILON * 2048.0;
        let c = -(1.0 + f32::EPSILON * 4096.0);
        assert_eq!(madd::<true>(a, a, c), f32::EPSILON / 2.0);
        assert_eq!(madd::<false>(a, a, c), 0.0);
    }
}
