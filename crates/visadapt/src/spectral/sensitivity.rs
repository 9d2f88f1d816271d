//! The spectral sensitivity of the rod and cone systems at a level of adaptation, derived
//! from the model: the paper's Fig. 4 (after Hood 1986).
//!
//! Ferwerda et al. 1996, Sec. 2.2: at scotopic levels detection is dominated by the rods, at
//! mesopic levels "detection at a particular wavelength will be served by the more sensitive
//! system" (rods below about 575 nm, cones above), at photopic levels by the cones. The
//! paper shows data; here the same three panels follow from the model's own parts:
//!
//! * The observer is adapted to an equal-energy white background of photopic luminance `L`
//!   (scotopic `L·2.261`, [`EQUAL_ENERGY_SP_RATIO`]).
//! * A monochromatic test light of wavelength λ and radiance `ΔL_e` (W·sr⁻¹·m⁻²) adds
//!   `683·V(λ)·ΔL_e` cd/m² for the cones and `1700·V'(λ)·ΔL_e` scotopic cd/m² for the rods
//!   (V = ȳ of CIE 1931, V' of CIE 1951, [`super`]).
//! * The cones detect it when that reaches their threshold `t_p(L)` (Eq. 4). The rod image
//!   enters the display with weight `k` (Eq. 6), so the rods detect it when
//!   `k·1700·V'(λ)·ΔL_e` reaches `t_s(L_s)` (Eq. 5); with `k = 0` (photopic levels, where the
//!   model retires the rods) they do not detect it at all.
//! * Sensitivity is the reciprocal of the threshold radiance, `S = 1/ΔL_e` in sr·m²/W; the
//!   visual system's sensitivity is that of the more sensitive system.
//!
//! At 0.1 cd/m² this puts the rod/cone crossover at 571 nm, the paper's "about 575 nm". At
//! 0.001 cd/m² the rods detect everything up to 659 nm, and the cones stay the more
//! sensitive system in the far red, as in the dark-adapted eye.

use super::{PHOTOPIC_EFFICACY_LM_PER_W, SCOTOPIC_EFFICACY_LM_PER_W, interpolate, tables};
use crate::mesopic::rod_weight;
use crate::scotopic::EQUAL_ENERGY_SP_RATIO;
use crate::tvi::{cone_threshold_cd_m2, rod_threshold_scotopic_cd_m2};
use crate::{Error, Result};

/// The scotopic level of Fig. 4 (a): starlight, 0.001 cd/m² (a project choice inside the
/// paper's scotopic range, Sec. 2.2).
pub const FIG4_SCOTOPIC_CD_M2: f64 = 1e-3;
/// The mesopic level of Fig. 4 (b): 0.1 cd/m², where the model's rod and cone sensitivities
/// cross near 575 nm as the paper describes (a project choice).
pub const FIG4_MESOPIC_CD_M2: f64 = 0.1;
/// The photopic level of Fig. 4 (c): 100 cd/m², an office (a project choice).
pub const FIG4_PHOTOPIC_CD_M2: f64 = 100.0;

/// Which system detects a test light first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Detector {
    /// The cone system (photopic).
    Cones,
    /// The rod system (scotopic).
    Rods,
}

/// Sensitivities to a monochromatic test light on an equal-energy white background.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpectralSensitivity {
    /// Wavelength of the test light, nm.
    pub wavelength_nm: f64,
    /// `log10` of the cone sensitivity, log sr·m²/W.
    pub log_cone: f64,
    /// `log10` of the rod sensitivity (weighted by `k`), log sr·m²/W; `None` when `k = 0`.
    pub log_rod: Option<f64>,
}

impl SpectralSensitivity {
    /// `log10` sensitivity of the visual system: the more sensitive of the two systems.
    pub fn log_system(&self) -> f64 {
        self.log_rod.map_or(self.log_cone, |r| r.max(self.log_cone))
    }

    /// The system that detects the light.
    pub fn detector(&self) -> Detector {
        match self.log_rod {
            Some(r) if r > self.log_cone => Detector::Rods,
            _ => Detector::Cones,
        }
    }
}

/// The sensitivities at `wavelength_nm` (380–780 nm, Sprague-interpolated tables) of an
/// observer adapted to equal-energy white at `adaptation_cd_m2` (see the module docs).
pub fn spectral_sensitivity(
    adaptation_cd_m2: f64,
    wavelength_nm: f64,
) -> Result<SpectralSensitivity> {
    crate::check_luminance("adaptation", adaptation_cd_m2)?;
    let range = || Error::invalid("wavelength", wavelength_nm, "must be in 380..=780 nm");
    let v = interpolate(&tables::CIE1931_Y_BAR, wavelength_nm).ok_or_else(range)?;
    let v_prime = interpolate(&tables::CIE1951_V_PRIME, wavelength_nm).ok_or_else(range)?;
    let scotopic = adaptation_cd_m2 * EQUAL_ENERGY_SP_RATIO;
    let k = rod_weight(scotopic);
    let log = |x: f64| {
        if x > 0.0 {
            x.log10()
        } else {
            f64::NEG_INFINITY
        }
    };
    let log_cone = log(PHOTOPIC_EFFICACY_LM_PER_W * v / cone_threshold_cd_m2(adaptation_cd_m2));
    let log_rod = (k > 0.0).then(|| {
        log(k * SCOTOPIC_EFFICACY_LM_PER_W * v_prime / rod_threshold_scotopic_cd_m2(scotopic))
    });
    Ok(SpectralSensitivity {
        wavelength_nm,
        log_cone,
        log_rod,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The wavelength above which the cones take over, found by bisection.
    fn crossover_nm(level: f64) -> f64 {
        let (mut lo, mut hi) = (500.0, 720.0);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            match spectral_sensitivity(level, mid).unwrap().detector() {
                Detector::Rods => lo = mid,
                Detector::Cones => hi = mid,
            }
        }
        lo
    }

    /// Fig. 4 (b) and Sec. 2.2: at mesopic levels rods detect below about 575 nm, cones above.
    #[test]
    fn mesopic_crossover_is_near_575_nm() {
        let c = crossover_nm(FIG4_MESOPIC_CD_M2);
        assert!((c - 575.0).abs() < 10.0, "{c}");
        // Hand computation at 0.1 cd/m²: t_p = 10^-0.6352, t_s(0.2261) = 10^(-0.6457-0.395),
        // k = 0.7407; V'/V must equal (683/1700)·t_s/(k·t_p) = 0.2124, which the tables
        // (V'/V = 0.218 at 570 nm, 0.139 at 580 nm) reach near 571 nm.
        assert!((c - 571.0).abs() < 2.0, "{c}");
    }

    /// Fig. 4 (a): at starlight the rods detect everything up to the far red, where the
    /// cones stay the more sensitive system even in the dark (V'/V falls below
    /// (683/1700)·t_s/t_p = 0.0052 near 659 nm); (c): in daylight the model gives rods no
    /// weight (k = 0) and the cones detect everything.
    #[test]
    fn scotopic_rods_and_photopic_cones_dominate() {
        for nm in (400..=650).step_by(10) {
            let s = spectral_sensitivity(FIG4_SCOTOPIC_CD_M2, nm as f64).unwrap();
            assert_eq!(s.detector(), Detector::Rods, "{nm} nm");
        }
        let c = crossover_nm(FIG4_SCOTOPIC_CD_M2);
        assert!((655.0..665.0).contains(&c), "{c}");
        for nm in (380..=780).step_by(10) {
            let p = spectral_sensitivity(FIG4_PHOTOPIC_CD_M2, nm as f64).unwrap();
            assert_eq!(
                (p.detector(), p.log_rod),
                (Detector::Cones, None),
                "{nm} nm"
            );
        }
        // Absolute sensitivity "is quite high" at scotopic levels and "has dropped
        // considerably" at photopic ones (Sec. 2.2): at 507 nm by more than 4 log units.
        let s = spectral_sensitivity(FIG4_SCOTOPIC_CD_M2, 507.0)
            .unwrap()
            .log_system();
        let p = spectral_sensitivity(FIG4_PHOTOPIC_CD_M2, 507.0)
            .unwrap()
            .log_system();
        assert!(s - p > 4.0, "{s} {p}");
        // Hand computation, cones at 555 nm and 100 cd/m²: log(683·1/10^(2-1.255)) = 2.0894.
        let c = spectral_sensitivity(100.0, 555.0).unwrap().log_cone;
        assert!((c - 2.0894).abs() < 1e-3, "{c}");
    }

    #[test]
    fn bad_levels_and_wavelengths_are_rejected() {
        assert!(spectral_sensitivity(0.0, 500.0).is_err());
        assert!(spectral_sensitivity(f64::NAN, 500.0).is_err());
        assert!(spectral_sensitivity(1.0, 300.0).is_err());
        assert!(spectral_sensitivity(1.0, f64::NAN).is_err());
    }
}
