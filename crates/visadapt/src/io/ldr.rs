//! Display-encoded photographs as input: 8- and 16-bit PNG, JPEG and TIFF, for users who
//! have no HDR capture of a scene.
//!
//! Such a file records what a display should show, not the light of the scene: its code
//! values are sRGB-encoded (IEC 61966-2-1) and relative, the brightest code value being
//! the display's white. The readers undo the sRGB curve ([`colour::srgb_decode`]), take
//! the primaries as Rec. 709 with a D65 white (the sRGB standard), and give an
//! [`HdrImage`] in relative units (`absolute_units = false`, `adopted_white` = D65) with
//! Y = 1 at code-value white. The caller states the scene luminance of that white in
//! cd/m² by scaling the image (`visadapt map photo.jpg --scale 250`, or
//! [`HdrImage::scale`]). Alpha is dropped, palettes and grey are expanded. 32-bit float
//! TIFFs are taken as already linear (the float TIFFs visadapt writes, in the units of
//! their `ImageDescription` when it is ours). No ICC profile is read: a photograph in
//! another colour space is read as sRGB.
//!
//! Every size is checked against [`Limits`] before any pixel is decoded.

use crate::colour;
use crate::{Error, HdrImage, Limits, Result};

/// The image formats of this module, as named in errors.
const PNG: &str = "PNG";
const JPEG: &str = "JPEG";
const TIFF: &str = "TIFF";

/// How the samples given to [`to_hdr`] are coded.
#[derive(Clone, Copy)]
enum Coding {
    /// sRGB-encoded in `[0, 1]`, relative.
    Srgb,
    /// Linear, relative.
    Linear,
    /// Linear, 1.0 = this many cd/m².
    LinearCdM2(f32),
}

/// Interleaved samples of `channels` per pixel (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA),
/// Rec. 709 primaries, to CIE XYZ planes.
fn to_hdr(
    width: usize,
    height: usize,
    channels: usize,
    samples: impl Fn(usize) -> f32,
    coding: Coding,
) -> Result<HdrImage> {
    let n = width * height;
    let decode = |v: f32| match coding {
        Coding::Srgb => colour::srgb_decode(v),
        Coding::Linear => v,
        Coding::LinearCdM2(l) => v * l,
    };
    let mut r = Vec::with_capacity(n);
    let mut g = Vec::with_capacity(n);
    let mut b = Vec::with_capacity(n);
    for i in 0..n {
        let at = |c: usize| decode(samples(i * channels + c));
        let (pr, pg, pb) = if channels < 3 {
            let v = at(0);
            (v, v, v)
        } else {
            (at(0), at(1), at(2))
        };
        r.push(pr);
        g.push(pg);
        b.push(pb);
    }
    let m = colour::REC709
        .rgb_to_xyz()
        .expect("Rec. 709 primaries are valid");
    colour::rgb_planes_to_xyz(&m, 1.0, &mut r, &mut g, &mut b);
    Ok(HdrImage {
        width,
        height,
        x: r,
        y: g,
        z: b,
        scotopic: None,
        view: None,
        absolute_units: matches!(coding, Coding::LinearCdM2(_)),
        adopted_white: Some(colour::D65),
    })
}

/// Check a decoder's dimensions against the limits and the memory the planes take.
fn check(format: &'static str, width: u64, height: u64, limits: &Limits) -> Result<(usize, usize)> {
    limits.check(format, width, height)?;
    // Three f32 planes plus the decoded samples (at most 8 bytes a pixel).
    let bytes = width.saturating_mul(height).saturating_mul(12 + 8);
    limits.check_memory("the image", Some(bytes))?;
    Ok((width as usize, height as usize))
}

/// Decode an 8- or 16-bit PNG (grey, grey + alpha, RGB, RGBA, palette).
pub fn decode_png(bytes: &[u8], limits: &Limits) -> Result<HdrImage> {
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND);
    let fail = |e: png::DecodingError| match e {
        png::DecodingError::IoError(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            Error::decode(PNG, "truncated file")
        }
        e => Error::decode(PNG, e.to_string()),
    };
    let mut reader = decoder.read_info().map_err(fail)?;
    let info = reader.info();
    let (width, height) = check(PNG, info.width.into(), info.height.into(), limits)?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| Error::decode(PNG, "the image is too large"))?;
    let mut buf = Vec::new();
    buf.try_reserve_exact(size)
        .map_err(|_| super::out_of_memory("the PNG samples", size as u64))?;
    buf.resize(size, 0);
    let frame = reader.next_frame(&mut buf).map_err(fail)?;
    let channels = frame.color_type.samples();
    let row = frame.line_size;
    match frame.bit_depth {
        png::BitDepth::Sixteen => to_hdr(
            width,
            height,
            channels,
            |k| {
                let (y, rest) = (k / (width * channels), k % (width * channels));
                let at = y * row + 2 * rest;
                f32::from(u16::from_be_bytes([buf[at], buf[at + 1]])) / 65535.0
            },
            Coding::Srgb,
        ),
        _ => to_hdr(
            width,
            height,
            channels,
            |k| {
                let (y, rest) = (k / (width * channels), k % (width * channels));
                f32::from(buf[y * row + rest]) / 255.0
            },
            Coding::Srgb,
        ),
    }
}

/// Decode a baseline or progressive JPEG (grey or colour; CMYK is refused).
pub fn decode_jpeg(bytes: &[u8], limits: &Limits) -> Result<HdrImage> {
    use zune_jpeg::zune_core::bytestream::ZCursor;
    use zune_jpeg::zune_core::colorspace::ColorSpace;
    use zune_jpeg::zune_core::options::DecoderOptions;
    let options = DecoderOptions::default()
        .jpeg_set_out_colorspace(ColorSpace::RGB)
        .set_max_width(usize::MAX)
        .set_max_height(usize::MAX);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    // The decoder's messages can end in a newline: `Error::decode` folds them to one line.
    let fail = |e: zune_jpeg::errors::DecodeErrors| Error::decode(JPEG, e.to_string());
    decoder.decode_headers().map_err(fail)?;
    let info = decoder
        .info()
        .ok_or_else(|| Error::decode(JPEG, "no image header"))?;
    let (width, height) = check(JPEG, info.width.into(), info.height.into(), limits)?;
    let pixels = decoder.decode().map_err(fail)?;
    if pixels.len() != width * height * 3 {
        return Err(Error::decode(JPEG, "the decoded image has the wrong size"));
    }
    to_hdr(
        width,
        height,
        3,
        |k| f32::from(pixels[k]) / 255.0,
        Coding::Srgb,
    )
}

/// Decode a TIFF: 8- or 16-bit grey or RGB (± alpha), sRGB-encoded; or 32-bit float,
/// linear (a visadapt float TIFF in cd/m²: see the module documentation).
pub fn decode_tiff(bytes: &[u8], limits: &Limits) -> Result<HdrImage> {
    use ::tiff::ColorType;
    use ::tiff::decoder::{Decoder, DecodingResult};
    let fail = |e: ::tiff::TiffError| match e {
        ::tiff::TiffError::LimitsExceeded => {
            Error::decode(TIFF, "the image exceeds the memory budget")
        }
        e => Error::decode(TIFF, e.to_string()),
    };
    let mut decoder = Decoder::new(std::io::Cursor::new(bytes)).map_err(fail)?;
    let (w, h) = decoder.dimensions().map_err(fail)?;
    let (width, height) = check(TIFF, w.into(), h.into(), limits)?;
    let channels = match decoder.colortype().map_err(fail)? {
        ColorType::Gray(_) => 1,
        ColorType::GrayA(_) => 2,
        ColorType::RGB(_) => 3,
        ColorType::RGBA(_) => 4,
        other => {
            return Err(Error::Unsupported(format!(
                "{TIFF}: {other:?} samples (grey or RGB are read)"
            )));
        }
    };
    let description = decoder
        .get_tag_ascii_string(::tiff::tags::Tag::ImageDescription)
        .ok();
    let budget = usize::try_from(limits.max_memory_bytes).unwrap_or(usize::MAX);
    decoder = decoder.with_limits({
        let mut l = ::tiff::decoder::Limits::default();
        l.decoding_buffer_size = budget;
        l.intermediate_buffer_size = budget;
        l
    });
    let n = width * height * channels;
    let short = || Error::decode(TIFF, "the decoded image has the wrong size");
    match decoder.read_image().map_err(fail)? {
        DecodingResult::U8(v) if v.len() == n => to_hdr(
            width,
            height,
            channels,
            |k| f32::from(v[k]) / 255.0,
            Coding::Srgb,
        ),
        DecodingResult::U16(v) if v.len() == n => to_hdr(
            width,
            height,
            channels,
            |k| f32::from(v[k]) / 65535.0,
            Coding::Srgb,
        ),
        DecodingResult::F32(v) if v.len() == n => {
            let coding = description
                .as_deref()
                .and_then(|d| d.strip_prefix(super::tiff::DISPLAY_MAX_PREFIX))
                .and_then(|d| d.strip_suffix(" cd/m2"))
                .and_then(|l| l.parse::<f32>().ok())
                .filter(|l| l.is_finite() && *l > 0.0)
                .map_or(Coding::Linear, Coding::LinearCdM2);
            to_hdr(width, height, channels, |k| v[k], coding)
        }
        DecodingResult::U8(_) | DecodingResult::U16(_) | DecodingResult::F32(_) => Err(short()),
        _ => Err(Error::Unsupported(format!(
            "{TIFF}: samples other than 8- or 16-bit integers or 32-bit floats"
        ))),
    }
}
