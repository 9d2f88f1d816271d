//! Encoding display images: PNG (8 or 16 bits per channel) and JPEG, both in sRGB
//! (IEC 61966-2-1 transfer curve, tagged with the PNG `sRGB` chunk), and the file-writing
//! discipline every output of the library follows.

use super::output::PendingFile;
use crate::colour::Srgb8;
use crate::simd::Isa;
use crate::{DisplayImage, Error, Result};
use std::io::Write;
use std::path::Path;

use crate::simd::at_level;

mod bands;

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
    let isa = Isa::detect();
    out.resize(image.len() * 3, 0);
    par_pixels(out, 3, |start, px| {
        let end = start + px.len() / 3;
        let (r, g, b) = (
            &image.r[start..end],
            &image.g[start..end],
            &image.b[start..end],
        );
        at_level!(isa, enc.encode_rgb(r, g, b, px));
    });
}

/// Interleaved sRGB-encoded samples, 16 bits per channel (see [`SrgbLut`](crate::colour::SrgbLut)), big-endian
/// (PNG's order) or little-endian, into `out` (its contents replaced, its memory reused),
/// encoded in parallel.
pub(crate) fn srgb16_into(image: &DisplayImage, big_endian: bool, out: &mut Vec<u8>) {
    let lut = bands::srgb16_lut();
    let isa = Isa::detect();
    out.resize(image.len() * 6, 0);
    par_pixels(out, 6, |start, px| {
        let end = start + px.len() / 6;
        let (r, g, b) = (
            &image.r[start..end],
            &image.g[start..end],
            &image.b[start..end],
        );
        at_level!(isa, lut.encode_rgb(r, g, b, big_endian, px));
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

/// How hard a PNG is compressed. All are lossless (the decoded samples are the same);
/// they differ in encoding time and file size only.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PngCompression {
    /// The adaptive filter (each row tried with Up, Sub, Average and Paeth, the smallest
    /// sum of absolute values kept: `png`'s `Filter::Adaptive`, the same filtered bytes),
    /// then zlib-rs's level 1, in parallel row bands. The default of [`write_png`], of
    /// [`OutputFormat::png`](crate::io::OutputFormat::png) and of the `map` and
    /// `sequence` commands. Files about 3 % larger than `png`'s own fdeflate path
    /// at `Compression::Fast` (24 1080p video frames: 11.99 MB against 11.64 MB).
    #[default]
    Fast,
    /// The `Up` filter alone (one filter per row instead of four tried, `png`'s choice
    /// for `Compression::Fastest`), then the same deflate in row bands, for video: less
    /// CPU time per frame, larger files (24 1080p video frames: 13.10 MB, against
    /// 20.23 MB from `png`'s own fdeflate path at `Compression::Fastest`).
    Fastest,
    /// The `Up` filter, then zlib-rs's run-length strategy (zlib's `Z_RLE`: matches at
    /// distance 1 only, dynamic Huffman codes per block; level 1 otherwise uses static
    /// codes), in the same row bands: about the CPU time of [`PngCompression::Fast`] on
    /// smooth frames, files 36-40 % smaller (the default of `video`'s PNG frames before
    /// [`PngCompression::Fdeflate`]; twice `Fast`'s CPU time on textured and
    /// photographic ones, see there). Measured on 24 mapped 1080p frames of the
    /// office video (encoding alone, CPU time per frame, load 3-5 on two cores; the
    /// Radiance sequence, then the OpenEXR one): `Rle` 11-14 ms and 18.5-21 ms, 7.29 MB
    /// and 14.12 MB; `Fast` 11.4-14 ms and 18-18.5 ms, 11.98 MB and 22.02 MB; `Fastest`
    /// 10-12 ms and 13.5-17 ms, 13.09 MB and 24.26 MB.
    Rle,
    /// The adaptive filter, as [`PngCompression::Fast`] (in parallel row bands), then
    /// fdeflate's compressor (one block of fixed Huffman codes made for filtered PNG
    /// rows, with runs of zeros) on one thread while the next rows are filtered: `png`'s
    /// own `Compression::Fast`, the same file byte for byte. The least CPU time of the
    /// four on textured and photographic frames, for files about the size of
    /// [`PngCompression::Rle`]'s there; on smooth ones `Rle`'s files are smaller (the
    /// 1080p office video above: 7.3 MB against 11.6 MB from `png`'s own path). The
    /// default of the `video` command's PNG frames. Encoding
    /// alone, the shortest of five runs on one thread at load 1.5 (file sizes): the
    /// `video` bench's 1080p frame 27 ms (2.39 MB) against `Rle` 68 ms (2.85 MB) and
    /// `Fast` 39 ms (2.33 MB); the mapped `Tree.exr` (928 × 906) 10 ms (1.35 MB) against
    /// 28 ms (1.42 MB) and 23 ms (1.93 MB); `office-fisheye.hdr` (786², smooth, black
    /// corners) 8.5 ms (536 kB) against 16 ms (503 kB) and 9.1 ms (478 kB).
    Fdeflate,
}

impl PngCompression {
    /// Every level.
    pub const ALL: [PngCompression; 4] = [
        PngCompression::Fast,
        PngCompression::Fastest,
        PngCompression::Rle,
        PngCompression::Fdeflate,
    ];

    /// The level's name as the command line and the Python package take it: `fast`,
    /// `fastest`, `rle` or `fdeflate` (parsed back by [`str::parse`]).
    pub const fn name(self) -> &'static str {
        match self {
            PngCompression::Fast => "fast",
            PngCompression::Fastest => "fastest",
            PngCompression::Rle => "rle",
            PngCompression::Fdeflate => "fdeflate",
        }
    }

    /// `png`'s own sequential encoding at this level (for comparisons: the same filter).
    #[cfg(test)]
    fn png(self) -> png::Compression {
        match self {
            PngCompression::Fast => png::Compression::Fast,
            PngCompression::Fastest | PngCompression::Rle => png::Compression::Fastest,
            PngCompression::Fdeflate => png::Compression::Fast,
        }
    }
}

impl std::str::FromStr for PngCompression {
    type Err = Error;

    /// A level by its [`name`](PngCompression::name), ignoring ASCII case.
    ///
    /// ```
    /// use visadapt::io::display::PngCompression;
    /// assert_eq!("RLE".parse::<PngCompression>()?, PngCompression::Rle);
    /// assert!("zip".parse::<PngCompression>().is_err());
    /// # Ok::<(), visadapt::Error>(())
    /// ```
    fn from_str(s: &str) -> Result<Self> {
        PngCompression::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                Error::invalid(
                    "PNG compression",
                    s,
                    "must be fast, fastest, rle or fdeflate",
                )
            })
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
    let depth = match bits {
        8 => png::BitDepth::Eight,
        16 => png::BitDepth::Sixteen,
        _ => {
            return Err(Error::invalid(
                "bit-depth",
                bits,
                "PNG output supports 8 or 16 bits",
            ));
        }
    };
    let mut enc = png::Encoder::new(w, width, height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    enc.set_depth(depth);
    let mut writer = enc.write_header().map_err(png_error)?;
    bands::write_zlib(image, bits, compression, |piece| {
        // A chunk holds at most 2³¹ − 1 bytes (PNG 1.2 §3.2).
        piece
            .chunks(i32::MAX as usize)
            .try_for_each(|chunk| writer.write_chunk(png::chunk::IDAT, chunk))
            .map_err(png_error)
    })?;
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
            for compression in [
                PngCompression::Fast,
                PngCompression::Fastest,
                PngCompression::Rle,
                PngCompression::Fdeflate,
            ] {
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

    /// The threads' compressors are reused from band to band and image to image (reset,
    /// or made anew for another level): a file is the same, byte for byte, whatever was
    /// encoded before it.
    #[test]
    fn reused_compressors_write_the_same_files() {
        let (a, b) = (picture(300, 1000), picture(1031, 257));
        let file = |image: &DisplayImage, bits, compression| {
            let mut f = Vec::new();
            write_png_with(image, bits, compression, &mut f).unwrap();
            f
        };
        let first = file(&a, 8, PngCompression::Fast);
        for compression in [
            PngCompression::Fastest,
            PngCompression::Rle,
            PngCompression::Fast,
        ] {
            for bits in [16, 8] {
                let _ = file(&b, bits, compression);
            }
        }
        assert!(first == file(&a, 8, PngCompression::Fast));
        assert!(first != file(&a, 8, PngCompression::Fastest));
    }

    /// A smooth picture (a mapped photograph's large areas): slow waves, no noise.
    fn smooth_picture(w: usize, h: usize) -> DisplayImage {
        let wave = |i: usize, k: f32| {
            let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
            0.5 + 0.4 * (3.0 * x + 2.0 * y + k).sin() * (1.0 - 0.5 * y)
        };
        DisplayImage {
            width: w,
            height: h,
            r: (0..w * h).map(|i| wave(i, 0.0)).collect(),
            g: (0..w * h).map(|i| wave(i, 1.0)).collect(),
            b: (0..w * h).map(|i| wave(i, 2.0)).collect(),
            display_max_cd_m2: 100.0,
        }
    }

    /// On a smooth picture the run-length strategy's dynamic codes beat level 1's static
    /// ones after the same `Up` filter: smaller files, the same samples.
    #[test]
    fn rle_files_are_smaller_on_smooth_pictures() {
        let image = smooth_picture(640, 360);
        let size = |compression| {
            let mut f = Vec::new();
            write_png_with(&image, 8, compression, &mut f).unwrap();
            assert_eq!(decoded(&f).1, to_srgb8(&image), "{compression:?}");
            f.len()
        };
        let (rle, fastest) = (size(PngCompression::Rle), size(PngCompression::Fastest));
        assert!(rle * 10 < fastest * 8, "{rle} against {fastest}");
    }

    /// The interleaved sRGB samples of `image` a PNG of `bits` per channel holds.
    fn samples(image: &DisplayImage, bits: u8) -> Vec<u8> {
        let mut samples = Vec::new();
        if bits == 8 {
            srgb8_into(image, &mut samples);
        } else {
            srgb16_into(image, true, &mut samples);
        }
        samples
    }

    /// The file `png`'s own encoder writes for `samples` (RGB, `bits` per channel), with
    /// the `sRGB` chunk if `srgb`, at `compression`.
    fn pngs_own(
        samples: &[u8],
        (w, h): (usize, usize),
        bits: u8,
        srgb: bool,
        compression: png::Compression,
    ) -> Vec<u8> {
        let mut file = Vec::new();
        let mut enc = png::Encoder::new(&mut file, w as u32, h as u32);
        enc.set_color(png::ColorType::Rgb);
        if srgb {
            enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        }
        enc.set_depth(if bits == 8 {
            png::BitDepth::Eight
        } else {
            png::BitDepth::Sixteen
        });
        enc.set_compression(compression);
        let mut writer = enc.write_header().unwrap();
        writer.write_image_data(samples).unwrap();
        writer.finish().unwrap();
        file
    }

    /// `Fdeflate` writes `png`'s own file at `Compression::Fast`, byte for byte (the same
    /// adaptive filter, fdeflate called row by row, the same stored fallback), at both
    /// depths, on one row, on one wave and on several (the 700-row images: 3 waves of
    /// 336 rows at 8 bits, 5 of 168 at 16), compressed (smooth pictures) and stored (the
    /// noisy ones, where fdeflate's codes would be larger than the rows).
    #[test]
    fn fdeflate_files_are_pngs_own_byte_for_byte() {
        let (mut stored, mut compressed) = (0, 0);
        for (w, h) in [(1, 1), (5, 3), (97, 61), (1031, 700)] {
            for image in [picture(w, h), smooth_picture(w, h)] {
                for bits in [8u8, 16] {
                    let own = PngCompression::Fdeflate.png();
                    let reference = pngs_own(&samples(&image, bits), (w, h), bits, true, own);
                    let mut file = Vec::new();
                    write_png_with(&image, bits, PngCompression::Fdeflate, &mut file).unwrap();
                    assert!(file == reference, "{w}x{h}, {bits} bits");
                    // BTYPE of the first deflate block: 0 stored, 2 fdeflate's codes.
                    match (idat(&file)[2] >> 1) & 3 {
                        0 => stored += 1,
                        _ => compressed += 1,
                    }
                }
            }
        }
        assert!(
            stored >= 2 && compressed >= 4,
            "{stored} stored, {compressed} compressed"
        );
    }

    /// The zlib stream of a PNG file: its IDAT chunks' data, concatenated.
    fn idat(png: &[u8]) -> Vec<u8> {
        let mut rest = &png[8..];
        let mut data = Vec::new();
        let mut chunks = 0;
        while !rest.is_empty() {
            let len = u32::from_be_bytes(rest[..4].try_into().unwrap()) as usize;
            if &rest[4..8] == b"IDAT" {
                data.extend_from_slice(&rest[8..8 + len]);
                chunks += 1;
            }
            rest = &rest[12 + len..];
        }
        assert!(chunks > 0);
        data
    }

    /// The filtered bytes of a zlib stream of `len` bytes (its Adler-32 checked).
    fn inflated(zlib: &[u8], len: usize) -> Vec<u8> {
        let mut out = vec![0u8; len + 1];
        let (got, rc) =
            zlib_rs::decompress_slice(&mut out, zlib, zlib_rs::InflateConfig::default());
        assert_eq!(rc, zlib_rs::ReturnCode::Ok, "inflate");
        assert_eq!(got.len(), len);
        got.to_vec()
    }

    /// Images of many bands (and of one, and of one pixel) at both depths and both
    /// compressions: the png crate decodes the exact samples, and the filtered bytes are
    /// those of `png`'s own sequential encoder at the same level, byte for byte (the
    /// same filter chosen for every row, the first of each band included).
    #[test]
    fn banded_pngs_hold_the_sequential_encoders_filtered_bytes() {
        let mut compared_bands = 0;
        for (w, h) in [(1, 1), (5, 3), (97, 61), (300, 1000), (1031, 257)] {
            let image = picture(w, h);
            for bits in [8u8, 16] {
                let expected = samples(&image, bits);
                let filtered_len = (w * usize::from(bits / 8) * 3 + 1) * h;
                for compression in [
                    PngCompression::Fast,
                    PngCompression::Fastest,
                    PngCompression::Rle,
                    PngCompression::Fdeflate,
                ] {
                    let what = format!("{w}x{h}, {bits} bits, {compression:?}");
                    let mut file = Vec::new();
                    write_png_with(&image, bits, compression, &mut file).unwrap();
                    let (_, samples) = decoded(&file);
                    assert!(samples == expected, "samples of {what}");

                    let reference = pngs_own(&expected, (w, h), bits, false, compression.png());
                    let ours = inflated(&idat(&file), filtered_len);
                    let theirs = inflated(&idat(&reference), filtered_len);
                    // Unless `png` stored the rows unfiltered (its fallback where fdeflate's
                    // output would be larger than the raw rows: this noisy picture often).
                    let unfiltered: Vec<u8> = expected
                        .chunks(filtered_len / h - 1)
                        .flat_map(|row| std::iter::once(0).chain(row.iter().copied()))
                        .collect();
                    assert!(
                        ours == theirs || theirs == unfiltered,
                        "filtered bytes of {what}"
                    );
                    if ours == theirs && w >= 300 {
                        compared_bands += 1;
                    }
                }
            }
        }
        // Multi-band images compared filter for filter (not only `png`'s fallback).
        assert!(compared_bands >= 3, "{compared_bands}");
    }
}
