//! Reading HDR images (Radiance `.hdr`/`.pic`, OpenEXR, PFM) into an [`HdrImage`] in
//! absolute units, and writing display images (PNG, JPEG, EXR).
//!
//! The input format is detected from the file's first bytes, not its name.

use crate::{HdrImage, Limits, Result};
use std::path::Path;

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
