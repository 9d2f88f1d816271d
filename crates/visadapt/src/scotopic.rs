//! Scotopic luminance, the input of the rod system.
//!
//! The paper's renderer wrote a scotopic luminance channel beside CIE XYZ (Sec. 4); when
//! an image has one, the operator uses it. Otherwise this module estimates it from CIE XYZ.
//!
//! Units: scotopic cd/m², i.e. `K'm ∫ L_e(λ) V'(λ) dλ` with the CIE 1951 scotopic luminous
//! efficiency V'(λ) and K'm = 1700 lm/W (CIE 1951; `colour.constants.CONSTANT_KP_M`).
//! For equal-energy white the ratio of scotopic to photopic luminance (S/P) is then
//! 1700·∫V' / (683·∫ȳ) = 2.261 (computed from the CIE 5 nm tables, 380–780 nm).
//!
//! # The estimate
//!
//! `V ≈ max(0, a·X + b·Y + c·Z)` with X, Y, Z in cd/m². The coefficients are a least-squares
//! fit (made for this project) of the scotopic/photopic ratio of the 24 ColorChecker
//! reflectances (N. Ohta's spectral data) under illuminants E, D65, A, D50, FL2 and FL11,
//! integrated at 5 nm with the CIE 1931 2° colour-matching functions and CIE 1951 V'(λ),
//! constrained so that equal-energy white gives exactly S/P = 2.261. Measured accuracy of
//! the fit (S/P relative to the spectral value): D65 2.427 vs 2.465 (−1.5 %), illuminant A
//! 1.397 vs 1.412 (−1.1 %), ColorChecker blue under E 5.83 vs 5.66; the worst case is the
//! saturated red patch (0.54 vs 0.85): long-wavelength reflectors are where no 3×3 linear
//! map can follow V'(λ). RMS relative error over the 144 samples: 16 %.
//!
//! Other published forms and why they are not used: Pattanaik et al. 1998
//! `-0.702X + 1.039Y + 0.433Z` is a fit of V'(λ) normalised to peak 1 (S/P 0.77 for white,
//! not 2.26); Ward Larson et al. 1997 Eq. 13 `Y·(1.33·(1 + (Y+Z)/X) − 1.68)` gives 2.31 for
//! white and diverges as X → 0. The clamp at zero keeps saturated reds (whose linear
//! estimate dips below zero near 620 nm, where V' is under 1 %) from going negative.

/// Coefficient of X in the scotopic estimate (fit described in the module docs).
pub const COEFF_X: f32 = -1.285_712;
/// Coefficient of Y in the scotopic estimate (fit described in the module docs).
pub const COEFF_Y: f32 = 2.402_365;
/// Coefficient of Z in the scotopic estimate (fit described in the module docs).
pub const COEFF_Z: f32 = 1.144_503;

/// Scotopic-to-photopic luminance ratio of equal-energy white, `1700·∫V'/(683·∫ȳ)`,
/// computed from the CIE 1931 and CIE 1951 5 nm tables (380–780 nm).
pub const EQUAL_ENERGY_SP_RATIO: f64 = 2.261;

/// Estimated scotopic luminance (scotopic cd/m²) of a colour given in CIE XYZ (cd/m²).
/// Never negative, and finite for finite input.
#[inline]
pub fn from_xyz(x: f32, y: f32, z: f32) -> f32 {
    // Computed at a quarter scale (exact: powers of two), so that no product overflows
    // near f32::MAX and the sum cannot be Inf − Inf = NaN; clamped there, then scaled back:
    // the same value as the plain sum wherever that is finite, at most f32::MAX.
    const Q: f32 = 0.25;
    let quarter = (Q * COEFF_X) * x + (Q * COEFF_Y) * y + (Q * COEFF_Z) * z;
    quarter.clamp(0.0, Q * f32::MAX) * 4.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finite_for_every_finite_input() {
        let m = f32::MAX;
        for (x, y, z) in [
            (m, m, m),
            (-m, m, m),
            (m, -m, -m),
            (0.0, m, m),
            (-m, 0.0, 0.0),
        ] {
            let v = from_xyz(x, y, z);
            assert!(v.is_finite() && v >= 0.0, "{x} {y} {z}: {v}");
        }
        assert_eq!(from_xyz(0.0, m, m), m);
        // Unchanged where the plain sum is finite.
        let plain = |x: f32, y: f32, z: f32| (COEFF_X * x + COEFF_Y * y + COEFF_Z * z).max(0.0);
        for (x, y, z) in [
            (1.0, 1.0, 1.0),
            (0.3, 2.5, 7.0),
            (1e30, 1e30, 1e30),
            (1e-30, 3e-30, 0.0),
        ] {
            assert_eq!(from_xyz(x, y, z), plain(x, y, z));
        }
    }

    #[test]
    fn equal_energy_white_has_sp_2_26() {
        let v = from_xyz(1.0, 1.0, 1.0);
        assert!((v as f64 - EQUAL_ENERGY_SP_RATIO).abs() < 2e-3, "{v}");
    }

    /// S/P of CIE illuminants computed spectrally (colour-science 0.4.7, CIE 1931 2° and
    /// CIE 1951 tables, 5 nm): D65 2.465, A 1.412. Chromaticities from CIE 15:2004.
    #[test]
    fn illuminant_sp_ratios_within_two_percent() {
        let d65 = from_xyz(0.950_43, 1.0, 1.088_80);
        assert!((d65 / 2.465 - 1.0).abs() < 0.02, "{d65}");
        let a = from_xyz(1.098_50, 1.0, 0.355_85);
        assert!((a / 1.412 - 1.0).abs() < 0.02, "{a}");
    }

    /// Blue reflectors are rod-rich, red ones rod-poor: the Purkinje shift depends on it.
    /// XYZ of the ColorChecker blue and red patches under illuminant E (N. Ohta data).
    #[test]
    fn blue_patch_is_rod_rich_red_patch_rod_poor() {
        let blue = from_xyz(0.082_13, 0.060_03, 0.271_97) / 0.060_03;
        let red = from_xyz(0.229_22, 0.129_14, 0.047_84) / 0.129_14;
        assert!(blue > 5.0 && blue < 6.5, "{blue}");
        assert!(red < 1.0, "{red}");
    }

    /// Spectrum-locus colours (CIE 1931 CMF values at 5 nm steps, a subset) never give a
    /// negative, infinite or NaN estimate, even at 1e30 cd/m².
    #[test]
    fn saturated_colours_stay_finite_and_non_negative() {
        let locus = [
            (0.1644, 0.0174, 0.8130), // 450 nm
            (0.0049, 0.3230, 0.2720), // 500 nm
            (0.2904, 0.9540, 0.0203), // 550 nm
            (1.0622, 0.6310, 0.0008), // 600 nm
            (0.8544, 0.3810, 0.0002), // 620 nm
            (0.2835, 0.1070, 0.0),    // 650 nm
            (0.0114, 0.0041, 0.0),    // 700 nm
        ];
        for (x, y, z) in locus {
            for s in [1e-30f32, 1.0, 1e30] {
                let v = from_xyz(x * s, y * s, z * s);
                assert!(v.is_finite() && v >= 0.0, "{x},{y},{z} x {s}: {v}");
            }
        }
        assert_eq!(from_xyz(0.2835, 0.1070, 0.0), 0.0);
    }
}
