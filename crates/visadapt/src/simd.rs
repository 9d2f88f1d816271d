//! Runtime CPU dispatch for the hot per-pixel kernels (the blur and the sRGB encoding).
//!
//! A default build targets baseline x86-64 (SSE2: four `f32` lanes, no fused multiply-add).
//! Almost every x86-64 machine in use has AVX2 and FMA (eight lanes, one rounding per
//! multiply-add), many AVX-512 (sixteen lanes), so the kernels are compiled for each, and
//! the widest is chosen at run time when the processor has it — no `-C target-cpu`
//! needed.
//!
//! The kernels are ordinary safe, generic Rust (`#[inline(always)]`, loops over small
//! fixed-size arrays that the compiler vectorises); [`at_level!`] compiles a closure that
//! calls them inside a function with the level's target features enabled. The `unsafe`
//! of the crate is here: the call of that function, after checking that the processor
//! has the features, and one instruction the compiler does not make of portable code
//! (an 8-lane permute, [`Avx2::permute8`], for the table look-ups of local adaptation:
//! `local_stages/mapping/1920x1080` at the AVX2 level took 6.1 ms with it against
//! 10.0–11.1 ms with selects, two rounds in turn), and the running byte sums of
//! OpenEXR's ZIP predictor ([`exr_unpredict_pairs`], SSE2).
//! Kernels take a `const FMA: bool` to use [`madd`] with a fused multiply-add only where
//! the instruction exists (elsewhere `f32::mul_add` would be a slow library call);
//! results of the two paths differ only in rounding, which the kernels' tests bound.
//!
//! The closures are marked `#[inline(always)]` (by the macros, [`at_level!`] and
//! [`run_inlined!`], the only way the crate calls [`Isa::run`]). Without the mark, whether
//! a closure is inlined into its target-feature function is up to the optimiser and to
//! how the crate is split into code-generation units: with this workspace's release
//! profile (one unit, thin LTO) it always was, but a crate depending on this one builds it
//! with Cargo's default profile (16 units, no LTO), where the closures were compiled on
//! their own, for the baseline, and every fused multiply-add became a call of the C
//! library's `fmaf`: the 1080p acuity blur took 78 ms instead of 4.2 ms (criterion, the
//! `operator` benchmarks built in a separate crate with the default profile, 2 cores).
#![allow(unsafe_code)]

/// `$body` compiled for the instruction-set level `$isa` (an [`Isa`] value chosen at run
/// time): one `#[inline(always)]` closure per level, each inlined into its own
/// target-feature function (a single closure run at all three levels would be compiled
/// once, for the baseline). The long form gives each level its own expression, for
/// kernels generic over the vector width or over fused multiply-adds.
macro_rules! at_level {
    ($isa:expr, $body:expr $(,)?) => {
        $crate::simd::at_level!($isa, avx512: $body, avx2: $body, baseline: $body)
    };
    ($isa:expr, avx512: $a:expr, avx2: $b:expr, baseline: $c:expr $(,)?) => {
        match $isa {
            $crate::simd::Isa::Avx512Fma => $crate::simd::run_inlined!(Avx512Fma, $a),
            $crate::simd::Isa::Avx2Fma => $crate::simd::run_inlined!(Avx2Fma, $b),
            $crate::simd::Isa::Baseline => $c,
        }
    };
}
pub(crate) use at_level;

/// `$body` compiled for the one level `Isa::$level`, in an `#[inline(always)]` closure.
macro_rules! run_inlined {
    ($level:ident, $body:expr) => {
        $crate::simd::Isa::$level.run(
            #[inline(always)]
            || $body,
        )
    };
}
pub(crate) use run_inlined;

/// An instruction-set level the kernels are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Isa {
    /// The build's target (baseline x86-64: SSE2), separate multiply and add.
    Baseline,
    /// AVX2 with fused multiply-add (x86-64 only, when the processor has both).
    Avx2Fma,
    /// AVX-512 (foundation) with fused multiply-add: sixteen lanes per vector (x86-64
    /// only). The same operations as [`Isa::Avx2Fma`], so the same results bit for bit;
    /// used by the exact-kernel blur (the recursive filter runs its AVX2 build here: its
    /// 32 lanes are exactly the four AVX2 vectors that hide each step's latency; so does
    /// local adaptation's mapping pass, measured faster: [`Isa::at_most_avx2`]).
    Avx512Fma,
}

impl Isa {
    /// The level the kernels use: the best this processor supports, unless the
    /// environment variable `VISADAPT_SIMD` is `baseline` or `avx2` (a cap, for
    /// comparisons; read once).
    pub(crate) fn detect() -> Isa {
        static CHOSEN: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
        *CHOSEN.get_or_init(|| {
            let best = Isa::best();
            match std::env::var_os("VISADAPT_SIMD") {
                Some(v) if v == "baseline" => Isa::Baseline,
                Some(v) if v == "avx2" && best == Isa::Avx512Fma => Isa::Avx2Fma,
                _ => best,
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
                if std::arch::is_x86_feature_detected!("avx512f") {
                    return Isa::Avx512Fma;
                }
                return Isa::Avx2Fma;
            }
        }
        Isa::Baseline
    }

    /// Every level this processor can run (for tests comparing the paths).
    #[cfg(test)]
    pub(crate) fn all_available() -> Vec<Isa> {
        match Isa::best() {
            Isa::Baseline => vec![Isa::Baseline],
            Isa::Avx2Fma => vec![Isa::Baseline, Isa::Avx2Fma],
            Isa::Avx512Fma => vec![Isa::Baseline, Isa::Avx2Fma, Isa::Avx512Fma],
        }
    }

    /// Run `f` compiled for this level. `f` should be an `#[inline(always)]` closure that
    /// calls `#[inline(always)]` kernels, so that they are compiled inside the
    /// target-feature function whatever the build profile: call it through [`at_level!`]
    /// or [`run_inlined!`], which mark the closure.
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
                        Isa::best() != Isa::Baseline,
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
            Isa::Avx512Fma => {
                #[cfg(target_arch = "x86_64")]
                {
                    assert!(
                        Isa::best() == Isa::Avx512Fma,
                        "AVX-512 kernels requested on a processor without them"
                    );
                    // SAFETY: `with_avx512_fma` only requires the processor to support
                    // AVX-512F, AVX2 and FMA, which was checked on the line above.
                    unsafe { with_avx512_fma(f) }
                }
                #[cfg(not(target_arch = "x86_64"))]
                {
                    unreachable!("AVX-512 is x86-64 only")
                }
            }
        }
    }

    /// Whether the kernels use fused multiply-adds at this level.
    #[cfg(test)]
    pub(crate) fn fma(self) -> bool {
        self != Isa::Baseline
    }
}

/// Proof that the processor runs AVX2, for the one explicit instruction of the kernels:
/// a lane permute ([`Avx2::permute8`]), which the compiler does not make of safe code (a
/// per-lane index into an 8-value table becomes a chain of selects or a gather). Only
/// [`Isa::avx2`] makes one, after detection.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx2(());

impl Isa {
    /// The proof of AVX2 when this is [`Isa::Avx2Fma`] (the processor has it).
    pub(crate) fn avx2(self) -> Option<Avx2> {
        (self == Isa::Avx2Fma && Isa::best() != Isa::Baseline).then_some(Avx2(()))
    }

    /// This level, or [`Isa::Avx2Fma`] in place of [`Isa::Avx512Fma`]: for the kernels
    /// whose AVX2 build measured faster.
    pub(crate) fn at_most_avx2(self) -> Isa {
        match self {
            Isa::Avx512Fma => Isa::Avx2Fma,
            other => other,
        }
    }
}

impl Avx2 {
    /// `table[index[l]]` for each of the 8 lanes (only the low three bits of an index
    /// count): one `vpermps` (`vpermilps` permutes only within 128-bit halves). Inlined
    /// into AVX2 kernels ([`at_level!`]); elsewhere a call.
    #[inline(always)]
    pub(crate) fn permute8(self, table: &[f32; 8], index: &[u32; 8]) -> [f32; 8] {
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: an `Avx2` exists only when the processor supports AVX2
            // (`Isa::avx2`), all `permute8_avx2` requires.
            unsafe { permute8_avx2(table, index) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (table, index);
            unreachable!("AVX2 is x86-64 only")
        }
    }
}

/// [`Avx2::permute8`]'s instruction.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn permute8_avx2(table: &[f32; 8], index: &[u32; 8]) -> [f32; 8] {
    use std::arch::x86_64::{
        __m256i, _mm256_loadu_ps, _mm256_loadu_si256, _mm256_permutevar8x32_ps, _mm256_storeu_ps,
    };
    let mut out = [0f32; 8];
    // SAFETY: the loads read 8 values of `table` and `index` and the store writes 8 of
    // `out`, each an array of exactly 8 (unaligned access is allowed).
    unsafe {
        let t = _mm256_loadu_ps(table.as_ptr());
        let i = _mm256_loadu_si256(index.as_ptr().cast::<__m256i>());
        _mm256_storeu_ps(out.as_mut_ptr(), _mm256_permutevar8x32_ps(t, i));
    }
    out
}

/// OpenEXR's ZIP predictor undone on the two halves of a block at once (see
/// `io::exr::reconstruct`): for `k` below the returned count, `dst[2k] = ta[k]` and
/// `dst[2k + 1] = tb[k]`, where `ta[k] = ta[k − 1] + first[k] − 128` from `ta[−1] = a`
/// and `tb` likewise over `second` from `b` (wrapping bytes). Returns that count (16
/// bytes of each half at a time, so all of `second` but its last `len % 16`) and the
/// last `ta` and `tb` (`a` and `b` when none). `first` is at least as long as `second`,
/// `dst` twice as long.
///
/// On x86-64, with SSE2 (part of every x86-64 processor): the running sum of 16 bytes in
/// four shifted additions, then the sum so far added to all sixteen; the halves
/// interleaved by two unpacks. The compiler does not make this of portable code (a
/// version on arrays of 16 bytes ran 6× slower than the scalar loop), and against the
/// scalar loop (two running sums, one byte of each per step) it took 2.0–3.1 ms instead
/// of 7.8–8.7 ms for the 68 blocks of a 1080p half-float ZIP16 frame (scratch timing,
/// three rounds in turn, load about 1.4). Elsewhere nothing is done: `(0, a, b)`.
pub(crate) fn exr_unpredict_pairs(
    first: &[u8],
    second: &[u8],
    a: u8,
    b: u8,
    dst: &mut [u8],
) -> (usize, u8, u8) {
    assert!(first.len() >= second.len() && dst.len() >= 2 * second.len());
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: SSE2 is part of the x86-64 architecture: every processor that runs
        // this build has it.
        unsafe { exr_unpredict_pairs_sse2(first, second, a, b, dst) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (first, second, dst);
        (0, a, b)
    }
}

/// [`exr_unpredict_pairs`] with SSE2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse2")]
fn exr_unpredict_pairs_sse2(
    first: &[u8],
    second: &[u8],
    a: u8,
    b: u8,
    dst: &mut [u8],
) -> (usize, u8, u8) {
    use std::arch::x86_64::{
        __m128i, _mm_add_epi8, _mm_cvtsi128_si32, _mm_loadu_si128, _mm_set1_epi8,
        _mm_shuffle_epi32, _mm_slli_si128, _mm_storeu_si128, _mm_unpackhi_epi8, _mm_unpackhi_epi16,
        _mm_unpacklo_epi8, _mm_xor_si128,
    };
    let bias = _mm_set1_epi8(i8::MIN);
    // x[i] − 128 (that is, x[i] ^ 0x80) summed over lanes 0..=i, plus `carry` in each.
    let running = |x: __m128i, carry: __m128i| {
        let x = _mm_xor_si128(x, bias);
        let x = _mm_add_epi8(x, _mm_slli_si128::<1>(x));
        let x = _mm_add_epi8(x, _mm_slli_si128::<2>(x));
        let x = _mm_add_epi8(x, _mm_slli_si128::<4>(x));
        let x = _mm_add_epi8(x, _mm_slli_si128::<8>(x));
        _mm_add_epi8(x, carry)
    };
    // Lane 15 in all sixteen lanes.
    let last = |x: __m128i| {
        let x = _mm_unpackhi_epi8(x, x);
        let x = _mm_unpackhi_epi16(x, x);
        _mm_shuffle_epi32::<0xff>(x)
    };
    let (mut ca, mut cb) = (_mm_set1_epi8(a as i8), _mm_set1_epi8(b as i8));
    let steps = second.len() / 16;
    for ((out, da), db) in dst
        .chunks_exact_mut(32)
        .zip(first.chunks_exact(16))
        .zip(second.chunks_exact(16))
    {
        // SAFETY: the loads read the 16 bytes of `da` and of `db`, the stores write the
        // 32 of `out` (unaligned access is allowed).
        unsafe {
            let ta = running(_mm_loadu_si128(da.as_ptr().cast()), ca);
            let tb = running(_mm_loadu_si128(db.as_ptr().cast()), cb);
            _mm_storeu_si128(out.as_mut_ptr().cast(), _mm_unpacklo_epi8(ta, tb));
            _mm_storeu_si128(out[16..].as_mut_ptr().cast(), _mm_unpackhi_epi8(ta, tb));
            (ca, cb) = (last(ta), last(tb));
        }
    }
    (
        16 * steps,
        _mm_cvtsi128_si32(ca) as u8,
        _mm_cvtsi128_si32(cb) as u8,
    )
}

/// `f` compiled with AVX-512F, AVX2 and FMA enabled (it is inlined here).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
#[inline]
fn with_avx512_fma<R>(f: impl FnOnce() -> R) -> R {
    f()
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
            let s: f32 = at_level!(isa, v.iter().sum());
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
