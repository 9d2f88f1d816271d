//! Size limits checked against a file's declared dimensions before any pixel memory is
//! allocated, so that a corrupt or hostile header cannot make us allocate gigabytes.

use crate::error::{Error, LimitsExceeded, Result};

/// Upper bounds on images the readers accept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest accepted `width × height`, in pixels. The default, 2^28 (268 M pixels,
    /// e.g. 16384 × 16384), needs about 5 GiB for the five f32 planes of an [`HdrImage`](crate::HdrImage).
    pub max_pixels: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_pixels: 1 << 28,
        }
    }
}

impl Limits {
    /// No practical limit (still guards against `usize` overflow).
    pub fn none() -> Self {
        Limits {
            max_pixels: u64::MAX,
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
            Error::Limits(LimitsExceeded {
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
}
