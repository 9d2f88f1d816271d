//! What an observer adapted to a given luminance can see: thresholds, contrast scale
//! factors, rod weight and acuity, without any image.
//!
//! This gathers, for one adaptation state, the quantities of Ferwerda et al. 1996 Eq. 3–7:
//! the cone (Eq. 4) and rod (Eq. 5) thresholds, the scale factors that map the world to a
//! display (Eq. 3), the mesopic rod weight (Eq. 6) and the resolvable frequency (Fig. 7).

use crate::Result;
use crate::acuity::{self, AcuityFilter};
use crate::adaptation::{ADAPTATION_FRACTION, DEFAULT_DISPLAY_MAX_CD_M2};
use crate::mesopic::rod_weight;
use crate::scale::{photopic_scale, scotopic_scale};
use crate::scotopic::EQUAL_ENERGY_SP_RATIO;
use crate::tvi::{cone_threshold_cd_m2, rod_threshold_scotopic_cd_m2};

/// The visual state of an observer adapted to a luminance, seen on a display.
#[derive(Debug, Clone, PartialEq)]
pub struct Observer {
    /// Photopic adaptation luminance, cd/m².
    pub adaptation_cd_m2: f64,
    /// Scotopic adaptation luminance, scotopic cd/m².
    pub scotopic_adaptation_cd_m2: f64,
    /// Display maximum luminance, cd/m².
    pub display_max_cd_m2: f64,
    /// Display observer's adaptation (`L_dmax/2`, Sec. 4.4), cd/m².
    pub display_adaptation_cd_m2: f64,
    /// Eq. 4 at the adaptation, cd/m².
    pub cone_threshold_cd_m2: f64,
    /// Eq. 5 at the scotopic adaptation, scotopic cd/m².
    pub rod_threshold_scotopic_cd_m2: f64,
    /// Eq. 3 with Eq. 4 for both observers.
    pub photopic_scale: f64,
    /// Eq. 3 with Eq. 5 (world) and Eq. 4 (display).
    pub scotopic_scale: f64,
    /// The mesopic rod weight `k` of Eq. 6.
    pub rod_weight: f64,
    /// The acuity filter of Eq. 7 (cutoff frequency, threshold contrast, sigma).
    pub acuity: AcuityFilter,
}

impl Observer {
    /// An observer adapted to `adaptation_cd_m2`; the scotopic adaptation defaults to that
    /// luminance times the S/P ratio of equal-energy white (2.261); the display maximum to
    /// 80 cd/m².
    pub fn new(
        adaptation_cd_m2: f64,
        scotopic_adaptation_cd_m2: Option<f64>,
        display_max_cd_m2: Option<f64>,
    ) -> Result<Self> {
        let check = crate::check_luminance;
        let l = check("adaptation", adaptation_cd_m2)?;
        let ls = check(
            "scotopic",
            scotopic_adaptation_cd_m2.unwrap_or(l * EQUAL_ENERGY_SP_RATIO),
        )?;
        let dmax = check(
            "display-max",
            display_max_cd_m2.unwrap_or(DEFAULT_DISPLAY_MAX_CD_M2),
        )?;
        let lda = ADAPTATION_FRACTION * dmax;
        Ok(Observer {
            adaptation_cd_m2: l,
            scotopic_adaptation_cd_m2: ls,
            display_max_cd_m2: dmax,
            display_adaptation_cd_m2: lda,
            cone_threshold_cd_m2: cone_threshold_cd_m2(l),
            rod_threshold_scotopic_cd_m2: rod_threshold_scotopic_cd_m2(ls),
            photopic_scale: photopic_scale(l, lda),
            scotopic_scale: scotopic_scale(ls, lda),
            rod_weight: rod_weight(ls),
            acuity: AcuityFilter::new(l, ls),
        })
    }

    /// Highest resolvable grating frequency, cycles/degree.
    pub fn acuity_cycles_per_degree(&self) -> f64 {
        self.acuity.cutoff_cycles_per_degree
    }

    /// Acuity as a Snellen fraction such as "20/40".
    pub fn snellen(&self) -> String {
        acuity::snellen(self.acuity.cutoff_cycles_per_degree)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn starlight_and_daylight_observers() {
        // Paper Sec. 3.4: ~2 c/deg ("nearly 20/300") at −3.3 log cd/m².
        let o = Observer::new(10f64.powf(-3.3), None, None).unwrap();
        assert!((o.acuity_cycles_per_degree() - 2.59).abs() < 0.05);
        assert_eq!(o.rod_weight, 1.0);
        let d = Observer::new(1000.0, None, None).unwrap();
        assert_eq!(d.rod_weight, 0.0);
        assert_eq!(d.snellen(), "20/12");
        // Hand computation: m_p(1000) = 10^(0.41763 − 1.745) = 0.04707.
        assert!((d.photopic_scale - 0.047_07).abs() < 1e-4);
        assert!((d.scotopic_adaptation_cd_m2 - 2261.0).abs() < 1e-9);
    }

    #[test]
    fn bad_luminances_are_rejected() {
        assert!(Observer::new(0.0, None, None).is_err());
        assert!(Observer::new(f64::NAN, None, None).is_err());
        assert!(Observer::new(1.0, Some(-1.0), None).is_err());
        assert!(Observer::new(1.0, None, Some(f64::INFINITY)).is_err());
    }
}
