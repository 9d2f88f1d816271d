//! Spectral data and integration: from spectral radiance to CIE XYZ and scotopic luminance.
//!
//! The paper's test scene was "rendered ... with a spectral color model, diffuse illumination
//! that is uniform across the visible spectrum, and the standard reflectivities for the
//! Macbeth chart" (Ferwerda et al. 1996, Sec. 5), and its renderer wrote photopic (CIE Y),
//! scotopic and CIE X, Z channels (Sec. 4). This module holds the tables needed to do the
//! same, at 5 nm from 380 to 780 nm ([`tables`]):
//!
//! * the CIE 1931 2° colour-matching functions x̄, ȳ, z̄ (ȳ is the photopic V(λ), Fig. 2);
//! * the CIE 1951 scotopic luminous efficiency V'(λ) (Fig. 2);
//! * the spectral reflectances of the 24 ColorChecker patches measured by N. Ohta (1997);
//! * the equal-energy illuminant E.
//!
//! The tables were generated from colour-science 0.4.7 by
//! `crates/visadapt/tools/gen_spectral_tables.py` (not run by the build). Public V'(λ) tables
//! with shifted values exist (model notes §3.3), so the tests below check the tables against
//! values of the CIE standards typed in from Wyszecki & Stiles (1982) Table I(3.3.1) and
//! Table I(4.3.2).
//!
//! # Units
//!
//! A spectral radiance `L_e(λ)` in W·sr⁻¹·m⁻²·nm⁻¹ gives `Y = K_m Σ L_e ȳ Δλ` in cd/m²
//! (K_m = 683 lm/W) and the scotopic luminance `V = K'_m Σ L_e V' Δλ` in scotopic cd/m²
//! (K'_m = 1700 lm/W), the units of the whole library. X and Z use K_m like Y.
//!
//! Submodule [`sensitivity`] derives the spectral sensitivity of the rod and cone systems at
//! a level of adaptation from the model (paper Fig. 4).

pub mod sensitivity;
pub mod tables;

pub use tables::{FIRST_NM, SAMPLES, STEP_NM};

/// Maximum photopic luminous efficacy K_m, lm/W, at 555 nm (CIE 15:2004; the SI
/// definition of the candela fixes 683 lm/W at 540 THz).
pub const PHOTOPIC_EFFICACY_LM_PER_W: f64 = 683.0;

/// Maximum scotopic luminous efficacy K'_m, lm/W, at 507 nm (CIE 1951, rounded from
/// 1700.06; colour-science `CONSTANT_KP_M`). The unit of scotopic luminance throughout the
/// library (see [`scotopic`](crate::scotopic)).
pub const SCOTOPIC_EFFICACY_LM_PER_W: f64 = 1700.0;

/// A spectrum sampled at the table wavelengths ([`wavelength_nm`]).
pub type Spectrum = [f64; SAMPLES];

/// The equal-energy illuminant E: the same spectral power at every wavelength (CIE 15:2004),
/// the paper's "illumination that is uniform across the visible spectrum" (Sec. 5).
pub const EQUAL_ENERGY: Spectrum = [1.0; SAMPLES];

/// The wavelength of sample `i`, nm.
pub fn wavelength_nm(i: usize) -> f64 {
    FIRST_NM + STEP_NM * i as f64
}

/// The photometric quantities of a spectral radiance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Photometry {
    /// CIE X, on the scale of `y`.
    pub x: f64,
    /// CIE Y: photopic luminance, cd/m² for a radiance in W·sr⁻¹·m⁻²·nm⁻¹.
    pub y: f64,
    /// CIE Z, on the scale of `y`.
    pub z: f64,
    /// Scotopic luminance, scotopic cd/m² for a radiance in W·sr⁻¹·m⁻²·nm⁻¹.
    pub scotopic: f64,
}

impl Photometry {
    /// The scotopic-to-photopic ratio S/P (NaN for a black spectrum).
    pub fn sp_ratio(&self) -> f64 {
        self.scotopic / self.y
    }

    /// Every quantity multiplied by `factor`.
    pub fn scaled(&self, factor: f64) -> Self {
        Photometry {
            x: self.x * factor,
            y: self.y * factor,
            z: self.z * factor,
            scotopic: self.scotopic * factor,
        }
    }
}

/// Integrate a spectral radiance (W·sr⁻¹·m⁻²·nm⁻¹ at the table wavelengths) against the
/// CIE 1931 colour-matching functions and CIE 1951 V'(λ): rectangle rule at 5 nm, as CIE
/// 15:2004 §7.1 prescribes for tabulated data.
pub fn integrate(radiance: &Spectrum) -> Photometry {
    let sum = |weights: &Spectrum| -> f64 {
        radiance
            .iter()
            .zip(weights)
            .map(|(l, w)| l * w)
            .sum::<f64>()
            * STEP_NM
    };
    let km = PHOTOPIC_EFFICACY_LM_PER_W;
    Photometry {
        x: km * sum(&tables::CIE1931_X_BAR),
        y: km * sum(&tables::CIE1931_Y_BAR),
        z: km * sum(&tables::CIE1931_Z_BAR),
        scotopic: SCOTOPIC_EFFICACY_LM_PER_W * sum(&tables::CIE1951_V_PRIME),
    }
}

/// The radiance reflected by a diffuse surface: `illuminant(λ)·reflectance(λ)`.
pub fn reflected(illuminant: &Spectrum, reflectance: &Spectrum) -> Spectrum {
    std::array::from_fn(|i| illuminant[i] * reflectance[i])
}

/// The spectral reflectance of ColorChecker patch `index` (0 = dark skin … 23 = black, chart
/// order), N. Ohta's measurements ([`tables::COLORCHECKER_OHTA`]).
///
/// # Panics
/// If `index >= 24`.
pub fn colorchecker(index: usize) -> &'static Spectrum {
    &tables::COLORCHECKER_OHTA[index]
}

/// Sprague (1880) interpolation of a 5 nm table at any wavelength inside 380–780 nm, the
/// method CIE 167:2005 recommends for interpolating spectral data (the same coefficients as
/// colour-science's `SpragueInterpolator`, with its end extrapolation). `None` outside the
/// table's range or for NaN.
pub fn interpolate(table: &Spectrum, wavelength_nm: f64) -> Option<f64> {
    let last = FIRST_NM + STEP_NM * (SAMPLES - 1) as f64;
    if !(FIRST_NM..=last).contains(&wavelength_nm) {
        return None;
    }
    let pos = (wavelength_nm - FIRST_NM) / STEP_NM;
    let j = (pos.floor() as usize).min(SAMPLES - 2);
    let t = pos - j as f64;
    // The table padded with two extrapolated samples at each end (Sprague's end conditions).
    let end = |c: [f64; 6], v: [f64; 6]| c.iter().zip(v).map(|(c, v)| c * v).sum::<f64>() / 209.0;
    let first6: [f64; 6] = std::array::from_fn(|k| table[k]);
    let last6: [f64; 6] = std::array::from_fn(|k| table[SAMPLES - 6 + k]);
    let padded = |k: usize| -> f64 {
        match k {
            0 => end([884.0, -1960.0, 3033.0, -2648.0, 1080.0, -180.0], first6),
            1 => end([508.0, -540.0, 488.0, -367.0, 144.0, -24.0], first6),
            k if k < SAMPLES + 2 => table[k - 2],
            k if k == SAMPLES + 2 => end([-24.0, 144.0, -367.0, 488.0, -540.0, 508.0], last6),
            _ => end([-180.0, 1080.0, -2648.0, 3033.0, -1960.0, 884.0], last6),
        }
    };
    // Six samples around the interval [j, j+1] (padded index j+2 is table[j]).
    let r: [f64; 6] = std::array::from_fn(|k| padded(j + k));
    const W: [[f64; 6]; 5] = [
        [2.0, -16.0, 0.0, 16.0, -2.0, 0.0],
        [-1.0, 16.0, -30.0, 16.0, -1.0, 0.0],
        [-9.0, 39.0, -70.0, 66.0, -33.0, 7.0],
        [13.0, -64.0, 126.0, -124.0, 61.0, -12.0],
        [-5.0, 25.0, -50.0, 50.0, -25.0, 5.0],
    ];
    let mut y = r[2];
    let mut tp = 1.0;
    for w in W {
        tp *= t;
        y += w.iter().zip(r).map(|(w, r)| w * r).sum::<f64>() / 24.0 * tp;
    }
    Some(y)
}

#[cfg(test)]
mod tests {
    use super::tables::*;
    use super::*;

    fn at(table: &Spectrum, nm: u32) -> f64 {
        table[((nm as f64 - FIRST_NM) / STEP_NM) as usize]
    }

    /// CIE 1951 V'(λ) against the standard as printed in Wyszecki & Stiles (1982) Table
    /// I(4.3.2) (also CVRL scvle_1 at 5 nm). A table shifted by a few nm, or a photopic table
    /// passed off as scotopic, fails at several of these.
    #[test]
    fn scotopic_table_matches_the_cie_1951_standard() {
        let reference = [
            (380, 0.000589),
            (400, 0.00929),
            (450, 0.455),
            (480, 0.793),
            (500, 0.982),
            (505, 0.998),
            (510, 0.997),
            (550, 0.481),
            (560, 0.3288),
            (600, 0.03315),
            (650, 0.000677),
            (700, 0.0000178),
        ];
        for (nm, v) in reference {
            let got = at(&CIE1951_V_PRIME, nm);
            assert!((got / v - 1.0).abs() < 1e-6, "V'({nm}) = {got}, CIE {v}");
        }
        // The 5 nm table's largest sample is 0.998 at 505 nm.
        let (imax, vmax) = CIE1951_V_PRIME
            .iter()
            .enumerate()
            .fold((0, 0.0), |a, (i, &v)| if v > a.1 { (i, v) } else { a });
        assert_eq!((wavelength_nm(imax), vmax), (505.0, 0.998));
    }

    /// V' peaks at 1.0 at 507 nm in the CIE 1 nm table, between the 5 nm samples. We test the
    /// 5 nm table interpolated with Sprague's method (CIE 167:2005): 0.99986 at 507 nm (the
    /// CIE 1 nm table gives 1.000 at 506, 507 and 508 nm, to three decimals), and the
    /// maximum of the interpolant lies at 507.4 nm.
    #[test]
    fn scotopic_peak_is_at_507_nm_when_interpolated() {
        let v507 = interpolate(&CIE1951_V_PRIME, 507.0).unwrap();
        assert!((v507 - 1.0).abs() < 5e-4, "{v507}");
        // colour-science's SpragueInterpolator on the same 5 nm data: 0.9998624 at 507 nm.
        assert!((v507 - 0.999_862_4).abs() < 1e-7, "{v507}");
        let (mut best, mut best_nm) = (0.0, 0.0);
        for i in 0..=3000 {
            let nm = 500.0 + i as f64 * 0.005;
            let v = interpolate(&CIE1951_V_PRIME, nm).unwrap();
            if v > best {
                (best, best_nm) = (v, nm);
            }
        }
        assert!((506.5..=508.0).contains(&best_nm), "peak at {best_nm}");
        assert!((best - 1.0).abs() < 5e-4, "{best}");
        // The interpolant passes through the samples, and stays inside the range.
        assert_eq!(interpolate(&CIE1951_V_PRIME, 505.0), Some(0.998));
        assert!(interpolate(&CIE1951_V_PRIME, 780.0).unwrap() - at(&CIE1951_V_PRIME, 780) < 1e-15);
        assert_eq!(interpolate(&CIE1951_V_PRIME, 379.0), None);
        assert_eq!(interpolate(&CIE1951_V_PRIME, f64::NAN), None);
        // colour-science at 381.5 nm (inside the first interval, which uses the end padding).
        let v = interpolate(&CIE1951_V_PRIME, 382.0).unwrap();
        assert!(v > 0.000589 && v < 0.001108, "{v}");
    }

    /// CIE 1931 2° values against CIE 15:2004 Table T.4 (Wyszecki & Stiles Table I(3.3.1)).
    #[test]
    fn colour_matching_functions_match_the_cie_1931_standard() {
        let reference = [
            (380, [0.001368, 0.000039, 0.006450]),
            (450, [0.33620, 0.03800, 1.77211]),
            (500, [0.00490, 0.32300, 0.27200]),
            (555, [0.5120501, 1.0, 0.00575]),
            (600, [1.06220, 0.63100, 0.00080]),
            (650, [0.28350, 0.10700, 0.00000]),
            (700, [0.01135916, 0.004102, 0.0]),
        ];
        for (nm, [x, y, z]) in reference {
            let got = [
                at(&CIE1931_X_BAR, nm),
                at(&CIE1931_Y_BAR, nm),
                at(&CIE1931_Z_BAR, nm),
            ];
            for (g, r) in got.iter().zip([x, y, z]) {
                assert!(
                    (g - r).abs() <= 1e-6 * r.max(1e-3),
                    "{nm} nm: {got:?} vs {x}, {y}, {z}"
                );
            }
        }
        // ȳ peaks at 1 at 555 nm, and Σȳ·5 nm over 380–780 nm is 106.857 (CIE 15:2004:
        // 21.3714 over 360–830 nm at 5 nm; the tails outside 380–780 add only 8e-5).
        let sum_y: f64 = CIE1931_Y_BAR.iter().sum();
        assert!((sum_y - 21.371_33).abs() < 1e-4, "{sum_y}");
        assert_eq!(at(&CIE1931_Y_BAR, 555), 1.0);
        // Equal-energy white has x = y = 1/3: the three functions have (nearly) equal areas.
        let sx: f64 = CIE1931_X_BAR.iter().sum();
        let sz: f64 = CIE1931_Z_BAR.iter().sum();
        assert!(
            (sx / sum_y - 1.0).abs() < 1e-3 && (sz / sum_y - 1.0).abs() < 1e-3,
            "{sx} {sz}"
        );
    }

    /// S/P of equal-energy white, 1700·ΣV' / (683·Σȳ) = 2.261, the value the rest of the
    /// library uses ([`crate::scotopic::EQUAL_ENERGY_SP_RATIO`]).
    #[test]
    fn equal_energy_white_has_sp_2_261() {
        let p = integrate(&EQUAL_ENERGY);
        assert!((p.sp_ratio() - 2.261_156).abs() < 1e-5, "{}", p.sp_ratio());
        assert!((p.sp_ratio() - crate::scotopic::EQUAL_ENERGY_SP_RATIO).abs() < 5e-4);
        // Y of a unit equal-energy radiance: 683 · 5 · 21.371328 = 72983.08 cd/m².
        assert!((p.y - 72_983.08).abs() < 0.1, "{}", p.y);
    }

    /// ColorChecker reflectances (Ohta): a few samples, and the S/P ratios under E that make
    /// the Purkinje shift appear (blue patch rod-rich, red patch rod-poor).
    #[test]
    fn colorchecker_patches_have_their_reflectances_and_sp_ratios() {
        assert_eq!(COLORCHECKER_NAMES[12], "blue");
        assert_eq!(COLORCHECKER_NAMES[14], "red");
        assert_eq!(COLORCHECKER_NAMES[18], "white 9.5 (.05 D)");
        assert_eq!(COLORCHECKER_NAMES[23], "black 2 (1.5 D)");
        // Ohta's data: the red patch reflects 0.04 at 500 nm and 0.6 at 700 nm; the white
        // patch 0.9 across the visible.
        let red = colorchecker(14);
        assert!(
            at(red, 500) < 0.06 && at(red, 700) > 0.5,
            "{} {}",
            at(red, 500),
            at(red, 700)
        );
        let white = colorchecker(18);
        assert!(white[8..72].iter().all(|&r| (0.8..0.95).contains(&r)));
        let sp = |i: usize| integrate(&reflected(&EQUAL_ENERGY, colorchecker(i))).sp_ratio();
        assert!((sp(14) - 0.845).abs() < 0.005, "red {}", sp(14));
        assert!((sp(12) - 5.663).abs() < 0.01, "blue {}", sp(12));
        assert!((sp(13) - 2.004).abs() < 0.01, "green {}", sp(13));
        // Neutral patches stay close to equal-energy white's 2.261.
        for i in 18..24 {
            assert!((sp(i) - 2.26).abs() < 0.06, "neutral {i}: {}", sp(i));
        }
        // Luminance factor of white 9.5 and black 2: 0.887 and 0.0335.
        let e = integrate(&EQUAL_ENERGY).y;
        let y = |i: usize| integrate(&reflected(&EQUAL_ENERGY, colorchecker(i))).y / e;
        assert!((y(18) - 0.8873).abs() < 1e-3 && (y(23) - 0.0335).abs() < 1e-3);
    }
}
