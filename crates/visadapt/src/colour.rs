//! Colour spaces: RGB primaries to CIE XYZ, XYZ to linear sRGB, and the sRGB transfer curve.
//!
//! The model works in CIE XYZ (paper Sec. 4: "image files with photopic luminance (CIE Y),
//! scotopic luminance, and CIE XZ channels"), and outputs "a fixed RGB color space", which
//! here is sRGB: ITU-R BT.709 primaries, D65 white, the IEC 61966-2-1 transfer curve.

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
    let saturate = |v: f64| {
        if v.is_finite() {
            v.clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
        } else {
            v as f32
        }
    };
    let m: Vec<f64> = m.iter().flatten().map(|v| v * scale).collect();
    for ((pr, pg), pb) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()) {
        let (cr, cg, cb) = (f64::from(*pr), f64::from(*pg), f64::from(*pb));
        *pr = saturate(m[0] * cr + m[1] * cg + m[2] * cb);
        *pg = saturate(m[3] * cr + m[4] * cg + m[5] * cb);
        *pb = saturate(m[6] * cr + m[7] * cg + m[8] * cb);
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
    table: Vec<f32>,
    max_code: f32,
}

impl SrgbLut {
    const N: usize = 4096;

    /// A table producing code values in `0..=2^bits − 1`.
    pub fn new(bits: u32) -> Self {
        let max_code = ((1u64 << bits) - 1) as f32;
        let table = (0..=Self::N)
            .map(|i| {
                let s = i as f32 / Self::N as f32;
                srgb_encode(s * s) * max_code
            })
            .collect();
        SrgbLut { table, max_code }
    }

    /// The code value (rounded) of the linear value `v` (clamped to `[0, 1]`, NaN → 0).
    #[inline]
    pub fn encode(&self, v: f32) -> u16 {
        let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
        let pos = v.sqrt() * Self::N as f32;
        let i = (pos as usize).min(Self::N - 1);
        let f = pos - i as f32;
        let c = self.table[i] + (self.table[i + 1] - self.table[i]) * f;
        (c + 0.5).min(self.max_code) as u16
    }
}

/// Exact 8-bit sRGB encoding: `round(255·srgb_encode(v))` computed in `f64`, for every
/// `f32`, without a power function.
///
/// The code of `v` is the number of thresholds `t_c = srgb_decode((c − ½)/255)`,
/// `c = 1..=255`, at or below it. A table indexed by the top 16 bits of `v`'s bit pattern
/// (exponent and 8 mantissa bits, for `v ≥ 2⁻¹³`; below, every value encodes to 0 as
/// `t_1 ≈ 1.5e-4`) gives the code at the start of each bucket; a bucket is at most 2⁻⁸
/// of its value wide, where the curve rises by at most 0.44 codes (at `v = 1`: slope
/// `255·1.055/2.4`), so one comparison with the next threshold finishes the job.
/// `srgb8_is_exact_at_every_code` checks both sides of every threshold.
#[derive(Debug, Clone)]
pub(crate) struct Srgb8 {
    /// Code at the start of each bucket, from `2⁻¹³` to `1.0`.
    base: Vec<u8>,
    /// `thresholds[c]`: the smallest `f32` encoding to `c` (`[0]` = 0, `[256]` = ∞).
    thresholds: [f32; 257],
}

/// Bucket of the smallest `v` the table covers, `2⁻¹³` (its bit pattern >> 15).
const SRGB8_FIRST_BUCKET: u32 = (127 - 13) << 8;

impl Srgb8 {
    /// The shared encoder (built once, 3.6 kB).
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
        let base = (SRGB8_FIRST_BUCKET..=last)
            .map(|b| {
                let start = f32::from_bits(b << 15);
                thresholds.iter().skip(1).filter(|&&t| t <= start).count() as u8
            })
            .collect();
        Srgb8 { base, thresholds }
    }

    /// The code of linear `v` (clamped to `[0, 1]`; NaN → 0).
    #[inline(always)]
    pub(crate) fn encode(&self, v: f32) -> u8 {
        let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
        let bucket = ((v.to_bits() >> 15).saturating_sub(SRGB8_FIRST_BUCKET)) as usize;
        let c = self.base[bucket.min(self.base.len() - 1)];
        c + u8::from(v >= self.thresholds[usize::from(c) + 1])
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
