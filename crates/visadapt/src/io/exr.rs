//! OpenEXR input and output.
//!
//! # Reading
//!
//! [`decode`] reads single-part and multi-part, scan-line and tiled OpenEXR files with any
//! compression the `exr` crate decodes (none, RLE, ZIP, ZIPS, PIZ, PXR24, B44, B44A,
//! DWAA, DWAB) and `half`, `float` or `uint` samples. It takes the pixels of the **data
//! window** of the first part (layer) that holds a usable set of channels, at its full
//! resolution (mip/rip levels are skipped). The display window, pixel aspect ratio and
//! alpha are ignored. Channel rules, tried in this order on the un-prefixed channels of a
//! part first, then on each `prefix.` group in name order:
//!
//! 1. `X`, `Y`, `Z` (and optionally `scotopic`): the paper's own layout (Ferwerda et al.
//!    1996, Sec. 4), CIE XYZ with `Y` in cd/m² and scotopic luminance in scotopic cd/m².
//!    The image is absolute; `chromaticities` and `whiteLuminance` are not applied.
//! 2. `R`, `G`, `B` (alpha ignored): RGB in the primaries of the `chromaticities`
//!    attribute (Rec. 709 / D65 when absent, the OpenEXR default), converted to XYZ with
//!    the SMPTE RP 177 matrix normalised so that RGB (1, 1, 1) has Y = 1.
//! 3. `Y`, `RY`, `BY`: luminance/chroma (OpenEXR `ImfRgbaYca`). RY and BY may be
//!    subsampled 2×2 (or 2× along one axis); they are reconstructed with OpenEXR's own
//!    14-tap interpolation filter (`reconstructChromaHoriz/Vert`, edge samples repeated)
//!    and converted with `R = (RY + 1)·Y`, `B = (BY + 1)·Y`,
//!    `G = (Y − wR·R − wB·B) / wG`, where `w` is the Y row of the RGB→XYZ matrix
//!    (`computeYw`); when both chroma values are 0 the pixel is grey, R = G = B = Y.
//!    OpenEXR's extra `fixSaturation` pass is not applied.
//! 4. `Y` alone (without RY/BY), or exactly one of `R`, `G`, `B`: a grey luminance image
//!    (a lone `G`, as in `WideFloatRange.exr`, is read as luminance, not as green). X and
//!    Z are set so the colour is the white point of `chromaticities`
//!    (X = Y·x_w/y_w, Z = Y·(1 − x_w − y_w)/y_w, D65 by default).
//! 5. Two of `R`, `G`, `B`: the missing one is taken as 0, as OpenEXR's `RgbaInputFile`
//!    does.
//!
//! Adopted white ([`HdrImage::adopted_white`], what the operator adapts from): the
//! `adoptedNeutral` attribute when present, else the white of `chromaticities` (D65 when
//! absent); for rule 1 (the paper's layout) equal energy, the paper's illuminant (Sec. 5).
//!
//! Units: when the part has a positive, finite `whiteLuminance` attribute (the luminance in
//! cd/m² of RGB (1, 1, 1), OpenEXR `ImfStandardAttributes.h`), rules 2–5 multiply by it and
//! the image is marked absolute; otherwise values are taken as cd/m² as they stand and
//! [`HdrImage::absolute_units`] is false. A `chromaticities` attribute whose primaries are
//! CIE XYZ itself (red (1, 0), green (0, 1), blue (0, 0), as in `XYZ.exr`) gives the
//! identity matrix. Arithmetic is in `f64`; a finite result too large for `f32` saturates
//! at ±`f32::MAX` instead of becoming infinite, so the reader never introduces Inf or NaN.
//!
//! Safety against damaged files: the header is read first, the data window is checked
//! against [`Limits`] and the channel count against [`MAX_CHANNELS`] before any pixel
//! memory is allocated; the planes, and every decompressed block in flight, are checked
//! against the memory budget ([`Limits::max_memory_bytes`]) before they are allocated (the
//! `exr` crate allocates a whole decompressed block before reading its data, and a failed
//! allocation aborts the process); chunk offsets and sizes are checked against the file
//! length. ZIP and ZIPS blocks are decompressed here (libdeflate, into a reused buffer,
//! then OpenEXR's predictor and byte interleaving undone in one pass), the same bytes as
//! the `exr` crate gives, checked by the tests against it;
//! the other compressions through the `exr` crate. Each call into the `exr` crate or the
//! inflater runs under `catch_unwind`, so a panic inside it becomes [`Error::Decode`], and
//! prints nothing (the process's panic hook is wrapped once to stay silent for those panics
//! only); this module's own code is not guarded, so a bug in it is not mistaken for a
//! corrupt file.
//!
//! # Writing
//!
//! [`write_display`] writes a [`DisplayImage`] as 32-bit float R, G, B (RLE) with
//! `chromaticities` = Rec. 709 and `whiteLuminance` = the display maximum, so RGB (1, 1, 1)
//! reads back as `L_dmax` cd/m². [`write_hdr`] writes an [`HdrImage`] in the paper's layout:
//! 32-bit float `X`, `Y`, `Z` (+ `scotopic`) in cd/m² (RLE). Blocks are chosen by bytes
//! ([`BlockLayout`]): scan lines for ordinary images, tiles for very narrow or very wide
//! ones, so that no shape makes a file of millions of tiny chunks or one huge one.
//!
//! # The view
//!
//! OpenEXR has no standard attribute for a camera's field of view, which acuity needs
//! (degrees to pixels). visadapt records it in a custom string attribute of the part,
//! [`VIEW_ATTRIBUTE`] = `visadaptView`, holding Radiance view options as a Radiance
//! `VIEW=` line does: `-vt?` (projection: `v` perspective, `a` angular fisheye, `h`
//! hemispherical fisheye, `c` cylindrical, `s` planisphere, `l` parallel), `-vh` and `-vv`
//! (full horizontal and vertical angles in degrees), e.g. `-vtv -vh 60 -vv 35.98`.
//! [`write_hdr`] writes it when the image has a view; [`decode`] reads it back into
//! [`HdrImage::view`]. Other tools keep or drop it as they do any unknown attribute.

use crate::colour::{self, Chromaticities, Mat3, REC709};
use crate::limits::saturating_f32;
use crate::simd::{self, Isa};
use crate::{DisplayImage, Error, HdrImage, Limits, Result};
use exr::block::chunk::TileCoordinates;
use exr::math::Vec2;
use exr::meta::attribute::{IntegerBounds, SampleType};
use exr::meta::header::Header;
use exr::meta::{BlockDescription, MetaData};
use std::collections::HashSet;
use std::io::Cursor;
use std::panic::AssertUnwindSafe;

/// Format name used in error messages.
const FORMAT: &str = "OpenEXR";

/// Name of the custom attribute holding the view (see the module docs, "The view").
pub const VIEW_ATTRIBUTE: &str = "visadaptView";

/// Largest number of channels accepted in the part that is read. Our own bound, not from
/// the OpenEXR specification (which sets none): production renders carry at most a few
/// hundred AOV channels, and the check keeps a hostile channel list from multiplying the
/// per-pixel byte count.
pub const MAX_CHANNELS: usize = 1024;

/// How many chunks are decompressed (in parallel) before their pixels are copied out.
/// Bounds the memory held in decompressed blocks to this many blocks. Our choice.
const BATCH: usize = 64;

/// OpenEXR's chroma reconstruction filter (`ImfRgbaYca.cpp`, `reconstructChromaHoriz` and
/// `reconstructChromaVert`): weights of the chroma samples at offsets −13, −11, …, −1, +1,
/// …, +13 pixels from an odd (chroma-less) pixel, a 27-pixel windowed sinc.
const CHROMA_FILTER: [f32; 14] = [
    0.002128, -0.007540, 0.019597, -0.043159, 0.087929, -0.186077, 0.627123, 0.627123, -0.186077,
    0.087929, -0.043159, 0.019597, -0.007540, 0.002128,
];

// ------------------------------------------------------------------------------------------
// Reading
// ------------------------------------------------------------------------------------------

/// Decode an OpenEXR file held in memory (see the [module documentation](self) for the
/// rules).
pub fn decode(bytes: &[u8], limits: &Limits) -> Result<HdrImage> {
    decode_checked(bytes, limits, 1.0, &mut Vec::new())
}

/// [`decode`] into an existing image, reusing the memory of its planes for the planes
/// read (for decoding a sequence of frames without allocating and page-faulting fresh
/// planes each time: a 1080p frame's three planes are 24 MiB of pages that the kernel
/// would zero). On success `image` is entirely overwritten; on error its contents are
/// unspecified (its planes may have been taken).
pub fn decode_into(bytes: &[u8], limits: &Limits, image: &mut HdrImage) -> Result<()> {
    decode_scaled_into(bytes, limits, 1.0, image)
}

/// [`decode_into`] with every value multiplied by `factor` (a unit conversion, `--scale`)
/// in the same pass: the factor joins the `whiteLuminance` scale of the conversion to
/// XYZ, so the values are rounded to `f32` once, not twice, and saturate as
/// [`HdrImage::scale`]'s do. Parts stored as XYZ, which are not converted, and factors
/// that are not finite (whose products with the matrix would not be the products of the
/// converted values) are applied by [`HdrImage::scale`] after decoding.
pub(crate) fn decode_scaled_into(
    bytes: &[u8],
    limits: &Limits,
    factor: f32,
    image: &mut HdrImage,
) -> Result<()> {
    if !factor.is_finite() {
        decode_scaled_into(bytes, limits, 1.0, image)?;
        image.scale(factor);
        return Ok(());
    }
    let mut spare: Vec<Vec<f32>> = [
        image.scotopic.take().unwrap_or_default(),
        std::mem::take(&mut image.z),
        std::mem::take(&mut image.y),
        std::mem::take(&mut image.x),
    ]
    .into_iter()
    .filter(|p| p.capacity() > 0)
    .collect();
    *image = decode_checked(bytes, limits, factor, &mut spare)?;
    Ok(())
}

/// Most bytes of a chunk header: part number (4), tile coordinates (16), data size (4)
/// and the two deep-data sizes (16) (OpenEXR file layout, "Chunk layout").
const MAX_CHUNK_HEADER: u64 = 40;

/// An upper bound on the bytes of a file whose headers are at the start of `head`: the
/// headers, every part's offset table, and for every chunk a header and at most one
/// uncompressed block (OpenEXR stores a block uncompressed when compression does not make
/// it smaller); `u64::MAX` when a part is deep (its chunks have no such bound: the memory
/// budget is the bound). `None` when the headers cannot be read from `head`.
pub(crate) fn file_len_bound(head: &[u8]) -> Option<u64> {
    let mut cursor = Cursor::new(head);
    let meta =
        foreign(|| MetaData::read_from_buffered(&mut cursor, false).map_err(exr_error)).ok()?;
    let mut total = cursor.position();
    for h in &meta.headers {
        if h.deep {
            return Some(u64::MAX);
        }
        let (w, ht) = (h.layer_size.0 as u64, h.layer_size.1 as u64);
        let (bw, bh) = match h.blocks {
            BlockDescription::ScanLines => (w, h.compression.scan_lines_per_block() as u64),
            BlockDescription::Tiles(t) => (t.tile_size.0 as u64, t.tile_size.1 as u64),
        };
        let block = bw
            .min(w.max(1))
            .checked_mul(bh.min(ht.max(1)))?
            .checked_mul(h.channels.bytes_per_pixel as u64)?;
        let per_chunk = block.checked_add(MAX_CHUNK_HEADER + 8)?;
        total = total.checked_add((h.chunk_count as u64).checked_mul(per_chunk)?)?;
    }
    Some(total)
}

thread_local! {
    /// Whether this thread is inside [`foreign`] (its panics are reported as errors, not
    /// printed).
    static IN_FOREIGN: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Run `f`, a call into the `exr` crate on file data, turning a panic there into a decode
/// error. Only calls into the foreign decoder are guarded: a panic in this module's own
/// code is a bug and propagates. The first call wraps the process's panic hook (once) so
/// that it stays silent for panics caught here and behaves as before for every other;
/// stderr then carries only the caller's one-line error.
fn foreign<T>(f: impl FnOnce() -> Result<T>) -> Result<T> {
    static QUIET_HOOK: std::sync::Once = std::sync::Once::new();
    QUIET_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !IN_FOREIGN.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    let outer = IN_FOREIGN.with(|c| c.replace(true));
    let result = std::panic::catch_unwind(AssertUnwindSafe(f));
    IN_FOREIGN.with(|c| c.set(outer));
    result.unwrap_or_else(|_| Err(Error::decode(FORMAT, "corrupt file (decoder failure)")))
}

/// The channels of a part that the image is made from, as indices into its channel list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Layout {
    /// Rule 1: CIE X, Y, Z in cd/m², optional scotopic.
    Xyz {
        x: usize,
        y: usize,
        z: usize,
        scotopic: Option<usize>,
    },
    /// Rules 2 and 5: RGB, a missing channel is 0.
    Rgb {
        r: Option<usize>,
        g: Option<usize>,
        b: Option<usize>,
    },
    /// Rule 3: luminance and (possibly subsampled) chroma.
    Yca { y: usize, ry: usize, by: usize },
    /// Rule 4: one luminance channel.
    Grey { l: usize },
}

impl Layout {
    /// The channels read, in a fixed order (the order of the planes that are filled).
    fn channels(&self) -> Vec<usize> {
        match *self {
            Layout::Xyz { x, y, z, scotopic } => [Some(x), Some(y), Some(z), scotopic]
                .into_iter()
                .flatten()
                .collect(),
            Layout::Rgb { r, g, b } => [r, g, b].into_iter().flatten().collect(),
            Layout::Yca { y, ry, by } => vec![y, ry, by],
            Layout::Grey { l } => vec![l],
        }
    }
}

/// Find a usable channel set among `names` (full names, indices into the channel list).
fn classify(names: &[(String, usize)]) -> Option<Layout> {
    // Groups: the un-prefixed channels first, then each "prefix." group in name order.
    let split = |n: &str| match n.rfind('.') {
        Some(i) => (n[..i].to_string(), n[i + 1..].to_string()),
        None => (String::new(), n.to_string()),
    };
    let mut prefixes: Vec<String> = names.iter().map(|(n, _)| split(n).0).collect();
    prefixes.sort();
    prefixes.dedup();
    for prefix in prefixes {
        let find = |base: &str| {
            names
                .iter()
                .find(|(n, _)| split(n) == (prefix.clone(), base.to_string()))
                .map(|&(_, i)| i)
        };
        let (x, y, z) = (find("X"), find("Y"), find("Z"));
        if let (Some(x), Some(y), Some(z)) = (x, y, z) {
            return Some(Layout::Xyz {
                x,
                y,
                z,
                scotopic: find("scotopic"),
            });
        }
        let (r, g, b) = (find("R"), find("G"), find("B"));
        if r.is_some() && g.is_some() && b.is_some() {
            return Some(Layout::Rgb { r, g, b });
        }
        if let Some(y) = y {
            if let (Some(ry), Some(by)) = (find("RY"), find("BY")) {
                return Some(Layout::Yca { y, ry, by });
            }
            return Some(Layout::Grey { l: y });
        }
        match [r, g, b].into_iter().flatten().collect::<Vec<_>>()[..] {
            [l] => return Some(Layout::Grey { l }),
            [_, _] => return Some(Layout::Rgb { r, g, b }),
            _ => {}
        }
    }
    None
}

/// The text of a channel name (names are bytes in OpenEXR, normally ASCII).
fn channel_name(header: &Header, i: usize) -> String {
    String::from_utf8_lossy(header.channels.list[i].name.bytes()).into_owned()
}

/// Convert an `exr` crate error into ours, on one line.
fn exr_error(e: exr::error::Error) -> Error {
    let one_line = |s: &str| s.split_whitespace().collect::<Vec<_>>().join(" ");
    match e {
        exr::error::Error::NotSupported(m) => {
            Error::Unsupported(format!("OpenEXR feature: {}", one_line(&m)))
        }
        exr::error::Error::Invalid(m) => Error::decode(FORMAT, one_line(&m)),
        exr::error::Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            Error::decode(FORMAT, "file is truncated")
        }
        exr::error::Error::Io(io) => Error::decode(FORMAT, one_line(&io.to_string())),
        exr::error::Error::Aborted => Error::decode(FORMAT, "reading was aborted"),
    }
}

/// A decode error with a reason.
fn invalid(reason: impl Into<String>) -> Error {
    Error::decode(FORMAT, reason)
}

/// Read a little-endian `i32` at `*pos`, advancing it.
fn read_i32(bytes: &[u8], pos: &mut usize) -> Result<i32> {
    let b = bytes
        .get(*pos..pos.saturating_add(4))
        .ok_or_else(|| invalid("file is truncated (chunk header)"))?;
    *pos += 4;
    Ok(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// One compressed block of the selected part, at full resolution.
#[derive(Debug)]
struct PendingBlock<'a> {
    /// Pixel rectangle, relative to the data window origin.
    rect: IntegerBounds,
    /// Compressed bytes, inside the file.
    data: &'a [u8],
    /// Bytes of the block once decompressed.
    expected_len: usize,
}

/// Decode, taking the memory of planes from `spare` where it is large enough.
fn decode_checked(
    bytes: &[u8],
    limits: &Limits,
    factor: f32,
    spare: &mut Vec<Vec<f32>>,
) -> Result<HdrImage> {
    let mut cursor = Cursor::new(bytes);
    let meta = foreign(|| MetaData::read_from_buffered(&mut cursor, false).map_err(exr_error))?;
    // The header reader consumes exactly the headers (it only peeks at the terminating
    // null bytes), so the chunk offset tables start here.
    let tables_start = usize::try_from(cursor.position()).map_err(|_| invalid("header"))?;

    // The first part with a usable set of channels.
    let mut selected = None;
    let mut deep_seen = false;
    for (index, header) in meta.headers.iter().enumerate() {
        if header.deep {
            deep_seen = true;
            continue;
        }
        let names: Vec<(String, usize)> = (0..header.channels.list.len())
            .map(|i| (channel_name(header, i), i))
            .collect();
        if let Some(layout) = classify(&names) {
            selected = Some((index, layout));
            break;
        }
    }
    let Some((index, layout)) = selected else {
        if deep_seen {
            return Err(Error::Unsupported("deep-data OpenEXR file".into()));
        }
        let found: Vec<String> = meta
            .headers
            .iter()
            .flat_map(|h| (0..h.channels.list.len()).map(move |i| channel_name(h, i)))
            .take(16)
            .collect();
        return Err(Error::Unsupported(format!(
            "OpenEXR file without usable channels (need R,G,B or Y or X,Y,Z; found [{}])",
            found.join(", ")
        )));
    };
    let header = &meta.headers[index];

    // Sizes first, before anything is allocated for pixels.
    let (width, height) = (header.layer_size.0, header.layer_size.1);
    let n = limits.check(FORMAT, width as u64, height as u64)?;
    if header.channels.list.len() > MAX_CHANNELS {
        return Err(invalid(format!(
            "{} channels (more than {MAX_CHANNELS})",
            header.channels.list.len()
        )));
    }
    validate_header(header, meta.headers.len() > 1, &layout)?;
    // The budget: the file's bytes, the planes read, and up to three more planes for the
    // conversion to XYZ (missing RGB channels, upsampled chroma).
    let plane_bytes = (n as u64).checked_mul(4);
    let planes_total = plane_bytes
        .and_then(|p| p.checked_mul(layout.channels().len() as u64 + 3))
        .and_then(|p| p.checked_add(bytes.len() as u64));
    limits.check_memory("the decoded planes", planes_total)?;
    let budget = Budget {
        limits,
        spare: limits.max_memory_bytes - planes_total.unwrap_or(0),
        zip: zip_is_ours(header.compression),
    };

    let pending = collect_blocks(bytes, &meta, tables_start, index)?;
    // The factor joins the conversion's scale; XYZ parts are not converted.
    let factor = f64::from(factor);
    let planes = decompress_and_scatter(header, &layout, &pending, &budget, factor, spare)?;
    debug_assert_eq!(planes.planes.first().map(Vec::len), Some(n));
    let mut image = to_hdr(header, &layout, planes, factor, width, height)?;
    if matches!(layout, Layout::Xyz { .. }) && factor != 1.0 {
        image.scale(factor as f32);
    }
    Ok(image)
}

/// Check the selected part's header with the `exr` crate's (non-strict) validation, and
/// the subsampling rules it does not handle.
fn validate_header(header: &Header, multipart: bool, layout: &Layout) -> Result<()> {
    let subsampled = header
        .channels
        .list
        .iter()
        .any(|c| c.sampling != Vec2(1, 1));
    let mut checked = std::borrow::Cow::Borrowed(header);
    if subsampled {
        // The exr crate refuses every subsampled file ("channel subsampling not supported
        // yet"); check the sampling rules of the OpenEXR file layout here, and the rest
        // with the crate on a copy whose channels are not subsampled.
        if header.blocks != BlockDescription::ScanLines {
            return Err(invalid("subsampled channels in a tiled file"));
        }
        let dw = header.data_window();
        for c in &header.channels.list {
            let (sx, sy) = (c.sampling.0, c.sampling.1);
            if sx == 0 || sy == 0 || sx > 1 << 16 || sy > 1 << 16 {
                return Err(invalid("invalid channel sampling factor"));
            }
            let (sxi, syi) = (sx as i64, sy as i64);
            if i64::from(dw.position.0).rem_euclid(sxi) != 0
                || i64::from(dw.position.1).rem_euclid(syi) != 0
                || !dw.size.0.is_multiple_of(sx)
                || !dw.size.1.is_multiple_of(sy)
            {
                return Err(invalid(
                    "channel sampling factor does not divide the data window",
                ));
            }
        }
        let used = layout.channels();
        for &i in &used {
            let s = header.channels.list[i].sampling;
            let chroma = matches!(layout, Layout::Yca { ry, by, .. } if i == *ry || i == *by);
            if s != Vec2(1, 1) && !(chroma && s.0 <= 2 && s.1 <= 2) {
                return Err(Error::Unsupported(format!(
                    "OpenEXR channel {} subsampled {}x{}",
                    channel_name(header, i),
                    s.0,
                    s.1
                )));
            }
        }
        use exr::compression::Compression::*;
        if !matches!(header.compression, Uncompressed | RLE | ZIP1 | ZIP16 | PIZ) {
            return Err(Error::Unsupported(format!(
                "luminance/chroma EXR with subsampled channels and {}",
                header.compression
            )));
        }
        let mut copy = header.clone();
        for c in copy.channels.list.iter_mut() {
            c.sampling = Vec2(1, 1);
        }
        checked = std::borrow::Cow::Owned(copy);
    }
    let mut long_names = false;
    foreign(|| {
        checked
            .validate(multipart, &mut long_names, false)
            .map_err(exr_error)
    })
}

/// Bytes of one decompressed block covering `rect` (relative to the data window), with
/// subsampled channels counted at their own resolution; `None` on overflow.
fn block_byte_len(header: &Header, rect: IntegerBounds) -> Option<usize> {
    let y0 = usize::try_from(rect.position.1).ok()?;
    let mut total = 0usize;
    for c in &header.channels.list {
        let (sx, sy) = (c.sampling.0.max(1), c.sampling.1.max(1));
        // Lines y in [y0, y1) with y % sy == 0.
        let rows = y0.checked_add(rect.size.1)?.div_ceil(sy) - y0.div_ceil(sy);
        let per_row = (rect.size.0 / sx).checked_mul(c.sample_type.bytes_per_sample())?;
        total = total.checked_add(per_row.checked_mul(rows)?)?;
    }
    Some(total)
}

/// Read the selected part's offset table and the chunk headers it points to, keeping the
/// full-resolution blocks. Checks every offset and size against the file.
fn collect_blocks<'a>(
    bytes: &'a [u8],
    meta: &MetaData,
    tables_start: usize,
    index: usize,
) -> Result<Vec<PendingBlock<'a>>> {
    let header = &meta.headers[index];
    let multipart = meta.requirements.is_multilayer();
    let too_big = || invalid("chunk offset table does not fit in the file");

    // Offset tables of all parts follow the headers, in part order.
    let mut table = tables_start;
    for h in &meta.headers[..index] {
        table = h
            .chunk_count
            .checked_mul(8)
            .and_then(|b| table.checked_add(b))
            .ok_or_else(too_big)?;
    }
    let table_len = header.chunk_count.checked_mul(8).ok_or_else(too_big)?;
    let table_end = table.checked_add(table_len).ok_or_else(too_big)?;
    let table_bytes = bytes.get(table..table_end).ok_or_else(too_big)?;

    // Level-0 blocks the part must contain.
    let (w, h) = (header.layer_size.0, header.layer_size.1);
    let (block_w, block_h) = match header.blocks {
        BlockDescription::ScanLines => (w, header.compression.scan_lines_per_block()),
        BlockDescription::Tiles(t) => (t.tile_size.0.min(w), t.tile_size.1.min(h)),
    };
    if block_w == 0 || block_h == 0 {
        return Err(invalid("zero tile size"));
    }
    let expected_blocks = w.div_ceil(block_w) * h.div_ceil(block_h);
    // Largest decompressed block; also the largest sensible compressed one (OpenEXR stores
    // a block uncompressed when compression does not make it smaller).
    let max_block = block_byte_len(
        header,
        IntegerBounds::new(Vec2(0, 0), Vec2(block_w, block_h)),
    )
    .ok_or_else(|| invalid("block size overflows"))?;

    let mut seen = HashSet::new();
    let mut pending = Vec::with_capacity(expected_blocks.min(header.chunk_count));
    for entry in table_bytes.chunks_exact(8) {
        let offset = u64::from_le_bytes(entry.try_into().expect("8 bytes"));
        let mut pos = usize::try_from(offset)
            .ok()
            .filter(|&o| o >= table_end && o < bytes.len())
            .ok_or_else(|| invalid(format!("chunk offset {offset} outside the file")))?;
        if multipart {
            let part = read_i32(bytes, &mut pos)?;
            if usize::try_from(part).ok() != Some(index) {
                return Err(invalid("chunk part number does not match its offset table"));
            }
        }
        let coords = match header.blocks {
            BlockDescription::ScanLines => {
                let y = read_i32(bytes, &mut pos)?;
                let lines = header.compression.scan_lines_per_block() as i64;
                let rel = i64::from(y) - i64::from(header.own_attributes.layer_position.1);
                if rel < 0 || rel % lines != 0 {
                    return Err(invalid(format!("scan line block at y = {y}")));
                }
                foreign(|| {
                    header
                        .get_scan_line_block_tile_coordinates(y)
                        .map_err(exr_error)
                })?
            }
            BlockDescription::Tiles(_) => {
                let mut c = [0usize; 4];
                for v in c.iter_mut() {
                    *v = usize::try_from(read_i32(bytes, &mut pos)?)
                        .map_err(|_| invalid("negative tile coordinate"))?;
                }
                TileCoordinates {
                    tile_index: Vec2(c[0], c[1]),
                    level_index: Vec2(c[2], c[3]),
                }
            }
        };
        let size = usize::try_from(read_i32(bytes, &mut pos)?)
            .map_err(|_| invalid("negative chunk size"))?;
        if coords.level_index != Vec2(0, 0) {
            continue; // a lower-resolution mip/rip level
        }
        if size > max_block {
            return Err(invalid(format!(
                "chunk of {size} bytes is larger than its block"
            )));
        }
        let data = pos
            .checked_add(size)
            .and_then(|end| bytes.get(pos..end))
            .ok_or_else(|| invalid("file is truncated (chunk data)"))?;
        let rect = foreign(|| {
            let rect = header
                .get_absolute_block_pixel_coordinates(coords)
                .map_err(exr_error)?;
            rect.validate(Some(header.layer_size)).map_err(exr_error)?;
            Ok(rect)
        })?;
        if rect.position.0 < 0
            || rect.position.1 < 0
            || rect.end().0 as i64 > w as i64
            || rect.end().1 as i64 > h as i64
            || rect.size.0 == 0
            || rect.size.1 == 0
        {
            return Err(invalid("block outside the data window"));
        }
        if !seen.insert((coords.tile_index.0, coords.tile_index.1)) {
            continue; // the same block twice: keep the first
        }
        let expected_len =
            block_byte_len(header, rect).ok_or_else(|| invalid("block size overflows"))?;
        pending.push(PendingBlock {
            rect,
            data,
            expected_len,
        });
    }
    if pending.len() != expected_blocks {
        return Err(invalid(format!(
            "{} of {expected_blocks} pixel blocks are missing",
            expected_blocks - pending.len().min(expected_blocks)
        )));
    }
    Ok(pending)
}

/// What is left of the memory budget for decompression once the planes are counted.
#[derive(Debug)]
struct Budget<'a> {
    limits: &'a Limits,
    /// Bytes available for the blocks in flight (compressed copy and decompressed block).
    spare: u64,
    /// Whether the blocks are decompressed by [`zip_block`] (an inflated block and a
    /// reconstructed one in flight) rather than by the `exr` crate (a copy of the
    /// compressed bytes and a decompressed block).
    zip: bool,
}

impl Budget<'_> {
    /// The longest prefix of `blocks` (at most [`BATCH`]) whose compressed copies and
    /// decompressed blocks fit in the spare budget; an error when not even the first does.
    /// The `exr` crate allocates a decompressed block in full before reading its data, so
    /// this check is what keeps a hostile block size from aborting the process.
    fn batch<'b, 'c>(&self, blocks: &'b [PendingBlock<'c>]) -> Result<&'b [PendingBlock<'c>]> {
        let cost = |b: &PendingBlock<'_>| {
            let first = if self.zip {
                b.expected_len as u64
            } else {
                b.data.len() as u64
            };
            b.expected_len as u64 + first
        };
        let mut total = 0u64;
        let mut count = 0usize;
        for b in blocks.iter().take(BATCH) {
            if total + cost(b) > self.spare {
                break;
            }
            total += cost(b);
            count += 1;
        }
        if count == 0 {
            let first = &blocks[0];
            self.limits.check_memory(
                &format!(
                    "the decoded planes and one decompressed block of {}x{} pixels",
                    first.rect.size.0, first.rect.size.1
                ),
                Some(cost(first) + (self.limits.max_memory_bytes - self.spare)),
            )?;
        }
        Ok(&blocks[..count.max(1)])
    }
}

/// Map `f` over `items`, in parallel with the `rayon` feature.
fn map_items<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync + Send) -> Vec<R> {
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        items.par_iter().map(f).collect()
    }
    #[cfg(not(feature = "rayon"))]
    {
        items.iter().map(f).collect()
    }
}

/// Map `f` over `items` mutably, in parallel with the `rayon` feature.
fn map_items_mut<T: Send, R: Send>(
    items: &mut [T],
    f: impl Fn(&mut T) -> R + Sync + Send,
) -> Vec<R> {
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        items.par_iter_mut().map(f).collect()
    }
    #[cfg(not(feature = "rayon"))]
    {
        items.iter_mut().map(f).collect()
    }
}

/// The planes read from the blocks, and whether they already hold XYZ.
#[derive(Debug)]
struct Planes {
    /// One per channel of [`Layout::channels`], each at the channel's own resolution.
    planes: Vec<Vec<f32>>,
    /// Whether the RGB→XYZ conversion (with the `whiteLuminance` scale) was applied to
    /// each block as it was copied out (only for [`Layout::Rgb`] with all three channels).
    xyz: bool,
}

/// The `whiteLuminance` scale of a part (1 when absent or unusable).
fn white_scale(header: &Header) -> f64 {
    header
        .own_attributes
        .white_luminance
        .filter(|v| v.is_finite() && *v > 0.0)
        .map_or(1.0, f64::from)
}

/// Decompress every block and copy the samples of the layout's channels into planes (one
/// per channel of [`Layout::channels`], each at the channel's own resolution). RGB
/// converted to XYZ on the way is multiplied by `factor` as well as `whiteLuminance`.
///
/// Scan-line parts (every block the full width, the common case of rendered frames) are
/// decompressed and copied out in parallel, block by block, each block's rows straight
/// into its own rows of the planes (converted to XYZ there as well when the layout is
/// RGB); tiled parts are decompressed in parallel and copied out on the calling thread.
/// Either way the planes are allocated only once the first block has decompressed (most
/// damaged files fail on it), and the first error in block order is the one reported.
fn decompress_and_scatter(
    header: &Header,
    layout: &Layout,
    pending: &[PendingBlock<'_>],
    budget: &Budget<'_>,
    factor: f64,
    spare: &mut Vec<Vec<f32>>,
) -> Result<Planes> {
    let used = layout.channels();
    let (w, h) = (header.layer_size.0, header.layer_size.1);

    // The exr crate sizes a block as `area × bytes_per_pixel`, which is wrong for
    // subsampled channels; give it a header copy whose bytes_per_pixel makes that product
    // the true size (its PIZ, RLE and ZIP decoders handle subsampled lines correctly).
    let subsampled = header
        .channels
        .list
        .iter()
        .any(|c| c.sampling != Vec2(1, 1));
    let mut patched: Vec<(usize, Header)> = Vec::new();
    if subsampled {
        for block in pending {
            let area = block.rect.size.0 * block.rect.size.1;
            if !block.expected_len.is_multiple_of(area) {
                return Err(Error::Unsupported(
                    "OpenEXR subsampled block whose size is not a whole number of bytes per pixel"
                        .into(),
                ));
            }
            let bpp = block.expected_len / area;
            if !patched.iter().any(|(b, _)| *b == bpp) {
                let mut copy = header.clone();
                copy.channels.bytes_per_pixel = bpp;
                patched.push((bpp, copy));
            }
        }
    }
    let header_for = |block: &PendingBlock<'_>| -> &Header {
        if subsampled {
            let bpp = block.expected_len / (block.rect.size.0 * block.rect.size.1);
            &patched
                .iter()
                .find(|(b, _)| *b == bpp)
                .expect("patched above")
                .1
        } else {
            header
        }
    };
    let ours = zip_is_ours(header.compression);
    let decompress = |block: &PendingBlock<'_>| -> Result<Vec<u8>> {
        if ours {
            let mut out = Vec::new();
            zip_block(block.data, block.expected_len, &mut out)?;
            return Ok(out);
        }
        exr_block(header_for(block), block)
    };
    // A block's bytes handed to `f`: ZIP/ZIPS blocks decompressed into this thread's reused
    // buffer, the others through `decompress`.
    let with_block = |block: &PendingBlock<'_>, f: &mut dyn FnMut(&[u8]) -> Result<()>| {
        if ours {
            let mut out = ZIP_BUFFER.with(std::cell::Cell::take);
            let result = zip_block(block.data, block.expected_len, &mut out).and_then(|()| f(&out));
            if out.capacity() <= MAX_KEPT_BUFFER {
                ZIP_BUFFER.with(|b| b.set(out));
            }
            result
        } else {
            f(&decompress(block)?)
        }
    };
    // Every sample of every plane is written: the blocks, checked in `collect_blocks`,
    // cover the data window exactly. So a reused plane is only resized, not cleared.
    let mut allocate = || -> Vec<Vec<f32>> {
        used.iter()
            .map(|&i| {
                let s = header.channels.list[i].sampling;
                let len = (w / s.0.max(1)) * (h / s.1.max(1));
                match spare.iter().position(|p| p.capacity() >= len) {
                    Some(k) => {
                        let mut plane = spare.swap_remove(k);
                        plane.resize(len, 0.0);
                        plane
                    }
                    // Zeroed allocation: pages are mapped lazily, no memset.
                    None => vec![0.0f32; len],
                }
            })
            .collect()
    };

    let full_width_lines = header.blocks == BlockDescription::ScanLines
        && pending
            .iter()
            .all(|b| b.rect.position.0 == 0 && b.rect.size.0 == w);
    if !full_width_lines {
        let mut planes: Vec<Vec<f32>> = Vec::new();
        let mut rest = pending;
        while !rest.is_empty() {
            let batch = budget.batch(rest)?;
            rest = &rest[batch.len()..];
            let decoded = map_items(batch, decompress);
            if planes.is_empty() {
                planes = allocate();
            }
            let mut whole: Vec<&mut [f32]> = planes.iter_mut().map(|p| &mut p[..]).collect();
            let origin = vec![0usize; whole.len()];
            for (block, data) in batch.iter().zip(decoded) {
                scatter(header, &used, block.rect, &data?, &mut whole, &origin)?;
            }
        }
        return Ok(Planes { planes, xyz: false });
    }

    // RGB is converted to XYZ block by block when all three channels are there at full
    // resolution and the matrix is usable (otherwise `to_hdr` converts, or reports the
    // degenerate `chromaticities`, as before).
    let matrix = match *layout {
        Layout::Rgb {
            r: Some(_),
            g: Some(_),
            b: Some(_),
        } if !subsampled => file_matrix(header).ok(),
        _ => None,
    };
    let scale = white_scale(header) * factor;
    let fill = |block: &PendingBlock<'_>,
                data: &[u8],
                dst: &mut [&mut [f32]],
                origin: &[usize]|
     -> Result<()> {
        scatter(header, &used, block.rect, data, dst, origin)?;
        if let (Some(m), [r, g, b]) = (&matrix, dst) {
            rgb_to_xyz(Isa::detect(), m, scale, r, g, b);
        }
        Ok(())
    };

    // The first block alone, before anything image-sized is allocated.
    if pending.is_empty() {
        return Ok(Planes {
            planes: Vec::new(),
            xyz: false,
        });
    }
    let first_data = decompress(&budget.batch(&pending[..1])?[0])?;
    let mut planes = allocate();

    // Each block's rows of every plane, as disjoint slices: the blocks in the order of their
    // rows, each plane cut along them.
    let mut order: Vec<usize> = (0..pending.len()).collect();
    order.sort_by_key(|&i| pending[i].rect.position.1);
    let mut jobs: Vec<(Vec<&mut [f32]>, Vec<usize>)> = (0..pending.len())
        .map(|_| (Vec::new(), Vec::new()))
        .collect();
    for (pi, plane) in planes.iter_mut().enumerate() {
        let s = header.channels.list[used[pi]].sampling;
        let (sx, sy) = (s.0.max(1), s.1.max(1));
        let plane_w = w / sx;
        let mut rest: &mut [f32] = plane;
        let mut consumed = 0usize;
        for &bi in &order {
            let rect = pending[bi].rect;
            let y0 = rect.position.1 as usize;
            let (r0, r1) = (y0.div_ceil(sy), (y0 + rect.size.1).div_ceil(sy));
            let (start, end) = (r0 * plane_w, r1 * plane_w);
            if start < consumed || end - consumed > rest.len() {
                return Err(invalid("overlapping pixel blocks"));
            }
            let (_, tail) = std::mem::take(&mut rest).split_at_mut(start - consumed);
            let (mine, tail) = tail.split_at_mut(end - start);
            rest = tail;
            consumed = end;
            jobs[bi].0.push(mine);
            jobs[bi].1.push(start);
        }
    }

    {
        let (dst, origin) = &mut jobs[0];
        fill(&pending[0], &first_data, dst, origin)?;
    }
    drop(first_data);
    let (mut blocks, mut slots) = (&pending[1..], &mut jobs[1..]);
    while !blocks.is_empty() {
        let count = budget.batch(blocks)?.len();
        let (batch, rest) = blocks.split_at(count);
        let (batch_slots, rest_slots) = std::mem::take(&mut slots).split_at_mut(count);
        let mut work: Vec<_> = batch.iter().zip(batch_slots.iter_mut()).collect();
        let results = map_items_mut(&mut work, |(block, (dst, origin))| -> Result<()> {
            with_block(block, &mut |data| fill(block, data, dst, origin))
        });
        results.into_iter().collect::<Result<()>>()?;
        (blocks, slots) = (rest, rest_slots);
    }
    drop(jobs);
    Ok(Planes {
        planes,
        xyz: matrix.is_some(),
    })
}

/// Decompress one block with the `exr` crate (`header` with the true bytes per pixel of
/// the block, see `decompress_and_scatter`).
fn exr_block(header: &Header, block: &PendingBlock<'_>) -> Result<Vec<u8>> {
    let data = foreign(|| {
        header
            .compression
            .decompress_image_section_from_le(header, block.data.to_vec(), block.rect, false)
            .map_err(exr_error)
    })?;
    if data.len() != block.expected_len {
        return Err(invalid("decompressed block has the wrong size"));
    }
    Ok(data)
}

/// Whether blocks of `compression` are decompressed by [`zip_block`] rather than by the
/// `exr` crate: ZIP (16 lines) and ZIPS (one line), on little-endian machines (the file's
/// byte order, so the reconstructed bytes are the native samples as they stand).
fn zip_is_ours(compression: exr::compression::Compression) -> bool {
    use exr::compression::Compression::{ZIP1, ZIP16};
    cfg!(target_endian = "little") && matches!(compression, ZIP1 | ZIP16)
}

thread_local! {
    /// This thread's buffer for the reconstructed bytes of ZIP blocks (see
    /// [`zip_block`]), reused from block to block and from frame to frame.
    static ZIP_BUFFER: std::cell::Cell<Vec<u8>> = const { std::cell::Cell::new(Vec::new()) };
}

/// Largest buffer [`ZIP_BUFFER`] keeps between blocks, bytes. Our choice: well above a
/// 4K ZIP block (3840 × 16 lines × 4 half channels = 480 KiB), so the frames of a video
/// never reallocate it, while a huge block of a damaged or unusual file is not held on to.
const MAX_KEPT_BUFFER: usize = 4 << 20;

/// Largest ratio of inflated to compressed bytes a deflate stream can reach: 1032:1, a
/// 258-byte match (RFC 1951 §3.2.5, the longest length) per two bits of codes (zlib's
/// "Technical Details", Mark Adler: "the limit is 1032:1").
const DEFLATE_MAX_RATIO: usize = 1032;

/// Whether a zlib stream of `compressed_len` bytes could inflate to `expected_len`: not
/// when that is more than [`DEFLATE_MAX_RATIO`] times as long. Checked before the
/// inflater's buffer is grown, so that a damaged header claiming a huge block over a few
/// bytes of data costs no more than those bytes.
fn could_inflate_to(compressed_len: usize, expected_len: usize) -> bool {
    expected_len <= compressed_len.saturating_mul(DEFLATE_MAX_RATIO)
}

/// This thread's inflater and its output buffer, reused from block to block (see
/// [`zip_block`]): libdeflate's decompressor state (about 10 KiB) is allocated once per
/// thread, and the buffer is grown, never cleared, as libdeflate writes every byte it
/// reports.
#[derive(Default)]
struct Inflater {
    decompressor: Option<libdeflater::Decompressor>,
    inflated: Vec<u8>,
}

thread_local! {
    static INFLATER: std::cell::RefCell<Inflater> = std::cell::RefCell::default();
}

/// Decompress one ZIP or ZIPS block (OpenEXR `ImfZip.cpp`, `Zip::uncompress`) into `out`,
/// resized to `expected_len`: the bytes as they stand when the block is stored
/// uncompressed (its compressed form was no smaller, OpenEXR file layout), else the zlib
/// stream inflated by libdeflate into this thread's [`Inflater`] (the Adler-32 checksum
/// checked; a stream of any other length than `expected_len` is an error), then
/// [`reconstruct`]. The same bytes as the `exr` crate's `zip::decompress_bytes`, without
/// its copies and allocations. libdeflate inflates a whole stream into a buffer of known
/// size, which is what a block is; measured on the 68 blocks of a 1080p half-float frame
/// of the `video` bench's sequence, nine rounds in turn on one thread: 0.60–0.68× the time
/// of zune-inflate 0.2.54, the inflater used before (the `exr` crate's).
///
/// A stream too short to hold `expected_len` bytes ([`could_inflate_to`]) is refused
/// before any buffer is grown, so a damaged header that claims a huge block over a few
/// bytes of data costs no more than those bytes.
fn zip_block(data: &[u8], expected_len: usize, out: &mut Vec<u8>) -> Result<()> {
    if data.len() == expected_len {
        out.clear();
        out.extend_from_slice(data);
        return Ok(());
    }
    let wrong_size = || invalid("decompressed block has the wrong size");
    if !could_inflate_to(data.len(), expected_len) {
        return Err(wrong_size());
    }
    INFLATER.with(|cell| {
        let Inflater {
            decompressor,
            inflated,
        } = &mut *cell.borrow_mut();
        if inflated.len() < expected_len {
            inflated.resize(expected_len, 0);
        }
        let target = &mut inflated[..expected_len];
        // The inflater is foreign code on file data: guarded as the exr crate is. A stream
        // longer than the block fails for want of space; a shorter one is counted.
        let inflater = decompressor.get_or_insert_with(libdeflater::Decompressor::new);
        let written = foreign(|| {
            inflater.zlib_decompress(data, target).map_err(|e| match e {
                libdeflater::DecompressionError::InsufficientSpace => wrong_size(),
                libdeflater::DecompressionError::BadData => {
                    invalid("ZIP-compressed block is malformed")
                }
            })
        })?;
        if written != expected_len {
            return Err(wrong_size());
        }
        // Grown, never cleared: every byte is overwritten by `reconstruct`.
        out.resize(expected_len, 0);
        reconstruct(target, out);
        if inflated.capacity() > MAX_KEPT_BUFFER {
            *inflated = Vec::new();
        }
        Ok(())
    })
}

/// Undo OpenEXR's ZIP preprocessing (`ImfZip.cpp`, `Zip::uncompress`): the predictor
/// (`t[0] = d[0]`, `t[i] = t[i−1] + d[i] − 128`, wrapping bytes) and the split of the
/// bytes into two halves (`out[2k] = t[k]`, `out[2k+1] = t[h+k]`, `h = ⌈n/2⌉`), in one
/// pass: two running sums, one through each half, the second started from the sum over
/// the whole first half (a separate pass that vectorises), 16 bytes of each at a time
/// where the processor allows ([`simd::exr_unpredict_pairs`]). `src` and `dst` have the
/// same length.
fn reconstruct(src: &[u8], dst: &mut [u8]) {
    let n = src.len();
    debug_assert_eq!(dst.len(), n);
    if n == 0 {
        return;
    }
    let (first, second) = src.split_at(n.div_ceil(2));
    // t[h−1] = d[0] + Σ_{i=1}^{h−1} (d[i] − 128): the byte sum minus (h − 1)·128.
    let sum = first.iter().fold(0u8, |s, &v| s.wrapping_add(v));
    let odd_count = ((first.len() - 1) & 1) as u8;
    let b = sum.wrapping_sub(odd_count.wrapping_mul(128));
    // t[−1] taken as 128, so that t[0] = d[0].
    let (done, mut a, mut b) = simd::exr_unpredict_pairs(first, second, 0x80, b, dst);
    for k in done..second.len() {
        a = a.wrapping_add(first[k] ^ 0x80);
        b = b.wrapping_add(second[k] ^ 0x80);
        dst[2 * k] = a;
        dst[2 * k + 1] = b;
    }
    if n % 2 == 1 {
        dst[n - 1] = a.wrapping_add(first[first.len() - 1] ^ 0x80);
    }
}

/// Convert one line of `count` samples of type `ty` (native endian) into `dst`.
fn convert_line(ty: SampleType, src: &[u8], dst: &mut [f32]) {
    match ty {
        SampleType::F16 => {
            use half::slice::{HalfBitsSliceExt, HalfFloatSliceExt};
            // In pieces through a small buffer of bits (the bytes need not be aligned),
            // converted by the `half` crate's slice conversion (F16C when the CPU has it).
            // Every f16 is exactly an f32: the result is the sample-by-sample one.
            const PIECE: usize = 256;
            let mut bits = [0u16; PIECE];
            for (d, s) in dst.chunks_mut(PIECE).zip(src.chunks(2 * PIECE)) {
                let b = &mut bits[..d.len()];
                for (v, pair) in b.iter_mut().zip(s.chunks_exact(2)) {
                    *v = u16::from_ne_bytes([pair[0], pair[1]]);
                }
                b.reinterpret_cast::<half::f16>().convert_to_f32_slice(d);
            }
        }
        SampleType::F32 => {
            for (d, s) in dst.iter_mut().zip(src.chunks_exact(4)) {
                *d = f32::from_ne_bytes([s[0], s[1], s[2], s[3]]);
            }
        }
        SampleType::U32 => {
            for (d, s) in dst.iter_mut().zip(src.chunks_exact(4)) {
                *d = u32::from_ne_bytes([s[0], s[1], s[2], s[3]]) as f32;
            }
        }
    }
}

/// Copy the samples of the `used` channels from one decompressed block (lines in order,
/// each line holding every channel's samples in channel-list order, native endian) into
/// `planes`, where `planes[p]` starts at sample `origin[p]` of plane `p` (0 for a whole
/// plane, the first sample of the block's rows for a block's own slice).
fn scatter(
    header: &Header,
    used: &[usize],
    rect: IntegerBounds,
    data: &[u8],
    planes: &mut [&mut [f32]],
    origin: &[usize],
) -> Result<()> {
    let short = || invalid("decompressed block is too short");
    let (x0, y0) = (rect.position.0 as usize, rect.position.1 as usize);
    let mut pos = 0usize;
    for y in y0..y0 + rect.size.1 {
        for (ci, c) in header.channels.list.iter().enumerate() {
            let (sx, sy) = (c.sampling.0.max(1), c.sampling.1.max(1));
            if !y.is_multiple_of(sy) {
                continue;
            }
            let count = rect.size.0 / sx;
            let size = c.sample_type.bytes_per_sample();
            let src = data.get(pos..pos + count * size).ok_or_else(short)?;
            pos += count * size;
            let Some(p) = used.iter().position(|&u| u == ci) else {
                continue;
            };
            let plane_w = header.layer_size.0 / sx;
            let start = ((y / sy) * plane_w + x0 / sx)
                .checked_sub(origin[p])
                .ok_or_else(short)?;
            let dst = planes[p].get_mut(start..start + count).ok_or_else(short)?;
            convert_line(c.sample_type, src, dst);
        }
    }
    if pos != data.len() {
        return Err(invalid("decompressed block has trailing bytes"));
    }
    Ok(())
}

/// The RGB→XYZ matrix of a file's `chromaticities` (Rec. 709 when absent).
fn file_matrix(header: &Header) -> Result<Mat3> {
    let c = match header.shared_attributes.chromaticities {
        Some(c) => {
            let xy = |v: Vec2<f32>| [f64::from(v.0), f64::from(v.1)];
            Chromaticities {
                red: xy(c.red),
                green: xy(c.green),
                blue: xy(c.blue),
                white: xy(c.white),
            }
        }
        None => REC709,
    };
    c.rgb_to_xyz()
        .ok_or_else(|| invalid("degenerate chromaticities attribute"))
}

/// The scene white of a part: its `adoptedNeutral` ("pixels whose (x, y) match the
/// adoptedNeutral value should be mapped to neutral values on the display", OpenEXR
/// `ImfStandardAttributes.h`), else the white of its `chromaticities` (D65 when absent), and
/// for the paper's X/Y/Z layout, to which `chromaticities` does not apply, the paper's
/// equal-energy illuminant (Sec. 5). `None` if the value found is not a usable white.
fn adopted_white(header: &Header, layout: &Layout) -> Option<colour::Xy> {
    let xy = |v: Vec2<f32>| [f64::from(v.0), f64::from(v.1)];
    let white = match (header.own_attributes.adopted_neutral, layout) {
        (Some(n), _) => xy(n),
        (None, Layout::Xyz { .. }) => colour::EQUAL_ENERGY,
        (None, _) => header
            .shared_attributes
            .chromaticities
            .map_or(REC709.white, |c| xy(c.white)),
    };
    colour::is_valid_white(white).then_some(white)
}

/// Reconstruct a full-resolution chroma plane from one subsampled `sx × sy` (each 1 or 2)
/// with OpenEXR's filter: samples sit on even pixels, odd pixels are interpolated.
fn upsample_chroma(src: &[f32], w: usize, h: usize, sx: usize, sy: usize) -> Vec<f32> {
    // Along one axis: `n` samples at even positions → `2n` values.
    fn axis(samples: &[f32], out: &mut [f32]) {
        let n = samples.len() as isize;
        let at = |j: isize| samples[j.clamp(0, n - 1) as usize];
        for (x, o) in out.iter_mut().enumerate() {
            if x.is_multiple_of(2) {
                *o = samples[x / 2];
            } else {
                // Offsets −13, −11, …, +13 from odd x hit the samples (x−13)/2 … (x+13)/2
                // (x − 13 is even, so the division is exact, also below zero).
                let first = (x as isize - 13) / 2;
                *o = CHROMA_FILTER
                    .iter()
                    .enumerate()
                    .map(|(k, wgt)| wgt * at(first + k as isize))
                    .sum();
            }
        }
    }
    let cw = w / sx;
    // Horizontal pass: cw × (h/sy) → w × (h/sy).
    let rows = h / sy;
    let mut horiz = vec![0.0f32; w * rows];
    for r in 0..rows {
        let line = &src[r * cw..(r + 1) * cw];
        let out = &mut horiz[r * w..(r + 1) * w];
        if sx == 1 {
            out.copy_from_slice(line);
        } else {
            axis(line, out);
        }
    }
    if sy == 1 {
        return horiz;
    }
    // Vertical pass: w × rows → w × h.
    let mut full = vec![0.0f32; w * h];
    let mut column = vec![0.0f32; rows];
    let mut column_out = vec![0.0f32; h];
    for x in 0..w {
        for (r, c) in column.iter_mut().enumerate() {
            *c = horiz[r * w + x];
        }
        axis(&column, &mut column_out);
        for (y, v) in column_out.iter().enumerate() {
            full[y * w + x] = *v;
        }
    }
    full
}

/// The view of [`VIEW_ATTRIBUTE`], if the part has one.
fn read_view(header: &Header) -> Result<Option<crate::View>> {
    use exr::meta::attribute::{AttributeValue, Text};
    let name = Text::new_or_panic(VIEW_ATTRIBUTE);
    match header.own_attributes.other.get(&name) {
        None => Ok(None),
        Some(AttributeValue::Text(t)) => {
            let view = super::radiance::parse_view_options(&t.to_string(), FORMAT)?;
            Ok(Some(view))
        }
        Some(_) => Err(Error::decode(
            FORMAT,
            format!("the {VIEW_ATTRIBUTE} attribute is not a string"),
        )),
    }
}

/// [`colour::rgb_planes_to_xyz`] over the planes in pieces, in parallel with the `rayon`
/// feature (each sample on its own: the same result as one call).
fn rgb_planes_to_xyz_parallel(m: &Mat3, scale: f64, r: &mut [f32], g: &mut [f32], b: &mut [f32]) {
    /// Samples per piece: our choice, large enough to make the per-piece cost negligible.
    const PIECE: usize = 1 << 14;
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        r.par_chunks_mut(PIECE)
            .zip(g.par_chunks_mut(PIECE))
            .zip(b.par_chunks_mut(PIECE))
            .for_each(|((r, g), b)| rgb_to_xyz(Isa::detect(), m, scale, r, g, b));
    }
    #[cfg(not(feature = "rayon"))]
    {
        let _ = PIECE;
        rgb_to_xyz(Isa::detect(), m, scale, r, g, b);
    }
}

/// [`colour::rgb_planes_to_xyz`] compiled for the instruction set `isa` (the widest
/// vectors the processor has, [`Isa::detect`]): the same `f64` operations in the same
/// order, without fused multiply-adds, so the same results bit for bit, two to four times
/// as many pixels per instruction as the baseline (SSE2) build.
fn rgb_to_xyz(isa: Isa, m: &Mat3, scale: f64, r: &mut [f32], g: &mut [f32], b: &mut [f32]) {
    // Results are the same at every level bit for bit except NaN payloads: a vector build may take an addition's operands in the other
    // order, and IEEE 754 leaves open which NaN comes out (every NaN is still a NaN).
    crate::simd::at_level!(isa, rgb_to_xyz_kernel(m, scale, r, g, b));
}

/// The loop of [`rgb_to_xyz`], inlined into each instruction set's build.
#[inline(always)]
fn rgb_to_xyz_kernel(m: &Mat3, scale: f64, r: &mut [f32], g: &mut [f32], b: &mut [f32]) {
    let k = [
        m[0][0] * scale,
        m[0][1] * scale,
        m[0][2] * scale,
        m[1][0] * scale,
        m[1][1] * scale,
        m[1][2] * scale,
        m[2][0] * scale,
        m[2][1] * scale,
        m[2][2] * scale,
    ];
    // `saturating_f32` without its branch: clamping leaves NaN as it is, and infinities
    // are kept.
    let max = f64::from(f32::MAX);
    let saturate = |v: f64| {
        (if v.is_infinite() {
            v
        } else {
            v.clamp(-max, max)
        }) as f32
    };
    let len = r.len().min(g.len()).min(b.len());
    let (r, g, b) = (&mut r[..len], &mut g[..len], &mut b[..len]);
    for i in 0..len {
        let (cr, cg, cb) = (f64::from(r[i]), f64::from(g[i]), f64::from(b[i]));
        r[i] = saturate(k[0] * cr + k[1] * cg + k[2] * cb);
        g[i] = saturate(k[3] * cr + k[4] * cg + k[5] * cb);
        b[i] = saturate(k[6] * cr + k[7] * cg + k[8] * cb);
    }
}

/// Build the [`HdrImage`] from the planes of `layout`, the values converted to XYZ times
/// `factor` (XYZ planes are taken as they are).
fn to_hdr(
    header: &Header,
    layout: &Layout,
    planes: Planes,
    factor: f64,
    width: usize,
    height: usize,
) -> Result<HdrImage> {
    let n = width * height;
    let Planes { mut planes, xyz } = planes;
    let white_luminance = header
        .own_attributes
        .white_luminance
        .filter(|v| v.is_finite() && *v > 0.0);
    let scale = white_scale(header) * factor;
    let mut image = HdrImage {
        width,
        height,
        x: Vec::new(),
        y: Vec::new(),
        z: Vec::new(),
        scotopic: None,
        view: read_view(header)?,
        absolute_units: white_luminance.is_some(),
        adopted_white: adopted_white(header, layout),
    };
    match *layout {
        Layout::Xyz { scotopic, .. } => {
            if scotopic.is_some() {
                image.scotopic = planes.pop();
            }
            image.z = planes.pop().unwrap_or_default();
            image.y = planes.pop().unwrap_or_default();
            image.x = planes.pop().unwrap_or_default();
            image.absolute_units = true;
        }
        Layout::Grey { .. } => {
            let m = file_matrix(header)?;
            // Row sums of the matrix: the XYZ of RGB (1,1,1), i.e. the white point with Y = 1.
            let wx = m[0].iter().sum::<f64>();
            let wz = m[2].iter().sum::<f64>();
            let l = planes.pop().unwrap_or_default();
            image.x = l
                .iter()
                .map(|&v| saturating_f32(f64::from(v) * scale * wx))
                .collect();
            image.z = l
                .iter()
                .map(|&v| saturating_f32(f64::from(v) * scale * wz))
                .collect();
            image.y = l;
            if scale != 1.0 {
                image
                    .y
                    .iter_mut()
                    .for_each(|v| *v = saturating_f32(f64::from(*v) * scale));
            }
        }
        Layout::Rgb { r, g, b } => {
            let m = file_matrix(header)?;
            let mut it = planes.into_iter();
            let mut take = |present: Option<usize>| {
                present
                    .and_then(|_| it.next())
                    .unwrap_or_else(|| vec![0.0; n])
            };
            let (mut pr, mut pg, mut pb) = (take(r), take(g), take(b));
            if !xyz {
                rgb_planes_to_xyz_parallel(&m, scale, &mut pr, &mut pg, &mut pb);
            }
            (image.x, image.y, image.z) = (pr, pg, pb);
        }
        Layout::Yca { ry, by, .. } => {
            let m = file_matrix(header)?;
            let (sry, sby) = (
                header.channels.list[ry].sampling,
                header.channels.list[by].sampling,
            );
            let mut it = planes.into_iter();
            let luminance = it.next().unwrap_or_default();
            let pry = it.next().unwrap_or_default();
            let pby = it.next().unwrap_or_default();
            let mut cr = upsample_chroma(&pry, width, height, sry.0, sry.1);
            let mut cb = upsample_chroma(&pby, width, height, sby.0, sby.1);
            // ImfRgbaYca computeYw: the Y row of the matrix, normalised to sum 1.
            let sum: f64 = m[1].iter().sum();
            let yw = [m[1][0] / sum, m[1][1] / sum, m[1][2] / sum];
            let mut lum = luminance;
            for ((l, r), b) in lum.iter_mut().zip(cr.iter_mut()).zip(cb.iter_mut()) {
                let yv = f64::from(*l);
                let (rr, bb) = (f64::from(*r), f64::from(*b));
                let (red, green, blue) = if rr == 0.0 && bb == 0.0 {
                    (yv, yv, yv)
                } else {
                    let red = (rr + 1.0) * yv;
                    let blue = (bb + 1.0) * yv;
                    (red, (yv - red * yw[0] - blue * yw[2]) / yw[1], blue)
                };
                // Reuse the planes: r ← R, l ← G, b ← B.
                (*r, *l, *b) = (red as f32, green as f32, blue as f32);
            }
            colour::rgb_planes_to_xyz(&m, scale, &mut cr, &mut lum, &mut cb);
            (image.x, image.y, image.z) = (cr, lum, cb);
        }
    }
    image
        .check_consistent()
        .map_err(|_| invalid("inconsistent planes"))?;
    Ok(image)
}

// ------------------------------------------------------------------------------------------
// Writing
// ------------------------------------------------------------------------------------------

/// Rec. 709 as an OpenEXR `chromaticities` attribute.
fn rec709_attribute() -> exr::meta::attribute::Chromaticities {
    let v = |p: colour::Xy| Vec2(p[0] as f32, p[1] as f32);
    exr::meta::attribute::Chromaticities {
        red: v(REC709.red),
        green: v(REC709.green),
        blue: v(REC709.blue),
        white: v(REC709.white),
    }
}

/// Bytes of uncompressed pixel data the writers aim to put in one block (chunk). Our
/// choice: large enough that the per-chunk cost (a header, an offset-table entry and one
/// compression call each) is negligible, small enough that blocks compress in parallel and
/// a reader holds little per block. The OpenEXR library's default 64 × 64 tiles of four
/// half channels are 32 KiB.
pub const BLOCK_BYTES: usize = 64 << 10;

/// Scan lines of fewer bytes than this are grouped into tiles instead (RLE stores one
/// scan line per chunk, OpenEXR file layout, "Scan line-based images": a 1-pixel-wide
/// image would take one chunk per pixel). Our choice.
pub const MIN_LINE_BYTES: usize = 4 << 10;

/// How a written image is divided into blocks: ordinary images (a scan line of
/// [`MIN_LINE_BYTES`] to 16 × [`BLOCK_BYTES`]) in scan lines, one per chunk as RLE
/// stores them; narrower or much wider ones in tiles of at most [`BLOCK_BYTES`] (the full
/// width, or as many pixels of a row as fit, by as many rows as fit). Chosen by bytes, not
/// lines, so the chunk count stays about `width × height × bytes_per_pixel /
/// BLOCK_BYTES` whatever the shape: a 1 × 4194304 RGB image is 769 chunks, not 4194304.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockLayout {
    /// One scan line per chunk.
    ScanLines,
    /// Tiles of `width × height` pixels (edge tiles are cut to the image).
    Tiles {
        /// Tile width in pixels.
        width: usize,
        /// Tile height in pixels.
        height: usize,
    },
}

impl BlockLayout {
    /// The layout for a `width × height` image of `bytes_per_pixel` bytes per pixel.
    pub fn for_image(width: usize, height: usize, bytes_per_pixel: usize) -> Self {
        let bpp = bytes_per_pixel.max(1);
        let line = width.saturating_mul(bpp);
        // Small images keep scan lines: they have few chunks whatever the layout.
        let small = line.saturating_mul(height) <= BLOCK_BYTES;
        if small || (MIN_LINE_BYTES..=16 * BLOCK_BYTES).contains(&line) {
            return BlockLayout::ScanLines;
        }
        let tile_width = width.clamp(1, (BLOCK_BYTES / bpp).max(1));
        let tile_height = height.clamp(1, (BLOCK_BYTES / (tile_width * bpp)).max(1));
        BlockLayout::Tiles {
            width: tile_width,
            height: tile_height,
        }
    }

    /// The number of chunks a `width × height` image takes in this layout (RLE).
    pub fn chunk_count(self, width: usize, height: usize) -> usize {
        match self {
            BlockLayout::ScanLines => height,
            BlockLayout::Tiles {
                width: tw,
                height: th,
            } => width.div_ceil(tw) * height.div_ceil(th),
        }
    }
}

/// The attributes [`write_layer`] writes beside the channels (none by default).
#[derive(Default)]
struct LayerMeta<'a> {
    white_luminance: Option<f32>,
    chromaticities: Option<exr::meta::attribute::Chromaticities>,
    adopted_neutral: Option<colour::Xy>,
    view: Option<&'a crate::View>,
}

/// Write one layer of f32 channels `(name, samples)` (one, three or four), RLE, in blocks
/// chosen by [`BlockLayout::for_image`]. The samples are read where they are, not copied.
fn write_layer(
    width: usize,
    height: usize,
    channels: &[(&'static str, &[f32])],
    meta: LayerMeta<'_>,
    w: impl std::io::Write + std::io::Seek,
) -> Result<()> {
    use exr::prelude::*;
    let LayerMeta {
        white_luminance,
        chromaticities,
        adopted_neutral,
        view,
    } = meta;
    let mut attributes = LayerAttributes {
        white_luminance,
        adopted_neutral: adopted_neutral.map(|[x, y]| Vec2(x as f32, y as f32)),
        ..LayerAttributes::default()
    };
    if let Some(v) = view {
        attributes.other.insert(
            Text::new_or_panic(VIEW_ATTRIBUTE),
            AttributeValue::Text(Text::new_or_panic(super::radiance::view_options(v))),
        );
    }
    let blocks = match BlockLayout::for_image(width, height, 4 * channels.len()) {
        BlockLayout::ScanLines => Blocks::ScanLines,
        BlockLayout::Tiles {
            width: tw,
            height: th,
        } => Blocks::Tiles(Vec2(tw, th)),
    };
    let encoding = Encoding {
        compression: Compression::RLE,
        blocks,
        line_order: LineOrder::Increasing,
    };
    let result = {
        // The same steps for each number of channels (each a different pixel type).
        macro_rules! write_with {
            ($channels:expr) => {{
                let layer = Layer::new((width, height), attributes, encoding, $channels);
                let mut image = Image::from_layer(layer);
                image.attributes.chromaticities = chromaticities;
                image.write().to_unbuffered(w)
            }};
        }
        let at = |p: &Vec2<usize>| p.1 * width + p.0;
        match *channels {
            [(n0, p0)] => write_with!(
                SpecificChannels::build()
                    .with_channel(n0)
                    .with_pixel_fn(|p| (p0[at(&p)],))
            ),
            [(n0, p0), (n1, p1), (n2, p2)] => write_with!(
                SpecificChannels::build()
                    .with_channel(n0)
                    .with_channel(n1)
                    .with_channel(n2)
                    .with_pixel_fn(|p| {
                        let i = at(&p);
                        (p0[i], p1[i], p2[i])
                    })
            ),
            [(n0, p0), (n1, p1), (n2, p2), (n3, p3)] => write_with!(
                SpecificChannels::build()
                    .with_channel(n0)
                    .with_channel(n1)
                    .with_channel(n2)
                    .with_channel(n3)
                    .with_pixel_fn(|p| {
                        let i = at(&p);
                        (p0[i], p1[i], p2[i], p3[i])
                    })
            ),
            _ => unreachable!("the writers pass one, three or four channels"),
        }
    };
    result.map_err(|e| match e {
        exr::error::Error::Io(io) => crate::Error::Io(io),
        other => crate::Error::Unsupported(format!("OpenEXR writer: {other}")),
    })
}

/// Check that `planes` each hold `width × height` samples and the size is non-zero.
fn check_planes(width: usize, height: usize, planes: &[&[f32]]) -> Result<()> {
    let n = width.checked_mul(height).unwrap_or(0);
    if n == 0 || planes.iter().any(|p| p.len() != n) {
        return Err(Error::invalid(
            "image",
            format!("{width}x{height}"),
            "planes must be non-empty and hold width*height samples",
        ));
    }
    Ok(())
}

/// Write a display image as an OpenEXR file: linear Rec. 709 R, G, B as 32-bit floats
/// (RLE), `chromaticities` = Rec. 709, `whiteLuminance` = `display_max_cd_m2`, so that
/// RGB (1, 1, 1) is the display maximum in cd/m².
pub fn write_display(image: &DisplayImage, w: impl std::io::Write + std::io::Seek) -> Result<()> {
    image.validate()?;
    let l = image.display_max_cd_m2;
    write_layer(
        image.width,
        image.height,
        &[("R", &image.r), ("G", &image.g), ("B", &image.b)],
        LayerMeta {
            white_luminance: Some(l),
            chromaticities: Some(rec709_attribute()),
            ..LayerMeta::default()
        },
        w,
    )
}

/// Write an HDR image in the paper's own layout: channels `X`, `Y`, `Z` (+ `scotopic` when
/// present) as 32-bit floats in cd/m² (scotopic cd/m²), RLE, with the image's adopted white
/// as `adoptedNeutral` when it has one other than E (the layout's own white) and its view in
/// [`VIEW_ATTRIBUTE`]. [`decode`] reads it back as an absolute image with the same adopted
/// white and view.
pub fn write_hdr(image: &HdrImage, w: impl std::io::Write + std::io::Seek) -> Result<()> {
    let mut planes: Vec<&[f32]> = vec![&image.x, &image.y, &image.z];
    if let Some(s) = &image.scotopic {
        planes.push(s);
    }
    check_planes(image.width, image.height, &planes)?;
    let mut channels: Vec<(&str, &[f32])> = vec![("X", &image.x), ("Y", &image.y), ("Z", &image.z)];
    if let Some(s) = &image.scotopic {
        channels.push(("scotopic", s));
    }
    write_layer(
        image.width,
        image.height,
        &channels,
        LayerMeta {
            // E is what the layout means without the attribute.
            adopted_neutral: image.adopted_white.filter(|w| *w != colour::EQUAL_ENERGY),
            view: image.view.as_ref(),
            ..LayerMeta::default()
        },
        w,
    )
}

/// Write one luminance plane in cd/m² (e.g. a [`visibility`](crate::visibility) tolerance
/// map) as a single-channel `Y` OpenEXR, 32-bit float, RLE, with `whiteLuminance` = 1 so
/// that [`decode`] reads it back as a grey image in absolute units.
pub fn write_luminance(
    width: usize,
    height: usize,
    y: &[f32],
    w: impl std::io::Write + std::io::Seek,
) -> Result<()> {
    check_planes(width, height, &[y])?;
    write_layer(
        width,
        height,
        &[("Y", y)],
        LayerMeta {
            white_luminance: Some(1.0),
            ..LayerMeta::default()
        },
        w,
    )
}

/// Write one plane of numbers that are not luminances (e.g. a
/// [`visibility`](crate::visibility) JND map) as a single-channel `Y` OpenEXR, 32-bit float,
/// RLE, without `whiteLuminance`: [`decode`] reads it back unchanged, as relative values.
pub fn write_plane(
    width: usize,
    height: usize,
    values: &[f32],
    w: impl std::io::Write + std::io::Seek,
) -> Result<()> {
    check_planes(width, height, &[values])?;
    write_layer(width, height, &[("Y", values)], LayerMeta::default(), w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chroma_filter_sums_to_one_and_keeps_constants() {
        let s: f32 = CHROMA_FILTER.iter().sum();
        assert!((s - 1.0).abs() < 1e-5, "{s}");
        let src = vec![0.25f32; 5 * 4];
        let up = upsample_chroma(&src, 10, 8, 2, 2);
        assert_eq!(up.len(), 80);
        assert!(up.iter().all(|v| (v - 0.25).abs() < 1e-5));
        // Even pixels keep their sample exactly.
        let ramp: Vec<f32> = (0..20).map(|i| i as f32).collect();
        let up = upsample_chroma(&ramp, 10, 8, 2, 2);
        assert_eq!(up[0], 0.0);
        assert_eq!(up[2 * 10 + 4], ramp[5 + 2]);
    }

    #[test]
    fn classify_rules() {
        let names = |v: &[&str]| -> Vec<(String, usize)> {
            v.iter()
                .enumerate()
                .map(|(i, n)| (n.to_string(), i))
                .collect()
        };
        assert_eq!(
            classify(&names(&["A", "B", "G", "R"])),
            Some(Layout::Rgb {
                r: Some(3),
                g: Some(2),
                b: Some(1)
            })
        );
        assert_eq!(classify(&names(&["G"])), Some(Layout::Grey { l: 0 }));
        assert_eq!(
            classify(&names(&["BY", "RY", "Y"])),
            Some(Layout::Yca { y: 2, ry: 1, by: 0 })
        );
        assert_eq!(
            classify(&names(&["X", "Y", "Z", "scotopic"])),
            Some(Layout::Xyz {
                x: 0,
                y: 1,
                z: 2,
                scotopic: Some(3)
            })
        );
        assert_eq!(
            classify(&names(&["depth.Z", "diffuse.B", "diffuse.G", "diffuse.R"])),
            Some(Layout::Rgb {
                r: Some(3),
                g: Some(2),
                b: Some(1)
            })
        );
        assert_eq!(classify(&names(&["A", "depth"])), None);
    }

    /// The planes' bits, for bit-for-bit comparisons (NaN included).
    fn bits(image: &HdrImage) -> Vec<Vec<u32>> {
        let mut planes = vec![&image.x, &image.y, &image.z];
        planes.extend(&image.scotopic);
        planes
            .into_iter()
            .map(|p| p.iter().map(|v| v.to_bits()).collect())
            .collect()
    }

    #[test]
    fn rgb_to_xyz_matches_colour_on_every_instruction_set() {
        let m = REC709.rgb_to_xyz().unwrap();
        let specials = [
            0.0f32,
            -0.0,
            1.0,
            -3.5,
            1e-42,
            f32::MIN_POSITIVE,
            f32::MAX,
            -f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            65504.0,
        ];
        // 1000 samples (not a multiple of any vector width): specials and a spread of
        // magnitudes.
        let plane = |seed: usize| -> Vec<f32> {
            (0..1000)
                .map(|i| match (i * 7 + seed) % 23 {
                    k if k < specials.len() => specials[k],
                    k => (k as f32 - 17.0) * 10f32.powi((i % 70) as i32 - 35),
                })
                .collect()
        };
        for scale in [1.0, 621.0, 1e30] {
            let (mut r0, mut g0, mut b0) = (plane(0), plane(5), plane(11));
            colour::rgb_planes_to_xyz(&m, scale, &mut r0, &mut g0, &mut b0);
            for isa in Isa::all_available() {
                let (mut r, mut g, mut b) = (plane(0), plane(5), plane(11));
                rgb_to_xyz(isa, &m, scale, &mut r, &mut g, &mut b);
                for (got, want) in [(&r, &r0), (&g, &g0), (&b, &b0)] {
                    let same = got
                        .iter()
                        .zip(want.iter())
                        .all(|(a, b)| a.to_bits() == b.to_bits());
                    assert!(same, "{isa:?} scale {scale}");
                }
            }
        }
    }

    /// An RGB half-float file of `w × h` pixels, ZIP16 scan lines or 16×16 tiles, whose
    /// values depend on `seed`.
    fn rgb_half(w: usize, h: usize, seed: f32, tiles: bool) -> Vec<u8> {
        use exr::prelude::*;
        let channels = SpecificChannels::rgb(|Vec2(i, j): Vec2<usize>| {
            let v = (i as f32 * 0.37 + j as f32 * 1.3 + seed).sin().abs() * 100.0 + seed;
            (
                f16::from_f32(v),
                f16::from_f32(v * 0.5),
                f16::from_f32(v * 2.0),
            )
        });
        let encoding = Encoding {
            compression: Compression::ZIP16,
            blocks: if tiles {
                Blocks::Tiles(Vec2(16, 16))
            } else {
                Blocks::ScanLines
            },
            line_order: LineOrder::Increasing,
        };
        let layer = Layer::new((w, h), LayerAttributes::default(), encoding, channels);
        let mut out = Cursor::new(Vec::new());
        Image::from_layer(layer)
            .write()
            .to_buffered(&mut out)
            .unwrap();
        out.into_inner()
    }

    #[test]
    fn decode_into_reuses_planes_and_overwrites_every_sample() {
        let mut xyz = HdrImage::zeros(50, 30);
        for (i, v) in xyz.y.iter_mut().enumerate() {
            *v = i as f32 * 0.25;
        }
        xyz.x.fill(7.0);
        xyz.scotopic = Some(vec![3.0; 50 * 30]);
        let mut xyz_file = Cursor::new(Vec::new());
        write_hdr(&xyz, &mut xyz_file).unwrap();
        let files = [
            rgb_half(64, 40, 1.0, false),
            rgb_half(64, 40, 2.0, false),
            rgb_half(40, 64, 3.0, true),
            rgb_half(20, 10, 4.0, false),
            xyz_file.into_inner(),
            rgb_half(64, 40, 5.0, true),
        ];
        let limits = Limits::default();
        // Each file decoded into the image left by the one before (larger, smaller, the
        // same size, with and without a scotopic plane): the same as a fresh decode.
        let mut image = HdrImage::zeros(1, 1);
        image.y.fill(f32::NAN);
        for (k, f) in files.iter().chain(files.iter().rev()).enumerate() {
            let fresh = decode(f, &limits).unwrap();
            let before = image.y.as_ptr();
            let reusable = image.y.capacity() >= fresh.y.len();
            decode_into(f, &limits, &mut image).unwrap();
            assert_eq!(bits(&image), bits(&fresh), "file {k}");
            assert_eq!(
                (
                    image.width,
                    image.height,
                    image.absolute_units,
                    image.adopted_white,
                    image.view
                ),
                (
                    fresh.width,
                    fresh.height,
                    fresh.absolute_units,
                    fresh.adopted_white,
                    fresh.view
                )
            );
            if reusable && k > 0 {
                // The memory of one of the old planes was reused for the new ones.
                let new = [image.x.as_ptr(), image.y.as_ptr(), image.z.as_ptr()];
                assert!(new.contains(&before), "file {k}");
            }
        }
        // A damaged file: an error, and the image can be decoded into again.
        let mut broken = files[0].clone();
        let n = broken.len();
        broken.truncate(n - 100);
        assert!(decode_into(&broken, &limits, &mut image).is_err());
        decode_into(&files[1], &limits, &mut image).unwrap();
        assert_eq!(bits(&image), bits(&decode(&files[1], &limits).unwrap()));
    }

    /// The ZIP blocks of `file`'s first usable part: the part's header and its blocks;
    /// `None` when the file is not read that far or is not ZIP-compressed.
    fn zip_part(file: &[u8]) -> Option<(MetaData, usize, usize)> {
        let mut cursor = Cursor::new(file);
        let meta =
            foreign(|| MetaData::read_from_buffered(&mut cursor, false).map_err(exr_error)).ok()?;
        let index = meta.headers.iter().position(|h| !h.deep)?;
        zip_is_ours(meta.headers[index].compression).then_some((
            meta,
            cursor.position() as usize,
            index,
        ))
    }

    /// Decompress every block of `file` with [`zip_block`] and with the `exr` crate and
    /// check that both agree (the same bytes, or both an error), also on `mutations` damaged
    /// copies of each block; returns the number of
    /// blocks decompressed, or `None` when the file has no ZIP part whose blocks collect.
    fn compare_zip_blocks(name: &str, file: &[u8], mutations: usize) -> Option<usize> {
        let (meta, tables, index) = zip_part(file)?;
        let header = &meta.headers[index];
        let blocks = collect_blocks(file, &meta, tables, index).ok()?;
        let subsampled = header
            .channels
            .list
            .iter()
            .any(|c| c.sampling != Vec2(1, 1));
        let mut ok = 0;
        let mut buffer = vec![0xAB; 7];
        for (k, block) in blocks.iter().enumerate() {
            let ours = zip_block(block.data, block.expected_len, &mut buffer);
            if subsampled {
                // The exr crate needs a patched header for these; ours must still not
                // panic and give the expected length.
                assert!(ours.is_err() || buffer.len() == block.expected_len);
                continue;
            }
            ok += usize::from(same_as_exr(name, k, header, block, ours, &buffer));
            // Damaged copies of the block: a flipped byte here and there, a cut stream.
            for m in 0..mutations {
                let mut data = block.data.to_vec();
                let at = (m * 7919 + k * 31) % data.len().max(1);
                match m % 3 {
                    0 if !data.is_empty() => data[at] ^= 1 << (m % 8),
                    1 => data.truncate(at),
                    _ => data.push(m as u8),
                }
                let damaged = PendingBlock {
                    data: &data,
                    ..*block
                };
                let ours = zip_block(damaged.data, damaged.expected_len, &mut buffer);
                same_as_exr(name, k, header, &damaged, ours, &buffer);
            }
        }
        Some(ok)
    }

    /// Check our result for one block against the `exr` crate's: the same bytes, or both
    /// an error. Whether the block decoded.
    fn same_as_exr(
        name: &str,
        k: usize,
        header: &Header,
        block: &PendingBlock<'_>,
        ours: Result<()>,
        buffer: &[u8],
    ) -> bool {
        match (ours, exr_block(header, block)) {
            (Ok(()), Ok(t)) => {
                assert!(buffer == t, "{name}: block {k} differs");
                true
            }
            (Err(e), Err(_)) => {
                assert!(!e.to_string().contains('\n'));
                false
            }
            (o, t) => panic!(
                "{name}: block {k}: ours {o:?}, exr {:?}",
                t.map(|v| v.len())
            ),
        }
    }

    /// A file of `channels` (name, sample type) with `w × h` pixels of smooth values
    /// plus noise (`noise` = 0: none; large: incompressible blocks, stored uncompressed).
    fn zip_file(
        w: usize,
        h: usize,
        channels: &[(&str, SampleType)],
        compression: exr::compression::Compression,
        tiles: Option<(usize, usize)>,
        noise: u32,
    ) -> Vec<u8> {
        use exr::prelude::*;
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let list: Vec<AnyChannel<FlatSamples>> = channels
            .iter()
            .enumerate()
            .map(|(c, &(name, ty))| {
                let mut value = |i: usize| {
                    let smooth = ((i % w) as f32 * 0.3 + (i / w) as f32 * 0.7 + c as f32).sin();
                    let jitter = if noise == 0 {
                        0.0
                    } else {
                        (rnd() % u64::from(noise)) as f32
                    };
                    smooth.abs() * 200.0 + jitter
                };
                let samples = match ty {
                    SampleType::F16 => {
                        FlatSamples::F16((0..w * h).map(|i| f16::from_f32(value(i))).collect())
                    }
                    SampleType::F32 => FlatSamples::F32((0..w * h).map(value).collect()),
                    SampleType::U32 => {
                        FlatSamples::U32((0..w * h).map(|i| value(i) as u32).collect())
                    }
                };
                AnyChannel::new(name, samples)
            })
            .collect();
        let layer = Layer::new(
            (w, h),
            LayerAttributes::default(),
            Encoding {
                compression,
                blocks: match tiles {
                    Some((tw, th)) => Blocks::Tiles(Vec2(tw, th)),
                    None => Blocks::ScanLines,
                },
                line_order: LineOrder::Increasing,
            },
            AnyChannels::sort(SmallVec::from_vec(list)),
        );
        let mut out = Cursor::new(Vec::new());
        Image::from_layer(layer)
            .write()
            .to_buffered(&mut out)
            .unwrap();
        out.into_inner()
    }

    #[test]
    fn reconstruct_matches_the_definition() {
        // OpenEXR ImfZip.cpp: predictor over the whole buffer, then interleave the halves.
        let reference = |d: &[u8]| -> Vec<u8> {
            let mut t = d.to_vec();
            for i in 1..t.len() {
                t[i] = t[i - 1].wrapping_add(t[i]).wrapping_sub(128);
            }
            let h = t.len().div_ceil(2);
            (0..t.len())
                .map(|i| if i % 2 == 0 { t[i / 2] } else { t[h + i / 2] })
                .collect()
        };
        let mut state = 88172645463325252u64;
        for n in (0..300).chain([4095, 4097, 184_319, 184_320]) {
            let d: Vec<u8> = (0..n)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state as u8
                })
                .collect();
            let mut out = vec![0u8; n];
            reconstruct(&d, &mut out);
            assert_eq!(out, reference(&d), "n = {n}");
        }
    }

    #[test]
    fn zip_blocks_match_the_exr_crate() {
        use SampleType::{F16, F32, U32};
        use exr::compression::Compression::{ZIP1, ZIP16};
        let layouts: [&[(&str, SampleType)]; 5] = [
            &[("B", F16), ("G", F16), ("R", F16)],
            &[("Y", F32)],
            &[("Y", U32)],
            &[("B", F16), ("G", F32), ("R", F16), ("Z", U32)],
            &[("Y", F16)],
        ];
        let mut blocks = 0;
        for compression in [ZIP1, ZIP16] {
            for channels in layouts {
                // Odd sizes, a last block of fewer lines than the block height, a single
                // pixel, tiles cut at the edges.
                for (w, h) in [(1, 1), (17, 23), (64, 40), (3, 35)] {
                    for tiles in [None, Some((16, 16)), Some((5, 7))] {
                        for noise in [0, 1 << 20] {
                            let file = zip_file(w, h, channels, compression, tiles, noise);
                            let name =
                                format!("{compression:?} {channels:?} {w}x{h} {tiles:?} {noise}");
                            let n = compare_zip_blocks(&name, &file, 6).expect("ZIP part");
                            assert!(n > 0, "{name}");
                            blocks += n;
                            // The whole image as well: the same planes as the exr crate's
                            // own reader gives.
                            compare_with_exr_reader(&name, &file);
                        }
                    }
                }
            }
        }
        assert!(blocks > 1000, "{blocks}");
    }

    /// Decode `file` and check its planes against the `exr` crate's own reader (the
    /// channels Y, or R, G, B converted with the Rec. 709 matrix as [`to_hdr`] does).
    fn compare_with_exr_reader(name: &str, file: &[u8]) {
        use exr::prelude::*;
        let ours = decode(file, &Limits::default()).unwrap();
        let image = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_buffered(Cursor::new(file))
            .unwrap();
        let plane = |n: &str| -> Option<Vec<f32>> {
            let c = image
                .layer_data
                .channel_data
                .list
                .iter()
                .find(|c| c.name.eq(n))?;
            Some(c.sample_data.values_as_f32().collect())
        };
        let m = REC709.rgb_to_xyz().unwrap();
        if let (Some(mut r), Some(mut g), Some(mut b)) = (plane("R"), plane("G"), plane("B")) {
            colour::rgb_planes_to_xyz(&m, 1.0, &mut r, &mut g, &mut b);
            for (got, want) in [(&ours.x, &r), (&ours.y, &g), (&ours.z, &b)] {
                assert!(
                    got.iter()
                        .zip(want)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{name}"
                );
            }
        } else {
            let y = plane("Y").unwrap();
            assert!(
                ours.y
                    .iter()
                    .zip(&y)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{name}"
            );
        }
    }

    #[test]
    fn zip_blocks_in_flight_are_counted_in_the_budget() {
        use exr::compression::Compression::ZIP16;
        let rgb = [
            ("B", SampleType::F16),
            ("G", SampleType::F16),
            ("R", SampleType::F16),
        ];
        let file = zip_file(64, 40, &rgb, ZIP16, None, 0);
        // The budget of `decode_checked`: the file, three planes and three more; then one
        // block of 64 × 16 pixels of 6 bytes, inflated and reconstructed.
        let planes = (64 * 40 * 4 * 6 + file.len()) as u64;
        let block = 64 * 16 * 6;
        let needed = planes + (2 * block) as u64;
        let limits = |max_memory_bytes| Limits {
            max_memory_bytes,
            ..Limits::default()
        };
        let e = decode(&file, &limits(needed - 1)).unwrap_err();
        assert!(matches!(e, Error::Limits(_)), "{e}");
        let image = decode(&file, &limits(needed)).unwrap();
        assert_eq!(
            bits(&image),
            bits(&decode(&file, &Limits::default()).unwrap())
        );
    }

    #[test]
    fn zip_block_of_the_wrong_length_is_an_error() {
        // A zlib stream of one stored deflate block (RFC 1950/1951) holding `payload`.
        let zlib = |payload: &[u8]| -> Vec<u8> {
            let len = payload.len() as u16;
            let mut z = vec![0x78, 0x01, 0x01];
            z.extend(len.to_le_bytes());
            z.extend((!len).to_le_bytes());
            z.extend(payload);
            let (mut a, mut b) = (1u32, 0u32);
            for &v in payload {
                a = (a + u32::from(v)) % 65521;
                b = (b + a) % 65521;
            }
            z.extend(((b << 16) | a).to_be_bytes());
            z
        };
        let payload: Vec<u8> = (0..100u8).collect();
        let mut out = Vec::new();
        // The right length decodes (to the reconstructed bytes).
        zip_block(&zlib(&payload), 100, &mut out).unwrap();
        let mut want = vec![0; 100];
        reconstruct(&payload, &mut want);
        assert_eq!(out, want);
        // One byte short, one byte too many, a damaged checksum, a cut stream.
        for (stream, expected) in [
            (zlib(&payload[..99]), 100),
            (zlib(&payload), 99),
            (zlib(&payload), 101),
        ] {
            let e = zip_block(&stream, expected, &mut out).unwrap_err();
            assert!(matches!(e, Error::Decode { .. }), "{e}");
        }
        let mut bad = zlib(&payload);
        *bad.last_mut().unwrap() ^= 1;
        assert!(zip_block(&bad, 100, &mut out).is_err());
        let cut = &zlib(&payload)[..50];
        assert!(zip_block(cut, 100, &mut out).is_err());
    }

    #[test]
    fn a_damaged_block_claiming_a_huge_size_reserves_nothing() {
        // A mutated data window (`tests/damaged.rs`, ZIP16 mutation 41) made a 2 KB file
        // claim 1 GB blocks; the buffer was grown and zero-filled before the stream was
        // found to be malformed, which took seconds.
        let mut out = Vec::new();
        let garbage = [0x78, 0x9c, 0x5d, 0xd3, 0x77, 0x34, 0x1b, 0x8a];
        assert!(zip_block(&garbage, 1 << 30, &mut out).is_err());
        assert!(out.capacity() < 1 << 20, "{}", out.capacity());
        // The bound: what a stream of that length can hold, and no less.
        assert!(!could_inflate_to(8, 8 * 1032 + 1));
        assert!(could_inflate_to(8, 8 * 1032));
        assert!(could_inflate_to(1000, 4000));
    }

    /// A directory of the shared data set, as the integration tests find it
    /// (`tests/common/mod.rs`): `$VISADAPT_SHARED_DATA` or `../shared/data` beside the
    /// repository; `None` (skip) when absent, a failure when
    /// `VISADAPT_REQUIRE_SHARED_DATA=1`.
    fn shared_dir(rel: &str) -> Option<std::fs::ReadDir> {
        let root = std::env::var_os("VISADAPT_SHARED_DATA")
            .map(std::path::PathBuf::from)
            .unwrap_or_else(|| {
                std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data")
            });
        match std::fs::read_dir(root.join(rel)) {
            Ok(dir) => Some(dir),
            Err(_)
                if std::env::var_os("VISADAPT_REQUIRE_SHARED_DATA").is_some_and(|v| v == "1") =>
            {
                panic!("shared test data {rel} is missing")
            }
            Err(_) => {
                eprintln!("note: shared test data {rel} not found, skipping");
                None
            }
        }
    }

    #[test]
    fn shared_files_recompressed_with_zip_match_the_exr_crate() {
        use exr::prelude::*;
        let Some(dir) = shared_dir("openexr") else {
            return;
        };
        let mut files: Vec<_> = dir
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "exr"))
            .collect();
        files.sort();
        let mut tried = 0;
        for path in files {
            let bytes = std::fs::read(&path).unwrap();
            // The exr crate refuses subsampled files (StarField.exr).
            let Ok(mut image) = exr::prelude::read()
                .no_deep_data()
                .largest_resolution_level()
                .all_channels()
                .all_layers()
                .all_attributes()
                .from_buffered(Cursor::new(&bytes[..]))
            else {
                continue;
            };
            for compression in [Compression::ZIP1, Compression::ZIP16] {
                for layer in image.layer_data.iter_mut() {
                    layer.encoding.compression = compression;
                }
                let mut out = Cursor::new(Vec::new());
                image.write().to_buffered(&mut out).unwrap();
                let file = out.into_inner();
                let name = format!("{} {compression:?}", path.display());
                assert!(compare_zip_blocks(&name, &file, 0).unwrap() > 0, "{name}");
                // And the whole decode is the same as of the original file.
                let (a, b) = (
                    decode(&file, &Limits::default()),
                    decode(&bytes, &Limits::default()),
                );
                match (a, b) {
                    (Ok(a), Ok(b)) => assert_eq!(bits(&a), bits(&b), "{name}"),
                    (a, b) => assert_eq!(a.is_ok(), b.is_ok(), "{name}"),
                }
                tried += 1;
            }
        }
        assert!(tried >= 14, "{tried}");
    }
}
