//! Runtime CPU dispatch for the hot per-pixel kernels (the blur and the sRGB encoding).
//!
//! A default build targets baseline x86-64 (SSE2: four `f32` lanes, no fused multiply-add).
//! Almost every x86-64 machine in use has AVX2 and FMA (eight lanes, one rounding per
//! multiply-add), many AVX-512 (sixteen lanes), so the kernels are compiled for each, and
//! the widest is chosen at run time when the processor has it — no `-C target-cpu`
//! needed.
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
    /// AVX-512 (foundation) with fused multiply-add: sixteen lanes per vector (x86-64
    /// only). The same operations as [`Isa::Avx2Fma`], so the same results bit for bit;
    /// used by the exact-kernel blur (the recursive filter runs its AVX2 build here: its
    /// 32 lanes are exactly the four AVX2 vectors that hide each step's latency).
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

/// Rows in a tile of [`column_tile_avx512`].
pub(crate) const TILE_ROWS: usize = 4;
/// Input rows a tile of [`column_tile_avx512`] can read: [`TILE_ROWS`] plus twice the
/// largest radius 10 (28 vectors with the accumulators, within AVX-512's 32 registers).
pub(crate) const TILE_INPUTS: usize = TILE_ROWS + 20;
/// Columns of a tile of [`column_tile_avx512`] (a block of the blur's pass down the ring).
pub(crate) const TILE_COLUMNS: usize = 128;

/// The symmetric kernel `taps[0..=R]` (centre first) down `TILE_ROWS` output rows of
/// `TILE_COLUMNS` columns at once, with AVX-512: output row `k` is
/// `taps[0]·rows[k + R] + Σ_j taps[j]·(rows[k + R − j] + rows[k + R + j])`, accumulated
/// in the order of `blur::fir::tap_sum` with fused multiply-adds (so bit for bit its
/// result on the FMA levels), written to `out[at + k·width..][..TILE_COLUMNS]`. Each
/// input vector is loaded once for all four output rows and held in a register.
///
/// # Panics
/// If the processor lacks AVX-512F, or `R > 10`, or `out` is too short.
pub(crate) fn column_tile_avx512<const R: usize>(
    taps: &[f32; 11],
    rows: &[&[f32; TILE_COLUMNS]; TILE_INPUTS],
    out: &mut [f32],
    at: usize,
    width: usize,
) {
    const { assert!(TILE_ROWS + 2 * R <= TILE_INPUTS) };
    assert!(
        Isa::best() == Isa::Avx512Fma,
        "AVX-512 kernels requested on a processor without them"
    );
    assert!(out.len() >= at + (TILE_ROWS - 1) * width + TILE_COLUMNS);
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `column_tile_kernel` only requires AVX-512F, AVX2 and FMA, checked above.
    unsafe {
        column_tile_kernel::<R>(taps, rows, out, at, width)
    }
}

/// [`column_tile_avx512`] compiled for AVX-512.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
fn column_tile_kernel<const R: usize>(
    taps: &[f32; 11],
    rows: &[&[f32; TILE_COLUMNS]; TILE_INPUTS],
    out: &mut [f32],
    at: usize,
    width: usize,
) {
    use std::arch::x86_64::{
        __m512, _mm512_add_ps, _mm512_fmadd_ps, _mm512_loadu_ps, _mm512_mul_ps, _mm512_set1_ps,
        _mm512_setzero_ps, _mm512_storeu_ps,
    };
    const LANES: usize = 16;
    let load = |v: &[f32; LANES]| -> __m512 {
        // SAFETY: `v` is 16 readable floats; the enclosing function has AVX-512F.
        unsafe { _mm512_loadu_ps(v.as_ptr()) }
    };
    let h: [__m512; 11] = taps.map(|t| _mm512_set1_ps(t));
    for c in (0..TILE_COLUMNS).step_by(LANES) {
        let mut xs = [_mm512_setzero_ps(); TILE_INPUTS];
        for (x, row) in xs.iter_mut().zip(rows).take(TILE_ROWS + 2 * R) {
            *x = load(row[c..c + LANES].try_into().expect("a vector"));
        }
        let mut acc: [__m512; TILE_ROWS] = std::array::from_fn(|k| _mm512_mul_ps(h[0], xs[k + R]));
        // The taps written out (a loop over them was left rolled at R = 9 and 10, its
        // inputs then kept in memory); `j ≤ R` is decided at compile time.
        macro_rules! taps {
            ($($j:literal)*) => {$(
                if $j <= R {
                    for (k, acc) in acc.iter_mut().enumerate() {
                        let pair = _mm512_add_ps(xs[k + R - $j], xs[k + R + $j]);
                        *acc = _mm512_fmadd_ps(h[$j], pair, *acc);
                    }
                }
            )*};
        }
        const { assert!(R <= 10) };
        taps!(1 2 3 4 5 6 7 8 9 10);
        for (k, acc) in acc.into_iter().enumerate() {
            let dst: &mut [f32; LANES] = (&mut out[at + k * width + c..][..LANES])
                .try_into()
                .expect("a vector");
            // SAFETY: `dst` is 16 writable floats; the enclosing function has AVX-512F.
            unsafe { _mm512_storeu_ps(dst.as_mut_ptr(), acc) }
        }
    }
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
