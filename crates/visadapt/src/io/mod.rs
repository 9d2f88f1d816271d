//! Reading HDR images (Radiance `.hdr`/`.pic`, OpenEXR, PFM) into an [`HdrImage`] in
//! absolute units, and writing display images (PNG, JPEG, EXR).
//!
//! The input format is detected from the file's first bytes, not its name.

use crate::{DisplayImage, Error, HdrImage, Limits, Result};
use std::path::Path;

pub mod display;
pub mod exr;
pub mod pfm;
pub mod radiance;

/// The input formats the library reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputFormat {
    /// Radiance RGBE/XYZE picture (`#?RADIANCE`, `#?RGBE`, or a header line first).
    Radiance,
    /// OpenEXR (magic `76 2f 31 01`).
    OpenExr,
    /// Portable float map (`PF` colour, `Pf` grey).
    Pfm,
}

/// Guess the format from the first bytes of a file.
pub fn detect(head: &[u8]) -> Option<InputFormat> {
    if head.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        Some(InputFormat::OpenExr)
    } else if head.starts_with(b"PF") || head.starts_with(b"Pf") {
        Some(InputFormat::Pfm)
    } else if head.starts_with(b"#?") || radiance::looks_like_header(head) {
        Some(InputFormat::Radiance)
    } else {
        None
    }
}

/// Read an HDR image from a file, whatever its format.
pub fn read(path: &Path, limits: &Limits) -> Result<HdrImage> {
    let bytes = std::fs::read(path)?;
    decode(&bytes, limits)
}

/// Decode an HDR image held in memory, whatever its format.
pub fn decode(bytes: &[u8], limits: &Limits) -> Result<HdrImage> {
    match detect(bytes) {
        Some(InputFormat::Radiance) => radiance::decode(bytes, limits),
        Some(InputFormat::OpenExr) => exr::decode(bytes, limits),
        Some(InputFormat::Pfm) => pfm::decode(bytes, limits),
        None => Err(crate::Error::Unsupported(
            "not a Radiance, OpenEXR or PFM file (unrecognised first bytes)".into(),
        )),
    }
}

/// The display-image formats the library writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    /// PNG, sRGB-encoded, with 8 or 16 bits per channel.
    Png {
        /// 8 or 16.
        bits: u8,
    },
    /// Baseline JPEG, sRGB-encoded.
    Jpeg {
        /// 1–100.
        quality: u8,
    },
    /// OpenEXR, display-referred linear Rec.709 RGB (1.0 = `L_dmax`, recorded in the
    /// `whiteLuminance` attribute).
    Exr,
}

impl OutputFormat {
    /// The format implied by a file name's extension (`.png`, `.jpg`/`.jpeg`, `.exr`),
    /// with 8-bit PNG and quality-90 JPEG.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("png") => Ok(OutputFormat::Png { bits: 8 }),
            Some("jpg" | "jpeg") => Ok(OutputFormat::Jpeg { quality: 90 }),
            Some("exr") => Ok(OutputFormat::Exr),
            _ => Err(Error::Unsupported(format!(
                "cannot tell the output format of {} (use .png, .jpg or .exr)",
                path.display()
            ))),
        }
    }
}

/// Write a display image to `path` in `format`, atomically: the file appears complete or
/// not at all (see [`display::write_atomically`]).
pub fn write_display(image: &DisplayImage, path: &Path, format: OutputFormat) -> Result<()> {
    display::write_atomically(path, |w| match format {
        OutputFormat::Png { bits } => display::write_png(image, bits, w),
        OutputFormat::Jpeg { quality } => display::write_jpeg(image, quality, w),
        OutputFormat::Exr => exr::write_display(image, w),
    })
}
