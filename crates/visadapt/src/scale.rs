//! Ward's contrast scale factor and the two operators built on it.
//!
//! Ferwerda et al. 1996, Sec. 4, Eq. 1–3: the display luminance is `L_d = m·L_w` with
//! `m = t(L_da) / t(L_wa)`, so that a just-visible contrast for the world observer
//! (adapted to `L_wa`) is just visible for the display observer (adapted to `L_da`).
//!
//! * Photopic operator: cone t.v.i. (Eq. 4) for both observers, `m_p = t_p(L_da)/t_p(L_wa)`.
//! * Scotopic ("rod monochromat") operator: "Equation 5 for the world observer and
//!   Equation 4 for the display observer, because the display observer is in a photopic
//!   state of adaptation", so `m_s = t_p(L_da)/t_s(L_wa,s)`, with `L_wa,s` in scotopic cd/m².
//!
//! Most public ports use the rod curve for the display observer as well
//! (`t_s(L_da)/t_s(L_wa)`), which makes the rod image 6.2 times too bright at
//! `L_da` = 40 cd/m²; the tests pin the paper's form.

use crate::tvi::{cone_threshold_cd_m2, rod_threshold_scotopic_cd_m2};

/// Eq. 3 with Eq. 4 for both observers: the photopic (cone) scale factor, display cd/m²
/// per world cd/m².
pub fn photopic_scale(world_adaptation_cd_m2: f64, display_adaptation_cd_m2: f64) -> f64 {
    cone_threshold_cd_m2(display_adaptation_cd_m2) / cone_threshold_cd_m2(world_adaptation_cd_m2)
}

/// Eq. 3 with Eq. 5 for the world observer and Eq. 4 for the (photopic) display observer:
/// the scotopic (rod) scale factor, display cd/m² per world scotopic cd/m².
pub fn scotopic_scale(world_adaptation_scotopic_cd_m2: f64, display_adaptation_cd_m2: f64) -> f64 {
    cone_threshold_cd_m2(display_adaptation_cd_m2)
        / rod_threshold_scotopic_cd_m2(world_adaptation_scotopic_cd_m2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tvi::rod_threshold_scotopic_cd_m2;

    /// Steady-state factors at L_da = 40 cd/m², computed by hand from Eq. 4/5:
    /// t_p(40) = 10^0.41763 = 2.6155 cd/m².
    #[test]
    fn factors_match_hand_computed_table() {
        let tp40 = 10f64.powf(0.417_63);
        // (L_wa, log t_p(L_wa), log t_s(L_wa)) from Eq. 4 and Eq. 5.
        let rows: [(f64, f64, f64); 5] = [
            (1e-2, -0.713_8, -2.261_827), // t_p: (0.152)^2.7 - 0.72
            (1.0, -0.407_489, -0.395),
            (10.0, 0.029_96, 0.605), // t_p: 0.899^2.7 - 0.72 = 0.74996 - 0.72
            (100.0, 0.745, 1.605),
            (1000.0, 1.745, 2.605),
        ];
        for (l, ltp, lts) in rows {
            let mp = photopic_scale(l, 40.0);
            let ms = scotopic_scale(l, 40.0);
            assert!(
                (mp / (tp40 / 10f64.powf(ltp)) - 1.0).abs() < 1e-3,
                "m_p at {l}: {mp}"
            );
            assert!(
                (ms / (tp40 / 10f64.powf(lts)) - 1.0).abs() < 1e-3,
                "m_s at {l}: {ms}"
            );
        }
        // Anchors quoted in the project's model notes: m_p(1) = 6.69, m_s(100) = 0.065.
        assert!((photopic_scale(1.0, 40.0) - 6.69).abs() < 0.01);
        assert!((scotopic_scale(100.0, 40.0) - 0.0654).abs() < 0.001);
    }

    /// The rod operator's display observer is photopic (Eq. 4), not Eq. 5: the ports'
    /// form t_s(L_da)/t_s(L_wa) is 10^(1.20706 - 0.41763) = 6.16 times brighter at 40 cd/m².
    #[test]
    fn rod_display_observer_is_photopic() {
        for l in [1e-3, 0.1, 1.0, 10.0] {
            let paper = scotopic_scale(l, 40.0);
            let ports = rod_threshold_scotopic_cd_m2(40.0) / rod_threshold_scotopic_cd_m2(l);
            assert!((ports / paper - 6.16).abs() < 0.01, "{}", ports / paper);
        }
    }

    #[test]
    fn equal_adaptation_gives_unit_scale() {
        assert!((photopic_scale(40.0, 40.0) - 1.0).abs() < 1e-12);
        // Brighter world → smaller factor.
        assert!(photopic_scale(1000.0, 40.0) < photopic_scale(100.0, 40.0));
    }
}
