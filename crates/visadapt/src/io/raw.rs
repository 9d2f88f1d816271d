//! Raw video frames: the formats of pipes to and from ffmpeg (`-f rawvideo`), with no
//! header and no padding, one frame after another, of a size both ends are told.
//!
//! * In: **`gbrpf32le`** ([`FrameReader`]), ffmpeg's planar float RGB: per frame three
//!   planes of `width × height` little-endian IEEE 754 32-bit floats, rows top to bottom,
//!   in ffmpeg's plane order for its GBR formats, green, then blue, then red
//!   (`AV_PIX_FMT_GBRPF32LE`, libavutil `pixfmt.h`). The values are taken as linear
//!   Rec. 709 RGB with a D65 white and converted to CIE XYZ as PFM files are
//!   ([`super::pfm`]); like PFM they carry no units, so the image is relative
//!   ([`HdrImage::absolute_units`] false: scale it to cd/m²). A stream that ends between
//!   two frames has ended; one that ends inside a frame is an error naming the stream and
//!   the frame.
//! * Out: **`rgb48le`** ([`RawFormat::Rgb48le`]): interleaved R, G, B, 16 bits each,
//!   little-endian, sRGB-encoded exactly as the 16-bit PNG writer encodes them (the same
//!   code values); **`rgb24`** ([`RawFormat::Rgb24`]): interleaved R, G, B, 8 bits each, the
//!   8-bit PNG and JPEG encoding. [`write_frame`].
//!
//! Frames are numbered from 0 in the order they are read. The frame size is checked
//! against [`Limits`] when the reader is made, before anything is allocated; the reader
//! holds one frame's planes and a one-plane buffer, whatever the length of the stream.

use crate::colour::{self, REC709};
use crate::{DisplayImage, Error, HdrImage, Limits, Result};
use std::io::{Read, Write};

/// The input format's name, as in errors and in ffmpeg's `-pix_fmt`.
const FORMAT: &str = "raw gbrpf32le";

/// Bytes of one `f32` sample.
const SAMPLE: usize = 4;

/// A reader of raw `gbrpf32le` frames of one size from any stream (see the
/// [module documentation](self)).
///
/// ```
/// use visadapt::{HdrImage, Limits, io::raw::FrameReader};
/// // Two 2x1 frames: the G, B and R planes of each, little-endian f32.
/// let mut bytes = Vec::new();
/// for v in [0.5f32, 0.5, 0.5, 0.5, 0.5, 0.5, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0] {
///     bytes.extend_from_slice(&v.to_le_bytes());
/// }
/// let mut frames = FrameReader::new(bytes.as_slice(), "the pipe", 2, 1, &Limits::default())?;
/// let mut image = HdrImage::zeros(0, 0);
/// assert!(frames.read_into(&mut image)?);
/// assert!((image.y[0] - 0.5).abs() < 1e-6);  // grey: Y = R = G = B
/// assert!(frames.read_into(&mut image)?);
/// assert!((image.y[1] - 2.0).abs() < 1e-6);
/// assert!(!frames.read_into(&mut image)?);   // the end of the stream
/// # Ok::<(), visadapt::Error>(())
/// ```
#[derive(Debug)]
pub struct FrameReader<R> {
    reader: R,
    name: String,
    width: usize,
    height: usize,
    /// Frames read so far (the number of the next one).
    frames: u64,
    /// One plane's bytes.
    bytes: Vec<u8>,
    /// The factor every value is multiplied by ([`FrameReader::with_scale`]).
    scale: f32,
}

impl<R: Read> FrameReader<R> {
    /// A reader of `width × height` frames from `reader`, called `name` in errors (e.g.
    /// `"standard input"`). Refuses a size of zero, one beyond [`Limits::max_pixels`],
    /// or one whose planes and read buffer (16 bytes a pixel) exceed
    /// [`Limits::max_memory_bytes`], before allocating anything.
    pub fn new(
        reader: R,
        name: impl Into<String>,
        width: u64,
        height: u64,
        limits: &Limits,
    ) -> Result<Self> {
        let n = limits.check(FORMAT, width, height)?;
        limits.check_memory(
            "a raw frame's planes and read buffer",
            (n as u64).checked_mul(4 * SAMPLE as u64),
        )?;
        Ok(FrameReader {
            reader,
            name: name.into(),
            width: width as usize,
            height: height as usize,
            frames: 0,
            bytes: Vec::new(),
            scale: 1.0,
        })
    }

    /// The reader with every value multiplied by `factor` (the frames' unit in cd/m²,
    /// `visadapt video --scale`) in the conversion to XYZ, as [`HdrImage::scale`] would
    /// after it, with one rounding instead of two (a factor that is not finite is
    /// applied by [`HdrImage::scale`]).
    pub fn with_scale(self, factor: f32) -> Self {
        FrameReader {
            scale: factor,
            ..self
        }
    }

    /// Frames read so far.
    pub fn frames_read(&self) -> u64 {
        self.frames
    }

    /// Bytes of one frame in the stream.
    pub fn frame_bytes(&self) -> u64 {
        (self.width * self.height * 3 * SAMPLE) as u64
    }

    /// Read the next frame into `image`, reusing its planes when they have the size:
    /// `Ok(true)` with a frame, `Ok(false)` at the end of the stream (before a frame's
    /// first byte). A stream that ends inside a frame is an [`Error::Decode`] naming the
    /// stream and the frame.
    pub fn read_into(&mut self, image: &mut HdrImage) -> Result<bool> {
        let n = self.width * self.height;
        let plane_bytes = n * SAMPLE;
        if self.bytes.len() != plane_bytes {
            self.bytes.clear();
            self.bytes.try_reserve_exact(plane_bytes).map_err(|_| {
                super::out_of_memory("a raw frame's read buffer", plane_bytes as u64)
            })?;
            self.bytes.resize(plane_bytes, 0);
        }
        // ffmpeg's plane order: G, B, R.
        let mut planes = [
            std::mem::take(&mut image.y),
            std::mem::take(&mut image.z),
            std::mem::take(&mut image.x),
        ];
        let read = self.read_planes(&mut planes);
        let [y, z, x] = planes;
        *image = HdrImage {
            width: self.width,
            height: self.height,
            x,
            y,
            z,
            scotopic: None,
            view: None,
            absolute_units: false,
            adopted_white: Some(REC709.white),
        };
        if !read? {
            return Ok(false);
        }
        let m = REC709.rgb_to_xyz().expect("Rec.709 primaries are valid");
        let fused = if self.scale.is_finite() {
            self.scale
        } else {
            1.0
        };
        let (x, y, z) = (&mut image.x, &mut image.y, &mut image.z);
        colour::rgb_planes_to_xyz(&m, f64::from(fused), x, y, z);
        if fused != self.scale {
            image.scale(self.scale);
        }
        self.frames += 1;
        Ok(true)
    }

    /// Fill the three planes (in stream order) from the stream; `Ok(false)` when it ends
    /// before the first byte.
    fn read_planes(&mut self, planes: &mut [Vec<f32>; 3]) -> Result<bool> {
        let n = self.width * self.height;
        for (k, plane) in planes.iter_mut().enumerate() {
            let got = fill(&mut self.reader, &mut self.bytes)?;
            if got < self.bytes.len() {
                if k == 0 && got == 0 {
                    return Ok(false);
                }
                return Err(Error::decode(
                    FORMAT,
                    format!(
                        "{}: frame {} is truncated: the stream ends after {} of its {} bytes ({}x{})",
                        self.name,
                        self.frames,
                        k * self.bytes.len() + got,
                        self.frame_bytes(),
                        self.width,
                        self.height
                    ),
                ));
            }
            plane.clear();
            plane
                .try_reserve_exact(n)
                .map_err(|_| super::out_of_memory("a raw frame's planes", (n * SAMPLE) as u64))?;
            plane.extend(
                self.bytes
                    .chunks_exact(SAMPLE)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            );
        }
        Ok(true)
    }
}

impl<R: Read> Iterator for FrameReader<R> {
    type Item = Result<HdrImage>;

    /// The next frame in a new image; `None` at the end of the stream.
    fn next(&mut self) -> Option<Self::Item> {
        let mut image = HdrImage::zeros(0, 0);
        match self.read_into(&mut image) {
            Ok(true) => Some(Ok(image)),
            Ok(false) => None,
            Err(e) => Some(Err(e)),
        }
    }
}

/// Read from `r` until `buf` is full or the stream ends; the number of bytes read.
fn fill(r: &mut impl Read, buf: &mut [u8]) -> Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(k) => got += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::Io(e)),
        }
    }
    Ok(got)
}

/// The raw output formats (see the [module documentation](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawFormat {
    /// Interleaved RGB, 16 bits a sample, little-endian, sRGB-encoded (ffmpeg `rgb48le`).
    Rgb48le,
    /// Interleaved RGB, 8 bits a sample, sRGB-encoded (ffmpeg `rgb24`).
    Rgb24,
}

impl RawFormat {
    /// The format's name for ffmpeg's `-pix_fmt`.
    pub fn pix_fmt(self) -> &'static str {
        match self {
            RawFormat::Rgb48le => "rgb48le",
            RawFormat::Rgb24 => "rgb24",
        }
    }

    /// Bytes a pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            RawFormat::Rgb48le => 6,
            RawFormat::Rgb24 => 3,
        }
    }
}

/// Encode a display image as one raw frame into `out` (its previous contents replaced,
/// its memory reused), after [`DisplayImage::validate_planes`].
pub fn encode_frame(image: &DisplayImage, format: RawFormat, out: &mut Vec<u8>) -> Result<()> {
    image.validate_planes()?;
    match format {
        RawFormat::Rgb48le => super::display::srgb16_into(image, false, out),
        RawFormat::Rgb24 => super::display::srgb8_into(image, out),
    }
    Ok(())
}

/// Write a display image as one raw frame to `w` (a pipe, standard output), encoded in
/// `buf`, whose memory is reused from frame to frame. Nothing is written when the image
/// is invalid.
///
/// ```
/// use visadapt::{DisplayImage, io::raw::{self, RawFormat}};
/// let image = DisplayImage { width: 2, height: 1, r: vec![1.0, 0.0], g: vec![1.0, 0.0],
///                            b: vec![1.0, 0.5], display_max_cd_m2: 100.0 };
/// let (mut out, mut buf) = (Vec::new(), Vec::new());
/// raw::write_frame(&image, RawFormat::Rgb24, &mut out, &mut buf)?;
/// assert_eq!(out, [255, 255, 255, 0, 0, 188]); // sRGB: 0.5 linear is code 188
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn write_frame(
    image: &DisplayImage,
    format: RawFormat,
    mut w: impl Write,
    buf: &mut Vec<u8>,
) -> Result<()> {
    encode_frame(image, format, buf)?;
    w.write_all(buf)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `frames` frames of `w × h` whose planes (G, B, R) hold `value(frame, plane, i)`.
    fn stream(
        frames: u64,
        w: usize,
        h: usize,
        value: impl Fn(u64, usize, usize) -> f32,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        for f in 0..frames {
            for p in 0..3 {
                for i in 0..w * h {
                    out.extend_from_slice(&value(f, p, i).to_le_bytes());
                }
            }
        }
        out
    }

    #[test]
    fn planes_are_green_blue_red_and_become_xyz() {
        // Pure red, green and blue pixels; then white of luminance 3.
        let value = |_f: u64, plane: usize, i: usize| match (plane, i) {
            (0, 1) | (1, 2) | (2, 0) => 1.0, // G at pixel 1, B at 2, R at 0
            (_, 3) => 3.0,
            _ => 0.0,
        };
        let bytes = stream(1, 4, 1, value);
        let mut frames =
            FrameReader::new(bytes.as_slice(), "test", 4, 1, &Limits::default()).unwrap();
        let image = frames.next().unwrap().unwrap();
        assert!(frames.next().is_none());
        assert_eq!(frames.frames_read(), 1);
        // The Rec. 709 luminance coefficients (ITU-R BT.709-6, item 3.3): 0.2126, 0.7152,
        // 0.0722, to the 4 decimals the standard gives.
        for (i, want) in [0.2126, 0.7152, 0.0722, 3.0].into_iter().enumerate() {
            assert!(
                (f64::from(image.y[i]) - want).abs() < 1e-4,
                "{i}: {}",
                image.y[i]
            );
        }
        // D65 white (x, y) = (0.3127, 0.3290): X/Y = 0.9505, Z/Y = 1.0891.
        assert!((f64::from(image.x[3]) / 3.0 - 0.9505).abs() < 1e-3);
        assert!((f64::from(image.z[3]) / 3.0 - 1.0891).abs() < 1e-3);
        assert!(!image.absolute_units);
        assert_eq!((image.width, image.height), (4, 1));
    }

    #[test]
    fn a_truncated_frame_names_the_stream_and_the_frame() {
        let mut bytes = stream(3, 3, 2, |f, _, i| (f as usize + i) as f32);
        bytes.truncate(bytes.len() - 5);
        let mut frames =
            FrameReader::new(bytes.as_slice(), "standard input", 3, 2, &Limits::default()).unwrap();
        let mut image = HdrImage::zeros(0, 0);
        assert!(frames.read_into(&mut image).unwrap());
        assert!(frames.read_into(&mut image).unwrap());
        assert!((image.y[2] - 3.0).abs() < 1e-5);
        let err = frames.read_into(&mut image).unwrap_err().to_string();
        assert_eq!(
            err,
            "invalid raw gbrpf32le data: standard input: frame 2 is truncated: \
             the stream ends after 67 of its 72 bytes (3x2)"
        );
        assert!(!err.contains('\n'));
    }

    #[test]
    fn absurd_sizes_are_refused_before_allocating() {
        let limits = Limits::default();
        for (w, h) in [(0, 10), (10, 0), (u64::MAX, 2), (1 << 20, 1 << 20)] {
            let err = FrameReader::new(std::io::repeat(0), "s", w, h, &limits).unwrap_err();
            assert!(
                matches!(err, Error::Limits(_) | Error::Decode { .. }),
                "{w}x{h}: {err}"
            );
        }
        // Within the pixel limit but beyond the memory budget (16 bytes a pixel).
        let small = Limits {
            max_memory_bytes: 16 * 1000 - 1,
            ..Limits::default()
        };
        assert!(matches!(
            FrameReader::new(std::io::repeat(0), "s", 100, 10, &small),
            Err(Error::Limits(_))
        ));
        assert!(
            FrameReader::new(
                std::io::repeat(0),
                "s",
                100,
                10,
                &Limits {
                    max_memory_bytes: 16 * 1000,
                    ..Limits::default()
                }
            )
            .is_ok()
        );
    }

    #[test]
    fn an_endless_stream_reuses_the_same_planes() {
        let mut frames =
            FrameReader::new(std::io::repeat(0), "zeros", 64, 32, &Limits::default()).unwrap();
        let mut image = HdrImage::zeros(0, 0);
        assert!(frames.read_into(&mut image).unwrap());
        let planes = [image.x.as_ptr(), image.y.as_ptr(), image.z.as_ptr()];
        for _ in 0..10 {
            assert!(frames.read_into(&mut image).unwrap());
        }
        assert_eq!(
            planes,
            [image.x.as_ptr(), image.y.as_ptr(), image.z.as_ptr()]
        );
        assert_eq!(frames.frames_read(), 11);
        assert!(image.y.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn raw_output_has_the_png_writers_codes() {
        let n = 4096;
        let ramp: Vec<f32> = (0..n).map(|i| i as f32 / (n - 1) as f32).collect();
        let image = DisplayImage {
            width: 64,
            height: 64,
            r: ramp.clone(),
            g: ramp.iter().map(|v| v * v).collect(),
            b: ramp.iter().rev().copied().collect(),
            display_max_cd_m2: 100.0,
        };
        let lut = colour::SrgbLut::new(16);
        let mut buf = Vec::new();
        encode_frame(&image, RawFormat::Rgb48le, &mut buf).unwrap();
        assert_eq!(buf.len(), n * 6);
        for i in 0..n {
            let code = |c: usize| u16::from_le_bytes([buf[6 * i + 2 * c], buf[6 * i + 2 * c + 1]]);
            assert_eq!(code(0), lut.encode(image.r[i]));
            assert_eq!(code(1), lut.encode(image.g[i]));
            assert_eq!(code(2), lut.encode(image.b[i]));
        }
        // Against the exact curve (IEC 61966-2-1): within the table's stated error.
        let exact = |v: f32| f64::from(colour::srgb_encode(v)) * 65535.0;
        for i in 0..n {
            let code = u16::from_le_bytes([buf[6 * i], buf[6 * i + 1]]);
            assert!((f64::from(code) - exact(image.r[i])).abs() <= 4.0, "{i}");
        }
        encode_frame(&image, RawFormat::Rgb24, &mut buf).unwrap();
        assert_eq!(buf.len(), n * 3);
        assert_eq!(buf, crate::io::display::to_srgb8(&image));
        // An inconsistent image is refused and nothing is written.
        let mut bad = image.clone();
        bad.g.pop();
        let mut out = Vec::new();
        assert!(write_frame(&bad, RawFormat::Rgb24, &mut out, &mut buf).is_err());
        assert!(out.is_empty());
    }
}
