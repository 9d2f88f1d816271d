//! The mesopic combination of the cone and rod images.
//!
//! Ferwerda et al. 1996, Sec. 4, Eq. 6: `L_d = L_dp + k·L_ds`, where "k is a constant that
//! varies from 1 to 0 as the scotopic world adaptation level goes from the bottom to the
//! top of the mesopic range". The rod image `L_ds` is achromatic (grey); the cone image
//! `L_dp` keeps its colour, and Eq. 6 is applied at every adaptation level.
//!
//! # The form of `k` (the paper gives none)
//!
//! * Range: the mesopic range is 0.01 to 10 cd/m² (paper Sec. 2.2 and Fig. 1: rods work
//!   from 1e-6 to 10 cd/m², cones from 0.01 to 1e8). `k` is a function of the scotopic world
//!   adaptation, so the ends are converted to scotopic cd/m² with the S/P ratio of
//!   equal-energy white, the paper's illuminant (Sec. 5): 0.0226 to 22.6 scotopic cd/m².
//! * Shape: a cubic smoothstep in log luminance, `k = 1 − (3u² − 2u³)` with
//!   `u = (log L − log L_bottom)/(log L_top − log L_bottom)` clamped to [0, 1]: continuous
//!   with a continuous slope (no kink when adaptation changes over time), monotone, exactly
//!   1 below the range and exactly 0 above it. Jensen et al., "Night Rendering" (2000,
//!   Sec. 3.1) blend rod and cone vision with the same smoothstep in log luminance.
//!
//! A form seen in public code, `((1 − (L/2 − 0.01)/(10 − 0.01))²` clamped after squaring,
//! climbs back to 1 above 20 cd/m² and adds rod grey in daylight; the tests exclude it.

use crate::scotopic::EQUAL_ENERGY_SP_RATIO;

/// Bottom of the mesopic range, photopic cd/m² (paper Sec. 2.2, Fig. 1).
pub const MESOPIC_BOTTOM_CD_M2: f64 = 0.01;
/// Top of the mesopic range, photopic cd/m² (paper Sec. 2.2, Fig. 1).
pub const MESOPIC_TOP_CD_M2: f64 = 10.0;

/// Bottom of the mesopic range in scotopic cd/m² (equal-energy white).
pub fn bottom_scotopic_cd_m2() -> f64 {
    MESOPIC_BOTTOM_CD_M2 * EQUAL_ENERGY_SP_RATIO
}

/// Top of the mesopic range in scotopic cd/m² (equal-energy white).
pub fn top_scotopic_cd_m2() -> f64 {
    MESOPIC_TOP_CD_M2 * EQUAL_ENERGY_SP_RATIO
}

/// The rod weight `k` of Eq. 6 at a scotopic world adaptation (scotopic cd/m²):
/// 1 at and below the bottom of the mesopic range, 0 at and above the top.
/// Non-positive adaptation gives 1; NaN gives NaN.
pub fn rod_weight(world_adaptation_scotopic_cd_m2: f64) -> f64 {
    let lo = bottom_scotopic_cd_m2().log10();
    let hi = top_scotopic_cd_m2().log10();
    let l = world_adaptation_scotopic_cd_m2;
    if l.is_nan() {
        return f64::NAN;
    }
    let u = ((l.log10() - lo) / (hi - lo)).clamp(0.0, 1.0);
    1.0 - u * u * (3.0 - 2.0 * u)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_of_the_mesopic_range() {
        assert_eq!(rod_weight(1e-6), 1.0);
        assert_eq!(rod_weight(0.0), 1.0);
        assert_eq!(rod_weight(0.0226), 1.0);
        assert!(rod_weight(0.0227) < 1.0);
        assert_eq!(rod_weight(22.61), 0.0);
        assert_eq!(rod_weight(1e5), 0.0);
        // Geometric middle of the range, sqrt(0.02261 * 22.61) = 0.715: exactly 1/2.
        assert!((rod_weight((0.02261f64 * 22.61).sqrt()) - 0.5).abs() < 1e-9);
        // A quarter of the way in log: u = 0.25 → 1 − (3/16 − 2/64) = 0.84375.
        let l = 10f64.powf(0.02261f64.log10() + 0.25 * 3.0);
        assert!((rod_weight(l) - 0.843_75).abs() < 1e-9);
    }

    #[test]
    fn monotone_and_continuous_and_stays_zero_in_daylight() {
        let mut prev = 1.0;
        for i in 0..=2000 {
            let l = 10f64.powf(-7.0 + i as f64 * 0.006);
            let k = rod_weight(l);
            assert!((0.0..=1.0).contains(&k));
            assert!(k <= prev + 1e-15, "rises at {l}");
            // Largest slope of smoothstep is 1.5 per unit u; u moves 0.006/3 per step.
            assert!(prev - k <= 1.5 * 0.006 / 3.0 + 1e-12, "jump at {l}");
            prev = k;
        }
        // The public-code form climbs back to 1 at 1000 cd/m²; ours stays at 0.
        assert_eq!(rod_weight(1000.0), 0.0);
    }
}
