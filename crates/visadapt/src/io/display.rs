//! Encoding display images: PNG (8 or 16 bits per channel) and JPEG, both in sRGB
//! (IEC 61966-2-1 transfer curve, tagged with the PNG `sRGB` chunk), and the file-writing
//! discipline every output of the library follows.

use crate::colour::SrgbLut;
use crate::{DisplayImage, Error, Result};
use std::io::Write;
use std::path::Path;

/// Interleaved sRGB-encoded samples of a display image, 8 bits per channel.
pub fn to_srgb8(image: &DisplayImage) -> Vec<u8> {
    let lut = SrgbLut::new(8);
    let mut out = vec![0u8; image.len() * 3];
    for (i, px) in out.chunks_exact_mut(3).enumerate() {
        px[0] = lut.encode(image.r[i]) as u8;
        px[1] = lut.encode(image.g[i]) as u8;
        px[2] = lut.encode(image.b[i]) as u8;
    }
    out
}

/// Write a PNG with `bits` (8 or 16) per channel, sRGB-encoded.
pub fn write_png(image: &DisplayImage, bits: u8, w: impl Write) -> Result<()> {
    let (width, height) = dims_u32(image)?;
    let mut enc = png::Encoder::new(w, width, height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    enc.set_compression(png::Compression::Fast);
    let data = match bits {
        8 => {
            enc.set_depth(png::BitDepth::Eight);
            to_srgb8(image)
        }
        16 => {
            enc.set_depth(png::BitDepth::Sixteen);
            let lut = SrgbLut::new(16);
            let mut out = vec![0u8; image.len() * 6];
            for (i, px) in out.chunks_exact_mut(6).enumerate() {
                px[0..2].copy_from_slice(&lut.encode(image.r[i]).to_be_bytes());
                px[2..4].copy_from_slice(&lut.encode(image.g[i]).to_be_bytes());
                px[4..6].copy_from_slice(&lut.encode(image.b[i]).to_be_bytes());
            }
            out
        }
        _ => {
            return Err(Error::invalid(
                "bit-depth",
                bits,
                "PNG output supports 8 or 16 bits",
            ));
        }
    };
    let mut writer = enc.write_header().map_err(png_error)?;
    writer.write_image_data(&data).map_err(png_error)?;
    writer.finish().map_err(png_error)
}

/// Write a baseline JPEG of the given quality (1–100), sRGB-encoded.
pub fn write_jpeg(image: &DisplayImage, quality: u8, w: impl Write) -> Result<()> {
    if !(1..=100).contains(&quality) {
        return Err(Error::invalid("quality", quality, "must be 1 to 100"));
    }
    let too_big = || {
        Error::Unsupported(format!(
            "JPEG cannot hold {}x{} pixels (at most 65535 per side)",
            image.width, image.height
        ))
    };
    let width = u16::try_from(image.width).map_err(|_| too_big())?;
    let height = u16::try_from(image.height).map_err(|_| too_big())?;
    let enc = jpeg_encoder::Encoder::new(w, quality);
    enc.encode(
        &to_srgb8(image),
        width,
        height,
        jpeg_encoder::ColorType::Rgb,
    )
    .map_err(|e| match e {
        jpeg_encoder::EncodingError::IoError(e) => Error::Io(e),
        other => Error::Unsupported(format!("JPEG encoder: {other}")),
    })
}

fn dims_u32(image: &DisplayImage) -> Result<(u32, u32)> {
    let bad = || {
        Error::Unsupported(format!(
            "{}x{} is too large for PNG",
            image.width, image.height
        ))
    };
    Ok((
        u32::try_from(image.width).map_err(|_| bad())?,
        u32::try_from(image.height).map_err(|_| bad())?,
    ))
}

pub(crate) fn png_error(e: png::EncodingError) -> Error {
    match e {
        png::EncodingError::IoError(e) => Error::Io(e),
        other => Error::Unsupported(format!("PNG encoder: {other}")),
    }
}

/// Write a file all at once or not at all: `write` fills a temporary file in the
/// destination's directory, which is then renamed over `path`. On any error the temporary
/// file is removed and `path` is untouched (a previous file there survives).
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> Result<()>,
) -> Result<()> {
    let tmp = temp_file_beside(path)?;
    {
        let mut w = std::io::BufWriter::new(tmp.as_file());
        write(&mut w)?;
        w.flush()?;
    }
    commit_temp_file(tmp, path)
}

/// A private temporary file in `path`'s directory, to be renamed over `path` by
/// [`commit_temp_file`] (dropping it instead removes it).
pub(crate) fn temp_file_beside(path: &Path) -> Result<tempfile::NamedTempFile> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    Ok(tempfile::Builder::new()
        .prefix(".visadapt-")
        .suffix(".tmp")
        .tempfile_in(dir)?)
}

/// Give a finished temporary file the permissions of the file it replaces (or the usual
/// 0644 of a new file, not the temporary file's private 0600), flush it to disk and
/// rename it over `path`.
pub(crate) fn commit_temp_file(tmp: tempfile::NamedTempFile, path: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let perms = std::fs::metadata(path)
            .map(|m| m.permissions())
            .unwrap_or_else(|_| std::fs::Permissions::from_mode(0o644));
        tmp.as_file().set_permissions(perms)?;
    }
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| Error::Io(e.error))?;
    Ok(())
}
