//! TIFF output of display images: 32-bit float linear RGB, for compositing and analysis
//! tools that read TIFF but not OpenEXR.
//!
//! [`write_display`] writes a [`DisplayImage`] as one uncompressed image of three 32-bit
//! IEEE float samples per pixel (`SampleFormat` = 3, `BitsPerSample` = 32, RGB,
//! contiguous), the linear Rec. 709 values of the display image, so that RGB (1, 1, 1) is
//! the display maximum, as in the OpenEXR output. TIFF has no standard tag for absolute
//! luminance: the `ImageDescription` tag states it in words,
//! `visadapt display-referred linear Rec. 709 RGB; 1.0 = L cd/m2` (L the display maximum),
//! and [`DISPLAY_MAX_PREFIX`] is its fixed beginning (TIFF 6.0, Sec. 8 and Sec. 19
//! (`SampleFormat`); Adobe TIFF Technical Note 3 for floating-point samples).

use crate::{DisplayImage, Error, Result};
use std::io::{Seek, Write};

/// How the `ImageDescription` of a written TIFF begins; the display maximum in cd/m²
/// follows it.
pub const DISPLAY_MAX_PREFIX: &str = "visadapt display-referred linear Rec. 709 RGB; 1.0 = ";

/// Write a display image as a 32-bit float RGB TIFF (see the module documentation).
///
/// ```
/// use visadapt::{DisplayImage, io};
/// let image = DisplayImage { width: 2, height: 1, r: vec![0.5, 1.0], g: vec![0.25, 1.0],
///                            b: vec![0.0, 1.0], display_max_cd_m2: 100.0 };
/// let mut tiff = std::io::Cursor::new(Vec::new());
/// io::tiff::write_display(&image, &mut tiff)?;
/// assert!(tiff.get_ref().starts_with(b"II*\0"));
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn write_display(image: &DisplayImage, w: impl Write + Seek) -> Result<()> {
    use ::tiff::encoder::{TiffEncoder, colortype::RGB32Float};
    use ::tiff::tags::Tag;
    image.validate()?;
    let (n, l) = (image.len(), image.display_max_cd_m2);
    let dims = |v: usize| {
        u32::try_from(v).map_err(|_| {
            Error::Unsupported(format!(
                "a {}x{} image is too large for TIFF",
                image.width, image.height
            ))
        })
    };
    let (width, height) = (dims(image.width)?, dims(image.height)?);
    // Classic TIFF addresses at most 4 GiB; 12 bytes a pixel plus headers.
    if (n as u64).saturating_mul(12) >= u32::MAX as u64 - (1 << 20) {
        return Err(Error::Unsupported(format!(
            "a {}x{} float image is beyond the 4 GiB of a classic TIFF (use .exr)",
            image.width, image.height
        )));
    }
    let mut rgb = Vec::new();
    rgb.try_reserve_exact(3 * n)
        .map_err(|_| super::out_of_memory("the TIFF samples", 12 * n as u64))?;
    for i in 0..n {
        rgb.extend_from_slice(&[image.r[i], image.g[i], image.b[i]]);
    }
    let fail = |e: ::tiff::TiffError| match e {
        ::tiff::TiffError::IoError(e) => Error::Io(e),
        e => Error::Unsupported(format!("TIFF: {e}")),
    };
    let mut encoder = TiffEncoder::new(w).map_err(fail)?;
    let mut tiff = encoder
        .new_image::<RGB32Float>(width, height)
        .map_err(fail)?;
    tiff.encoder()
        .write_tag(
            Tag::ImageDescription,
            format!("{DISPLAY_MAX_PREFIX}{l} cd/m2").as_str(),
        )
        .map_err(fail)?;
    tiff.encoder()
        .write_tag(
            Tag::Software,
            concat!("visadapt ", env!("CARGO_PKG_VERSION")),
        )
        .map_err(fail)?;
    tiff.write_data(&rgb).map_err(fail)
}
