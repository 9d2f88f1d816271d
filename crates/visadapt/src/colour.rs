//! Colour spaces: RGB primaries to CIE XYZ, XYZ to linear sRGB, the sRGB transfer curve, and
//! chromatic adaptation from the scene's white to the display's.
//!
//! The model works in CIE XYZ (paper Sec. 4: "image files with photopic luminance (CIE Y),
//! scotopic luminance, and CIE XZ channels"), and outputs "a fixed RGB color space", which
//! here is sRGB: ITU-R BT.709 primaries, D65 white, the IEC 61966-2-1 transfer curve.
//!
//! # Chromatic adaptation (beyond the paper)
//!
//! The paper maps luminance only ("the chromatic channels follow the same mapping") and says
//! nothing of white balance. Without it, a scene lit by the paper's own equal-energy
//! illuminant E (Sec. 5), or any Radiance RGB file (whose white is E), shows its whites pink on
//! a D65 display: XYZ = (1, 1, 1) is linear sRGB (1.205, 0.948, 0.909), CIELAB a* = +8.5,
//! b* = +5.6 against D65. An observer adapted to the scene sees those whites as white, and one
//! adapted to the display expects white to be the display white. So the cone image is taken
//! from the scene's adopted white to the display white by a von Kries transform in the CAT16
//! cone space (Li, Li, Wang, Zu, Luo, Cui, Melgosa, Brill & Pointer 2017, "Comprehensive color
//! solutions: CAM16, CAT16, and CAM16-UCS", Color Res. Appl. 42:703–718, Eq. 4–6):
//! `XYZ' = M16⁻¹ · diag(LMS_display / LMS_scene) · M16 · XYZ`, with complete adaptation
//! (degree `D = 1`): the paper's steady state is full adaptation, and a user asking for
//! "what the scene looks like" expects its neutral surfaces neutral ([`cat16`]).
//!
//! What it leaves alone: the transform maps the scene white (Y = 1) to the display white
//! (Y = 1), so every neutral keeps its luminance exactly; a coloured surface's Y moves by
//! well under 1 % for E → D65 (the ColorChecker red patch by −0.5 %, against −3.6 % with
//! Bradford). All thresholds, adaptation luminances and the scotopic channel are computed from
//! the untransformed XYZ and V, so Eqs. 1–7 are unchanged, and the rod image stays grey (the
//! display white). [`WhitePoint::Off`] keeps the paper's behaviour (no adaptation).

use crate::limits::saturating_f32;

/// A CIE 1931 xy chromaticity.
pub type Xy = [f64; 2];

/// The chromaticities of an RGB colour space's primaries and white point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chromaticities {
    /// Red primary.
    pub red: Xy,
    /// Green primary.
    pub green: Xy,
    /// Blue primary.
    pub blue: Xy,
    /// White point (the colour of RGB = (1, 1, 1)).
    pub white: Xy,
}

/// ITU-R BT.709 / sRGB primaries with D65 white (BT.709-6 Table 1; also the OpenEXR default
/// `chromaticities`).
pub const REC709: Chromaticities = Chromaticities {
    red: [0.64, 0.33],
    green: [0.30, 0.60],
    blue: [0.15, 0.06],
    white: [0.3127, 0.3290],
};

/// Radiance's default primaries (`src/common/color.h`, `CIE_x_r` … `CIE_y_w`): CIE-like
/// RGB with an equal-energy white, used when a Radiance file has no `PRIMARIES=` line.
pub const RADIANCE_DEFAULT: Chromaticities = Chromaticities {
    red: [0.640, 0.330],
    green: [0.290, 0.600],
    blue: [0.150, 0.060],
    white: [1.0 / 3.0, 1.0 / 3.0],
};

/// A row-major 3×3 matrix.
pub type Mat3 = [[f64; 3]; 3];

/// The equal-energy white E, x = y = 1/3: the paper's illuminant (Sec. 5) and the white of
/// Radiance RGB.
pub const EQUAL_ENERGY: Xy = [1.0 / 3.0, 1.0 / 3.0];

/// CIE D65 as BT.709 rounds it (x = 0.3127, y = 0.3290): the white of the sRGB display.
pub const D65: Xy = REC709.white;

/// The 3×3 identity, the "no chromatic adaptation" transform.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The CAT16 matrix from CIE XYZ to its sharpened cone space `M16` (Li et al. 2017, Eq. 4).
pub const CAT16_XYZ_TO_LMS: Mat3 = [
    [0.401288, 0.650173, -0.051461],
    [-0.250268, 1.204414, 0.045854],
    [-0.002079, 0.048952, 0.953127],
];

/// The XYZ, with Y = 1, of a chromaticity; `None` unless `y > 0` and both are finite.
pub fn xyz_of_white(white: Xy) -> Option<[f64; 3]> {
    let [x, y] = white;
    (x.is_finite() && y.is_finite() && y > 0.0).then(|| [x / y, 1.0, (1.0 - x - y) / y])
}

/// Whether `white` can serve as an adopted white: finite, `x > 0`, `y > 0`, `x + y < 1`
/// (inside the triangle of non-negative XYZ, so every cone response of it is positive).
pub fn is_valid_white(white: Xy) -> bool {
    let [x, y] = white;
    x.is_finite() && y.is_finite() && x > 0.0 && y > 0.0 && x + y < 1.0
}

/// The complete CAT16 von Kries transform, in CIE XYZ, from an observer adapted to `from` to
/// one adapted to `to` (Li et al. 2017, Eq. 4–6 with `D = 1`):
/// `M16⁻¹ · diag(M16·W_to / M16·W_from) · M16`, both whites with Y = 1. It maps `from` to
/// `to` exactly, so neutrals keep their luminance. `None` if a white is not
/// [valid](is_valid_white) or a cone response of it is not positive.
pub fn cat16(from: Xy, to: Xy) -> Option<Mat3> {
    if !(is_valid_white(from) && is_valid_white(to)) {
        return None;
    }
    let m = CAT16_XYZ_TO_LMS;
    let src = mul_vec(&m, xyz_of_white(from)?);
    let dst = mul_vec(&m, xyz_of_white(to)?);
    if src.iter().chain(&dst).any(|v| v.is_nan() || *v <= 0.0) {
        return None;
    }
    let gain = [
        [dst[0] / src[0], 0.0, 0.0],
        [0.0, dst[1] / src[1], 0.0],
        [0.0, 0.0, dst[2] / src[2]],
    ];
    Some(mul_mat(&invert(&m)?, &mul_mat(&gain, &m)))
}

/// The scene white the cone image is adapted from (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum WhitePoint {
    /// The white the file declares ([`HdrImage::adopted_white`](crate::HdrImage)): Radiance
    /// files the white of their `PRIMARIES=` (E by default), OpenEXR its `adoptedNeutral` or
    /// `chromaticities` white (E for the paper's XYZ layout), PFM D65, the built-in chart E;
    /// D65 (no change) when the image declares none.
    #[default]
    Auto,
    /// No chromatic adaptation: XYZ goes to the display as it is (the paper's behaviour).
    Off,
    /// This chromaticity, whatever the file says.
    Chromaticity(Xy),
}

impl std::str::FromStr for WhitePoint {
    type Err = String;

    /// `auto`, `none` (or `off`), `E`, `D65`, or a chromaticity `x,y` (case-insensitive
    /// names).
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(WhitePoint::Auto),
            "none" | "off" => Ok(WhitePoint::Off),
            "e" => Ok(WhitePoint::Chromaticity(EQUAL_ENERGY)),
            "d65" => Ok(WhitePoint::Chromaticity(D65)),
            other => {
                let bad = || format!("{s:?} is not auto, none, E, D65 or a chromaticity x,y");
                let (x, y) = other.split_once(',').ok_or_else(bad)?;
                let x: f64 = x.trim().parse().map_err(|_| bad())?;
                let y: f64 = y.trim().parse().map_err(|_| bad())?;
                if !is_valid_white([x, y]) {
                    return Err(format!(
                        "{s:?}: a white chromaticity needs x > 0, y > 0 and x + y < 1"
                    ));
                }
                Ok(WhitePoint::Chromaticity([x, y]))
            }
        }
    }
}

impl std::fmt::Display for WhitePoint {
    /// The form [`FromStr`](std::str::FromStr) reads.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            WhitePoint::Auto => f.write_str("auto"),
            WhitePoint::Off => f.write_str("none"),
            WhitePoint::Chromaticity(w) => write!(f, "{},{}", w[0], w[1]),
        }
    }
}

/// A short name for a white chromaticity: `E`, `D65`, or `x,y` to 4 decimals.
pub fn white_name(white: Xy) -> String {
    let near = |a: Xy| (white[0] - a[0]).abs() < 5e-5 && (white[1] - a[1]).abs() < 5e-5;
    if near(EQUAL_ENERGY) {
        "E".to_string()
    } else if near(D65) {
        "D65".to_string()
    } else {
        format!("{:.4},{:.4}", white[0], white[1])
    }
}

impl Chromaticities {
    /// The matrix taking linear RGB in these primaries to CIE XYZ, normalised so that
    /// RGB = (1, 1, 1) has Y = 1 (SMPTE RP 177-1993, Sec. 3.3). Each primary's column is
    /// taken as (x, y, 1 − x − y), a multiple of its XYZ, so primaries with y = 0 work too
    /// (the CIE XYZ "primaries" red (1, 0), green (0, 1), blue (0, 0) of an EXR file whose
    /// channels hold XYZ give the identity); only the white needs y ≠ 0. `None` if the
    /// primaries are degenerate (collinear) or not finite.
    pub fn rgb_to_xyz(&self) -> Option<Mat3> {
        let col = |c: Xy| [c[0], c[1], 1.0 - c[0] - c[1]];
        let (r, g, b) = (col(self.red), col(self.green), col(self.blue));
        let [xw, yw] = self.white;
        if !(yw.abs() > 1e-12 && xw.is_finite() && yw.is_finite()) {
            return None;
        }
        let w = [xw / yw, 1.0, (1.0 - xw - yw) / yw];
        let p = [[r[0], g[0], b[0]], [r[1], g[1], b[1]], [r[2], g[2], b[2]]];
        let s = mul_vec(&invert(&p)?, w);
        let m = [
            [p[0][0] * s[0], p[0][1] * s[1], p[0][2] * s[2]],
            [p[1][0] * s[0], p[1][1] * s[1], p[1][2] * s[2]],
            [p[2][0] * s[0], p[2][1] * s[1], p[2][2] * s[2]],
        ];
        m.iter().flatten().all(|v| v.is_finite()).then_some(m)
    }
}

/// In place: linear (R, G, B) planes → CIE (X, Y, Z) planes through `m` (e.g.
/// [`Chromaticities::rgb_to_xyz`]), times `scale`, in `f64`. Results beyond the `f32`
/// range saturate to ±`f32::MAX`; NaN and infinities pass through.
pub fn rgb_planes_to_xyz(m: &Mat3, scale: f64, r: &mut [f32], g: &mut [f32], b: &mut [f32]) {
    let m: Vec<f64> = m.iter().flatten().map(|v| v * scale).collect();
    for ((pr, pg), pb) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()) {
        let (cr, cg, cb) = (f64::from(*pr), f64::from(*pg), f64::from(*pb));
        *pr = saturating_f32(m[0] * cr + m[1] * cg + m[2] * cb);
        *pg = saturating_f32(m[3] * cr + m[4] * cg + m[5] * cb);
        *pb = saturating_f32(m[6] * cr + m[7] * cg + m[8] * cb);
    }
}

/// The inverse of a 3×3 matrix, `None` if it is (nearly) singular.
pub fn invert(m: &Mat3) -> Option<Mat3> {
    let c = |r: usize, s: usize| {
        m[(r + 1) % 3][(s + 1) % 3] * m[(r + 2) % 3][(s + 2) % 3]
            - m[(r + 1) % 3][(s + 2) % 3] * m[(r + 2) % 3][(s + 1) % 3]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    let scale = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    if !det.is_finite() || det.abs() <= 1e-12 * scale.powi(3) {
        return None;
    }
    let mut inv = [[0.0; 3]; 3];
    for (r, row) in inv.iter_mut().enumerate() {
        for (s, v) in row.iter_mut().enumerate() {
            *v = c(s, r) / det;
        }
    }
    Some(inv)
}

/// `m · v`.
pub fn mul_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// `a · b`.
pub fn mul_mat(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[r][k] * b[k][c]).sum();
        }
    }
    out
}

/// CIE XYZ to linear sRGB (inverse of [`REC709`]'s [`Chromaticities::rgb_to_xyz`]).
pub fn xyz_to_linear_srgb_matrix() -> Mat3 {
    invert(&REC709.rgb_to_xyz().expect("Rec.709 primaries are valid"))
        .expect("Rec.709 matrix is invertible")
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1): linear `[0,1]` to encoded
/// `[0,1]`. Linear segment `12.92·v` below 0.0031308, else `1.055·v^(1/2.4) − 0.055`.
pub fn srgb_encode(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The inverse of [`srgb_encode`].
pub fn srgb_decode(e: f32) -> f32 {
    let e = e.clamp(0.0, 1.0);
    if e <= 0.040_45 {
        e / 12.92
    } else {
        ((e + 0.055) / 1.055).powf(2.4)
    }
}

/// A lookup table for encoding linear `[0,1]` to sRGB code values with `bits` of
/// precision (8 or 16). Indexing by `sqrt(v)` spends the entries where the curve is
/// steep (near black); with 4096 entries and linear interpolation the error is below
/// 0.1 code value at 8 bits and a few code values at 16 bits.
#[derive(Debug, Clone)]
pub struct SrgbLut {
    /// `N + 1` entries (a fixed size: the loads need no bounds checks).
    table: Box<[f32; SrgbLut::N + 1]>,
    max_code: f32,
}

impl SrgbLut {
    const N: usize = 4096;

    /// A table producing code values in `0..=2^bits − 1`.
    pub fn new(bits: u32) -> Self {
        let max_code = ((1u64 << bits) - 1) as f32;
        let table: Vec<f32> = (0..=Self::N)
            .map(|i| {
                let s = i as f32 / Self::N as f32;
                srgb_encode(s * s) * max_code
            })
            .collect();
        let table = table.into_boxed_slice().try_into().expect("N + 1 entries");
        SrgbLut { table, max_code }
    }

    /// The code value (rounded) of the linear value `v` (clamped to `[0, 1]`, NaN → 0).
    #[inline(always)]
    pub fn encode(&self, v: f32) -> u16 {
        let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
        let pos = v.sqrt() * Self::N as f32;
        let i = (pos as usize).min(Self::N - 1);
        let f = pos - i as f32;
        let c = self.table[i] + (self.table[i + 1] - self.table[i]) * f;
        (c + 0.5).min(self.max_code) as u16
    }

    /// The codes of a row of pixels, interleaved RGB, two bytes each, big-endian (PNG's
    /// order) or little-endian, into `out` (`6 × r.len()` bytes; `g` and `b` as long as
    /// `r`): the same as [`SrgbLut::encode`] on each sample, in steps of 16 pixels that
    /// the compiler vectorises (run it inside `Isa::run` for the wider instruction sets).
    #[inline(always)]
    pub(crate) fn encode_rgb(
        &self,
        r: &[f32],
        g: &[f32],
        b: &[f32],
        big_endian: bool,
        out: &mut [u8],
    ) {
        let n = r.len();
        let (r, g, b, out) = (&r[..n], &g[..n], &b[..n], &mut out[..6 * n]);
        let bytes = |c: u16| {
            if big_endian {
                c.to_be_bytes()
            } else {
                c.to_le_bytes()
            }
        };
        let whole = n - n % SRGB8_STEP;
        for (k, px) in out[..6 * whole]
            .chunks_exact_mut(6 * SRGB8_STEP)
            .enumerate()
        {
            let at = k * SRGB8_STEP;
            let codes = |plane: &[f32]| {
                let mut c = [0u16; SRGB8_STEP];
                for (c, &v) in c.iter_mut().zip(&plane[at..at + SRGB8_STEP]) {
                    *c = self.encode(v);
                }
                c
            };
            let (cr, cg, cb) = (codes(r), codes(g), codes(b));
            for (i, px) in px.chunks_exact_mut(6).enumerate() {
                px[0..2].copy_from_slice(&bytes(cr[i]));
                px[2..4].copy_from_slice(&bytes(cg[i]));
                px[4..6].copy_from_slice(&bytes(cb[i]));
            }
        }
        for (i, px) in out[6 * whole..].chunks_exact_mut(6).enumerate() {
            let i = whole + i;
            px[0..2].copy_from_slice(&bytes(self.encode(r[i])));
            px[2..4].copy_from_slice(&bytes(self.encode(g[i])));
            px[4..6].copy_from_slice(&bytes(self.encode(b[i])));
        }
    }
}

/// Exact 8-bit sRGB encoding: `round(255·srgb_encode(v))` computed in `f64`, for every
/// `f32`, without a power function or a branch, one table load per sample.
///
/// The code of `v` is the number of thresholds `t_c = srgb_decode((c − ½)/255)`,
/// `c = 1..=255`, at or below it. A bucket is the set of `f32` sharing the top 17 bits
/// of their bit pattern (sign, exponent and 8 mantissa bits); the table covers the
/// buckets from `2⁻¹³` to `1.0` (below `2⁻¹³` every value encodes to 0, as
/// `t_1 ≈ 1.5e-4`). A bucket is at most 2⁻⁸ of its value wide, where the curve rises by
/// at most 0.44 codes (at `v = 1`: slope `255·1.055/2.4`, times `1/256`), so at most one
/// threshold falls inside it; its entry holds the code at the bucket's start (bits 16
/// and up) and the low 15 bits of the pattern of that threshold (`0x8000`, above every
/// 15-bit value, if there is none): the code is the first plus whether `v`'s low 15 bits
/// reach the second. `srgb8_is_exact_at_every_code` checks both sides of every
/// threshold, `srgb8_rows_match_the_exact_curve` a dense sweep with the special values.
#[derive(Debug, Clone)]
pub(crate) struct Srgb8 {
    /// Per bucket from `2⁻¹³` to `1.0`: `code << 16 | low bits of the next threshold`.
    table: Box<[u32; SRGB8_BUCKETS]>,
    /// `thresholds[c]`: the smallest `f32` encoding to `c` (`[0]` = 0, `[256]` = ∞).
    #[cfg_attr(not(test), allow(dead_code))]
    thresholds: [f32; 257],
}

/// Bucket of the smallest `v` the table covers, `2⁻¹³` (its bit pattern >> 15).
const SRGB8_FIRST_BUCKET: u32 = (127 - 13) << 8;

/// Buckets from `2⁻¹³` to `1.0`: 13 octaves of 256, and `1.0`'s.
const SRGB8_BUCKETS: usize = 13 * 256 + 1;

/// Pixels per step of [`Srgb8::encode_rgb`] and [`SrgbLut::encode_rgb`]: one 16-lane
/// AVX-512 vector per channel.
const SRGB8_STEP: usize = 16;

impl Srgb8 {
    /// The shared encoder (built once, 13 kB of table).
    pub(crate) fn get() -> &'static Srgb8 {
        static ENCODER: std::sync::OnceLock<Srgb8> = std::sync::OnceLock::new();
        ENCODER.get_or_init(Srgb8::build)
    }

    fn build() -> Srgb8 {
        let decode = |e: f64| {
            if e <= 0.040_45 {
                e / 12.92
            } else {
                ((e + 0.055) / 1.055).powf(2.4)
            }
        };
        let mut thresholds = [f32::INFINITY; 257];
        thresholds[0] = 0.0;
        for (c, t) in thresholds.iter_mut().enumerate().take(256).skip(1) {
            let exact = decode((c as f64 - 0.5) / 255.0);
            let mut f = exact as f32;
            if f64::from(f) < exact {
                f = f.next_up();
            }
            *t = f;
        }
        let last = 1.0f32.to_bits() >> 15;
        let table: Vec<u32> = (SRGB8_FIRST_BUCKET..=last)
            .map(|b| {
                let start = f32::from_bits(b << 15);
                let code = thresholds.iter().skip(1).filter(|&&t| t <= start).count();
                let next = thresholds[code + 1];
                let inside = |t: f32| t.is_finite() && t.to_bits() >> 15 == b;
                assert!(
                    !inside(thresholds[(code + 2).min(256)]),
                    "two thresholds in bucket {b}"
                );
                let low = if inside(next) {
                    next.to_bits() & 0x7fff
                } else {
                    0x8000
                };
                (code as u32) << 16 | low
            })
            .collect();
        // Below the first bucket (mapped onto it) every value encodes to 0.
        assert!(thresholds[1] > f32::from_bits((SRGB8_FIRST_BUCKET + 1) << 15));
        let table = table.into_boxed_slice().try_into().expect("13 octaves");
        Srgb8 { table, thresholds }
    }

    /// The code of linear `v` (clamped to `[0, 1]`; NaN → 0).
    #[inline(always)]
    pub(crate) fn encode(&self, v: f32) -> u8 {
        let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
        let bits = v.to_bits();
        let bucket = (bits >> 15).saturating_sub(SRGB8_FIRST_BUCKET) as usize;
        // `bucket` is at most the last one (`v ≤ 1`); `min` lets the load go unchecked.
        let entry = self.table[bucket.min(SRGB8_BUCKETS - 1)];
        ((entry >> 16) + u32::from(bits & 0x7fff >= entry & 0xffff)) as u8
    }

    /// The codes of a row of pixels, interleaved RGB, into `out` (`3 × r.len()` bytes;
    /// `g` and `b` as long as `r`): the same as [`Srgb8::encode`] on each sample, in
    /// steps of 16 pixels that the compiler vectorises (the table loads as gathers where
    /// the instruction set has them: run it inside [`Isa::run`](crate::simd::Isa)).
    #[inline(always)]
    pub(crate) fn encode_rgb(&self, r: &[f32], g: &[f32], b: &[f32], out: &mut [u8]) {
        let n = r.len();
        let (r, g, b, out) = (&r[..n], &g[..n], &b[..n], &mut out[..3 * n]);
        let whole = n - n % SRGB8_STEP;
        for (k, px) in out[..3 * whole]
            .chunks_exact_mut(3 * SRGB8_STEP)
            .enumerate()
        {
            let at = k * SRGB8_STEP;
            let codes = |plane: &[f32]| {
                let mut c = [0u8; SRGB8_STEP];
                for (c, &v) in c.iter_mut().zip(&plane[at..at + SRGB8_STEP]) {
                    *c = self.encode(v);
                }
                c
            };
            let (cr, cg, cb) = (codes(r), codes(g), codes(b));
            for (i, px) in px.chunks_exact_mut(3).enumerate() {
                px[0] = cr[i];
                px[1] = cg[i];
                px[2] = cb[i];
            }
        }
        for (i, px) in out[3 * whole..].chunks_exact_mut(3).enumerate() {
            let i = whole + i;
            px[0] = self.encode(r[i]);
            px[1] = self.encode(g[i]);
            px[2] = self.encode(b[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every 8-bit code: its threshold encodes to it, the float just below to the code
    /// before; the exact reference is `round(255·encode(v))` in `f64`.
    #[test]
    fn srgb8_is_exact_at_every_code() {
        let enc = Srgb8::get();
        let exact = |v: f32| {
            let v = f64::from(v);
            let e = if v <= 0.003_130_8 {
                12.92 * v
            } else {
                1.055 * v.powf(1.0 / 2.4) - 0.055
            };
            (e * 255.0).round() as u8
        };
        for c in 1..=255usize {
            let t = enc.thresholds[c];
            assert_eq!(enc.encode(t), c as u8, "threshold of {c}");
            assert_eq!(exact(t), c as u8, "threshold of {c}");
            assert_eq!(enc.encode(t.next_down()), c as u8 - 1, "below {c}");
            assert_eq!(exact(t.next_down()), c as u8 - 1, "below {c}");
        }
        // And a dense sweep, the edges and the bad values.
        for i in 0..=1_000_000 {
            let v = i as f32 / 1e6;
            assert_eq!(enc.encode(v), exact(v), "{v}");
        }
        for (v, c) in [(0.0, 0), (-1.0, 0), (f32::NAN, 0), (1.0, 255), (7.0, 255)] {
            assert_eq!(enc.encode(v), c, "{v}");
        }
        assert_eq!(enc.encode(f32::INFINITY), 255);
        assert_eq!(enc.encode(f32::MIN_POSITIVE), 0);
    }

    #[test]
    fn rec709_matrix_matches_iec_61966_2_1() {
        // IEC 61966-2-1 Eq. (F.7) quotes the sRGB → XYZ matrix to 4 decimals.
        let m = REC709.rgb_to_xyz().unwrap();
        let expected = [
            [0.4124, 0.3576, 0.1805],
            [0.2126, 0.7152, 0.0722],
            [0.0193, 0.1192, 0.9505],
        ];
        for r in 0..3 {
            for c in 0..3 {
                assert!(
                    (m[r][c] - expected[r][c]).abs() < 1.5e-4,
                    "{r},{c}: {}",
                    m[r][c]
                );
            }
        }
    }

    #[test]
    fn radiance_primaries_have_equal_energy_white() {
        let m = RADIANCE_DEFAULT.rgb_to_xyz().unwrap();
        let w = mul_vec(&m, [1.0, 1.0, 1.0]);
        assert!(
            (w[0] - 1.0).abs() < 1e-12 && (w[1] - 1.0).abs() < 1e-12 && (w[2] - 1.0).abs() < 1e-12
        );
    }

    #[test]
    fn xyz_primaries_give_the_identity() {
        let xyz = Chromaticities {
            red: [1.0, 0.0],
            green: [0.0, 1.0],
            blue: [0.0, 0.0],
            white: [1.0 / 3.0, 1.0 / 3.0],
        };
        let m = xyz.rgb_to_xyz().unwrap();
        for (r, row) in m.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                let e = if r == c { 1.0 } else { 0.0 };
                assert!((v - e).abs() < 1e-12, "{r},{c}: {v}");
            }
        }
    }

    #[test]
    fn degenerate_primaries_are_rejected() {
        let c = Chromaticities {
            red: [0.3, 0.3],
            green: [0.3, 0.3],
            blue: [0.15, 0.06],
            white: REC709.white,
        };
        assert!(c.rgb_to_xyz().is_none());
    }

    #[test]
    fn cat16_e_to_d65_matches_an_independent_computation() {
        // colour-science 0.4.7, `chromatic_adaptation_VonKries(..., transform="CAT16")` from
        // E (1/3, 1/3) to D65 (0.3127, 0.3290), as quoted to 5 decimals.
        let expected = [
            [0.98586, -0.04907, 0.01366],
            [-0.00637, 1.00614, 0.00023],
            [0.00011, 0.00394, 1.08500],
        ];
        let m = cat16(EQUAL_ENERGY, D65).unwrap();
        for r in 0..3 {
            for c in 0..3 {
                assert!(
                    (m[r][c] - expected[r][c]).abs() < 1e-4,
                    "{r},{c}: {}",
                    m[r][c]
                );
            }
        }
    }

    #[test]
    fn cat16_maps_white_to_white_and_keeps_its_luminance() {
        for (from, to) in [
            (EQUAL_ENERGY, D65),
            (D65, EQUAL_ENERGY),
            ([0.4476, 0.4074], D65),
        ] {
            let m = cat16(from, to).unwrap();
            let w = mul_vec(&m, xyz_of_white(from).unwrap());
            let t = xyz_of_white(to).unwrap();
            for i in 0..3 {
                assert!((w[i] - t[i]).abs() < 1e-12, "{from:?} -> {to:?}: {w:?}");
            }
        }
        let same = cat16(D65, D65).unwrap();
        for (r, row) in same.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                assert!((v - IDENTITY[r][c]).abs() < 1e-12);
            }
        }
        assert!(cat16([0.0, 0.3], D65).is_none());
        assert!(cat16([0.6, 0.5], D65).is_none());
        assert!(cat16(D65, [f64::NAN, 0.3]).is_none());
    }

    #[test]
    fn white_point_parses_names_and_chromaticities() {
        let p = |s: &str| s.parse::<WhitePoint>();
        assert_eq!(p("auto"), Ok(WhitePoint::Auto));
        assert_eq!(p("none"), Ok(WhitePoint::Off));
        assert_eq!(p("E"), Ok(WhitePoint::Chromaticity(EQUAL_ENERGY)));
        assert_eq!(p("d65"), Ok(WhitePoint::Chromaticity(D65)));
        assert_eq!(
            p("0.4476,0.4074"),
            Ok(WhitePoint::Chromaticity([0.4476, 0.4074]))
        );
        for bad in ["", "D50x", "0.3", "0.3,", "0,0.3", "0.7,0.5", "nan,0.3"] {
            assert!(p(bad).is_err(), "{bad}");
        }
        assert_eq!(white_name(EQUAL_ENERGY), "E");
        assert_eq!(white_name(D65), "D65");
        assert_eq!(white_name([0.4476, 0.4074]), "0.4476,0.4074");
    }

    /// `round(255·srgb_encode(v))` in `f64`, `v` clamped to `[0, 1]`, NaN → 0: the
    /// reference of [`Srgb8`].
    fn exact8(v: f32) -> u8 {
        let v = if v > 0.0 { f64::from(v.min(1.0)) } else { 0.0 };
        let e = if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (e * 255.0).round() as u8
    }

    /// A dense sweep: every 251st `f32` pattern from 0 to just above 1 (4.2 M values, all
    /// the low bits visited), the four floats on each side of every code's threshold,
    /// zeros, subnormals, negatives, values above 1, infinities and NaNs. [`Srgb8::encode`]
    /// and [`Srgb8::encode_rgb`] (at every instruction-set level, rows of every length
    /// modulo the 16-pixel step) give exactly the reference code for each.
    #[test]
    fn srgb8_rows_match_the_exact_curve() {
        let enc = Srgb8::get();
        let mut values: Vec<f32> = (0..=1.0f32.next_up().to_bits())
            .step_by(251)
            .map(f32::from_bits)
            .collect();
        for &t in &enc.thresholds[1..256] {
            let mut v = t;
            for _ in 0..4 {
                v = v.next_down();
            }
            for _ in 0..8 {
                values.push(v);
                v = v.next_up();
            }
        }
        values.extend([
            0.0,
            -0.0,
            1.0,
            1.0f32.next_up(),
            1.0f32.next_down(),
            2.0,
            1e30,
            f32::MAX,
            -1.0,
            -1e-30,
            f32::MIN,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            -f32::from_bits(1),
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::from_bits(0x7fc0_1234),
            f32::from_bits(0xffff_ffff),
        ]);
        let expected: Vec<u8> = values.iter().map(|&v| exact8(v)).collect();
        let scalar: Vec<u8> = values.iter().map(|&v| enc.encode(v)).collect();
        let first_bad = scalar.iter().zip(&expected).position(|(a, b)| a != b);
        assert_eq!(first_bad, None, "{:?}", first_bad.map(|i| values[i]));
        // Three planes: the values, reversed, and rotated by one.
        let n = values.len();
        let g: Vec<f32> = values.iter().rev().copied().collect();
        let b: Vec<f32> = (0..n).map(|i| values[(i + 1) % n]).collect();
        for isa in crate::simd::Isa::all_available() {
            for len in [n, n - 1, n - 15, 17, 16, 15, 1, 0] {
                let mut out = vec![0u8; 3 * len];
                crate::simd::at_level!(
                    isa,
                    enc.encode_rgb(&values[..len], &g[..len], &b[..len], &mut out)
                );
                for (i, px) in out.chunks_exact(3).enumerate() {
                    let want = [expected[i], expected[n - 1 - i], expected[(i + 1) % n]];
                    assert_eq!(px, want, "{isa:?}, row of {len}, pixel {i}: {}", values[i]);
                }
            }
        }
    }

    /// [`SrgbLut::encode_rgb`] (16 bits, both byte orders, every instruction-set level,
    /// rows of every length modulo the 16-pixel step) gives exactly [`SrgbLut::encode`]'s
    /// codes, on a dense sweep of `[0, 1]` with the special values.
    #[test]
    fn srgb16_rows_match_the_per_sample_codes() {
        let lut = SrgbLut::new(16);
        let mut values: Vec<f32> = (0..=1.0f32.next_up().to_bits())
            .step_by(4099)
            .map(f32::from_bits)
            .collect();
        values.extend([0.0, -0.0, 1.0, 2.0, -1.0, f32::INFINITY, f32::NEG_INFINITY]);
        values.extend([f32::NAN, -f32::NAN, f32::MIN_POSITIVE, f32::MAX, f32::MIN]);
        let n = values.len();
        let g: Vec<f32> = values.iter().rev().copied().collect();
        let b: Vec<f32> = (0..n).map(|i| values[(i + 1) % n]).collect();
        for isa in crate::simd::Isa::all_available() {
            for big_endian in [true, false] {
                for len in [n, n - 1, n - 15, 17, 16, 15, 1, 0] {
                    let mut out = vec![0u8; 6 * len];
                    let (r, g, b) = (&values[..len], &g[..len], &b[..len]);
                    crate::simd::at_level!(isa, lut.encode_rgb(r, g, b, big_endian, &mut out));
                    for (i, px) in out.chunks_exact(6).enumerate() {
                        let code = |k: usize| {
                            let c = [px[2 * k], px[2 * k + 1]];
                            if big_endian {
                                u16::from_be_bytes(c)
                            } else {
                                u16::from_le_bytes(c)
                            }
                        };
                        let want = [r[i], g[i], b[i]].map(|v| lut.encode(v));
                        assert_eq!([code(0), code(1), code(2)], want, "{isa:?}, {len}, {i}");
                    }
                }
            }
        }
        assert_eq!(lut.encode(f32::NAN), 0);
        assert_eq!(lut.encode(f32::INFINITY), 65535);
    }

    #[test]
    fn srgb_curve_round_trips_and_hits_reference_points() {
        // IEC 61966-2-1: linear 0.5 encodes to 0.7354; 0.0031308 sits at the knee (0.04045).
        assert!((srgb_encode(0.5) - 0.735_357).abs() < 1e-5);
        assert!((srgb_encode(0.003_130_8) - 0.040_45).abs() < 1e-5);
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert!((srgb_decode(srgb_encode(v)) - v).abs() < 1e-5);
        }
    }

    #[test]
    fn lut_matches_exact_curve() {
        let lut = SrgbLut::new(8);
        for i in 0..=10000 {
            let v = i as f32 / 10000.0;
            let exact = (srgb_encode(v) * 255.0).round();
            assert!((lut.encode(v) as f32 - exact).abs() <= 1.0, "{v}");
        }
        let lut16 = SrgbLut::new(16);
        for i in 0..=10000 {
            let v = i as f32 / 10000.0;
            let exact = srgb_encode(v) * 65535.0;
            assert!((lut16.encode(v) as f32 - exact).abs() <= 8.0, "{v}");
        }
        assert_eq!(lut.encode(f32::NAN), 0);
        assert_eq!(lut.encode(2.0), 255);
    }
}
