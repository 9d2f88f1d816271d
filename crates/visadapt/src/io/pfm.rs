//! Portable float map (PFM) input and output.
//!
//! Reads the two PFM variants: `PF` (three channels, RGB) and `Pf` (one channel, grey).
//! The header is three whitespace-separated tokens after the magic, `<width> <height>
//! <scale>`, followed by exactly one whitespace byte (normally `\n`) and then
//! `width × height × channels` 32-bit floats, interleaved, rows stored **bottom to top**
//! (they are flipped to top-first).
//!
//! Rules applied:
//! * the sign of `scale` gives the byte order: negative = little-endian, positive =
//!   big-endian; zero, NaN or infinite scales are rejected;
//! * `|scale|` is the PFM "scale factor": when it is not 1 every value is multiplied by it
//!   (most writers put ±1, and most readers ignore it; multiplying keeps the units the
//!   writer declared);
//! * RGB is taken as linear Rec. 709 / sRGB primaries with D65 white and converted to CIE
//!   XYZ with [`REC709`]'s matrix; grey is luminance Y, with X and Z set so the colour is
//!   D65 white (X = 0.9505·Y, Z = 1.0891·Y, the row sums of that matrix); the adopted
//!   white ([`HdrImage::adopted_white`]) is D65;
//! * PFM carries no units, so the image is relative ([`HdrImage::absolute_units`] false);
//! * sizes are overflow-checked and checked against [`Limits`] before allocation; fewer
//!   data bytes than the header declares is a decode error, extra bytes are ignored.
//!
//! [`encode`] writes colour (`PF`) little-endian PFM in linear Rec. 709.

use crate::colour::{self, REC709};
use crate::limits::saturating_f32;
use crate::{Error, HdrImage, Limits, Result};

/// Format name used in error messages.
const FORMAT: &str = "PFM";

/// Longest header token accepted (a width, height or scale), in bytes. Our bound: a
/// decimal `u64` has at most 20 digits and any sensible float fits easily.
const MAX_TOKEN: usize = 64;

/// Read the next whitespace-separated header token at `*pos`.
fn token<'a>(bytes: &'a [u8], pos: &mut usize) -> Result<&'a str> {
    while bytes.get(*pos).is_some_and(u8::is_ascii_whitespace) {
        *pos += 1;
    }
    let start = *pos;
    while bytes.get(*pos).is_some_and(|b| !b.is_ascii_whitespace()) {
        *pos += 1;
        if *pos - start > MAX_TOKEN {
            return Err(Error::decode(FORMAT, "header token too long"));
        }
    }
    if start == *pos {
        return Err(Error::decode(FORMAT, "header is truncated"));
    }
    std::str::from_utf8(&bytes[start..*pos])
        .map_err(|_| Error::decode(FORMAT, "header is not text"))
}

/// Parse a width or height: decimal digits only.
fn dimension(t: &str) -> Result<u64> {
    if !t.bytes().all(|b| b.is_ascii_digit()) {
        return Err(Error::decode(FORMAT, format!("invalid dimension {t:?}")));
    }
    t.parse()
        .map_err(|_| Error::decode(FORMAT, format!("invalid dimension {t:?}")))
}

/// The header: channels, width, height, scale, and the offset of the first data byte.
fn parse_header(bytes: &[u8]) -> Result<(usize, u64, u64, f64, usize)> {
    let channels = match bytes.get(..2) {
        Some(b"PF") => 3usize,
        Some(b"Pf") => 1,
        _ => return Err(Error::decode(FORMAT, "missing PF/Pf magic")),
    };
    let mut pos = 2;
    if !bytes.get(pos).is_some_and(u8::is_ascii_whitespace) {
        return Err(Error::decode(FORMAT, "missing whitespace after the magic"));
    }
    let width = dimension(token(bytes, &mut pos)?)?;
    let height = dimension(token(bytes, &mut pos)?)?;
    let scale_text = token(bytes, &mut pos)?;
    let scale: f64 = scale_text
        .parse()
        .ok()
        .filter(|s: &f64| s.is_finite() && *s != 0.0)
        .ok_or_else(|| Error::decode(FORMAT, format!("invalid scale {scale_text:?}")))?;
    // Exactly one whitespace byte separates the header from the data.
    if !bytes.get(pos).is_some_and(u8::is_ascii_whitespace) {
        return Err(Error::decode(FORMAT, "header is truncated"));
    }
    Ok((channels, width, height, scale, pos + 1))
}

/// The length of the whole file its header at the start of `head` declares, `None` when
/// the header cannot be parsed (the decoder then reports why).
pub(crate) fn file_len(head: &[u8]) -> Option<u64> {
    let (channels, width, height, _, pos) = parse_header(head).ok()?;
    width
        .checked_mul(height)?
        .checked_mul(channels as u64 * 4)?
        .checked_add(pos as u64)
}

/// Decode a PFM file held in memory (see the [module documentation](self)).
pub fn decode(bytes: &[u8], limits: &Limits) -> Result<HdrImage> {
    decode_scaled(bytes, limits, 1.0)
}

/// [`decode`] with every value multiplied by `factor` (`--scale`) in the conversion to
/// XYZ: the factor joins the Rec. 709 matrix (as in the raw frame reader, so that a PFM
/// file and a raw frame of the same samples give the same values), one rounding to `f32`
/// where scaling after decoding made two. A factor that is not finite is applied by
/// [`HdrImage::scale`] after decoding.
pub(crate) fn decode_scaled(bytes: &[u8], limits: &Limits, factor: f32) -> Result<HdrImage> {
    if !factor.is_finite() {
        let mut image = decode_scaled(bytes, limits, 1.0)?;
        image.scale(factor);
        return Ok(image);
    }
    let scaled = f64::from(factor);
    let (channels, width, height, scale, pos) = parse_header(bytes)?;
    let n = limits.check(FORMAT, width, height)?;
    let (w, h) = (width as usize, height as usize);
    let need = n
        .checked_mul(channels * 4)
        .ok_or_else(|| Error::decode(FORMAT, "image size overflows"))?;
    let data = bytes
        .get(pos..)
        .and_then(|d| d.get(..need))
        .ok_or_else(|| Error::decode(FORMAT, "file is truncated"))?;

    let little = scale < 0.0;
    let factor = if scale.abs() == 1.0 { 1.0 } else { scale.abs() };
    let value = |i: usize| -> f64 {
        let b = [
            data[4 * i],
            data[4 * i + 1],
            data[4 * i + 2],
            data[4 * i + 3],
        ];
        let v = if little {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        };
        f64::from(v) * factor
    };

    let m = REC709
        .rgb_to_xyz()
        .expect("Rec.709 primaries are valid")
        .map(|row| row.map(|v| v * scaled));
    let mut image = HdrImage::zeros(w, h);
    image.adopted_white = Some(REC709.white);
    for file_row in 0..h {
        let y = h - 1 - file_row; // bottom row first in the file
        for x in 0..w {
            let i = file_row * w + x;
            let o = y * w + x;
            let rgb = if channels == 3 {
                [value(3 * i), value(3 * i + 1), value(3 * i + 2)]
            } else {
                let l = value(i);
                [l, l, l]
            };
            let xyz = colour::mul_vec(&m, rgb);
            image.x[o] = saturating_f32(xyz[0]);
            image.y[o] = saturating_f32(if channels == 1 {
                rgb[0] * scaled
            } else {
                xyz[1]
            });
            image.z[o] = saturating_f32(xyz[2]);
        }
    }
    Ok(image)
}

/// Encode an HDR image as colour PFM (`PF`), little-endian (scale −1), linear Rec. 709
/// RGB converted from XYZ, rows bottom to top. The scotopic plane is not stored.
pub fn encode(image: &HdrImage) -> Vec<u8> {
    let (w, h) = (image.width, image.height);
    let m = colour::xyz_to_linear_srgb_matrix();
    let mut out = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    out.reserve(w * h * 12);
    for y in (0..h).rev() {
        for x in 0..w {
            let i = y * w + x;
            let xyz = [
                f64::from(image.x[i]),
                f64::from(image.y[i]),
                f64::from(image.z[i]),
            ];
            for v in colour::mul_vec(&m, xyz) {
                out.extend_from_slice(&saturating_f32(v).to_le_bytes());
            }
        }
    }
    out
}
