//! A PNG's image data (the zlib stream of its IDAT chunks) encoded in parallel row bands.
//!
//! Each band of rows is sRGB-encoded, filtered and deflated on its own (a `rayon` task
//! with the `rayon` feature): the first row of a band is filtered against the row above
//! it (encoded once more for that), so the filtered bytes are exactly those of one
//! sequential pass. Each band is deflated into raw DEFLATE blocks (RFC 1951) by its own
//! compressor, ended with a sync flush (an empty stored block: the segment ends on a byte
//! boundary, its back-references stay inside it) except the last band, which ends with
//! the final block. The segments, after the two-byte zlib header (RFC 1950 §2.2) and
//! followed by the Adler-32 of all filtered bytes (the bands' sums combined), are one
//! valid zlib stream; each band's segment is written as its own IDAT chunk (PNG 1.2 §4.1.3
//! allows several, their data concatenated), so nothing is copied to join them.
//!
//! [`PngCompression::Fdeflate`]'s compressor cannot be split so: its stream is one block
//! from one compressor. There the bands are only encoded and filtered in parallel, a wave
//! of them at a time, while the previous wave is compressed ([`fdeflate_stream`]).

use super::PngCompression;
use crate::DisplayImage;
use crate::colour::{Srgb8, SrgbLut};
use crate::simd::{Isa, at_level};
use zlib_rs::{Deflate, DeflateConfig, DeflateFlush, Strategy};

/// The zlib header: CM = 8 (deflate), CINFO = 7 (32 KiB window), FLEVEL = 0 ("fastest"),
/// FCHECK making the 16-bit value a multiple of 31 (RFC 1950 §2.2): `0x7801`, the header
/// `png`'s fdeflate path writes.
const ZLIB_HEADER: [u8; 2] = [0x78, 0x01];

/// Raw bytes per band: about 256 KiB (45 rows of a 1920-pixel 8-bit RGB image, 24 bands
/// at 1080p), enough bands to keep every core busy to the end, few enough that the
/// compressors' restarts cost little (see `bands_cost_little_in_size`).
const BAND_BYTES: usize = 1 << 18;

/// How one band's rows are filtered (PNG 1.2 §6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Filtering {
    /// Each row with the filter whose output has the smallest sum of absolute values (as
    /// signed bytes), of Up, Sub, Average and Paeth tried in that order (a later one kept
    /// on a tie, the first with sum 0 at once): `png`'s `Filter::Adaptive`, the same bytes.
    Adaptive,
    /// Every row with `Up`: `png`'s choice for `Compression::Fastest`.
    Up,
}

/// The filtering and deflate settings of a [`PngCompression`].
#[derive(Clone, Copy, Debug)]
struct Settings {
    filtering: Filtering,
    level: i32,
    strategy: Strategy,
}

impl Settings {
    /// The settings of a banded compression; `None` for [`PngCompression::Fdeflate`],
    /// whose compressor is sequential.
    fn of(compression: PngCompression) -> Option<Settings> {
        Some(match compression {
            PngCompression::Fast => Settings {
                filtering: Filtering::Adaptive,
                level: 1,
                strategy: Strategy::Default,
            },
            PngCompression::Fastest => Settings {
                filtering: Filtering::Up,
                level: 1,
                strategy: Strategy::Default,
            },
            PngCompression::Rle => Settings {
                filtering: Filtering::Up,
                level: 1,
                strategy: Strategy::Rle,
            },
            PngCompression::Fdeflate => return None,
        })
    }
}

/// One band's output: its deflate segment (after the zlib header for the first band) and
/// the Adler-32 of its filtered bytes.
struct Segment {
    bytes: Vec<u8>,
    adler: u32,
    filtered_len: u64,
}

/// The image data of `image` as a zlib stream, handed to `piece` in pieces, each to be
/// written as one IDAT chunk in order: `bits` 8 or 16 (checked by the caller), RGB.
pub(super) fn write_zlib(
    image: &DisplayImage,
    bits: u8,
    compression: PngCompression,
    mut piece: impl FnMut(&[u8]) -> crate::Result<()>,
) -> crate::Result<()> {
    let Some(settings) = Settings::of(compression) else {
        return fdeflate_stream(image, bits, piece);
    };
    let pieces = zlib_pieces(image, bits, settings).map_err(crate::Error::Unsupported)?;
    pieces.iter().try_for_each(|p| piece(p))
}

/// The image data of `image` as a zlib stream in pieces, one per band, deflated with
/// `settings`.
fn zlib_pieces(image: &DisplayImage, bits: u8, settings: Settings) -> Result<Vec<Vec<u8>>, String> {
    let row_bytes = image.width * bytes_per_pixel(bits);
    let rows_per_band = (BAND_BYTES / row_bytes.max(1)).clamp(1, image.height.max(1));
    let bands = image.height.div_ceil(rows_per_band).max(1);
    let isa = Isa::detect();
    let band = |k: usize| {
        let rows = k * rows_per_band..((k + 1) * rows_per_band).min(image.height);
        at_level!(
            isa,
            encode_band(image, bits, settings, rows.clone(), k == 0, k + 1 == bands)
        )
    };
    #[cfg(feature = "rayon")]
    let segments: Vec<Result<Segment, String>> = {
        use rayon::prelude::*;
        (0..bands).into_par_iter().map(band).collect()
    };
    #[cfg(not(feature = "rayon"))]
    let segments: Vec<Result<Segment, String>> = (0..bands).map(band).collect();
    let mut adler = 1u32;
    let mut pieces = Vec::with_capacity(bands);
    for segment in segments {
        let segment = segment?;
        adler = zlib_rs::adler32::adler32_combine(adler, segment.adler, segment.filtered_len);
        pieces.push(segment.bytes);
    }
    if let Some(last) = pieces.last_mut() {
        last.extend_from_slice(&adler.to_be_bytes());
    }
    Ok(pieces)
}

/// The image data of `image` as one zlib stream compressed by fdeflate (one block of
/// fixed Huffman codes made for filtered PNG rows, and runs of zeros), handed to `then`,
/// as `png`'s own encoder writes it at `Compression::Fast`, with its fallback: the rows
/// stored unfiltered where that is smaller. The same bytes as `png`'s encoder (tested).
///
/// fdeflate's compressor is sequential; the sRGB encoding and the adaptive filter are
/// not. The rows go in waves of [`WAVE_BANDS`] bands: while one wave is compressed, the
/// next is encoded and filtered in parallel bands (`rayon::join`), into the other of two
/// buffers. The buffers and the stream are the calling thread's [`Scratch`], kept for
/// its next image.
pub(super) fn fdeflate_stream<R>(
    image: &DisplayImage,
    bits: u8,
    then: impl FnOnce(&[u8]) -> crate::Result<R>,
) -> crate::Result<R> {
    let mut scratch = Scratch::take();
    let result = scratch
        .fdeflate(image, bits)
        .map_err(crate::Error::Unsupported)
        .and_then(then);
    scratch.keep();
    result
}

/// The buffers of [`fdeflate_stream`], kept by each thread that writes PNGs, so that
/// frame after frame reuses memory already paged in: allocated afresh, they were 400 to
/// 550 page faults (memory cleared by the kernel, then by `calloc`) of every 1080p frame
/// in `video`. Kept only up to [`SCRATCH_KEPT_MAX_BYTES`].
#[derive(Default)]
struct Scratch {
    /// The filtered rows of the wave being compressed and of the next one.
    waves: [Vec<u8>; 2],
    /// The zlib stream.
    stream: Vec<u8>,
}

thread_local! {
    static SCRATCH: std::cell::Cell<Scratch> = std::cell::Cell::new(Scratch::default());
}

/// The most a thread keeps in its [`Scratch`] between images: a 4K frame's (two waves
/// of about 1 MiB and a stream of at most the 24 MiB of its 8-bit rows). Our choice, so
/// that huge images do not leave their buffers behind in every thread.
const SCRATCH_KEPT_MAX_BYTES: usize = 32 << 20;

impl Scratch {
    fn take() -> Scratch {
        SCRATCH.take()
    }

    /// Back to the thread for its next image, if small enough.
    fn keep(self) {
        let bytes = self.waves.iter().map(Vec::capacity).sum::<usize>() + self.stream.capacity();
        if bytes <= SCRATCH_KEPT_MAX_BYTES {
            SCRATCH.set(self);
        }
    }

    /// The zlib stream of `image` (see [`fdeflate_stream`]).
    fn fdeflate(&mut self, image: &DisplayImage, bits: u8) -> Result<&[u8], String> {
        let row_bytes = image.width * bytes_per_pixel(bits);
        let stride = row_bytes + 1;
        let len = stride * image.height;
        let rows_per_band = (BAND_BYTES / row_bytes.max(1)).clamp(1, image.height.max(1));
        let wave_rows = rows_per_band * WAVE_BANDS;
        let wave = |k: usize| k * wave_rows..((k + 1) * wave_rows).min(image.height);
        let waves = image.height.div_ceil(wave_rows);
        let buffer_len = wave_rows.min(image.height) * stride;
        let [ready, next] = &mut self.waves;
        // Every byte read is written by `filter_wave` first: no need to clear.
        for buffer in [&mut *ready, &mut *next] {
            buffer.resize(buffer_len, 0);
        }
        let failed = |e: std::io::Error| format!("fdeflate: {e}");
        let mut stream = std::mem::take(&mut self.stream);
        stream.clear();
        stream.reserve(len / 4 + 64);
        let mut compressor =
            fdeflate::Compressor::new(std::io::Cursor::new(stream)).map_err(failed)?;
        filter_wave(image, bits, wave(0), rows_per_band, ready);
        for k in 0..waves {
            let filtered = &ready[..wave(k).len() * stride];
            let compress = || {
                filtered
                    .chunks_exact(stride)
                    .try_for_each(|row| compressor.write_data(row))
            };
            let filter_next = || filter_wave(image, bits, wave(k + 1), rows_per_band, next);
            #[cfg(feature = "rayon")]
            let (compressed, ()) = rayon::join(compress, filter_next);
            #[cfg(not(feature = "rayon"))]
            let (compressed, ()) = {
                let (mut compress, mut filter_next) = (compress, filter_next);
                (compress(), filter_next())
            };
            compressed.map_err(failed)?;
            std::mem::swap(ready, next);
        }
        self.stream = compressor.finish().map_err(failed)?.into_inner();
        if self.stream.len() <= fdeflate::StoredOnlyCompressor::<()>::compressed_size(len) {
            return Ok(&self.stream);
        }
        // Larger than the rows themselves: stored, unfiltered (filter type 0), as `png`
        // does.
        let mut out = std::mem::take(&mut self.stream);
        out.clear();
        out.reserve(len + len / 4096 + 64);
        let mut stored =
            fdeflate::StoredOnlyCompressor::new(std::io::Cursor::new(out)).map_err(failed)?;
        let row = &mut self.waves[0];
        row.resize(row.len().max(row_bytes), 0);
        let row = &mut row[..row_bytes];
        for y in 0..image.height {
            encode_row(image, bits, y, row);
            stored.write_data(&[0]).map_err(failed)?;
            stored.write_data(row).map_err(failed)?;
        }
        self.stream = stored.finish().map_err(failed)?.into_inner();
        Ok(&self.stream)
    }
}

/// Bands of rows per wave of [`fdeflate_stream`]: about 1 MiB of rows (six waves of a
/// 1080p 8-bit frame), as many bands as keep several cores busy filtering while one
/// compresses.
const WAVE_BANDS: usize = 4;

/// `rows` of `image` (empty past the last row) encoded and adaptively filtered into the
/// start of `out`, in parallel bands of `rows_per_band`.
fn filter_wave(
    image: &DisplayImage,
    bits: u8,
    rows: std::ops::Range<usize>,
    rows_per_band: usize,
    out: &mut [u8],
) {
    let stride = image.width * bytes_per_pixel(bits) + 1;
    let out = &mut out[..rows.len() * stride];
    let isa = Isa::detect();
    let band = |(k, out): (usize, &mut [u8])| {
        let first = rows.start + k * rows_per_band;
        let rows = first..first + out.len() / stride;
        at_level!(isa, filter_band(image, bits, rows, out));
    };
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(rows_per_band * stride)
            .enumerate()
            .for_each(band);
    }
    #[cfg(not(feature = "rayon"))]
    out.chunks_mut(rows_per_band * stride)
        .enumerate()
        .for_each(band);
}

/// The adaptively filtered `rows` of `image` into `out` (each its type byte, then its
/// bytes).
#[inline(always)]
fn filter_band(image: &DisplayImage, bits: u8, rows: std::ops::Range<usize>, out: &mut [u8]) {
    let stride = image.width * bytes_per_pixel(bits) + 1;
    let mut filter = RowFilter::new(image, bits, Filtering::Adaptive, rows.start);
    for (y, row) in rows.zip(out.chunks_exact_mut(stride)) {
        row.copy_from_slice(filter.row(y));
    }
}

thread_local! {
    /// Each thread's compressor, reset for each band (a new one allocates and clears
    /// about 320 KiB at zlib's default memory level: window, hash chains, pending buffer),
    /// with the level and strategy
    /// it was made for.
    static COMPRESSOR: std::cell::Cell<Option<(Deflate, (i32, Strategy))>> =
        const { std::cell::Cell::new(None) };
}

/// Encode, filter and deflate `rows` of `image`.
#[inline(always)]
fn encode_band(
    image: &DisplayImage,
    bits: u8,
    settings: Settings,
    rows: std::ops::Range<usize>,
    first: bool,
    last: bool,
) -> Result<Segment, String> {
    let key = (settings.level, settings.strategy);
    let mut deflate = match COMPRESSOR.take() {
        Some((mut deflate, made_for)) if made_for == key => {
            deflate.reset();
            deflate
        }
        _ => Deflate::new_with_config(DeflateConfig {
            level: settings.level,
            // Negative: raw deflate, no zlib header or trailer (zlib's convention).
            window_bits: -15,
            strategy: settings.strategy,
            ..DeflateConfig::default()
        }),
    };
    let segment = deflate_rows(image, bits, settings, rows, first, last, &mut deflate);
    if segment.is_ok() {
        COMPRESSOR.set(Some((deflate, key)));
    }
    segment
}

/// [`encode_band`] with a compressor ready for a new stream.
#[inline(always)]
fn deflate_rows(
    image: &DisplayImage,
    bits: u8,
    settings: Settings,
    rows: std::ops::Range<usize>,
    first: bool,
    last: bool,
    deflate: &mut Deflate,
) -> Result<Segment, String> {
    let raw_len = (image.width * bytes_per_pixel(bits) + 1) * rows.len();
    let mut filter = RowFilter::new(image, bits, settings.filtering, rows.start);
    // A quarter of the raw size to start with: grown as needed (level 1 output of a
    // mapped frame is 10-30 % of it), so little is zero-filled in advance.
    let mut out = Output::new(raw_len / 4 + 64, first);
    let mut adler = 1u32;
    for y in rows {
        let row = filter.row(y);
        adler = zlib_rs::adler32::adler32(adler, row);
        out.deflate(deflate, row, DeflateFlush::NoFlush)?;
    }
    let flush = if last {
        DeflateFlush::Finish
    } else {
        DeflateFlush::SyncFlush
    };
    out.deflate(deflate, &[], flush)?;
    Ok(Segment {
        bytes: out.into_bytes(),
        adler,
        filtered_len: raw_len as u64,
    })
}

/// Bytes per pixel of interleaved RGB at `bits` (8 or 16) per channel.
fn bytes_per_pixel(bits: u8) -> usize {
    if bits == 8 { 3 } else { 6 }
}

/// The filtered rows of an image, one after another (PNG 1.2 §6): each row sRGB-encoded,
/// then filtered against the row above it (the row above the first one asked for is
/// encoded too, so that a band's rows are those of one sequential pass).
struct RowFilter<'a> {
    image: &'a DisplayImage,
    bits: u8,
    filtering: Filtering,
    prev: Vec<u8>,
    cur: Vec<u8>,
    /// The filter type byte, then the filtered row; `trial` is the adaptive choice's
    /// second one.
    best: Vec<u8>,
    trial: Vec<u8>,
}

impl<'a> RowFilter<'a> {
    /// Ready for row `first` (and the rows after it, in order).
    #[inline(always)]
    fn new(image: &'a DisplayImage, bits: u8, filtering: Filtering, first: usize) -> Self {
        let row_bytes = image.width * bytes_per_pixel(bits);
        let mut prev = vec![0u8; row_bytes];
        if first > 0 {
            encode_row(image, bits, first - 1, &mut prev);
        }
        RowFilter {
            image,
            bits,
            filtering,
            prev,
            cur: vec![0u8; row_bytes],
            best: vec![0u8; row_bytes + 1],
            trial: vec![0u8; row_bytes + 1],
        }
    }

    /// Row `y` (the row after the previous call's), filtered: its type byte first.
    #[inline(always)]
    fn row(&mut self, y: usize) -> &[u8] {
        encode_row(self.image, self.bits, y, &mut self.cur);
        match self.filtering {
            Filtering::Up => {
                self.best[0] = 2;
                up(&self.prev, &self.cur, &mut self.best[1..]);
            }
            Filtering::Adaptive => adaptive(
                bytes_per_pixel(self.bits),
                &self.prev,
                &self.cur,
                &mut self.best,
                &mut self.trial,
            ),
        }
        std::mem::swap(&mut self.prev, &mut self.cur);
        &self.best
    }
}

/// Row `y` of `image` as sRGB codes, interleaved RGB (`bits` 8 or 16, big-endian).
#[inline(always)]
fn encode_row(image: &DisplayImage, bits: u8, y: usize, out: &mut [u8]) {
    let start = y * image.width;
    let end = start + image.width;
    let (r, g, b) = (
        &image.r[start..end],
        &image.g[start..end],
        &image.b[start..end],
    );
    if bits == 8 {
        srgb8_row(r, g, b, out);
    } else {
        srgb16_row(r, g, b, out);
    }
}

/// A growing output buffer for a compressor (kept initialised: the crate has no `unsafe`
/// outside its `simd` module).
struct Output {
    buf: Vec<u8>,
    len: usize,
}

impl Output {
    fn new(capacity: usize, zlib_header: bool) -> Output {
        let mut buf = vec![0u8; capacity + 2];
        let mut len = 0;
        if zlib_header {
            buf[..2].copy_from_slice(&ZLIB_HEADER);
            len = 2;
        }
        Output { buf, len }
    }

    /// Compress all of `input` (and, with a flush, everything pending).
    fn deflate(
        &mut self,
        deflate: &mut Deflate,
        mut input: &[u8],
        flush: DeflateFlush,
    ) -> Result<(), String> {
        loop {
            if self.buf.len() - self.len < 64 {
                let grow = self.buf.len().max(4096);
                self.buf.resize(self.buf.len() + grow, 0);
            }
            let (before_in, before_out) = (deflate.total_in(), deflate.total_out());
            let status = deflate
                .compress(input, &mut self.buf[self.len..], flush)
                .map_err(|e| format!("deflate: {}", e.as_str()))?;
            let used = (deflate.total_in() - before_in) as usize;
            let wrote = (deflate.total_out() - before_out) as usize;
            input = &input[used..];
            self.len += wrote;
            let room_left = self.len < self.buf.len();
            let done = match flush {
                DeflateFlush::Finish => status == zlib_rs::Status::StreamEnd,
                // All input taken and the output not full: nothing is pending.
                _ => input.is_empty() && room_left,
            };
            if done {
                return Ok(());
            }
        }
    }

    fn into_bytes(mut self) -> Vec<u8> {
        self.buf.truncate(self.len);
        self.buf
    }
}

/// A row of 8-bit sRGB codes, interleaved RGB.
#[inline(always)]
fn srgb8_row(r: &[f32], g: &[f32], b: &[f32], out: &mut [u8]) {
    Srgb8::get().encode_rgb(r, g, b, out);
}

/// A row of 16-bit sRGB codes, interleaved RGB, big-endian.
#[inline(always)]
fn srgb16_row(r: &[f32], g: &[f32], b: &[f32], out: &mut [u8]) {
    srgb16_lut().encode_rgb(r, g, b, true, out);
}

/// The shared 16-bit table (see [`SrgbLut`]).
pub(super) fn srgb16_lut() -> &'static SrgbLut {
    static LUT: std::sync::OnceLock<SrgbLut> = std::sync::OnceLock::new();
    LUT.get_or_init(|| SrgbLut::new(16))
}

/// The adaptive choice into `best` (type byte first); `trial` is scratch.
#[inline(always)]
fn adaptive(bpp: usize, prev: &[u8], cur: &[u8], best: &mut Vec<u8>, trial: &mut Vec<u8>) {
    let mut min_cost = u64::MAX;
    for kind in [2u8, 1, 3, 4] {
        trial[0] = kind;
        let out = &mut trial[1..];
        match kind {
            2 => up(prev, cur, out),
            1 => sub(bpp, cur, out),
            3 => avg(bpp, prev, cur, out),
            _ => paeth(bpp, prev, cur, out),
        }
        let cost = sum_abs(&trial[1..]);
        if cost <= min_cost {
            min_cost = cost;
            std::mem::swap(best, trial);
            if cost == 0 {
                return;
            }
        }
    }
}

/// `Up`: each byte minus the byte above.
#[inline(always)]
fn up(prev: &[u8], cur: &[u8], out: &mut [u8]) {
    for ((o, &c), &p) in out.iter_mut().zip(cur).zip(prev) {
        *o = c.wrapping_sub(p);
    }
}

/// `Sub`: each byte minus the byte one pixel to the left (0 left of the row).
#[inline(always)]
fn sub(bpp: usize, cur: &[u8], out: &mut [u8]) {
    out[..bpp].copy_from_slice(&cur[..bpp]);
    for ((o, &c), &a) in out[bpp..].iter_mut().zip(&cur[bpp..]).zip(cur) {
        *o = c.wrapping_sub(a);
    }
}

/// `Average`: each byte minus the floored mean of the bytes left and above.
#[inline(always)]
fn avg(bpp: usize, prev: &[u8], cur: &[u8], out: &mut [u8]) {
    for ((o, &c), &b) in out[..bpp].iter_mut().zip(cur).zip(prev) {
        *o = c.wrapping_sub(b / 2);
    }
    for (((o, &c), &a), &b) in out[bpp..]
        .iter_mut()
        .zip(&cur[bpp..])
        .zip(cur)
        .zip(&prev[bpp..])
    {
        *o = c.wrapping_sub(((u16::from(a) + u16::from(b)) >> 1) as u8);
    }
}

/// `Paeth`: each byte minus the Paeth predictor of the bytes left (a), above (b) and
/// above-left (c) (PNG 1.2 §6.6).
#[inline(always)]
fn paeth(bpp: usize, prev: &[u8], cur: &[u8], out: &mut [u8]) {
    for ((o, &c), &b) in out[..bpp].iter_mut().zip(cur).zip(prev) {
        *o = c.wrapping_sub(paeth_predictor(0, b, 0));
    }
    for ((((o, &x), &a), &b), &c) in out[bpp..]
        .iter_mut()
        .zip(&cur[bpp..])
        .zip(cur)
        .zip(&prev[bpp..])
        .zip(prev)
    {
        *o = x.wrapping_sub(paeth_predictor(a, b, c));
    }
}

/// The Paeth predictor, branch-free: the one of `a`, `b`, `c` nearest `a + b − c`, ties
/// to `a`, then `b`.
#[inline(always)]
fn paeth_predictor(a: u8, b: u8, c: u8) -> u8 {
    let (ia, ib, ic) = (i16::from(a), i16::from(b), i16::from(c));
    let pa = (ib - ic).abs();
    let pb = (ia - ic).abs();
    let pc = (ia + ib - 2 * ic).abs();
    let not_a = pb < pa || pc < pa;
    let b_or_c = if pc < pb { c } else { b };
    if not_a { b_or_c } else { a }
}

/// The sum of the bytes' absolute values as signed bytes (the adaptive filter's cost):
/// in 32 `u16` lanes (one AVX2 vector of bytes widened to two) over blocks of
/// [`SUM_ABS_STEPS`] steps, then in `u64`. The compiler widened each byte to `u32` for a
/// single running sum, 8 bytes per instruction: a 5 761-byte row took 0.43 µs that way
/// and 0.20 µs this way (AVX2, scratch timing, three rounds), four times per row.
#[inline(always)]
fn sum_abs(bytes: &[u8]) -> u64 {
    const LANES: usize = 32;
    let mut sum = 0u64;
    for block in bytes.chunks(LANES * SUM_ABS_STEPS) {
        let mut lanes = [0u16; LANES];
        let mut steps = block.chunks_exact(LANES);
        for step in &mut steps {
            for (lane, &b) in lanes.iter_mut().zip(step) {
                *lane += u16::from((b as i8).unsigned_abs());
            }
        }
        sum += lanes.iter().map(|&l| u64::from(l)).sum::<u64>();
        for &b in steps.remainder() {
            sum += u64::from((b as i8).unsigned_abs());
        }
    }
    sum
}

/// Steps of [`sum_abs`]'s lanes per block: each adds at most 128 (`|−128|`) to a lane, and
/// 256 × 128 = 32 768 fits a `u16`.
const SUM_ABS_STEPS: usize = 256;

#[cfg(test)]
mod tests {
    use super::*;

    /// [`sum_abs`] against a byte-by-byte sum: every byte value, and rows of `0x80` (the
    /// largest cost, 128 per byte) long enough to fill a block's `u16` lanes and spill
    /// into a remainder.
    #[test]
    fn sum_abs_is_the_sum_of_the_signed_magnitudes() {
        let plain = |bytes: &[u8]| -> u64 {
            bytes
                .iter()
                .map(|&b| (i64::from(b as i8)).unsigned_abs())
                .sum()
        };
        let every: Vec<u8> = (0..=255u8).cycle().take(3 * 8192 + 77).collect();
        for len in [0, 1, 31, 32, 33, 8191, 8192, 8193, every.len()] {
            assert_eq!(sum_abs(&every[..len]), plain(&every[..len]), "{len}");
        }
        for len in [8192, 8192 + 31, 5 * 8192 + 1] {
            let worst = vec![0x80u8; len];
            assert_eq!(sum_abs(&worst), 128 * len as u64, "{len}");
        }
    }
}
