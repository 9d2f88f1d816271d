//! Threshold-versus-intensity (t.v.i.) curves of the cone and rod systems.
//!
//! Ferwerda et al. 1996, Sec. 4, Eq. 4 (cones) and Eq. 5 (rods), fitted to the data of
//! Fig. 3: the luminance increment `t(L_a)` that is just detectable on a background to
//! which the observer is adapted, as a function of that adaptation luminance `L_a`.
//!
//! * Cones take photopic luminance in cd/m² and return a photopic threshold in cd/m².
//! * Rods take scotopic luminance in scotopic cd/m² (CIE 1951 V'(λ), K'm = 1700 lm/W) and
//!   return a threshold in the same unit. The paper converted its data to "log cd/m²
//!   taking into account ... differences in the luminous efficiency of the rod and cone
//!   systems" (Sec. 3.2), which is how we read Eq. 5's abscissa.
//!
//! The curves are implemented exactly as printed: three branches each, in log10 units.
//! Their branches meet to within 0.003 (cones) and 0.012 (rods) log units at the
//! breakpoints, a property of the published fit that we keep rather than "fix".

/// Eq. 4, lower breakpoint: below `log10 L_a = -2.6` the cone threshold is constant.
pub const CONE_LOW_BREAK_LOG: f64 = -2.6;
/// Eq. 4, upper breakpoint: above `log10 L_a = 1.9` cones obey Weber's law.
pub const CONE_HIGH_BREAK_LOG: f64 = 1.9;
/// Eq. 4: absolute cone threshold, `log10 t_p = -0.72` (log cd/m²).
pub const CONE_FLOOR_LOG: f64 = -0.72;
/// Eq. 4: cone Weber branch offset, `log10 t_p = log10 L_a - 1.255` (Weber fraction 5.6 %).
pub const CONE_WEBER_OFFSET_LOG: f64 = -1.255;

/// Eq. 5, lower breakpoint: below `log10 L_a = -3.94` the rod threshold is constant.
pub const ROD_LOW_BREAK_LOG: f64 = -3.94;
/// Eq. 5, upper breakpoint: above `log10 L_a = -1.44` rods obey Weber's law.
pub const ROD_HIGH_BREAK_LOG: f64 = -1.44;
/// Eq. 5: absolute rod threshold, `log10 t_s = -2.86` (log scotopic cd/m²).
pub const ROD_FLOOR_LOG: f64 = -2.86;
/// Eq. 5: rod Weber branch offset, `log10 t_s = log10 L_a - 0.395` (Weber fraction 40 %).
pub const ROD_WEBER_OFFSET_LOG: f64 = -0.395;

/// Eq. 4: `log10` of the cone threshold (cd/m²) at `log10` of the photopic adaptation
/// luminance (cd/m²). `-inf` (zero luminance) falls on the absolute-threshold branch.
pub fn log_cone_threshold(log_adaptation: f64) -> f64 {
    if log_adaptation <= CONE_LOW_BREAK_LOG {
        CONE_FLOOR_LOG
    } else if log_adaptation >= CONE_HIGH_BREAK_LOG {
        log_adaptation + CONE_WEBER_OFFSET_LOG
    } else {
        // Eq. 4, middle branch: (0.249 log La + 0.65)^2.7 - 0.72. The base is positive on
        // the whole branch (0.0026 at the lower breakpoint), so powf is defined.
        (0.249 * log_adaptation + 0.65).powf(2.7) + CONE_FLOOR_LOG
    }
}

/// Eq. 5: `log10` of the rod threshold (scotopic cd/m²) at `log10` of the scotopic
/// adaptation luminance (scotopic cd/m²).
pub fn log_rod_threshold(log_adaptation: f64) -> f64 {
    if log_adaptation <= ROD_LOW_BREAK_LOG {
        ROD_FLOOR_LOG
    } else if log_adaptation >= ROD_HIGH_BREAK_LOG {
        log_adaptation + ROD_WEBER_OFFSET_LOG
    } else {
        // Eq. 5, middle branch: (0.405 log La + 1.6)^2.18 - 2.86. The base is positive on
        // the whole branch (0.0043 at the lower breakpoint).
        (0.405 * log_adaptation + 1.6).powf(2.18) + ROD_FLOOR_LOG
    }
}

/// Eq. 4 inverted: `log10` of the photopic adaptation luminance whose cone threshold is
/// `10^log_threshold` cd/m²; `-inf` (the dark) at or below the absolute threshold.
/// `log_cone_threshold(inverse(y)) == y` to rounding wherever Eq. 4 rises. Where the
/// published branches overlap (within 0.003 log of the upper break) the middle branch is
/// taken. Below the lower break Eq. 4 is flat and has no inverse: thresholds within 1e-7
/// log of the floor (what the middle branch gives at the break) map linearly in luminance
/// from `10^`[`CONE_LOW_BREAK_LOG`] down to 0 (our choice: the inverse is continuous and
/// reaches 0 with the excess, as the equivalent background of
/// [`timecourse`](crate::timecourse) needs).
pub fn log_cone_adaptation_for_threshold(log_threshold: f64) -> f64 {
    let y = log_threshold - CONE_FLOOR_LOG;
    if y.is_nan() {
        return f64::NAN;
    }
    if y <= 0.0 {
        return f64::NEG_INFINITY;
    }
    let middle = (y.powf(1.0 / 2.7) - 0.65) / 0.249;
    if middle < CONE_LOW_BREAK_LOG {
        CONE_LOW_BREAK_LOG + (y / (0.249 * CONE_LOW_BREAK_LOG + 0.65f64).powf(2.7)).log10()
    } else if middle < CONE_HIGH_BREAK_LOG {
        middle
    } else {
        log_threshold - CONE_WEBER_OFFSET_LOG
    }
}

/// Eq. 5 inverted: `log10` of the scotopic adaptation luminance whose rod threshold is
/// `10^log_threshold` scotopic cd/m², as [`log_cone_adaptation_for_threshold`] (the
/// branches overlap within 0.012 log of the upper break; the flat part is reached within
/// 7e-6 log of the floor).
pub fn log_rod_adaptation_for_threshold(log_threshold: f64) -> f64 {
    let y = log_threshold - ROD_FLOOR_LOG;
    if y.is_nan() {
        return f64::NAN;
    }
    if y <= 0.0 {
        return f64::NEG_INFINITY;
    }
    let middle = (y.powf(1.0 / 2.18) - 1.6) / 0.405;
    if middle < ROD_LOW_BREAK_LOG {
        ROD_LOW_BREAK_LOG + (y / (0.405 * ROD_LOW_BREAK_LOG + 1.6f64).powf(2.18)).log10()
    } else if middle < ROD_HIGH_BREAK_LOG {
        middle
    } else {
        log_threshold - ROD_WEBER_OFFSET_LOG
    }
}

/// Eq. 4: cone threshold in cd/m² for an observer adapted to `adaptation_cd_m2`.
/// Non-positive adaptation gives the absolute threshold 10^-0.72 cd/m²; NaN gives NaN.
pub fn cone_threshold_cd_m2(adaptation_cd_m2: f64) -> f64 {
    10f64.powf(log_cone_threshold(adaptation_cd_m2.log10()))
}

/// Eq. 5: rod threshold in scotopic cd/m² for an observer adapted to
/// `adaptation_scotopic_cd_m2`. Non-positive adaptation gives the absolute threshold
/// 10^-2.86 scotopic cd/m²; NaN gives NaN.
pub fn rod_threshold_scotopic_cd_m2(adaptation_scotopic_cd_m2: f64) -> f64 {
    10f64.powf(log_rod_threshold(adaptation_scotopic_cd_m2.log10()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eq. 4 evaluated by hand (calculator) at and around its breakpoints.
    #[test]
    fn cone_curve_matches_eq4() {
        // log La = -2.6: lower branch, -0.72 exactly.
        assert_eq!(log_cone_threshold(-2.6), -0.72);
        assert_eq!(log_cone_threshold(-5.0), -0.72);
        // Just above -2.6: middle branch, (0.249*-2.59+0.65)^2.7 - 0.72 = 0.00501^2.7 - 0.72.
        let v = log_cone_threshold(-2.59);
        assert!((v - (0.005_09f64.powf(2.7) - 0.72)).abs() < 1e-9, "{v}");
        // log La = 0: 0.65^2.7 - 0.72 = 0.312511 - 0.72 = -0.407489.
        assert!((log_cone_threshold(0.0) - (-0.407_489)).abs() < 1e-5);
        // log La = 1.8999: middle branch 1.12307^2.7 - 0.72 = 0.64806.
        assert!((log_cone_threshold(1.899_9) - 0.648_06).abs() < 2e-4);
        // log La = 1.9: upper branch 1.9 - 1.255 = 0.645 (branches meet within 0.003).
        assert!((log_cone_threshold(1.9) - 0.645).abs() < 1e-12);
        // log La = 3: 3 - 1.255.
        assert!((log_cone_threshold(3.0) - 1.745).abs() < 1e-12);
        // 40 cd/m² (the display adaptation): log 40 = 1.60206 → (1.04891)^2.7 - 0.72 = 0.41763.
        assert!((cone_threshold_cd_m2(40.0).log10() - 0.417_6).abs() < 2e-4);
    }

    /// Eq. 5 evaluated by hand at and around its breakpoints.
    #[test]
    fn rod_curve_matches_eq5() {
        assert_eq!(log_rod_threshold(-3.94), -2.86);
        assert_eq!(log_rod_threshold(-6.0), -2.86);
        // log La = -2: (0.405*-2+1.6)^2.18 - 2.86 = 0.79^2.18 - 2.86 = 0.598173 - 2.86.
        assert!((log_rod_threshold(-2.0) - (-2.261_827)).abs() < 1e-5);
        // log La = -1.4401: middle branch 1.016_76^2.18 - 2.86 = -1.82310 (upper gives -1.8351).
        assert!((log_rod_threshold(-1.440_1) - (-1.823_10)).abs() < 1e-4);
        // log La = -1.44: upper branch -1.44 - 0.395 = -1.835.
        assert!((log_rod_threshold(-1.44) - (-1.835)).abs() < 1e-12);
        // 40 scotopic cd/m²: Weber branch, log 40 - 0.395 = 1.20706.
        assert!((rod_threshold_scotopic_cd_m2(40.0).log10() - 1.207_06).abs() < 1e-5);
    }

    #[test]
    fn branches_are_nearly_continuous_and_curves_monotone() {
        let gap = |f: fn(f64) -> f64, x: f64| (f(x + 1e-9) - f(x - 1e-9)).abs();
        assert!(gap(log_cone_threshold, -2.6) < 0.003);
        assert!(gap(log_cone_threshold, 1.9) < 0.004);
        assert!(gap(log_rod_threshold, -3.94) < 0.003);
        assert!(gap(log_rod_threshold, -1.44) < 0.012);
        let mut prev = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        for i in 0..=1400 {
            let l = -7.0 + i as f64 * 0.01;
            let c = log_cone_threshold(l);
            let r = log_rod_threshold(l);
            // Non-decreasing, allowing the published fits' tiny steps at the breakpoints.
            assert!(c >= prev.0 - 0.004 && r >= prev.1 - 0.012, "at {l}");
            prev = (c, r);
        }
    }

    #[test]
    fn inverses_round_trip_above_the_absolute_threshold() {
        for i in 0..=1000 {
            let l = -3.9 + i as f64 * 0.0099; // log10 L from -3.9 to 6
            for (f, inv) in [
                (
                    log_cone_threshold as fn(f64) -> f64,
                    log_cone_adaptation_for_threshold as fn(f64) -> f64,
                ),
                (log_rod_threshold, log_rod_adaptation_for_threshold),
            ] {
                let y = f(l);
                if l > -2.59 {
                    assert!((f(inv(y)) - y).abs() < 1e-9, "at {l}: {y} -> {}", inv(y));
                }
            }
        }
        assert_eq!(
            log_cone_adaptation_for_threshold(CONE_FLOOR_LOG),
            f64::NEG_INFINITY
        );
        assert_eq!(log_rod_adaptation_for_threshold(-5.0), f64::NEG_INFINITY);
        assert!((log_cone_adaptation_for_threshold(1.745) - 3.0).abs() < 1e-12);
        assert!((log_rod_adaptation_for_threshold(-2.261_827) - -2.0).abs() < 1e-5);
    }

    #[test]
    fn zero_and_negative_adaptation_fall_on_the_absolute_threshold() {
        assert!((cone_threshold_cd_m2(0.0) - 10f64.powf(-0.72)).abs() < 1e-12);
        assert!((rod_threshold_scotopic_cd_m2(0.0) - 10f64.powf(-2.86)).abs() < 1e-15);
        assert!(cone_threshold_cd_m2(f64::NAN).is_nan());
    }
}
