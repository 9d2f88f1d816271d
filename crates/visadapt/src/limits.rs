//! Size and memory limits, checked against what a file declares before any memory is
//! allocated for it, so that a corrupt or hostile header cannot make us allocate gigabytes
//! (or abort: a failed allocation ends the process, it cannot be caught).

use crate::error::{Error, LimitsExceeded, Result};

/// Largest luminance (cd/m², or scotopic cd/m²) a parameter may have: 1e19, just below
/// √`f32::MAX` ≈ 1.84e19, so that the product of two such quantities stays finite in the
/// f32 pipeline. Our bound; the brightest natural luminance, the sun's disc, is about
/// 1.6e9 cd/m² (Wyszecki & Stiles, *Color Science*, 2nd ed., 1982, Table 1(4.4)).
pub const MAX_LUMINANCE_CD_M2: f64 = 1e19;

/// Smallest luminance (cd/m², or scotopic cd/m²) a parameter may have: 1e-19, the
/// reciprocal of [`MAX_LUMINANCE_CD_M2`] and just above √ of `f32::MIN_POSITIVE` ≈
/// 1.08e-19, so that it is a normal `f32` (1e-300 became 0 in the f32 pipeline, a
/// division by zero) and the ratio of any two parameters stays finite. Our bound; the
/// absolute threshold of vision lies near 1e-6 cd/m² (Hecht, Shlaer & Pirenne 1942).
pub const MIN_LUMINANCE_CD_M2: f64 = 1e-19;

/// `v` as `f32`, saturating finite values at ±`f32::MAX` instead of overflowing to ±Inf
/// (`as` rounds them to infinity); Inf and NaN pass through.
#[inline(always)]
pub fn saturating_f32(v: f64) -> f32 {
    if v.is_finite() {
        v.clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
    } else {
        v as f32
    }
}

/// `v` for a message: in exponent form when it is very large or very small.
fn number(v: f64) -> String {
    if v.is_finite() && v != 0.0 && !(1e-6..1e16).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// Whether `v` lies in [[`MIN_LUMINANCE_CD_M2`], [`MAX_LUMINANCE_CD_M2`]] (NaN does not).
#[inline]
fn in_carried_range(v: f64) -> bool {
    (MIN_LUMINANCE_CD_M2..=MAX_LUMINANCE_CD_M2).contains(&v)
}

/// Check a luminance parameter named `name` (as the CLI spells it): finite and between
/// [`MIN_LUMINANCE_CD_M2`] and [`MAX_LUMINANCE_CD_M2`]. Returns it.
pub fn check_luminance(name: &'static str, v: f64) -> Result<f64> {
    if in_carried_range(v) {
        Ok(v)
    } else {
        Err(Error::invalid(
            name,
            number(v),
            format!(
                "must be a positive luminance from {MIN_LUMINANCE_CD_M2:e} to {MAX_LUMINANCE_CD_M2:e} cd/m² (the range the f32 pipeline carries)"
            ),
        ))
    }
}

/// Check a positive factor named `name` (e.g. `scale`): finite and between
/// [`MIN_LUMINANCE_CD_M2`] and [`MAX_LUMINANCE_CD_M2`] (it multiplies luminances).
pub fn check_factor(name: &'static str, v: f64) -> Result<f64> {
    if in_carried_range(v) {
        Ok(v)
    } else {
        Err(Error::invalid(
            name,
            number(v),
            format!(
                "must be a positive number from {MIN_LUMINANCE_CD_M2:e} to {MAX_LUMINANCE_CD_M2:e}"
            ),
        ))
    }
}

/// Upper bounds on images the readers accept and on the memory they may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest accepted `width × height`, in pixels. The default, 2^28 (268 M pixels,
    /// e.g. 16384 × 16384), needs about 5 GiB for the five f32 planes of an
    /// [`HdrImage`](crate::HdrImage).
    pub max_pixels: u64,
    /// Memory budget in bytes for everything whose size the input controls: the file's
    /// bytes held in memory, the decoded planes, each decompressed block and the blocks
    /// in flight together. Checked before each such allocation. The default,
    /// [`Limits::DEFAULT_MAX_MEMORY_BYTES`], is half the 24 GiB of the machines the
    /// project is built on, and holds an image at the default pixel limit (2^28 pixels)
    /// together with the working set of `visadapt map` (measured 13-16 bytes per pixel
    /// with [`operator::map_owned`](crate::operator::map_owned), about 4 GiB at the
    /// limit; [`operator::map`](crate::operator::map), which keeps its input, needs 12
    /// more).
    pub max_memory_bytes: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_pixels: 1 << 28,
            max_memory_bytes: Self::DEFAULT_MAX_MEMORY_BYTES,
        }
    }
}

impl Limits {
    /// The default memory budget, 12 GiB (our choice; see [`Limits::max_memory_bytes`]).
    pub const DEFAULT_MAX_MEMORY_BYTES: u64 = 12 << 30;

    /// No practical limit (still guards against `usize` overflow).
    pub fn none() -> Self {
        Limits {
            max_pixels: u64::MAX,
            max_memory_bytes: u64::MAX,
        }
    }

    /// Check declared dimensions: both must be non-zero and their product within the limit.
    /// Returns the pixel count as `usize`.
    pub fn check(&self, format: &'static str, width: u64, height: u64) -> Result<usize> {
        if width == 0 || height == 0 {
            return Err(Error::decode(
                format,
                format!("image has zero size ({width}x{height})"),
            ));
        }
        let exceeded = || {
            Error::Limits(LimitsExceeded::Pixels {
                width,
                height,
                max_pixels: self.max_pixels,
            })
        };
        let n = width.checked_mul(height).ok_or_else(exceeded)?;
        if n > self.max_pixels {
            return Err(exceeded());
        }
        // Five f32 planes must be addressable.
        let n_usize = usize::try_from(n).map_err(|_| exceeded())?;
        n_usize.checked_mul(5 * 4).ok_or_else(exceeded)?;
        Ok(n_usize)
    }

    /// Check that `bytes` (of `what`, for the message) fit in the memory budget. `None`
    /// stands for a size that overflowed while it was computed.
    pub fn check_memory(&self, what: &str, bytes: Option<u64>) -> Result<()> {
        match bytes {
            Some(b) if b <= self.max_memory_bytes => Ok(()),
            _ => Err(Error::Limits(LimitsExceeded::Memory {
                what: what.to_string(),
                bytes: bytes.unwrap_or(u64::MAX),
                max_memory_bytes: self.max_memory_bytes,
            })),
        }
    }
}
