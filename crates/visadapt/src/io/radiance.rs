//! Reader for Radiance pictures (`.hdr`, `.pic`): 32-bit RGBE and XYZE, in absolute units;
//! and a writer of display images as RGBE ([`write_display`]).
//!
//! A Radiance picture is a text header, a resolution line and the scanlines
//! (Radiance reference: `src/common/header.c`, `resolu.c`, `color.c` of the Radiance
//! source tree; Ward, "Real Pixels", *Graphics Gems II*, 1991):
//!
//! * **Header**: text lines up to the first empty line. The magic line `#?RADIANCE` (or
//!   `#?RGBE`, any `#?` line) usually comes first, but some writers put lines such as
//!   `VIEW=` before it; both are accepted. Recognised lines: `FORMAT=` (`32-bit_rle_rgbe`,
//!   the default, or `32-bit_rle_xyze`), `EXPOSURE=` (all of them multiply),
//!   `COLORCORR=` (three per-channel factors, which also multiply), `PRIMARIES=` (the RGB
//!   chromaticities), `VIEW=` (the camera). Everything else is ignored.
//! * **Resolution line**: `-Y H +X W` for the standard top-to-bottom, left-to-right
//!   layout, or one of the seven other orientations (`resolu.c`, `str2resolu`); the first
//!   axis is the one that changes between scanlines. The image is reoriented to the
//!   standard layout of [`HdrImage`].
//! * **Scanlines** (`color.c`, `freadcolrs` / `oldreadcolrs`): each scanline is, on its
//!   own, either new-style run-length encoded (`2 2 hi lo`, then the four components one
//!   after the other as runs and literals), or a sequence of 4-byte records that are
//!   flat pixels or old-style repeat records `1 1 1 n` (with counts of consecutive repeat
//!   records shifted by 8 bits each).
//!
//! Units (Radiance convention, `color.h` `WHTEFFICACY` = 179 lm/W): after dividing by the
//! exposure and colour correction, an RGBE value is radiometric and its luminance in
//! cd/m² is 179 × Y of the RGB→XYZ matrix of the file's primaries; an XYZE value is
//! already photometric, CIE XYZ with Y in cd/m². The adopted white
//! ([`HdrImage::adopted_white`]) is the white of the `PRIMARIES=`, equal energy by default
//! (`color.h` `CIE_x_w` = `CIE_y_w` = 1/3), for RGBE and XYZE alike. (`pcond.c` computes luminance as
//! `179·Y(rgb)/exposure` for RGBE but `Y/exposure` for XYZE, and `ra_xyze.c` converts
//! RGBE to XYZE by writing the unscaled values with `EXPOSURE=1/179`.)
//!
//! The reader never panics on bad input and never allocates more than the size checked
//! against [`Limits`]: every inconsistency or truncation is an [`Error::Decode`].

use crate::colour::{self, Chromaticities, Mat3, RADIANCE_DEFAULT, Xy};
use crate::limits::saturating_f32;
use crate::simd::{Isa, at_level};
use crate::{Error, HdrImage, Limits, Projection, Result, View};

/// The format name used in errors and in [`Limits::check`].
const FORMAT: &str = "Radiance";

/// Luminous efficacy of equal-energy white light in lm/W, the factor that turns Radiance
/// radiometric RGB into luminance (Radiance `src/common/color.h`, `WHTEFFICACY`).
pub const WHITE_EFFICACY: f64 = 179.0;

/// Shortest scanline that may be new-style run-length encoded (Radiance `color.c`,
/// `MINELEN`). Shorter scanlines are always flat / old-style.
const MIN_RLE_LEN: usize = 8;

/// Longest scanline that may be new-style run-length encoded: the length must fit in the
/// 15 bits of the `2 2 hi lo` marker (Radiance `color.c`, `MAXELEN`).
const MAX_RLE_LEN: usize = 0x7fff;

/// Exponent bias of the shared exponent byte: a value is `mantissa/256 · 2^(e − 128)`
/// (Radiance `color.h`, `COLXS`).
const EXPONENT_BIAS: i32 = 128;

/// How many bytes [`looks_like_header`] inspects. Radiance headers written by the usual
/// tools (`rpict`, `hdrgen`, `pfilt`) fit well within this; it only bounds the sniffing.
const SNIFF_LEN: usize = 8192;

/// Longest resolution line accepted, in bytes. Radiance reads it into a 32-byte buffer
/// (`resolu.h`, `RESOLU_BUFLEN`); we allow some extra whitespace.
const MAX_RESOLUTION_LINE: usize = 64;

/// Largest magnitude allowed for an entry of the final pixel matrix (RGB or XYZ to
/// cd/m², including 179, exposure and colour correction). A decoded component is at most
/// 255.5 · 2^119 ≈ 1.7e38, so entries below 1e250 keep every f64 sum finite (no
/// overflow to ±inf, hence no NaN). Chosen by us; real files are many orders below it.
const MAX_MATRIX_ENTRY: f64 = 1e250;

/// Radiance view defaults (`src/common/view.h`, `STDVIEW`): perspective, 45° × 45°.
const DEFAULT_VIEW: View = View {
    projection: Projection::Perspective,
    horizontal_deg: 45.0,
    vertical_deg: 45.0,
};

/// Does `head` (the first bytes of a file) look like a Radiance header that does not start
/// with `#?`? True when it begins with printable text lines, one of which, before the
/// header's empty line and within the first 8 KiB, is a `#?RADIANCE` / `#?RGBE` magic
/// line or a `FORMAT=32-bit_rle_…` line. Binary data fails on its first control byte.
pub fn looks_like_header(head: &[u8]) -> bool {
    let mut rest = &head[..head.len().min(SNIFF_LEN)];
    while let Some(nl) = rest.iter().position(|&b| b == b'\n') {
        let line = strip_cr(&rest[..nl]);
        if line.is_empty() {
            return false; // end of header, no marker seen
        }
        if !line.iter().all(|&b| b == b'\t' || (b >= 0x20 && b != 0x7f)) {
            return false;
        }
        if line.starts_with(b"#?RADIANCE")
            || line.starts_with(b"#?RGBE")
            || line.starts_with(b"FORMAT=32-bit_rle_")
        {
            return true;
        }
        rest = &rest[nl + 1..];
    }
    false
}

/// Decode a Radiance picture held in memory into CIE XYZ in cd/m².
///
/// The result has `absolute_units = true`, no scotopic plane, and `view` set from the
/// `VIEW=` lines when there are any.
pub fn decode(bytes: &[u8], limits: &Limits) -> Result<HdrImage> {
    let mut image = HdrImage {
        width: 0,
        height: 0,
        x: Vec::new(),
        y: Vec::new(),
        z: Vec::new(),
        scotopic: None,
        view: None,
        absolute_units: true,
        adopted_white: None,
    };
    decode_into(bytes, limits, &mut image)?;
    Ok(image)
}

/// [`decode`] into an existing image, reusing its planes' memory when they are large
/// enough (for decoding a sequence of frames without allocating and page-faulting fresh
/// planes each time). On success `image` is entirely overwritten (size, planes, `view`,
/// `scotopic = None`, `absolute_units = true`, `adopted_white` = the white of the
/// `PRIMARIES=`, E by default); on error its contents are unspecified.
pub fn decode_into(bytes: &[u8], limits: &Limits, image: &mut HdrImage) -> Result<()> {
    decode_with(bytes, limits, 1.0, image, true)
}

/// [`decode_into`] with every value multiplied by `factor` (a unit conversion, `--scale`)
/// in the same pass: the factor joins the conversion matrix, so the values are rounded to
/// `f32` once, not twice, and saturate as [`HdrImage::scale`]'s do. A factor the matrix
/// cannot take (one that is not finite, or that puts an entry beyond the matrix's bound)
/// is applied by [`HdrImage::scale`] after decoding.
pub(crate) fn decode_scaled_into(
    bytes: &[u8],
    limits: &Limits,
    factor: f32,
    image: &mut HdrImage,
) -> Result<()> {
    decode_with(bytes, limits, factor, image, true)
}

/// [`decode_scaled_into`], with the parallel decoder allowed or not (the tests compare the
/// two).
fn decode_with(
    bytes: &[u8],
    limits: &Limits,
    factor: f32,
    image: &mut HdrImage,
    parallel: bool,
) -> Result<()> {
    let (header, after_header) = parse_header(bytes)?;
    let (res, data_start) = parse_resolution(bytes, after_header)?;
    let n = limits.check(FORMAT, res.width, res.height)?;
    // Both dimensions are at most the checked pixel count, which fits in usize.
    let (width, height) = (res.width as usize, res.height as usize);
    let (scan_len, scan_count) = if res.y_major {
        (width, height)
    } else {
        (height, width)
    };
    let data = &bytes[data_start..];
    // Every scanline takes at least one 4-byte record: reject hopeless files before
    // allocating the planes.
    if data.len() / 4 < scan_count {
        return Err(truncated());
    }
    // The factor in the matrix, or (when the matrix cannot take it) after decoding.
    let (conv, after) = match Converter::new(&header, factor) {
        Ok(conv) => (conv, 1.0),
        Err(_) if factor != 1.0 => (Converter::new(&header, 1.0)?, factor),
        Err(e) => return Err(e),
    };
    let scaled = |image: &mut HdrImage| {
        if after != 1.0 {
            image.scale(after);
        }
    };

    for plane in [&mut image.x, &mut image.y, &mut image.z] {
        if plane.capacity() >= n {
            plane.resize(n, 0.0);
        } else {
            // Zeroed allocation: pages are mapped lazily, no memset.
            *plane = vec![0.0; n];
        }
    }
    image.width = width;
    image.height = height;
    image.scotopic = None;
    image.view = header.view;
    image.absolute_units = true;
    image.adopted_white = colour::is_valid_white(header.white).then_some(header.white);
    let (x, y, z) = (&mut image.x, &mut image.y, &mut image.z);

    // Row-major files (all the usual ones) are decoded in parallel once a serial walk has
    // found where each scanline starts; a file the walk does not vouch for (damaged, or
    // with old-style repeat records) takes the serial decoder below, which reports its
    // errors.
    #[cfg(feature = "rayon")]
    if parallel
        && res.y_major
        && height >= 2 * PARALLEL_ROWS
        && let Some(starts) = scanline_starts(data, scan_count, scan_len)
    {
        let rows = Rows {
            data,
            starts: &starts,
            width,
            height,
            y_decreasing: res.y_decreasing,
            x_decreasing: res.x_decreasing,
            conv: &conv,
        };
        rows.decode_parallel(x, y, z)?;
        scaled(image);
        return Ok(());
    }
    #[cfg(not(feature = "rayon"))]
    let _ = parallel;

    // Every output sample is written exactly once: scanline s, position i maps
    // one-to-one onto (row, column) for each of the eight orientations. Scanlines that
    // run against the output order are reversed first, so conversion always writes a
    // contiguous row (straight into the image for row-major files, into `column_buf`
    // for column-major ones).
    let mut scan = vec![0u8; 4 * scan_len];
    let mut column_buf = if res.y_major {
        Vec::new()
    } else {
        vec![0.0f32; 3 * scan_len]
    };
    let reverse = if res.y_major {
        res.x_decreasing
    } else {
        !res.y_decreasing
    };
    let mut pos = 0usize;
    for s in 0..scan_count {
        read_scanline(data, &mut pos, &mut scan, scan_len)?;
        if reverse {
            scan.chunks_exact_mut(scan_len).for_each(<[u8]>::reverse);
        }
        if res.y_major {
            // Scanline s is a row; `-Y` runs top to bottom.
            let row = if res.y_decreasing { s } else { height - 1 - s };
            let span = row * width..(row + 1) * width;
            conv.convert(
                &scan,
                &mut x[span.clone()],
                &mut y[span.clone()],
                &mut z[span],
            );
        } else {
            // Scanline s is a column, now top to bottom; `-X` starts at the right.
            let col = if res.x_decreasing { width - 1 - s } else { s };
            let (cx, rest) = column_buf.split_at_mut(scan_len);
            let (cy, cz) = rest.split_at_mut(scan_len);
            conv.convert(&scan, cx, cy, cz);
            for (plane, values) in [(&mut *x, &*cx), (&mut *y, &*cy), (&mut *z, &*cz)] {
                for (dst, v) in plane.iter_mut().skip(col).step_by(width).zip(values) {
                    *dst = *v;
                }
            }
        }
    }
    scaled(image);
    Ok(())
}

/// Scanlines per parallel task (our choice: 1080 rows make 68 tasks, enough to balance two
/// to eight threads, each task long enough, ~0.3 ms, to make the scheduling cost
/// negligible).
#[cfg(feature = "rayon")]
const PARALLEL_ROWS: usize = 16;

/// The start of every scanline, and the end of the last, found by a walk over the
/// run-length codes that does not decode them: `None` when some scanline is not plainly
/// one of the two common kinds (a new-style run-length scanline whose codes fit it, or
/// `len` flat pixels without an old-style repeat record), or the data ends early. Then
/// the serial decoder runs instead (a repeat record continues the pixels before it, so
/// its scanline's length is only known by decoding it; and it reports the errors).
#[cfg(feature = "rayon")]
fn scanline_starts(data: &[u8], count: usize, len: usize) -> Option<Vec<usize>> {
    let mut starts = Vec::with_capacity(count + 1);
    let mut pos = 0usize;
    starts.push(pos);
    for _ in 0..count {
        pos = skip_scanline(data, pos, len)?;
        starts.push(pos);
    }
    Some(starts)
}

/// Where the scanline of `len` pixels at `data[pos..]` ends, when it is a whole run-length
/// scanline (the same test as [`read_scanline`]) or `len` flat pixels without a repeat
/// record; `None` otherwise.
#[cfg(feature = "rayon")]
fn skip_scanline(data: &[u8], pos: usize, len: usize) -> Option<usize> {
    let rest = data.get(pos..)?;
    if (MIN_RLE_LEN..=MAX_RLE_LEN).contains(&len)
        && let [2, 2, hi, lo, ..] = *rest
        && hi & 0x80 == 0
    {
        if usize::from(hi) << 8 | usize::from(lo) != len {
            return None;
        }
        // The four components' codes, as `read_rle` reads them.
        let mut p = pos + 4;
        for _ in 0..4 {
            let mut j = 0usize;
            while j < len {
                let code = *data.get(p)?;
                let n = if code > 128 {
                    p += 2;
                    usize::from(code - 128)
                } else if code == 0 {
                    return None;
                } else {
                    p += 1 + usize::from(code);
                    usize::from(code)
                };
                j += n;
            }
            if j != len {
                return None;
            }
        }
        (p <= data.len()).then_some(p)
    } else {
        let block = rest.get(..len.checked_mul(4)?)?;
        let repeat = block.chunks_exact(4).fold(false, |acc, rec| {
            acc | (u32::from_le_bytes([rec[0], rec[1], rec[2], rec[3]]) & 0x00ff_ffff == 0x01_0101)
        });
        (!repeat).then_some(pos + 4 * len)
    }
}

/// A row-major picture whose scanline starts are known, to decode in parallel.
#[cfg(feature = "rayon")]
struct Rows<'a> {
    data: &'a [u8],
    /// From [`scanline_starts`]: `height + 1` offsets into `data`.
    starts: &'a [usize],
    width: usize,
    height: usize,
    y_decreasing: bool,
    x_decreasing: bool,
    conv: &'a Converter,
}

#[cfg(feature = "rayon")]
impl Rows<'_> {
    /// Decode every scanline into its row of `x`, `y`, `z` (each `width × height`), in
    /// tasks of [`PARALLEL_ROWS`] rows; the same values, bit for bit, as the serial
    /// decoder. The first error in row order is returned (none is expected: the walk has
    /// checked every scanline's codes).
    fn decode_parallel(&self, x: &mut [f32], y: &mut [f32], z: &mut [f32]) -> Result<()> {
        use rayon::prelude::*;
        let step = PARALLEL_ROWS * self.width;
        let results: Vec<Result<()>> = x
            .par_chunks_mut(step)
            .zip(y.par_chunks_mut(step))
            .zip(z.par_chunks_mut(step))
            .enumerate()
            .map(|(task, ((x, y), z))| {
                let mut scan = vec![0u8; 4 * self.width];
                let rows = x
                    .chunks_exact_mut(self.width)
                    .zip(y.chunks_exact_mut(self.width))
                    .zip(z.chunks_exact_mut(self.width));
                for (k, ((x, y), z)) in rows.enumerate() {
                    let row = task * PARALLEL_ROWS + k;
                    // `-Y` runs top to bottom.
                    let s = if self.y_decreasing {
                        row
                    } else {
                        self.height - 1 - row
                    };
                    let mut pos = self.starts[s];
                    read_scanline(self.data, &mut pos, &mut scan, self.width)?;
                    if pos != self.starts[s + 1] {
                        return Err(Error::decode(FORMAT, "scanline ends out of place"));
                    }
                    if self.x_decreasing {
                        scan.chunks_exact_mut(self.width).for_each(<[u8]>::reverse);
                    }
                    self.conv.convert(&scan, x, y, z);
                }
                Ok(())
            })
            .collect();
        results.into_iter().collect()
    }
}

/// Most bytes one pixel can take in a scanline: seven 4-byte records (the pixel and up to
/// six old-style repeat records, whose shift reaches 40 bits; a seventh is refused by
/// [`read_records`]). New-style run-length data takes at most 8 (a one-byte literal per
/// component).
const MAX_BYTES_PER_PIXEL: u64 = 28;

/// Most bytes a scanline can take besides its pixels (the `2 2 hi lo` marker).
const MAX_SCANLINE_OVERHEAD: u64 = 4;

/// An upper bound on the bytes of a file whose header and resolution line are at the
/// start of `head`: the data of a valid picture cannot be longer. `None` when they cannot
/// be parsed from `head` (the decoder then says why).
pub(crate) fn file_len_bound(head: &[u8]) -> Option<u64> {
    let (_, after_header) = parse_header(head).ok()?;
    let (res, data_start) = parse_resolution(head, after_header).ok()?;
    let scanlines = if res.y_major { res.height } else { res.width };
    res.width
        .checked_mul(res.height)?
        .checked_mul(MAX_BYTES_PER_PIXEL)?
        .checked_add(scanlines.checked_mul(MAX_SCANLINE_OVERHEAD)?)?
        .checked_add(data_start as u64)
}

/// The error for data that ends too early.
fn truncated() -> Error {
    Error::decode(FORMAT, "file is truncated")
}

/// `line` without one trailing carriage return (files that went through a text-mode
/// transfer end header lines with CR LF).
fn strip_cr(line: &[u8]) -> &[u8] {
    line.strip_suffix(b"\r").unwrap_or(line)
}

/// The pixel encoding declared by `FORMAT=`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PixelFormat {
    /// `32-bit_rle_rgbe`: RGB in the file's primaries, radiometric (× 179 for cd/m²).
    Rgbe,
    /// `32-bit_rle_xyze`: CIE XYZ, photometric (Y in cd/m²).
    Xyze,
}

/// What the header says about the pixels.
#[derive(Debug, Clone)]
struct Header {
    format: PixelFormat,
    /// Product of all `EXPOSURE=` values.
    exposure: f64,
    /// Per-channel product of all `COLORCORR=` values.
    colorcorr: [f64; 3],
    /// RGB→XYZ matrix of the `PRIMARIES=` (or default) chromaticities, white Y = 1.
    rgb_to_xyz: Mat3,
    /// The white of the `PRIMARIES=` (E by default), for RGBE and XYZE alike.
    white: Xy,
    view: Option<View>,
}

/// Parse the header; returns it and the offset just after its terminating empty line.
fn parse_header(bytes: &[u8]) -> Result<(Header, usize)> {
    let mut pos = 0usize;
    let mut magic = false;
    let mut format: Option<PixelFormat> = None;
    let mut exposure = 1.0f64;
    let mut colorcorr = [1.0f64; 3];
    let mut primaries: Chromaticities = RADIANCE_DEFAULT;
    let mut view: Option<View> = None;
    loop {
        let rest = &bytes[pos..];
        let Some(nl) = rest.iter().position(|&b| b == b'\n') else {
            return Err(if magic || format.is_some() {
                Error::decode(
                    FORMAT,
                    "header is not terminated by an empty line (truncated?)",
                )
            } else {
                Error::decode(FORMAT, "not a Radiance picture: no header")
            });
        };
        let line = strip_cr(&rest[..nl]);
        pos += nl + 1;
        if line.is_empty() {
            break;
        }
        if line.starts_with(b"#?") {
            magic = true;
        } else if let Some(v) = line.strip_prefix(b"FORMAT=") {
            format = Some(match text("FORMAT", v)?.trim() {
                "32-bit_rle_rgbe" => PixelFormat::Rgbe,
                "32-bit_rle_xyze" => PixelFormat::Xyze,
                other => {
                    return Err(Error::Unsupported(format!(
                        "Radiance pixel format {other:?} (only 32-bit_rle_rgbe and 32-bit_rle_xyze are read)"
                    )));
                }
            });
        } else if let Some(v) = line.strip_prefix(b"EXPOSURE=") {
            let [e] = numbers::<1>("EXPOSURE", v)?;
            if !(e.is_finite() && e > 0.0) {
                return Err(Error::decode(
                    FORMAT,
                    format!("EXPOSURE={e} is not a positive number"),
                ));
            }
            exposure *= e;
        } else if let Some(v) = line.strip_prefix(b"COLORCORR=") {
            let c = numbers::<3>("COLORCORR", v)?;
            if !c.iter().all(|c| c.is_finite() && *c > 0.0) {
                return Err(Error::decode(
                    FORMAT,
                    format!("COLORCORR={c:?} has a non-positive factor"),
                ));
            }
            for (acc, c) in colorcorr.iter_mut().zip(c) {
                *acc *= c;
            }
        } else if let Some(v) = line.strip_prefix(b"PRIMARIES=") {
            let p = numbers::<8>("PRIMARIES", v)?;
            primaries = Chromaticities {
                red: [p[0], p[1]],
                green: [p[2], p[3]],
                blue: [p[4], p[5]],
                white: [p[6], p[7]],
            };
        } else if let Some(v) = line.strip_prefix(b"VIEW=") {
            view = Some(parse_view(text("VIEW", v)?, view.unwrap_or(DEFAULT_VIEW))?);
        }
    }
    if !magic && format.is_none() {
        return Err(Error::decode(
            FORMAT,
            "not a Radiance picture: header has neither a #? line nor a FORMAT= line",
        ));
    }
    let positive = |v: &f64| v.is_finite() && *v > 0.0;
    if !(positive(&exposure) && colorcorr.iter().all(positive)) {
        return Err(Error::decode(
            FORMAT,
            "product of EXPOSURE/COLORCORR values is out of range",
        ));
    }
    let rgb_to_xyz = primaries
        .rgb_to_xyz()
        .ok_or_else(|| Error::decode(FORMAT, format!("degenerate PRIMARIES {primaries:?}")))?;
    let header = Header {
        format: format.unwrap_or(PixelFormat::Rgbe),
        exposure,
        colorcorr,
        rgb_to_xyz,
        white: primaries.white,
        view,
    };
    Ok((header, pos))
}

/// A header value as text.
fn text<'a>(key: &str, v: &'a [u8]) -> Result<&'a str> {
    std::str::from_utf8(v).map_err(|_| Error::decode(FORMAT, format!("{key}= line is not text")))
}

/// Exactly `N` whitespace-separated decimal numbers.
fn numbers<const N: usize>(key: &str, v: &[u8]) -> Result<[f64; N]> {
    let s = text(key, v)?;
    let bad = || Error::decode(FORMAT, format!("{key}= line {s:?} must hold {N} numbers"));
    let mut out = [0.0; N];
    let mut it = s.split_ascii_whitespace();
    for o in &mut out {
        *o = it.next().ok_or_else(bad)?.parse().map_err(|_| bad())?;
    }
    if it.next().is_some() {
        return Err(bad());
    }
    Ok(out)
}

/// A view as Radiance view options, e.g. `-vtv -vh 60 -vv 35.98` (Radiance's `-vt?` type
/// letters), the text of a `VIEW=` line and of the OpenEXR
/// [`VIEW_ATTRIBUTE`](super::exr::VIEW_ATTRIBUTE).
pub fn view_options(view: &View) -> String {
    let t = match view.projection {
        Projection::Perspective => 'v',
        Projection::Parallel => 'l',
        Projection::Cylindrical => 'c',
        Projection::HemisphericalFisheye => 'h',
        Projection::AngularFisheye => 'a',
        Projection::Planisphere => 's',
    };
    format!(
        "-vt{t} -vh {} -vv {}",
        view.horizontal_deg, view.vertical_deg
    )
}

/// Parse Radiance view options (as [`view_options`] writes them) over Radiance's default
/// view; errors name `format`.
pub(crate) fn parse_view_options(s: &str, format: &'static str) -> Result<View> {
    parse_view(s, DEFAULT_VIEW).map_err(|e| match e {
        Error::Decode { reason, .. } => Error::decode(format, reason),
        other => other,
    })
}

/// Apply the options of one `VIEW=` line to `view` (Radiance `image.c`, `sscanview`:
/// successive view lines modify the same view, so a later option overrides an earlier
/// one). Reads `-vt?`, `-vh`, `-vv`; every other option and its arguments are skipped.
/// Radiance also takes view options from `rpict`/`rvu`/`rpiece`/`pinterp` command lines
/// recorded in the header (`image.c`, `isview`); we read only `VIEW=` lines.
fn parse_view(s: &str, mut view: View) -> Result<View> {
    let mut tokens = s.split_ascii_whitespace();
    while let Some(t) = tokens.next() {
        if let Some(kind) = t.strip_prefix("-vt") {
            view.projection = match kind {
                "v" => Projection::Perspective,
                "l" => Projection::Parallel,
                "c" => Projection::Cylindrical,
                "h" => Projection::HemisphericalFisheye,
                "a" => Projection::AngularFisheye,
                "s" => Projection::Planisphere,
                _ => {
                    return Err(Error::decode(
                        FORMAT,
                        format!("unknown view type {t:?} in VIEW="),
                    ));
                }
            };
        } else if t == "-vh" || t == "-vv" {
            let v: f64 = tokens
                .next()
                .and_then(|v| v.parse().ok())
                .filter(|v: &f64| v.is_finite() && *v > 0.0)
                .ok_or_else(|| {
                    Error::decode(FORMAT, format!("VIEW= option {t} needs a positive number"))
                })?;
            if t == "-vh" {
                view.horizontal_deg = v;
            } else {
                view.vertical_deg = v;
            }
        }
    }
    Ok(view)
}

/// The resolution line, as flags of Radiance `resolu.h` (`YMAJOR`, `XDECR`, `YDECR`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Resolution {
    width: u64,
    height: u64,
    /// Y is the first axis: scanlines are rows (standard).
    y_major: bool,
    /// X runs right to left.
    x_decreasing: bool,
    /// Y runs top to bottom (Radiance's Y axis points up).
    y_decreasing: bool,
}

/// Parse the resolution line at `pos`; returns it and the offset of the first scanline.
fn parse_resolution(bytes: &[u8], pos: usize) -> Result<(Resolution, usize)> {
    let rest = &bytes[pos..];
    let window = &rest[..rest.len().min(MAX_RESOLUTION_LINE)];
    let bad = |why: &str| Error::decode(FORMAT, format!("bad resolution line: {why}"));
    let Some(nl) = window.iter().position(|&b| b == b'\n') else {
        return Err(if rest.len() < MAX_RESOLUTION_LINE {
            truncated()
        } else {
            bad("missing or too long")
        });
    };
    let line = std::str::from_utf8(strip_cr(&window[..nl])).map_err(|_| bad("not text"))?;
    let mut tokens = line.split_ascii_whitespace();
    let mut next = || {
        tokens
            .next()
            .ok_or_else(|| bad("expected e.g. \"-Y 480 +X 640\""))
    };
    let axis = |t: &str| -> Result<(bool, char)> {
        match t.as_bytes() {
            [sign @ (b'+' | b'-'), axis @ (b'X' | b'Y')] => Ok((*sign == b'-', *axis as char)),
            _ => Err(bad("expected e.g. \"-Y 480 +X 640\"")),
        }
    };
    let size = |t: &str| -> Result<u64> {
        if t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit()) {
            return Err(bad("size is not a positive integer"));
        }
        t.parse().map_err(|_| bad("absurd size"))
    };
    let (dec1, axis1) = axis(next()?)?;
    let n1 = size(next()?)?;
    let (dec2, axis2) = axis(next()?)?;
    let n2 = size(next()?)?;
    if tokens.next().is_some() {
        return Err(bad("trailing text"));
    }
    let res = match (axis1, axis2) {
        ('Y', 'X') => Resolution {
            width: n2,
            height: n1,
            y_major: true,
            x_decreasing: dec2,
            y_decreasing: dec1,
        },
        ('X', 'Y') => Resolution {
            width: n1,
            height: n2,
            y_major: false,
            x_decreasing: dec1,
            y_decreasing: dec2,
        },
        _ => return Err(bad("needs one X and one Y axis")),
    };
    Ok((res, pos + nl + 1))
}

/// Read one scanline of `len` pixels at `data[*pos..]` into `scan`, stored planar
/// (`len` red mantissas, then green, blue, exponents), advancing `pos`.
/// Radiance `color.c`, `freadcolrs`: new-style RLE when the length allows it and the
/// scanline starts `2 2 hi lo` (hi < 128), otherwise flat/old-style records.
fn read_scanline(data: &[u8], pos: &mut usize, scan: &mut [u8], len: usize) -> Result<()> {
    let rest = data.get(*pos..).unwrap_or_default();
    if (MIN_RLE_LEN..=MAX_RLE_LEN).contains(&len)
        && let [2, 2, hi, lo, ..] = *rest
        && hi & 0x80 == 0
    {
        let declared = usize::from(hi) << 8 | usize::from(lo);
        if declared != len {
            return Err(Error::decode(
                FORMAT,
                format!("run-length scanline declares {declared} pixels, image is {len} wide"),
            ));
        }
        *pos += 4;
        read_rle(data, pos, scan, len)
    } else {
        read_records(data, pos, scan, len)
    }
}

/// New-style run-length components: for each of the four components, codes `n > 128`
/// (a run of `n − 128` copies of the next byte) and `1 ≤ n ≤ 128` (`n` literal bytes).
fn read_rle(data: &[u8], pos: &mut usize, scan: &mut [u8], len: usize) -> Result<()> {
    let mut p = *pos;
    for plane in scan.chunks_exact_mut(len) {
        let mut j = 0usize;
        while j < len {
            let &code = data.get(p).ok_or_else(truncated)?;
            if code > 128 {
                let n = usize::from(code - 128);
                let &val = data.get(p + 1).ok_or_else(truncated)?;
                p += 2;
                let run = plane.get_mut(j..j + n).ok_or_else(overrun)?;
                run.fill(val);
                j += n;
            } else {
                let n = usize::from(code);
                if n == 0 {
                    return Err(Error::decode(FORMAT, "zero-length run in scanline"));
                }
                let dst = plane.get_mut(j..j + n).ok_or_else(overrun)?;
                let src = data.get(p + 1..p + 1 + n).ok_or_else(truncated)?;
                dst.copy_from_slice(src);
                p += 1 + n;
                j += n;
            }
        }
    }
    *pos = p;
    Ok(())
}

/// The error for a run reaching past the end of its scanline.
fn overrun() -> Error {
    Error::decode(FORMAT, "run overruns the scanline")
}

/// Flat pixels and old-style repeat records (Radiance `color.c`, `oldreadcolrs`): a
/// record `1 1 1 n` repeats the previous pixel `n << shift` times, where `shift` grows
/// by 8 for each consecutive repeat record and resets after a pixel.
fn read_records(data: &[u8], pos: &mut usize, scan: &mut [u8], len: usize) -> Result<()> {
    let (r, rest) = scan.split_at_mut(len);
    let (g, rest) = rest.split_at_mut(len);
    let (b, e) = rest.split_at_mut(len);
    // Fast path: if the next `len` records hold no repeat record, they are the scanline.
    if let Some(block) = data.get(*pos..).and_then(|d| d.get(..4 * len)) {
        let mut repeat = false;
        let planes = r
            .iter_mut()
            .zip(g.iter_mut())
            .zip(b.iter_mut().zip(e.iter_mut()));
        for (((r, g), (b, e)), rec) in planes.zip(block.chunks_exact(4)) {
            (*r, *g, *b, *e) = (rec[0], rec[1], rec[2], rec[3]);
            repeat |= rec[0] == 1 && rec[1] == 1 && rec[2] == 1;
        }
        if !repeat {
            *pos += 4 * len;
            return Ok(());
        }
    }
    let mut records = data.get(*pos..).unwrap_or_default().chunks_exact(4);
    let mut used = 0usize;
    let mut i = 0usize;
    let mut shift = 0u32;
    while i < len {
        let rec = records.next().ok_or_else(truncated)?;
        used += 1;
        if let [1, 1, 1, count] = *rec {
            if i == 0 {
                return Err(Error::decode(
                    FORMAT,
                    "repeat record with no pixel to repeat",
                ));
            }
            // A count shifted by 48 bits or more exceeds any scanline, and so does a
            // seventh repeat record in a row (this bounds the bytes of a scanline); zero
            // counts are legitimate (they only carry the shift).
            let count = match (count, shift) {
                (_, 48..) => return Err(overrun()),
                (0, _) => 0,
                (c, s) => u64::from(c) << s,
            };
            let end = (i as u64).saturating_add(count);
            if end > len as u64 {
                return Err(overrun());
            }
            let end = end as usize;
            for plane in [&mut *r, &mut *g, &mut *b, &mut *e] {
                let v = plane[i - 1];
                plane[i..end].fill(v);
            }
            i = end;
            shift = shift.saturating_add(8);
        } else {
            (r[i], g[i], b[i], e[i]) = (rec[0], rec[1], rec[2], rec[3]);
            i += 1;
            shift = 0;
        }
    }
    *pos += 4 * used;
    Ok(())
}

/// Turns decoded 4-byte pixels into CIE XYZ in cd/m².
#[derive(Debug, Clone)]
struct Converter {
    /// Row-major matrix from the decoded file channels (before exposure) to XYZ in cd/m²:
    /// `rgb_to_xyz · 179 / exposure · diag(1/colorcorr)` for RGBE, `1/exposure ·
    /// diag(1/colorcorr)` for XYZE.
    m: Mat3,
    /// `m` in single precision, used when all its entries are comfortably within f32
    /// range (`fast`).
    m32: [[f32; 3]; 3],
    /// Whether the single-precision path is exact enough: every entry of `m` is 0 or
    /// has a magnitude in `[F32_PATH_MIN, F32_PATH_MAX]`.
    fast: bool,
    /// `2^(e − 136)` for exponent byte `e` ≥ 1 (the `1/256` of the mantissa folded in), 0
    /// for `e = 0` (Radiance `color.c`, `colr_color`). All exact in f64.
    scale: [f64; 256],
}

/// Smallest nonzero matrix magnitude for the single-precision path: entries below it
/// would lose precision in f32 products with the smallest decoded components. Chosen by
/// us; real files have entries between about 0.01 and 1e5.
const F32_PATH_MIN: f64 = 1e-20;

/// Largest matrix magnitude for the single-precision path (chosen by us; see
/// [`F32_PATH_MIN`]). Overflowing products are caught per pixel and redone in f64.
const F32_PATH_MAX: f64 = 1e20;

impl Converter {
    /// The converter of `h`'s pixels, each value multiplied by `factor` (1 for the file's
    /// own cd/m²).
    fn new(h: &Header, factor: f32) -> Result<Self> {
        let (base, k) = match h.format {
            PixelFormat::Rgbe => (h.rgb_to_xyz, WHITE_EFFICACY / h.exposure),
            PixelFormat::Xyze => (
                [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                1.0 / h.exposure,
            ),
        };
        let k = k * f64::from(factor);
        let mut m = [[0.0; 3]; 3];
        for (row, base_row) in m.iter_mut().zip(base) {
            for ((v, b), cc) in row.iter_mut().zip(base_row).zip(h.colorcorr) {
                *v = b * k / cc;
            }
        }
        if !m
            .iter()
            .flatten()
            .all(|v| v.is_finite() && v.abs() <= MAX_MATRIX_ENTRY)
        {
            return Err(Error::decode(
                FORMAT,
                "EXPOSURE, COLORCORR and PRIMARIES give an out-of-range pixel scale",
            ));
        }
        let fast = m
            .iter()
            .flatten()
            .all(|v| *v == 0.0 || (F32_PATH_MIN..=F32_PATH_MAX).contains(&v.abs()));
        let m32 = m.map(|row| row.map(|v| v as f32));
        let mut scale = [0.0f64; 256];
        for (e, s) in scale.iter_mut().enumerate().skip(1) {
            // e − 136 is in −135..=119: exact powers of two.
            *s = 2f64.powi(e as i32 - (EXPONENT_BIAS + 8));
        }
        Ok(Converter {
            m,
            m32,
            fast,
            scale,
        })
    }

    /// Convert one planar scanline (`len` red, green, blue mantissas then exponents) into
    /// the X, Y, Z rows, each `len` long.
    fn convert(&self, scan: &[u8], xs: &mut [f32], ys: &mut [f32], zs: &mut [f32]) {
        self.convert_at(Isa::detect(), scan, xs, ys, zs);
    }

    /// [`Converter::convert`] compiled for `isa` (the same operations, no fused
    /// multiply-adds: the same bits at every level, tested).
    fn convert_at(&self, isa: Isa, scan: &[u8], xs: &mut [f32], ys: &mut [f32], zs: &mut [f32]) {
        at_level!(isa, self.convert_inlined(scan, xs, ys, zs));
    }

    #[inline(always)]
    fn convert_inlined(&self, scan: &[u8], xs: &mut [f32], ys: &mut [f32], zs: &mut [f32]) {
        let len = xs.len();
        let (r, rest) = scan.split_at(len);
        let (g, rest) = rest.split_at(len);
        let (b, e) = rest.split_at(len);
        let (ys, zs) = (&mut ys[..len], &mut zs[..len]);
        // Exponent bytes 1..=9 give f32-subnormal scale factors, which the bit trick of
        // `convert32` does not produce; they (and overflow) take the f64 path.
        let tiny_exponent = e
            .iter()
            .fold(false, |acc, &e| acc | (e.wrapping_sub(1) < 9));
        if self.fast && !tiny_exponent {
            self.convert32(r, g, b, e, xs, ys, zs);
            let finite = [&*xs, &*ys, &*zs]
                .iter()
                .all(|p| p.iter().fold(true, |acc, v| acc & v.is_finite()));
            if finite {
                return;
            }
        }
        for i in 0..len {
            [xs[i], ys[i], zs[i]] = self.pixel64([r[i], g[i], b[i], e[i]]);
        }
    }

    /// Single-precision conversion, written to vectorise: the scale `2^(e − 136)` is
    /// built from its bits (`(e − 9) << 23`, valid for `e` ≥ 10; 0 for `e` = 0).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn convert32(
        &self,
        r: &[u8],
        g: &[u8],
        b: &[u8],
        e: &[u8],
        xs: &mut [f32],
        ys: &mut [f32],
        zs: &mut [f32],
    ) {
        let len = xs.len();
        let (r, g, b, e, ys, zs) = (
            &r[..len],
            &g[..len],
            &b[..len],
            &e[..len],
            &mut ys[..len],
            &mut zs[..len],
        );
        let m = self.m32;
        for i in 0..len {
            let ei = u32::from(e[i]);
            let bits = if ei >= 10 { (ei - 9) << 23 } else { 0 };
            let f = f32::from_bits(bits);
            let cr = (f32::from(r[i]) + 0.5) * f;
            let cg = (f32::from(g[i]) + 0.5) * f;
            let cb = (f32::from(b[i]) + 0.5) * f;
            xs[i] = m[0][0] * cr + m[0][1] * cg + m[0][2] * cb;
            ys[i] = m[1][0] * cr + m[1][1] * cg + m[1][2] * cb;
            zs[i] = m[2][0] * cr + m[2][1] * cg + m[2][2] * cb;
        }
    }

    /// One pixel in double precision, clamped to the f32 range.
    #[inline]
    fn pixel64(&self, [r, g, b, e]: [u8; 4]) -> [f32; 3] {
        let f = self.scale[usize::from(e)];
        let c = [
            (f64::from(r) + 0.5) * f,
            (f64::from(g) + 0.5) * f,
            (f64::from(b) + 0.5) * f,
        ];
        self.m
            .map(|row| saturating_f32(row[0] * c[0] + row[1] * c[1] + row[2] * c[2]))
    }
}

/// Write a display image as a Radiance RGBE picture: the linear Rec. 709 values of the
/// display image with `PRIMARIES=` Rec. 709 and `EXPOSURE=` 179 / `display_max_cd_m2`, so
/// that a Radiance reader (this one, `pvalue`, `ximage`) gives RGB (1, 1, 1) the display
/// maximum in cd/m² (the units of the module documentation), as the OpenEXR output does.
/// Scanlines are new-style run-length records for widths of 8 to 32767 (Radiance's
/// `fwritecolrs` range), flat pixels otherwise; a flat pixel that would read as a repeat
/// record (`1 1 1 n`) or a run-length start is moved by one step of its blue or green
/// mantissa.
///
/// ```
/// use visadapt::{DisplayImage, Limits, io};
/// let image = DisplayImage { width: 9, height: 2, r: vec![1.0; 18], g: vec![1.0; 18],
///                            b: vec![1.0; 18], display_max_cd_m2: 100.0 };
/// let mut hdr = Vec::new();
/// io::radiance::write_display(&image, &mut hdr)?;
/// let back = io::decode(&hdr, &Limits::default())?;
/// assert!((back.y[0] - 100.0).abs() < 0.5);
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn write_display(image: &crate::DisplayImage, mut w: impl std::io::Write) -> Result<()> {
    use std::io::Write;
    let (width, height) = (image.width, image.height);
    image.validate()?;
    let l = image.display_max_cd_m2;
    let p = colour::REC709;
    let header = format!(
        "#?RADIANCE\n\
         # visadapt display-referred linear Rec. 709 RGB; 1.0 = {l} cd/m2\n\
         SOFTWARE=visadapt {}\n\
         FORMAT=32-bit_rle_rgbe\n\
         PRIMARIES={} {} {} {} {} {} {} {}\n\
         EXPOSURE={}\n\
         \n\
         -Y {height} +X {width}\n",
        env!("CARGO_PKG_VERSION"),
        p.red[0],
        p.red[1],
        p.green[0],
        p.green[1],
        p.blue[0],
        p.blue[1],
        p.white[0],
        p.white[1],
        WHITE_EFFICACY / f64::from(l),
    );
    let mut out = std::io::BufWriter::new(&mut w);
    out.write_all(header.as_bytes())?;
    let run_length = (8..=32767).contains(&width);
    let mut row = vec![[0u8; 4]; width];
    let mut bytes = Vec::with_capacity(4 * width + 4 * width.div_ceil(128) + 4);
    for y in 0..height {
        for (x, px) in row.iter_mut().enumerate() {
            let i = y * width + x;
            *px = rgbe([image.r[i], image.g[i], image.b[i]]);
        }
        bytes.clear();
        if run_length {
            bytes.extend_from_slice(&[2, 2, (width >> 8) as u8, (width & 0xff) as u8]);
            // Each component in literal records of at most 128 bytes.
            for c in 0..4 {
                for chunk in row.chunks(128) {
                    bytes.push(chunk.len() as u8);
                    bytes.extend(chunk.iter().map(|px| px[c]));
                }
            }
        } else {
            for (x, px) in row.iter_mut().enumerate() {
                if px[..3] == [1, 1, 1] {
                    px[2] = 2;
                }
                if x == 0 && px[0] == 2 && px[1] == 2 && px[2] < 128 {
                    px[1] = 3;
                }
                bytes.extend_from_slice(px);
            }
        }
        out.write_all(&bytes)?;
    }
    out.flush()?;
    Ok(())
}

/// One RGBE pixel (`color.c`, `setcolr`): the largest component's binary exponent, the
/// three mantissas over 256; non-finite and negative values are written as 0.
fn rgbe(rgb: [f32; 3]) -> [u8; 4] {
    let c = rgb.map(|v| {
        if v.is_finite() && v > 0.0 {
            v as f64
        } else {
            0.0
        }
    });
    let v = c[0].max(c[1]).max(c[2]);
    if v < 1e-32 {
        return [0; 4];
    }
    // v = m · 2^e with m in [0.5, 1).
    let e = v.log2().floor() as i32 + 1;
    let e = e.clamp(-128, 127);
    let scale = 256.0 / 2f64.powi(e);
    let m = c.map(|x| (x * scale).min(255.0) as u8);
    [m[0], m[1], m[2], (e + 128) as u8]
}

#[cfg(test)]
mod tests {
    //! Unit tests: hand-built files for every encoding, header feature and orientation,
    //! with expected cd/m² values computed here from the format's definition.

    use super::*;
    use crate::colour::{REC709, mul_vec};

    /// Knuth's MMIX linear congruential generator (multiplier 6364136223846793005,
    /// increment 1442695040888963407), its high 31 bits per call: reproducible noise for
    /// the tests, no statistical quality needed.
    fn lcg(seed: u64) -> impl FnMut() -> usize {
        let mut s = seed;
        move || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 33) as usize
        }
    }

    /// The scanline conversion gives the same bits at every instruction-set level, on the
    /// f32 path and on the f64 one (exponents 1..=9), with and without `EXPOSURE`.
    #[test]
    fn conversion_is_the_same_at_every_level() {
        let mut next = lcg(77);
        for header_text in [
            "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 1\n",
            "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=0.37\n\n-Y 1 +X 1\n",
            "#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n",
        ] {
            let (header, _) = parse_header(header_text.as_bytes()).unwrap();
            let conv = Converter::new(&header, 1.0).unwrap();
            for tiny in [false, true] {
                let len = 1000;
                let mut scan: Vec<u8> = (0..4 * len).map(|_| next() as u8).collect();
                for e in &mut scan[3 * len..] {
                    *e = if tiny { (*e % 12) + 1 } else { 100 + *e % 60 };
                }
                let rows = |isa: Isa| {
                    let (mut x, mut y, mut z) = (vec![0f32; len], vec![0f32; len], vec![0f32; len]);
                    conv.convert_at(isa, &scan, &mut x, &mut y, &mut z);
                    [x, y, z].map(|p| p.iter().map(|v| v.to_bits()).collect::<Vec<_>>())
                };
                let baseline = rows(Isa::Baseline);
                for isa in Isa::all_available() {
                    assert_eq!(rows(isa), baseline, "{isa:?} {header_text:?} {tiny}");
                }
            }
        }
    }

    /// Radiance's Y row for its default primaries (`color.h`, `CIE_rf`, `CIE_gf`,
    /// `CIE_bf`): luminance = 179 × (0.265074 R + 0.670115 G + 0.064811 B). `color.h`
    /// derives them from a white of (0.3333, 0.3333) where `colour::RADIANCE_DEFAULT` uses
    /// exactly 1/3, which changes the coefficients by up to 3.5e-4 (relative).
    const RADIANCE_Y_ROW: [f64; 3] = [0.265_074_126, 0.670_114_631, 0.064_811_243];

    /// The radiometric value of an RGBE/XYZE pixel, by the definition
    /// `(m + 0.5)/256 · 2^(e − 128)`, 0 when `e = 0`.
    fn colr(p: [u8; 4]) -> [f64; 3] {
        if p[3] == 0 {
            return [0.0; 3];
        }
        let f = 2f64.powi(i32::from(p[3]) - 128) / 256.0;
        [0, 1, 2].map(|i| (f64::from(p[i]) + 0.5) * f)
    }

    /// A file: the header lines, an empty line, the resolution line, then `data`.
    fn file(header: &[&str], resolution: &str, data: &[u8]) -> Vec<u8> {
        let mut v = Vec::new();
        for line in header {
            v.extend_from_slice(line.as_bytes());
            v.push(b'\n');
        }
        v.push(b'\n');
        v.extend_from_slice(resolution.as_bytes());
        v.push(b'\n');
        v.extend_from_slice(data);
        v
    }

    /// Flat scanline bytes.
    fn flat(pixels: &[[u8; 4]]) -> Vec<u8> {
        pixels.iter().flatten().copied().collect()
    }

    /// A new-style RLE scanline: marker, then per component runs of ≥ 3 equal bytes as
    /// run codes and the rest as literals of at most 128.
    fn rle(pixels: &[[u8; 4]]) -> Vec<u8> {
        let n = pixels.len();
        let mut v = vec![2, 2, (n >> 8) as u8, (n & 255) as u8];
        for c in 0..4 {
            let comp: Vec<u8> = pixels.iter().map(|p| p[c]).collect();
            let mut i = 0;
            let mut lit: Vec<u8> = Vec::new();
            let flush = |lit: &mut Vec<u8>, v: &mut Vec<u8>| {
                for chunk in lit.chunks(128) {
                    v.push(chunk.len() as u8);
                    v.extend_from_slice(chunk);
                }
                lit.clear();
            };
            while i < n {
                let mut run = 1;
                while i + run < n && run < 127 && comp[i + run] == comp[i] {
                    run += 1;
                }
                if run >= 3 {
                    flush(&mut lit, &mut v);
                    v.push(128 + run as u8);
                    v.push(comp[i]);
                    i += run;
                } else {
                    lit.push(comp[i]);
                    i += 1;
                }
            }
            flush(&mut lit, &mut v);
        }
        v
    }

    fn decode_ok(bytes: &[u8]) -> HdrImage {
        decode(bytes, &Limits::default()).expect("decodes")
    }

    fn assert_decode_err(bytes: &[u8], what: &str) {
        match decode(bytes, &Limits::default()) {
            Err(Error::Decode { .. }) => {}
            other => panic!("{what}: expected a decode error, got {other:?}"),
        }
    }

    /// Assert `got` is within `rel` relative error of `want`.
    fn close(got: f32, want: f64, rel: f64, what: &str) {
        let tol = rel * want.abs().max(1e-30);
        assert!(
            (f64::from(got) - want).abs() <= tol,
            "{what}: got {got}, want {want} (±{tol})"
        );
    }

    /// Expected XYZ in cd/m² of an RGBE pixel with the default primaries.
    fn expected_rgbe(p: [u8; 4]) -> [f64; 3] {
        let m = RADIANCE_DEFAULT.rgb_to_xyz().unwrap();
        mul_vec(&m, colr(p)).map(|v| v * 179.0)
    }

    const PIXELS: [[u8; 4]; 6] = [
        [128, 64, 32, 129],
        [0, 0, 0, 0],
        [255, 255, 255, 140],
        [10, 200, 90, 100],
        [1, 2, 3, 1],
        [77, 77, 77, 128],
    ];

    #[test]
    fn flat_rgbe_values_match_the_definition() {
        // 3 wide (below MINELEN): flat records.
        let bytes = file(
            &["#?RADIANCE", "FORMAT=32-bit_rle_rgbe"],
            "-Y 2 +X 3",
            &flat(&PIXELS),
        );
        let img = decode_ok(&bytes);
        assert_eq!((img.width, img.height), (3, 2));
        assert!(img.absolute_units && img.scotopic.is_none() && img.view.is_none());
        // The brief's example pixel: r = 128.5/256·2, g = 64.5/256·2, b = 32.5/256·2.
        let rgb = [128.5 / 128.0, 64.5 / 128.0, 32.5 / 128.0];
        let lum = 179.0 * (0..3).map(|i| RADIANCE_Y_ROW[i] * rgb[i]).sum::<f64>();
        close(img.y[0], lum, 5e-4, "luminance of (128,64,32,129)");
        for (i, p) in PIXELS.iter().enumerate() {
            let want = expected_rgbe(*p);
            close(img.x[i], want[0], 1e-6, "X");
            close(img.y[i], want[1], 1e-6, "Y");
            close(img.z[i], want[2], 1e-6, "Z");
        }
        assert_eq!(img.y[1], 0.0);
    }

    #[test]
    fn missing_format_means_rgbe_and_exponent_zero_is_black() {
        let bytes = file(
            &["#?RADIANCE"],
            "-Y 1 +X 2",
            &flat(&[[200, 100, 50, 0], [1, 1, 2, 128]]),
        );
        let img = decode_ok(&bytes);
        assert_eq!((img.x[0], img.y[0], img.z[0]), (0.0, 0.0, 0.0));
        close(img.y[1], expected_rgbe([1, 1, 2, 128])[1], 1e-6, "Y");
    }

    /// A 10×3 image with runs and literals in every component.
    fn wide_pixels() -> Vec<[u8; 4]> {
        (0..30u8)
            .map(|i| {
                let run = i / 5;
                [
                    100 + run,
                    if i.is_multiple_of(2) { 10 } else { 200 },
                    50,
                    120 + (i % 3),
                ]
            })
            .collect()
    }

    #[test]
    fn new_rle_equals_flat() {
        let px = wide_pixels();
        let mut rle_data = Vec::new();
        for row in px.chunks(10) {
            rle_data.extend(rle(row));
        }
        let a = decode_ok(&file(&["#?RADIANCE"], "-Y 3 +X 10", &rle_data));
        let b = decode_ok(&file(&["#?RADIANCE"], "-Y 3 +X 10", &flat(&px)));
        assert_eq!(a, b);
        for (i, p) in px.iter().enumerate() {
            close(a.y[i], expected_rgbe(*p)[1], 1e-6, "Y");
        }
    }

    #[test]
    fn new_rle_hand_written_bytes() {
        // 8 pixels: R = run of 8 × 100; G = literal 8 bytes; B = run 5 × 7 + literal 3;
        // E = run of 8 × 130.
        let mut data = vec![2, 2, 0, 8];
        data.extend([128 + 8, 100]);
        data.extend([8, 1, 2, 3, 4, 5, 6, 7, 8]);
        data.extend([128 + 5, 7, 3, 9, 9, 9]);
        data.extend([128 + 8, 130]);
        let img = decode_ok(&file(&["#?RADIANCE"], "-Y 1 +X 8", &data));
        for i in 0..8 {
            let p = [100, i as u8 + 1, if i < 5 { 7 } else { 9 }, 130];
            let want = expected_rgbe(p);
            close(img.x[i], want[0], 1e-6, "X");
            close(img.y[i], want[1], 1e-6, "Y");
            close(img.z[i], want[2], 1e-6, "Z");
        }
    }

    #[test]
    fn old_rle_repeats_with_shift() {
        // 300 pixels: one pixel, then 299 = 43 + (1 << 8) repeats in two records.
        let p = [90, 80, 70, 135];
        let mut data = p.to_vec();
        data.extend([1, 1, 1, 43, 1, 1, 1, 1]);
        let img = decode_ok(&file(&["#?RADIANCE"], "-Y 1 +X 300", &data));
        let want = expected_rgbe(p);
        for i in 0..300 {
            close(img.y[i], want[1], 1e-6, "Y");
        }
        // A repeat, then a new pixel, then a repeat (shift resets).
        let q = [10, 20, 30, 128];
        let mut data = p.to_vec();
        data.extend([1, 1, 1, 2]);
        data.extend(q);
        data.extend([1, 1, 1, 5]);
        let img = decode_ok(&file(&["#?RADIANCE"], "-Y 1 +X 9", &data));
        let (wp, wq) = (expected_rgbe(p)[1], expected_rgbe(q)[1]);
        for i in 0..9 {
            close(img.y[i], if i < 3 { wp } else { wq }, 1e-6, "Y");
        }
    }

    #[test]
    fn scanline_encodings_mix_per_scanline() {
        let px = wide_pixels();
        let rows: Vec<&[[u8; 4]]> = px.chunks(10).collect();
        let mut data = rle(rows[0]);
        data.extend(flat(rows[1]));
        // Old-style: first pixel, its repeats, rest flat.
        let mut old = Vec::new();
        let mut i = 0;
        while i < 10 {
            old.extend(rows[2][i]);
            let mut n = 0;
            while i + 1 + n < 10 && rows[2][i + 1 + n] == rows[2][i] {
                n += 1;
            }
            if n > 0 {
                old.extend([1, 1, 1, n as u8]);
            }
            i += 1 + n;
        }
        data.extend(old);
        let img = decode_ok(&file(&["#?RADIANCE"], "-Y 3 +X 10", &data));
        let reference = decode_ok(&file(&["#?RADIANCE"], "-Y 3 +X 10", &flat(&px)));
        assert_eq!(img, reference);
    }

    #[test]
    fn first_byte_two_without_rle_marker_is_a_flat_pixel() {
        // Width 8, first pixel (2, 5, 0, 130): not `2 2 hi lo`, so flat records.
        let mut px = vec![[2u8, 5, 0, 130]];
        px.extend([[50u8, 60, 70, 128]; 7]);
        let img = decode_ok(&file(&["#?RADIANCE"], "-Y 1 +X 8", &flat(&px)));
        close(img.y[0], expected_rgbe(px[0])[1], 1e-6, "Y");
        close(img.y[7], expected_rgbe(px[7])[1], 1e-6, "Y");
    }

    #[test]
    fn xyze_is_photometric() {
        let p = [128, 64, 32, 129];
        let bytes = file(
            &["#?RADIANCE", "FORMAT=32-bit_rle_xyze", "EXPOSURE=0.5"],
            "-Y 1 +X 1",
            &p,
        );
        let img = decode_ok(&bytes);
        // X = 128.5/128, Y = 64.5/128, Z = 32.5/128, divided by the exposure 0.5.
        close(img.x[0], 128.5 / 128.0 / 0.5, 1e-6, "X");
        close(img.y[0], 64.5 / 128.0 / 0.5, 1e-6, "Y");
        close(img.z[0], 32.5 / 128.0 / 0.5, 1e-6, "Z");
    }

    #[test]
    fn xyze_from_ra_xyze_matches_the_rgbe_original() {
        // ra_xyze writes M·rgb unscaled with EXPOSURE=1/179: both must give the same cd/m².
        let p = [128, 64, 32, 129];
        let rgbe = decode_ok(&file(&["#?RADIANCE"], "-Y 1 +X 1", &p));
        let xyz = mul_vec(&RADIANCE_DEFAULT.rgb_to_xyz().unwrap(), colr(p));
        // Re-encode xyz with a common exponent: 2^1 → e = 129, mantissa = v·128 − 0.5.
        let m = xyz.map(|v| (v * 128.0).floor() as u8);
        let bytes = file(
            &[
                "#?RADIANCE",
                "FORMAT=32-bit_rle_xyze",
                "EXPOSURE=5.586592e-03",
            ],
            "-Y 1 +X 1",
            &[m[0], m[1], m[2], 129],
        );
        let img = decode_ok(&bytes);
        // Mantissa quantisation: within 1/128 of a value ~0.5–1, i.e. < 2 %.
        close(img.y[0], f64::from(rgbe.y[0]), 0.02, "Y");
        close(img.x[0], f64::from(rgbe.x[0]), 0.02, "X");
    }

    #[test]
    fn primaries_line_is_used() {
        let p = [100, 150, 200, 130];
        let bytes = file(
            &[
                "#?RADIANCE",
                "PRIMARIES= 0.64 0.33 0.30 0.60 0.15 0.06 0.3127 0.3290",
            ],
            "-Y 1 +X 1",
            &p,
        );
        let img = decode_ok(&bytes);
        // IEC 61966-2-1 sRGB → XYZ matrix (4 decimals).
        let m = [
            [0.4124, 0.3576, 0.1805],
            [0.2126, 0.7152, 0.0722],
            [0.0193, 0.1192, 0.9505],
        ];
        let want = mul_vec(&m, colr(p)).map(|v| v * 179.0);
        close(img.x[0], want[0], 5e-4, "X");
        close(img.y[0], want[1], 5e-4, "Y");
        close(img.z[0], want[2], 5e-4, "Z");
        let exact = mul_vec(&REC709.rgb_to_xyz().unwrap(), colr(p)).map(|v| v * 179.0);
        close(img.y[0], exact[1], 1e-6, "Y exact");
    }

    #[test]
    fn two_exposures_and_colorcorr_divide() {
        let p = [128, 64, 32, 129];
        let bytes = file(
            &[
                "#?RADIANCE",
                "EXPOSURE=2.720623e-02",
                "VIEW= -vta",
                "EXPOSURE= 4.676974e+01 ",
                "COLORCORR= 2 0.5 4",
            ],
            "-Y 1 +X 1",
            &p,
        );
        let img = decode_ok(&bytes);
        let c = colr(p);
        let corrected = [c[0] / 2.0, c[1] / 0.5, c[2] / 4.0];
        let want = mul_vec(&RADIANCE_DEFAULT.rgb_to_xyz().unwrap(), corrected)
            .map(|v| v * 179.0 / (2.720623e-02 * 4.676974e+01));
        close(img.x[0], want[0], 1e-6, "X");
        close(img.y[0], want[1], 1e-6, "Y");
        close(img.z[0], want[2], 1e-6, "Z");
    }

    #[test]
    fn header_lines_before_magic_are_accepted() {
        let bytes = file(
            &[
                "VIEW= -vth -vh 170 -vv 160",
                "SOFTWARE= x",
                "#?RADIANCE",
                "FORMAT=32-bit_rle_rgbe",
            ],
            "-Y 1 +X 1",
            &[128, 64, 32, 129],
        );
        assert!(looks_like_header(&bytes));
        assert_eq!(
            crate::io::detect(&bytes),
            Some(crate::io::InputFormat::Radiance)
        );
        let img = decode_ok(&bytes);
        close(img.y[0], expected_rgbe([128, 64, 32, 129])[1], 1e-6, "Y");
        assert_eq!(
            img.view,
            Some(View {
                projection: Projection::HemisphericalFisheye,
                horizontal_deg: 170.0,
                vertical_deg: 160.0
            })
        );
        // No magic line, FORMAT only: also a Radiance file.
        let bytes = file(
            &["FORMAT=32-bit_rle_rgbe"],
            "-Y 1 +X 1",
            &[128, 64, 32, 129],
        );
        assert!(looks_like_header(&bytes));
        decode_ok(&bytes);
    }

    #[test]
    fn crlf_header_is_accepted() {
        let mut bytes = b"#?RADIANCE\r\nFORMAT=32-bit_rle_rgbe\r\n\r\n-Y 1 +X 1\r\n".to_vec();
        bytes.extend([128, 64, 32, 129]);
        close(
            decode_ok(&bytes).y[0],
            expected_rgbe([128, 64, 32, 129])[1],
            1e-6,
            "Y",
        );
    }

    #[test]
    fn looks_like_header_rejects_binary_and_text() {
        assert!(!looks_like_header(b""));
        assert!(!looks_like_header(b"VIEW= -vta\n"));
        assert!(!looks_like_header(b"hello\nworld\n\n#?RADIANCE\n"));
        assert!(!looks_like_header(b"KEY=1\n\x00\x01\x02#?RADIANCE\n"));
        assert!(!looks_like_header(&[
            0x76, 0x2f, 0x31, 0x01, b'\n', b'#', b'?', b'R'
        ]));
        // Marker beyond the sniffing window.
        let mut far = b"X=1\n".repeat(SNIFF_LEN / 4);
        far.extend(b"#?RADIANCE\n");
        assert!(!looks_like_header(&far));
        // Pseudo-random binary data.
        let mut s = 0x1234_5678_u32;
        for _ in 0..200 {
            let v: Vec<u8> = (0..4096)
                .map(|_| {
                    s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (s >> 24) as u8
                })
                .collect();
            assert!(!looks_like_header(&v));
        }
        assert!(looks_like_header(
            b"CAPDATE= 2003:12:15\nVIEW= -vta\n#?RGBE\n"
        ));
    }

    /// A 3×2 image, and the byte data of it in each of the 8 orientations.
    #[test]
    fn all_eight_orientations_reorient_to_standard() {
        let (w, h) = (3usize, 2usize);
        // Pixel (row, col) in the standard layout has distinct red mantissa 10·row + col.
        let px = |row: usize, col: usize| [(10 * row + col) as u8 + 1, 50, 60, 128];
        let standard: Vec<[u8; 4]> = (0..h).flat_map(|r| (0..w).map(move |c| px(r, c))).collect();
        let reference = decode_ok(&file(&["#?RADIANCE"], "-Y 2 +X 3", &flat(&standard)));
        for (line, y_major, x_dec, y_dec) in [
            ("-Y 2 +X 3", true, false, true),
            ("-Y 2 -X 3", true, true, true),
            ("+Y 2 +X 3", true, false, false),
            ("+Y 2 -X 3", true, true, false),
            ("+X 3 -Y 2", false, false, true),
            ("+X 3 +Y 2", false, false, false),
            ("-X 3 -Y 2", false, true, true),
            ("-X 3 +Y 2", false, true, false),
        ] {
            // Radiance coordinates: x right, y up. Display row = h − 1 − y.
            let mut data = Vec::new();
            let (outer, inner) = if y_major { (h, w) } else { (w, h) };
            for s in 0..outer {
                for i in 0..inner {
                    let (x, y) = if y_major {
                        let y = if y_dec { h - 1 - s } else { s };
                        let x = if x_dec { w - 1 - i } else { i };
                        (x, y)
                    } else {
                        let x = if x_dec { w - 1 - s } else { s };
                        let y = if y_dec { h - 1 - i } else { i };
                        (x, y)
                    };
                    data.extend(px(h - 1 - y, x));
                }
            }
            let img = decode_ok(&file(&["#?RADIANCE"], line, &data));
            assert_eq!(img, reference, "orientation {line}");
        }
    }

    #[test]
    fn rle_column_major_orientation() {
        // Scanlines of 8 (the height) can be RLE in a column-major file.
        let (w, h) = (2usize, 8usize);
        let px = |row: usize, col: usize| [(row * 2 + col) as u8 + 1, 9, 9, 129];
        let standard: Vec<[u8; 4]> = (0..h).flat_map(|r| (0..w).map(move |c| px(r, c))).collect();
        let reference = decode_ok(&file(&["#?RADIANCE"], "-Y 8 +X 2", &flat(&standard)));
        let mut data = Vec::new();
        for col in (0..w).rev() {
            // -X: right column first; +Y: bottom to top.
            let column: Vec<[u8; 4]> = (0..h).rev().map(|row| px(row, col)).collect();
            data.extend(rle(&column));
        }
        assert_eq!(
            decode_ok(&file(&["#?RADIANCE"], "-X 2 +Y 8", &data)),
            reference
        );
    }

    #[test]
    fn view_lines() {
        let view = |lines: &[&str]| {
            let mut header = vec!["#?RADIANCE"];
            header.extend(lines);
            decode_ok(&file(&header, "-Y 1 +X 1", &[1, 1, 2, 128])).view
        };
        assert_eq!(view(&[]), None);
        assert_eq!(view(&["VIEW= -vp 0 0 0"]), Some(DEFAULT_VIEW));
        for (t, p) in [
            ("v", Projection::Perspective),
            ("l", Projection::Parallel),
            ("c", Projection::Cylindrical),
            ("h", Projection::HemisphericalFisheye),
            ("a", Projection::AngularFisheye),
            ("s", Projection::Planisphere),
        ] {
            let line = format!(
                "VIEW= -vt{t} -vp -0.2 3 2.7 -vd -2 -0.4 -1 -vu 0 0 1 -vh 66.6 -vv 37.5 -vo 0 -va 0 -vs 0 -vl 0"
            );
            assert_eq!(
                view(&[&line]),
                Some(View {
                    projection: p,
                    horizontal_deg: 66.6,
                    vertical_deg: 37.5
                })
            );
        }
        // Later lines and options override earlier ones.
        assert_eq!(
            view(&["VIEW= -vta -vh 180 -vv 180", "VIEW= -vh 90 -vh 100"]),
            Some(View {
                projection: Projection::AngularFisheye,
                horizontal_deg: 100.0,
                vertical_deg: 180.0
            })
        );
        for bad in [
            "VIEW= -vtq",
            "VIEW= -vh",
            "VIEW= -vh abc",
            "VIEW= -vv -5",
            "VIEW= -vh inf",
        ] {
            assert_decode_err(
                &file(&["#?RADIANCE", bad], "-Y 1 +X 1", &[1, 1, 2, 128]),
                bad,
            );
        }
    }

    #[test]
    fn header_errors() {
        let px = [1u8, 1, 2, 128];
        let with = |line: &str| file(&["#?RADIANCE", line], "-Y 1 +X 1", &px);
        for bad in [
            "EXPOSURE=0",
            "EXPOSURE=-1",
            "EXPOSURE=nan",
            "EXPOSURE=inf",
            "EXPOSURE=abc",
            "EXPOSURE=",
            "EXPOSURE=1 2",
            "COLORCORR=1 1",
            "COLORCORR=1 0 1",
            "PRIMARIES=0.64 0.33 0.3 0.6 0.15 0.06 0.3127",
            "PRIMARIES=0.3 0.3 0.3 0.3 0.15 0.06 0.3127 0.3290",
            // A white point with y = 0 has no luminance to normalise to. (A primary with
            // y = 0 is valid: an imaginary primary, such as those of CIE XYZ.)
            "PRIMARIES=0.64 0.33 0.3 0.6 0.15 0.06 0.3127 0",
        ] {
            assert_decode_err(&with(bad), bad);
        }
        // Exposures whose product leaves the representable range.
        let tiny = file(
            &["#?RADIANCE", "EXPOSURE=1e-200", "EXPOSURE=1e-200"],
            "-Y 1 +X 1",
            &px,
        );
        assert_decode_err(&tiny, "exposure product underflow");
        let small = file(&["#?RADIANCE", "EXPOSURE=1e-300"], "-Y 1 +X 1", &px);
        assert_decode_err(&small, "exposure scale overflow");
        for fmt in ["FORMAT=32-bit_rle_rgbx", "FORMAT=ascii", "FORMAT=float"] {
            assert!(
                matches!(
                    decode(&with(fmt), &Limits::default()),
                    Err(Error::Unsupported(_))
                ),
                "{fmt}"
            );
        }
        // No magic and no FORMAT line.
        assert_decode_err(&file(&["SOFTWARE=x"], "-Y 1 +X 1", &px), "no magic");
        // Header never ends.
        assert_decode_err(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n", "unterminated");
        assert_decode_err(b"", "empty");
    }

    #[test]
    fn resolution_errors() {
        let px = [1u8, 1, 2, 128];
        for bad in [
            "",
            "-Y 1",
            "-Y 1 +X",
            "-Y 0 +X 1",
            "-Y 1 +X 0",
            "-Y 1 -Y 1",
            "+X 1 +X 1",
            "-Z 1 +X 1",
            "Y 1 X 1",
            "-Y -1 +X 1",
            "-Y 1.5 +X 1",
            "-Y abc +X 1",
            "-Y 1 +X 1 junk",
            "-Y 99999999999999999999999 +X 1",
            "-y 1 +x 1",
        ] {
            assert_decode_err(&file(&["#?RADIANCE"], bad, &px), bad);
        }
        // Missing resolution line entirely.
        assert_decode_err(b"#?RADIANCE\n\n", "missing");
        assert_decode_err(
            &[b"#?RADIANCE\n\n".as_slice(), &[b'-'; 200]].concat(),
            "overlong",
        );
    }

    #[test]
    fn huge_dimensions_are_a_limits_error() {
        let bytes = file(
            &["#?RADIANCE"],
            "-Y 100000000 +X 100000000",
            &[1, 1, 2, 128],
        );
        assert!(matches!(
            decode(&bytes, &Limits::default()),
            Err(Error::Limits(_))
        ));
        let bytes = file(
            &["#?RADIANCE"],
            "-Y 18446744073709551615 +X 18446744073709551615",
            &[],
        );
        assert!(matches!(
            decode(&bytes, &Limits::none()),
            Err(Error::Limits(_))
        ));
        let bytes = file(&["#?RADIANCE"], "-Y 10 +X 10", &[]);
        assert!(matches!(
            decode(
                &bytes,
                &Limits {
                    max_pixels: 99,
                    ..Limits::default()
                }
            ),
            Err(Error::Limits(_))
        ));
        // Within the limits but without the data: truncated, before allocating 5 GiB.
        let bytes = file(&["#?RADIANCE"], "-Y 16384 +X 16384", &[1, 1, 2, 128]);
        assert_decode_err(&bytes, "declared large, tiny data");
    }

    #[test]
    fn scanline_errors() {
        let hdr = ["#?RADIANCE"];
        // RLE run overrunning the scanline (9 > 8).
        let mut data = vec![2, 2, 0, 8, 128 + 9, 1];
        data.extend([0; 40]);
        assert_decode_err(&file(&hdr, "-Y 1 +X 8", &data), "run overrun");
        // Literal overrunning.
        let mut data = vec![2, 2, 0, 8, 9];
        data.extend([0; 40]);
        assert_decode_err(&file(&hdr, "-Y 1 +X 8", &data), "literal overrun");
        // Zero-length literal.
        let mut data = vec![2, 2, 0, 8, 0];
        data.extend([0; 40]);
        assert_decode_err(&file(&hdr, "-Y 1 +X 8", &data), "zero length");
        // Width mismatch in the marker.
        let mut data = vec![2, 2, 0, 9];
        data.extend([128 + 8, 1].repeat(4));
        assert_decode_err(&file(&hdr, "-Y 1 +X 8", &data), "width mismatch");
        // Old-style repeat with nothing before it, and repeat overrunning.
        assert_decode_err(
            &file(&hdr, "-Y 1 +X 4", &[1, 1, 1, 3, 0, 0, 0, 0]),
            "repeat first",
        );
        assert_decode_err(
            &file(&hdr, "-Y 1 +X 4", &[5, 5, 5, 128, 1, 1, 1, 4]),
            "repeat overrun",
        );
        assert_decode_err(
            &file(
                &hdr,
                "-Y 1 +X 4",
                &[
                    5, 5, 5, 128, 1, 1, 1, 0, 1, 1, 1, 0, 1, 1, 1, 0, 1, 1, 1, 0, 1, 1, 1, 0, 1, 1,
                    1, 0, 1, 1, 1, 0, 1, 1, 1, 1,
                ],
            ),
            "repeat shifted out of range",
        );
    }

    #[test]
    fn every_truncation_is_an_error() {
        let px = wide_pixels();
        let mut rle_data = Vec::new();
        for row in px.chunks(10) {
            rle_data.extend(rle(row));
        }
        let mut old = vec![90u8, 80, 70, 135];
        old.extend([1, 1, 1, 43, 1, 1, 1, 1]);
        let files = [
            file(
                &["VIEW= -vta", "#?RADIANCE", "EXPOSURE=2"],
                "-Y 3 +X 10",
                &rle_data,
            ),
            file(&["#?RADIANCE"], "+X 10 -Y 3", &flat(&px)),
            file(
                &["#?RADIANCE", "FORMAT=32-bit_rle_xyze"],
                "-Y 1 +X 300",
                &old,
            ),
        ];
        for f in &files {
            decode_ok(f);
            for cut in 0..f.len() {
                match decode(&f[..cut], &Limits::default()) {
                    Err(Error::Decode { .. }) => {}
                    other => panic!("cut at {cut}/{}: {other:?}", f.len()),
                }
            }
        }
    }

    #[test]
    fn corrupted_bytes_never_panic() {
        let px = wide_pixels();
        let mut base = Vec::new();
        for row in px.chunks(10) {
            base.extend(rle(row));
        }
        let base = file(&["#?RADIANCE"], "-Y 3 +X 10", &base);
        let mut rand = lcg(42);
        for _ in 0..20_000 {
            let mut f = base.clone();
            for _ in 0..1 + rand() % 4 {
                let i = rand() % f.len();
                f[i] = rand() as u8;
            }
            let _ = decode(&f, &Limits::default());
        }
        for len in [0usize, 1, 10, 100, 1000] {
            let g: Vec<u8> = (0..len).map(|_| rand() as u8).collect();
            assert!(decode(&g, &Limits::default()).is_err());
        }
    }

    #[test]
    fn radiance_default_y_row_matches_color_h() {
        let m = RADIANCE_DEFAULT.rgb_to_xyz().unwrap();
        for i in 0..3 {
            assert!(
                (m[1][i] / RADIANCE_Y_ROW[i] - 1.0).abs() < 5e-4,
                "{i}: {}",
                m[1][i]
            );
        }
    }

    #[test]
    fn double_precision_path_matches() {
        // Exposure 1e-25 puts the matrix outside the f32 path's range: f64 for all pixels.
        let bytes = file(
            &["#?RADIANCE", "EXPOSURE=1e-25"],
            "-Y 2 +X 3",
            &flat(&PIXELS),
        );
        let img = decode_ok(&bytes);
        for (i, p) in PIXELS.iter().enumerate() {
            let want = expected_rgbe(*p).map(|v| v / 1e-25);
            close(img.x[i], want[0], 1e-6, "X");
            close(img.y[i], want[1], 1e-6, "Y");
            close(img.z[i], want[2], 1e-6, "Z");
        }
        // Tiny exponents (1..=9) in an otherwise ordinary scanline.
        let px: Vec<[u8; 4]> = (1..=12u8).map(|e| [200, 100, 50, e]).collect();
        let img = decode_ok(&file(&["#?RADIANCE"], "-Y 1 +X 12", &rle(&px)));
        for (i, p) in px.iter().enumerate() {
            let want = expected_rgbe(*p);
            // Values near 1e-38 and below are f32 subnormals: absolute precision 1.4e-45.
            let got = f64::from(img.y[i]);
            assert!(
                (got - want[1]).abs() <= 1e-6 * want[1] + 2e-45,
                "{i}: {got} vs {}",
                want[1]
            );
        }
    }

    #[test]
    fn decode_into_reuses_and_overwrites() {
        let px = wide_pixels();
        let big = file(&["#?RADIANCE", "VIEW= -vta"], "-Y 3 +X 10", &flat(&px));
        let small = file(&["#?RADIANCE"], "+X 2 -Y 1", &flat(&px[..2]));
        let mut img = decode_ok(&big);
        decode_into(&small, &Limits::default(), &mut img).unwrap();
        assert_eq!(img, decode_ok(&small));
        decode_into(&big, &Limits::default(), &mut img).unwrap();
        assert_eq!(img, decode_ok(&big));
    }

    #[test]
    fn extreme_exponents_stay_finite() {
        let bytes = file(
            &["#?RADIANCE"],
            "-Y 1 +X 2",
            &flat(&[[255, 255, 255, 255], [0, 0, 1, 1]]),
        );
        let img = decode_ok(&bytes);
        assert!(
            img.x
                .iter()
                .chain(&img.y)
                .chain(&img.z)
                .all(|v| v.is_finite())
        );
        assert_eq!(img.y[0], f32::MAX);
        close(img.z[1], expected_rgbe([0, 0, 1, 1])[2], 1e-3, "tiny Z");
    }

    /// Decode `bytes` with the serial decoder and with the parallel one: both must give
    /// the same image bit for bit, or the same error.
    #[cfg(feature = "rayon")]
    fn serial_and_parallel(bytes: &[u8]) -> Result<HdrImage> {
        let run = |parallel| {
            let mut image = HdrImage::zeros(0, 0);
            decode_with(bytes, &Limits::default(), 1.0, &mut image, parallel).map(|()| image)
        };
        let (serial, parallel) = (run(false), run(true));
        match (&serial, &parallel) {
            (Ok(a), Ok(b)) => {
                assert_eq!(
                    (a.width, a.height, a.view, a.adopted_white),
                    (b.width, b.height, b.view, b.adopted_white)
                );
                for (pa, pb) in [(&a.x, &b.x), (&a.y, &b.y), (&a.z, &b.z)] {
                    assert!(
                        pa.iter()
                            .map(|v| v.to_bits())
                            .eq(pb.iter().map(|v| v.to_bits()))
                    );
                }
            }
            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
            _ => panic!("serial {serial:?} but parallel {parallel:?}"),
        }
        parallel
    }

    /// `w × h` pseudo-random pixels with runs of equal components (so that run-length
    /// scanlines hold both runs and literals), some black, and no `1 1 1` or `2 2` pixels.
    #[cfg(feature = "rayon")]
    fn varied_pixels(w: usize, h: usize, seed: u64) -> Vec<[u8; 4]> {
        let mut rand = lcg(seed);
        let mut next = || rand() as u8;
        let mut px = Vec::with_capacity(w * h);
        let mut current = [100u8, 90, 80, 130];
        for _ in 0..w * h {
            match next() % 8 {
                0 => current = [0; 4],
                1..=3 => current = [next() | 8, next() | 8, next() | 8, 120 + next() % 16],
                _ => {}
            }
            px.push(current);
        }
        px
    }

    /// The `2 + h`-offset scanline data of `px` (`w` wide) in the row order of a
    /// resolution line `-Y`/`+Y` and column order `+X`/`-X`, every row encoded by `enc`.
    #[cfg(feature = "rayon")]
    fn scanlines(
        px: &[[u8; 4]],
        w: usize,
        y_dec: bool,
        x_dec: bool,
        enc: impl Fn(usize, &[[u8; 4]]) -> Vec<u8>,
    ) -> Vec<u8> {
        let h = px.len() / w;
        let mut data = Vec::new();
        for s in 0..h {
            let row = if y_dec { s } else { h - 1 - s };
            let mut line = px[row * w..(row + 1) * w].to_vec();
            if x_dec {
                line.reverse();
            }
            data.extend(enc(s, &line));
        }
        data
    }

    #[cfg(feature = "rayon")]
    #[test]
    fn parallel_rows_equal_serial_rows() {
        let (w, h) = (37usize, 45usize);
        let px = varied_pixels(w, h, 7);
        let reference = decode_ok(&file(
            &["#?RADIANCE"],
            &format!("-Y {h} +X {w}"),
            &flat(&px),
        ));
        for (y_dec, x_dec, axes) in [
            (true, false, format!("-Y {h} +X {w}")),
            (false, false, format!("+Y {h} +X {w}")),
            (true, true, format!("-Y {h} -X {w}")),
            (false, true, format!("+Y {h} -X {w}")),
        ] {
            // All run-length, all flat, and mixed scanlines.
            for (kind, data) in [
                ("rle", scanlines(&px, w, y_dec, x_dec, |_, l| rle(l))),
                ("flat", scanlines(&px, w, y_dec, x_dec, |_, l| flat(l))),
                (
                    "mixed",
                    scanlines(&px, w, y_dec, x_dec, |s, l| {
                        if s % 3 == 0 { flat(l) } else { rle(l) }
                    }),
                ),
            ] {
                // The walk vouches for these scanlines: the parallel path is the one tested.
                assert!(scanline_starts(&data, h, w).is_some(), "{axes} {kind}");
                let img = serial_and_parallel(&file(&["#?RADIANCE"], &axes, &data)).unwrap();
                assert_eq!(img, reference, "{axes} {kind}");
                // Exposure and colour correction folded into the matrix, on both paths.
                let header = ["#?RADIANCE", "EXPOSURE=0.37", "COLORCORR=1 0.9 1.1"];
                let img = serial_and_parallel(&file(&header, &axes, &data)).unwrap();
                close(img.y[5], f64::from(reference.y[5]) / 0.37, 1e-6, "exposure");
            }
        }
    }

    #[cfg(feature = "rayon")]
    #[test]
    fn old_style_repeats_take_the_serial_decoder() {
        let (w, h) = (37usize, 40usize);
        let px = varied_pixels(w, h, 11);
        // Row 20 as a pixel and one repeat record for the next 36.
        let data = scanlines(&px, w, true, false, |s, l| {
            if s == 20 {
                let mut v = l[0].to_vec();
                v.extend([1, 1, 1, 36]);
                v
            } else {
                rle(l)
            }
        });
        assert!(scanline_starts(&data, h, w).is_none());
        let img =
            serial_and_parallel(&file(&["#?RADIANCE"], &format!("-Y {h} +X {w}"), &data)).unwrap();
        let row = &img.y[20 * w..21 * w];
        assert!(row.iter().all(|v| v.to_bits() == row[0].to_bits()));
        // A row whose first pixel reads as a repeat record: an error either way.
        let data = scanlines(&px, w, true, false, |s, l| {
            let mut v = flat(l);
            if s == 30 {
                v[..3].copy_from_slice(&[1, 1, 1]);
            }
            v
        });
        let err = serial_and_parallel(&file(&["#?RADIANCE"], &format!("-Y {h} +X {w}"), &data));
        assert!(
            err.unwrap_err()
                .to_string()
                .contains("repeat record with no pixel")
        );
    }

    #[cfg(feature = "rayon")]
    #[test]
    fn damaged_files_fail_alike_serial_and_parallel() {
        let (w, h) = (23usize, 36usize);
        let px = varied_pixels(w, h, 3);
        let axes = format!("-Y {h} +X {w}");
        let rle_file = file(
            &["#?RADIANCE"],
            &axes,
            &scanlines(&px, w, true, false, |_, l| rle(l)),
        );
        let mixed = file(
            &["#?RADIANCE"],
            &axes,
            &scanlines(&px, w, true, false, |s, l| {
                if s % 2 == 0 { flat(l) } else { rle(l) }
            }),
        );
        for f in [&rle_file, &mixed] {
            serial_and_parallel(f).unwrap();
            // Every truncation.
            for cut in 0..f.len() {
                assert!(serial_and_parallel(&f[..cut]).is_err(), "cut at {cut}");
            }
        }
        // Random bytes changed in the scanlines: the same image or the same error.
        let start = file(&["#?RADIANCE"], &axes, &[]).len();
        let mut rand = lcg(5);
        let mut errors = 0;
        for _ in 0..3000 {
            let mut f = if rand().is_multiple_of(2) {
                rle_file.clone()
            } else {
                mixed.clone()
            };
            for _ in 0..1 + rand() % 3 {
                let i = start + rand() % (f.len() - start);
                f[i] = match rand() % 4 {
                    0 => 0,
                    1 => 1,
                    2 => 2,
                    _ => rand() as u8,
                };
            }
            errors += usize::from(serial_and_parallel(&f).is_err());
        }
        // Some changes break a code, others only change a value: both outcomes compared.
        assert!((1..3000).contains(&errors), "{errors} errors");
    }

    #[cfg(feature = "rayon")]
    #[test]
    fn parallel_decoder_on_real_pictures() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
        for name in ["mixtex.hdr", "sunset-fisheye.hdr"] {
            let bytes = std::fs::read(dir.join(name)).unwrap();
            let img = serial_and_parallel(&bytes).unwrap();
            assert!(img.y.iter().any(|v| *v > 0.0), "{name}");
        }
        if let Some(shared) = std::env::var_os("VISADAPT_SHARED_DATA") {
            let bytes =
                std::fs::read(std::path::Path::new(&shared).join("radiance/office-fisheye.hdr"))
                    .unwrap();
            serial_and_parallel(&bytes).unwrap();
        }
    }
}
