//! Encoding display images: PNG (8 or 16 bits per channel) and JPEG, both in sRGB
//! (IEC 61966-2-1 transfer curve, tagged with the PNG `sRGB` chunk), and the file-writing
//! discipline every output of the library follows.

use super::output::PendingFile;
use crate::colour::{Srgb8, SrgbLut};
use crate::{DisplayImage, Error, Result};
use std::io::Write;
use std::path::Path;

/// Interleaved sRGB-encoded samples of a display image, 8 bits per channel, exactly
/// rounded (see `colour::Srgb8`), encoded in parallel.
pub fn to_srgb8(image: &DisplayImage) -> Vec<u8> {
    let mut out = Vec::new();
    srgb8_into(image, &mut out);
    out
}

/// [`to_srgb8`] into `out` (its contents replaced, its memory reused).
pub(crate) fn srgb8_into(image: &DisplayImage, out: &mut Vec<u8>) {
    let enc = Srgb8::get();
    out.resize(image.len() * 3, 0);
    par_pixels(out, 3, |start, px| {
        for (i, px) in px.chunks_exact_mut(3).enumerate() {
            px[0] = enc.encode(image.r[start + i]);
            px[1] = enc.encode(image.g[start + i]);
            px[2] = enc.encode(image.b[start + i]);
        }
    });
}

/// Interleaved sRGB-encoded samples, 16 bits per channel (see [`SrgbLut`]), big-endian
/// (PNG's order) or little-endian, into `out` (its contents replaced, its memory reused),
/// encoded in parallel.
pub(crate) fn srgb16_into(image: &DisplayImage, big_endian: bool, out: &mut Vec<u8>) {
    static LUT: std::sync::OnceLock<SrgbLut> = std::sync::OnceLock::new();
    let lut = LUT.get_or_init(|| SrgbLut::new(16));
    let bytes = |v: f32| {
        let c = lut.encode(v);
        if big_endian {
            c.to_be_bytes()
        } else {
            c.to_le_bytes()
        }
    };
    out.resize(image.len() * 6, 0);
    par_pixels(out, 6, |start, px| {
        for (i, px) in px.chunks_exact_mut(6).enumerate() {
            let i = start + i;
            px[0..2].copy_from_slice(&bytes(image.r[i]));
            px[2..4].copy_from_slice(&bytes(image.g[i]));
            px[4..6].copy_from_slice(&bytes(image.b[i]));
        }
    });
}

/// Run `f(first pixel, bytes)` over pieces of `out` (`bytes_per_pixel` per pixel), in
/// parallel with the `rayon` feature.
fn par_pixels(out: &mut [u8], bytes_per_pixel: usize, f: impl Fn(usize, &mut [u8]) + Sync) {
    /// Pixels per work item.
    const PIXELS: usize = 1 << 14;
    let chunk = PIXELS * bytes_per_pixel;
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(chunk)
            .enumerate()
            .for_each(|(i, c)| f(i * PIXELS, c));
    }
    #[cfg(not(feature = "rayon"))]
    for (i, c) in out.chunks_mut(chunk).enumerate() {
        f(i * PIXELS, c);
    }
}

/// How hard a PNG is compressed. Both are lossless (the decoded samples are the same);
/// they differ in encoding time and file size only.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PngCompression {
    /// `png`'s `Compression::Fast`: the fdeflate encoder after the adaptive filter (each
    /// row tried with the five PNG filters, the smallest kept). The default of
    /// [`write_png`] and of every output of the library.
    #[default]
    Fast,
    /// `png`'s `Compression::Fastest`: the same fdeflate encoder after the `Up` filter
    /// alone (one filter per row instead of five tried), for video: less CPU time per
    /// frame, larger files (see the README's "Performance: Video").
    Fastest,
}

impl PngCompression {
    fn png(self) -> png::Compression {
        match self {
            PngCompression::Fast => png::Compression::Fast,
            PngCompression::Fastest => png::Compression::Fastest,
        }
    }
}

/// Write a PNG with `bits` (8 or 16) per channel, sRGB-encoded, at
/// [`PngCompression::Fast`].
pub fn write_png(image: &DisplayImage, bits: u8, w: impl Write) -> Result<()> {
    write_png_with(image, bits, PngCompression::Fast, w)
}

/// [`write_png`] at the given compression.
pub fn write_png_with(
    image: &DisplayImage,
    bits: u8,
    compression: PngCompression,
    w: impl Write,
) -> Result<()> {
    image.validate_planes()?;
    let (width, height) = dims_u32(image)?;
    let mut enc = png::Encoder::new(w, width, height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    enc.set_compression(compression.png());
    let data = match bits {
        8 => {
            enc.set_depth(png::BitDepth::Eight);
            to_srgb8(image)
        }
        16 => {
            enc.set_depth(png::BitDepth::Sixteen);
            let mut data = Vec::new();
            srgb16_into(image, true, &mut data);
            data
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
    image.validate_planes()?;
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
/// destination's directory, which is then moved over `path` (see [`super::output`]: it is
/// unnamed until complete where the platform allows, never replaces an input of the
/// process, and takes the permissions described there). On any error the temporary file
/// is removed and `path` is untouched (a previous file there survives).
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> Result<()>,
) -> Result<()> {
    let pending = PendingFile::create(path)?;
    {
        let mut w = std::io::BufWriter::new(pending.file());
        write(&mut w)?;
        w.flush()?;
    }
    pending.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A display image with gradients, noise-like detail and clipped areas.
    fn picture(width: usize, height: usize) -> DisplayImage {
        let n = width * height;
        let value = |i: usize, k: u32| {
            let (x, y) = ((i % width) as f32, (i / width) as f32);
            let wave = ((x * 0.37 + y * 0.11 + k as f32).sin() * 0.5 + 0.5) * (y / height as f32);
            let hash = (i as u32).wrapping_mul(2_654_435_761).wrapping_add(k) >> 24;
            wave * 1.1 + hash as f32 / 2550.0 - 0.02
        };
        DisplayImage {
            width,
            height,
            r: (0..n).map(|i| value(i, 0)).collect(),
            g: (0..n).map(|i| value(i, 1)).collect(),
            b: (0..n).map(|i| value(i, 2)).collect(),
            display_max_cd_m2: 100.0,
        }
    }

    fn decoded(png: &[u8]) -> (png::BitDepth, Vec<u8>) {
        let mut reader = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let frame = reader.next_frame(&mut buf).unwrap();
        buf.truncate(frame.buffer_size());
        (frame.bit_depth, buf)
    }

    /// Both compressions are lossless: the same samples, 8 and 16 bits, as the encoded
    /// buffers; `Fast` is `write_png`'s file, byte for byte.
    #[test]
    fn every_png_compression_decodes_to_the_same_samples() {
        let image = picture(97, 61);
        for bits in [8, 16] {
            let mut expected = Vec::new();
            if bits == 8 {
                expected = to_srgb8(&image);
            } else {
                srgb16_into(&image, true, &mut expected);
            }
            let mut plain = Vec::new();
            write_png(&image, bits, &mut plain).unwrap();
            let mut files = Vec::new();
            for compression in [PngCompression::Fast, PngCompression::Fastest] {
                let mut file = Vec::new();
                write_png_with(&image, bits, compression, &mut file).unwrap();
                let (depth, samples) = decoded(&file);
                assert_eq!(depth as u8, bits, "{compression:?}");
                assert_eq!(samples, expected, "{compression:?}, {bits} bits");
                files.push(file);
            }
            assert_eq!(files[0], plain, "{bits} bits");
        }
    }
}
