//! Reading HDR images (Radiance `.hdr`/`.pic`, OpenEXR, PFM) into an [`HdrImage`] in
//! absolute units, and display-encoded photographs (8/16-bit PNG, JPEG, TIFF: [`ldr`]) in
//! relative units; writing display images (PNG, JPEG, OpenEXR, 32-bit float TIFF,
//! Radiance); raw video frames to and from ffmpeg pipes ([`raw`]).
//!
//! The input format is detected from the file's first bytes, not its name.

use crate::{DisplayImage, Error, HdrImage, Limits, Result};
use std::path::Path;

pub mod display;
pub mod exr;
pub mod ldr;
pub mod output;
pub mod pfm;
pub mod radiance;
pub mod raw;
pub mod tiff;

/// The input formats the library reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputFormat {
    /// Radiance RGBE/XYZE picture (`#?RADIANCE`, `#?RGBE`, or a header line first).
    Radiance,
    /// OpenEXR (magic `76 2f 31 01`).
    OpenExr,
    /// Portable float map (`PF` colour, `Pf` grey).
    Pfm,
    /// PNG (magic `89 50 4e 47`), 8 or 16 bits, sRGB-encoded ([`ldr`]).
    Png,
    /// JPEG (magic `ff d8 ff`), sRGB-encoded ([`ldr`]).
    Jpeg,
    /// TIFF (`II*\0` or `MM\0*`), 8/16-bit sRGB-encoded or 32-bit float ([`ldr`]).
    Tiff,
}

/// Guess the format from the first bytes of a file.
pub fn detect(head: &[u8]) -> Option<InputFormat> {
    if head.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        Some(InputFormat::OpenExr)
    } else if head.starts_with(b"PF") || head.starts_with(b"Pf") {
        Some(InputFormat::Pfm)
    } else if head.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some(InputFormat::Png)
    } else if head.starts_with(&[0xff, 0xd8, 0xff]) {
        Some(InputFormat::Jpeg)
    } else if head.starts_with(b"II*\0") || head.starts_with(b"MM\0*") {
        Some(InputFormat::Tiff)
    } else if head.starts_with(b"#?") || radiance::looks_like_header(head) {
        Some(InputFormat::Radiance)
    } else {
        None
    }
}

/// How many bytes are read first, to detect the format and parse the header from. Headers
/// longer than this are refused (real ones are a few hundred bytes to a few KiB; an EXR
/// with hundreds of channels stays far below it).
pub const HEAD_LEN: usize = 1 << 20;

/// Read an HDR image from a file, whatever its format (see [`read_bytes`] for what is
/// read).
pub fn read(path: &Path, limits: &Limits) -> Result<HdrImage> {
    read_scaled(path, limits, 1.0)
}

/// [`read`] with every value multiplied by `factor` (see [`read_scaled_into`]).
pub fn read_scaled(path: &Path, limits: &Limits, factor: f32) -> Result<HdrImage> {
    let mut image = HdrImage::zeros(0, 0);
    read_scaled_into(path, limits, factor, &mut Vec::new(), &mut image)?;
    Ok(image)
}

/// [`read`] into existing buffers, reusing their memory (for a sequence of frames):
/// `bytes` receives the file's bytes, `image` the decoded image (Radiance and OpenEXR files
/// are decoded into its planes, see [`radiance::decode_into`] and [`exr::decode_into`]).
pub fn read_into(
    path: &Path,
    limits: &Limits,
    bytes: &mut Vec<u8>,
    image: &mut HdrImage,
) -> Result<()> {
    read_scaled_into(path, limits, 1.0, bytes, image)
}

/// [`read_into`] with every value multiplied by `factor`, as [`HdrImage::scale`] would
/// after it (a unit conversion: `--scale`), but for Radiance, OpenEXR and PFM files in
/// the decoder's own conversion pass, which saves a pass over the planes: the factor
/// joins the matrix from the file's channels to XYZ, so each value is rounded to `f32`
/// once instead of twice (the two ways agree within about one unit in the last place)
/// and saturates at ±`f32::MAX` as [`HdrImage::scale`]'s products do. Photographs,
/// OpenEXR XYZ parts, and factors a decoder's matrix cannot take (not finite, or far
/// beyond any unit conversion) are scaled after decoding.
///
/// ```
/// use visadapt::{HdrImage, Limits, io};
/// let mut scene = HdrImage::zeros(4, 2);
/// scene.y.fill(0.5);
/// let path = std::env::temp_dir().join("visadapt-doc-read-scaled.exr");
/// io::exr::write_hdr(&scene, std::fs::File::create(&path)?)?;
/// let (mut bytes, mut image) = (Vec::new(), HdrImage::zeros(0, 0));
/// io::read_scaled_into(&path, &Limits::default(), 179.0, &mut bytes, &mut image)?;
/// assert!((image.y[0] - 89.5).abs() < 1e-4);
/// # std::fs::remove_file(&path)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn read_scaled_into(
    path: &Path,
    limits: &Limits,
    factor: f32,
    bytes: &mut Vec<u8>,
    image: &mut HdrImage,
) -> Result<()> {
    let format = read_bytes(path, limits, bytes)?;
    decode_scaled_into(format, bytes, limits, factor, image)
}

/// The image of `bytes` (a file of `format`) with every value multiplied by `factor`,
/// into `image`: the decoders' own conversion where they have one (see
/// [`read_scaled_into`]).
fn decode_scaled_into(
    format: InputFormat,
    bytes: &[u8],
    limits: &Limits,
    factor: f32,
    image: &mut HdrImage,
) -> Result<()> {
    match format {
        InputFormat::Radiance => radiance::decode_scaled_into(bytes, limits, factor, image),
        InputFormat::OpenExr => exr::decode_scaled_into(bytes, limits, factor, image),
        InputFormat::Pfm => {
            *image = pfm::decode_scaled(bytes, limits, factor)?;
            Ok(())
        }
        _ => {
            *image = decode(bytes, limits)?;
            if factor != 1.0 {
                image.scale(factor);
            }
            Ok(())
        }
    }
}

/// Read the bytes of the HDR image file at `path` into `bytes`, no more than its format
/// can need: the first [`HEAD_LEN`] bytes are read and the format is detected from them
/// (an unrecognised file is refused there, so `/dev/zero` costs one read), then at most
/// as many bytes as the header says the pixel data can take (see each format's reader),
/// and never more than [`Limits::max_memory_bytes`]. Bytes after that are not read.
/// The file is also registered as an input that no output of this process may replace
/// ([`output::protect_input`]).
pub fn read_bytes(path: &Path, limits: &Limits, bytes: &mut Vec<u8>) -> Result<InputFormat> {
    let mut file = std::fs::File::open(path)?;
    output::protect_input(path, &file)?;
    let on_disk = file
        .metadata()
        .ok()
        .filter(|m| m.is_file())
        .map(|m| m.len());
    read_bytes_from(&mut file, on_disk, limits, bytes)
}

/// Read an HDR image from a stream (standard input, a pipe, a socket), whatever its
/// format, with the same bounds as [`read_bytes`]: the format is detected from the first
/// bytes, and no more is read than the header says the pixels need and the memory budget
/// allows. The rest of the stream is left unread.
///
/// ```
/// use visadapt::{HdrImage, Limits, io};
/// let mut scene = HdrImage::zeros(4, 2);
/// scene.y.fill(3.0);
/// let mut exr = std::io::Cursor::new(Vec::new());
/// io::exr::write_hdr(&scene, &mut exr)?;
/// let back = io::read_from(exr.get_ref().as_slice(), &Limits::default())?;
/// assert_eq!((back.width, back.height), (4, 2));
/// assert!((back.y[0] - 3.0).abs() < 1e-6);
/// // An endless stream of zeros costs one read of the first bytes.
/// let err = io::read_from(std::io::repeat(0), &Limits::default()).unwrap_err();
/// assert!(err.to_string().contains("unrecognised"));
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn read_from(reader: impl std::io::Read, limits: &Limits) -> Result<HdrImage> {
    read_scaled_from(reader, limits, 1.0)
}

/// [`read_from`] with every value multiplied by `factor`, in the decoder's conversion
/// where it has one: the same values as [`read_scaled`] of the same bytes in a file, bit
/// for bit (`visadapt map - --scale S` reads standard input so).
///
/// ```
/// use visadapt::{HdrImage, Limits, io};
/// let mut scene = HdrImage::zeros(4, 2);
/// scene.y.fill(0.5);
/// let mut exr = std::io::Cursor::new(Vec::new());
/// io::exr::write_hdr(&scene, &mut exr)?;
/// let back = io::read_scaled_from(exr.get_ref().as_slice(), &Limits::default(), 179.0)?;
/// assert!((back.y[0] - 89.5).abs() < 1e-4);
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn read_scaled_from(
    mut reader: impl std::io::Read,
    limits: &Limits,
    factor: f32,
) -> Result<HdrImage> {
    let mut bytes = Vec::new();
    let format = read_bytes_from(&mut reader, None, limits, &mut bytes)?;
    let mut image = HdrImage::zeros(0, 0);
    decode_scaled_into(format, &bytes, limits, factor, &mut image)?;
    Ok(image)
}

/// [`read_bytes`] from any reader; `on_disk` is its length when known (a regular file), to
/// reserve the memory at once but no more than there are bytes.
fn read_bytes_from(
    reader: &mut impl std::io::Read,
    on_disk: Option<u64>,
    limits: &Limits,
    bytes: &mut Vec<u8>,
) -> Result<InputFormat> {
    use std::io::Read;
    bytes.clear();
    let head_len = (HEAD_LEN as u64).min(limits.max_memory_bytes);
    reader.by_ref().take(head_len).read_to_end(bytes)?;
    let format = detect(bytes).ok_or_else(|| unrecognised(bytes))?;
    let complete = (bytes.len() as u64) < head_len;
    if complete {
        return Ok(format);
    }
    let bound = match format {
        InputFormat::Radiance => radiance::file_len_bound(bytes),
        InputFormat::OpenExr => exr::file_len_bound(bytes),
        InputFormat::Pfm => pfm::file_len(bytes),
        // Compressed without a stated length: the whole file, within the budget.
        InputFormat::Png | InputFormat::Jpeg | InputFormat::Tiff => Some(u64::MAX),
    };
    let bound = bound.ok_or_else(|| {
        Error::decode(
            format_name(format),
            format!("the header does not end within the first {HEAD_LEN} bytes"),
        )
    })?;
    // Read at most one byte more than the budget, to tell a file that exceeds it.
    let want = bound.min(limits.max_memory_bytes.saturating_add(1));
    if want < bytes.len() as u64 {
        bytes.truncate(want as usize);
    } else if want > bytes.len() as u64 {
        let reserve = want
            .min(on_disk.unwrap_or(want))
            .saturating_sub(bytes.len() as u64);
        limits.check_memory("the file's bytes", Some(bytes.len() as u64 + reserve))?;
        // A stream's length is unknown: it grows as it is read, not to what a header says.
        let reserve = if on_disk.is_some() { reserve } else { 0 };
        bytes
            .try_reserve_exact(usize::try_from(reserve).unwrap_or(usize::MAX))
            .map_err(|_| out_of_memory("the file's bytes", reserve))?;
        reader
            .by_ref()
            .take(want - bytes.len() as u64)
            .read_to_end(bytes)?;
    }
    limits.check_memory("the file's bytes", Some(bytes.len() as u64))?;
    Ok(format)
}

/// The format's name, as in its reader's errors.
fn format_name(f: InputFormat) -> &'static str {
    match f {
        InputFormat::Radiance => "Radiance",
        InputFormat::OpenExr => "OpenEXR",
        InputFormat::Pfm => "PFM",
        InputFormat::Png => "PNG",
        InputFormat::Jpeg => "JPEG",
        InputFormat::Tiff => "TIFF",
    }
}

/// The error for a file of no format we read.
fn unrecognised(bytes: &[u8]) -> Error {
    if bytes.is_empty() {
        return Error::decode("image", "empty file");
    }
    Error::Unsupported(
        "not a Radiance, OpenEXR or PFM file, nor a PNG, JPEG or TIFF photograph (unrecognised first bytes)"
            .into(),
    )
}

/// The error for an allocation the system refused although it was within the budget.
pub(crate) fn out_of_memory(what: &str, bytes: u64) -> Error {
    Error::Io(std::io::Error::new(
        std::io::ErrorKind::OutOfMemory,
        format!(
            "cannot allocate {} for {what}",
            crate::error::human_bytes(bytes)
        ),
    ))
}

/// Decode an HDR image held in memory, whatever its format.
pub fn decode(bytes: &[u8], limits: &Limits) -> Result<HdrImage> {
    match detect(bytes) {
        Some(InputFormat::Radiance) => radiance::decode(bytes, limits),
        Some(InputFormat::OpenExr) => exr::decode(bytes, limits),
        Some(InputFormat::Pfm) => pfm::decode(bytes, limits),
        Some(InputFormat::Png) => ldr::decode_png(bytes, limits),
        Some(InputFormat::Jpeg) => ldr::decode_jpeg(bytes, limits),
        Some(InputFormat::Tiff) => ldr::decode_tiff(bytes, limits),
        None => Err(unrecognised(bytes)),
    }
}

/// The display-image formats the library writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    /// PNG, sRGB-encoded, with 8 or 16 bits per channel.
    Png {
        /// 8 or 16.
        bits: u8,
        /// How hard the file is compressed (lossless at every level: the same samples).
        compression: display::PngCompression,
    },
    /// Baseline JPEG, sRGB-encoded.
    Jpeg {
        /// 1–100.
        quality: u8,
    },
    /// OpenEXR, display-referred linear Rec.709 RGB (1.0 = `L_dmax`, recorded in the
    /// `whiteLuminance` attribute).
    Exr,
    /// TIFF, display-referred linear Rec. 709 RGB as 32-bit floats (1.0 = `L_dmax`, stated
    /// in the `ImageDescription`; [`tiff::write_display`]).
    Tiff,
    /// Radiance RGBE, display-referred linear Rec. 709 RGB with `EXPOSURE=` such that
    /// readers give RGB (1, 1, 1) `L_dmax` cd/m² ([`radiance::write_display`]).
    Radiance,
}

impl OutputFormat {
    /// PNG with `bits` (8 or 16) per channel at the default compression,
    /// [`PngCompression::Fast`](display::PngCompression::Fast).
    pub const fn png(bits: u8) -> Self {
        OutputFormat::Png {
            bits,
            compression: display::PngCompression::Fast,
        }
    }

    /// This format with PNGs at `compression` (other formats are returned unchanged), e.g.
    /// for a compression chosen once for whatever format a file name implies.
    #[must_use]
    pub const fn with_png_compression(self, compression: display::PngCompression) -> Self {
        match self {
            OutputFormat::Png { bits, .. } => OutputFormat::Png { bits, compression },
            other => other,
        }
    }

    /// Encode `image` in this format into `w`. The one place that dispatches on the format:
    /// [`write_display`], [`write_display_to`] and [`OutputFormat::encode_into`] all write
    /// through it, so the three give the same file byte for byte.
    fn encode(self, image: &DisplayImage, w: impl std::io::Write + std::io::Seek) -> Result<()> {
        match self {
            OutputFormat::Png { bits, compression } => {
                display::write_png_with(image, bits, compression, w)
            }
            OutputFormat::Jpeg { quality } => display::write_jpeg(image, quality, w),
            OutputFormat::Exr => exr::write_display(image, w),
            OutputFormat::Tiff => tiff::write_display(image, w),
            OutputFormat::Radiance => radiance::write_display(image, w),
        }
    }

    /// Encode `image` in this format into `bytes`, its previous contents replaced and its
    /// memory reused: the file [`write_display`] would write, byte for byte.
    pub fn encode_into(self, image: &DisplayImage, bytes: &mut Vec<u8>) -> Result<()> {
        bytes.clear();
        self.encode(image, std::io::Cursor::new(bytes))
    }

    /// The format implied by a file name's extension (`.png`, `.jpg`/`.jpeg`, `.exr`,
    /// `.tif`/`.tiff`, `.hdr`), with 8-bit PNG at the default compression and quality-90
    /// JPEG.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("png") => Ok(OutputFormat::png(8)),
            Some("jpg" | "jpeg") => Ok(OutputFormat::Jpeg { quality: 90 }),
            Some("exr") => Ok(OutputFormat::Exr),
            Some("tif" | "tiff") => Ok(OutputFormat::Tiff),
            Some("hdr") => Ok(OutputFormat::Radiance),
            _ => Err(Error::Unsupported(format!(
                "cannot tell the output format of {} (use .png, .jpg, .exr, .tif or .hdr)",
                path.display()
            ))),
        }
    }
}

/// Encode a display image in `format` into `w`, any writer (standard output, a pipe, a
/// socket): the file is built in memory first, so that nothing is written when encoding
/// fails and formats that seek (OpenEXR) work on streams.
///
/// ```
/// use visadapt::{DisplayImage, io::{self, OutputFormat}};
/// let image = DisplayImage { width: 2, height: 1, r: vec![0.5; 2], g: vec![0.5; 2],
///                            b: vec![0.5; 2], display_max_cd_m2: 100.0 };
/// let mut out = Vec::new();
/// io::write_display_to(&image, OutputFormat::png(8), &mut out)?;
/// assert!(out.starts_with(b"\x89PNG"));
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn write_display_to(
    image: &DisplayImage,
    format: OutputFormat,
    mut w: impl std::io::Write,
) -> Result<()> {
    let mut buf = Vec::new();
    format.encode_into(image, &mut buf)?;
    w.write_all(&buf)?;
    w.flush()?;
    Ok(())
}

/// Write a display image to `path` in `format`, atomically: the file appears complete or
/// not at all (see [`display::write_atomically`]).
pub fn write_display(image: &DisplayImage, path: &Path, format: OutputFormat) -> Result<()> {
    display::write_atomically(path, |w| format.encode(image, w))
}

#[cfg(test)]
mod tests {
    use super::*;
    use display::PngCompression;

    /// A small display image with a gradient, values beyond the display's range and a
    /// ragged size, so that filters, clipping and band edges all matter.
    fn image() -> DisplayImage {
        let (width, height) = (37, 29);
        let plane = |k: f32| -> Vec<f32> {
            (0..width * height)
                .map(|i| ((i % width) as f32 * 0.031 + (i / width) as f32 * 0.017 * k) % 1.2)
                .collect()
        };
        DisplayImage {
            width,
            height,
            r: plane(1.0),
            g: plane(2.0),
            b: plane(3.0),
            display_max_cd_m2: 80.0,
        }
    }

    #[test]
    fn every_writer_gives_the_same_file_in_every_format() {
        let image = image();
        let dir = tempfile::tempdir().unwrap();
        let mut formats = vec![
            OutputFormat::png(16),
            OutputFormat::Jpeg { quality: 75 },
            OutputFormat::Exr,
            OutputFormat::Tiff,
            OutputFormat::Radiance,
        ];
        for compression in [
            PngCompression::Fast,
            PngCompression::Fastest,
            PngCompression::Rle,
            PngCompression::Fdeflate,
        ] {
            formats.push(OutputFormat::png(8).with_png_compression(compression));
        }
        // A buffer reused from a larger file: its old bytes must not survive.
        let mut reused = vec![0xA5u8; 1 << 20];
        for (k, format) in formats.into_iter().enumerate() {
            let path = dir.path().join(format!("out{k}"));
            write_display(&image, &path, format).unwrap();
            let file = std::fs::read(&path).unwrap();
            let mut streamed = Vec::new();
            write_display_to(&image, format, &mut streamed).unwrap();
            format.encode_into(&image, &mut reused).unwrap();
            assert!(file == streamed, "{format:?}: write_display_to differs");
            assert!(file == reused, "{format:?}: encode_into differs");
            if let OutputFormat::Png { bits, compression } = format {
                let mut direct = Vec::new();
                display::write_png_with(&image, bits, compression, &mut direct).unwrap();
                assert!(file == direct, "{format:?}: not the level asked for");
            }
        }
    }

    #[test]
    fn the_png_compression_is_the_files_and_applies_to_png_only() {
        let image = image();
        let bytes = |format: OutputFormat| {
            let mut v = Vec::new();
            format.encode_into(&image, &mut v).unwrap();
            v
        };
        let fast = bytes(OutputFormat::png(8));
        let rle = bytes(OutputFormat::png(8).with_png_compression(PngCompression::Rle));
        // Different files (the Up filter and run-length codes against the adaptive
        // filter and level 1), checked to hold the same samples in `display`'s tests.
        assert_ne!(fast, rle);
        assert_eq!(
            OutputFormat::png(16).with_png_compression(PngCompression::Rle),
            OutputFormat::Png {
                bits: 16,
                compression: PngCompression::Rle
            }
        );
        for other in [
            OutputFormat::Jpeg { quality: 90 },
            OutputFormat::Exr,
            OutputFormat::Tiff,
            OutputFormat::Radiance,
        ] {
            assert_eq!(other.with_png_compression(PngCompression::Rle), other);
        }
        assert_eq!(
            OutputFormat::from_path(Path::new("a/b.PNG")).unwrap(),
            OutputFormat::png(8)
        );
    }
}
