//! Visual acuity and the Gaussian that removes detail the world observer cannot resolve.
//!
//! Ferwerda et al. 1996, Sec. 3.4 and Fig. 7 (Shaler 1937: the highest resolvable grating
//! frequency falls from about 50 cycles/degree at 3 log cd/m² to about 2 at −3.3 log cd/m²)
//! and Sec. 4.1, Eq. 7: the image is filtered with a Gaussian `f` whose Fourier transform at
//! the cutoff frequency `ω_c(L_wa)` equals the threshold contrast `t(L_wa)/L_wa`, so that a
//! full-contrast grating at the cutoff is shown exactly at threshold.
//!
//! # Cutoff frequency
//!
//! Ward Larson, Rushmeier and Piatko 1997 (IEEE TVCG 3(4), Eq. 15) fitted Shaler's data as
//! `ω_c(L) = 17.25·atan(1.4·log10 L + 0.35) + 25.72` cycles/degree (L in cd/m²): 49.1 at
//! 3 log cd/m², 2.6 at −3.3, matching Fig. 7. Below 1e-9 cd/m² the fit turns negative; we
//! hold it at [`MIN_CUTOFF_CYCLES_PER_DEGREE`].
//!
//! # The Gaussian
//!
//! A unit-area Gaussian of standard deviation `s` (degrees) has the transfer function
//! `F(ω) = exp(−2π²s²ω²)`. Solving `F(ω_c) = c` gives
//! `s = sqrt(ln(1/c)/2) / (π·ω_c)`.
//!
//! # The threshold contrast `c` (beyond the paper: one definition with the JND metric)
//!
//! The paper writes `t(L_wa)/L_wa` and does not say how the rod and cone curves combine.
//! Its Sec. 3.2 describes the visual system's threshold as "the envelope of the rod and
//! cone t.v.i. curves", which gives the rule [`AcuityThreshold::Envelope`]:
//! `c = min(c_p, c_s)` with `c_p = t_p(L_wa)/L_wa` (Eq. 4) and `c_s = t_s(L_wa,s)/L_wa,s`
//! (Eq. 5; Weber contrast is unit-free, so each system uses its own luminance), as Ward
//! Larson, Rushmeier and Piatko 1997 combine the two curves at their crossover (their
//! Table 1).
//!
//! The visibility metric ([`crate::visibility`]) measures the same observer differently:
//! the rod signal weighted by `k` of Eq. 6 (the rods "shutting down due to saturation",
//! Sec. 4) and pooled with the cone signal by probability summation (Quick 1974; Graham
//! 1989). With the envelope, a full-contrast grating at the cutoff then scores only
//! 0.74 JND at 0.1 cd/m² and 0.58 at 0.3 (the blur passes the rods' contrast while the
//! metric discounts the rods by `k`), and 1.0 only from 1 cd/m² up. The default,
//! [`AcuityThreshold::Pooled`], uses the metric's own threshold: the Weber contrast `c`
//! of a change in the background's colour that reaches 1 JND,
//!
//! `c = 1 / ((1/c_p)^β + (k/c_s)^β)^(1/β)`, `β` =
//! [`POOLING_EXPONENT`](crate::visibility::POOLING_EXPONENT) = 3.5,
//!
//! (the cones see `C/c_p` JNDs of a contrast `C`, the rods `k·C/c_s`, and their pooled sum
//! is 1 at `C = c`), so that a full-contrast grating at `ω_c` is shown at exactly 1 JND
//! wherever the equation has a solution, as the paper's Eq. 7 intends ("a scene grating at
//! frequency ω_c(L_wa) will be displayed at the threshold of visibility", Sec. 4.1). It
//! equals the envelope within 0.3 % from 1 cd/m² up (the rods are out by `k`) and below
//! the mesopic range, where the cones add nothing; in between it is larger (0.54 against
//! 0.40 at 0.1 cd/m², 0.70 against 0.40 at 0.3), so the blur there is smaller: the rods
//! the metric discounts no longer resolve detail for the observer.
//!
//! # Fallback below the rod Weber range
//!
//! Eq. 7 read literally misbehaves at night: below the rod Weber range (scotopic adaptation
//! under 10^-1.44 scotopic cd/m², Eq. 5) the threshold contrast rises toward 1, which makes
//! `ln(1/c)` and thus the blur *shrink* as light falls, and once `c ≥ 1` (below about
//! 2.6e-3 cd/m²) the equation has no solution at all. There the threshold contrast is held
//! at the rod Weber fraction 10^-0.395 = 0.403 (Eq. 5's upper branch): the rods' contrast
//! `c_s` is held there before the rule combines it with the cones', so the blur keeps
//! growing as the cutoff frequency falls, continuously and monotonically. The price is the
//! calibration: there a full-contrast grating at the cutoff scores `0.403/c_s` JND (0.91
//! at 0.01 cd/m², 0.60 at 2.6e-3), slightly invisible. The report flags
//! when this fallback is in use and prints both contrasts: the one the filter passes at the
//! cutoff ([`AcuityFilter::gain_at_cutoff`]) and the one Eq. 7 asks for
//! ([`AcuityFilter::threshold_contrast`]). Inside the rod Weber range the rods' contrast
//! *is* the Weber fraction, up to rounding (`10^(log L − 0.395)/L`), so the comparison
//! allows [`FALLBACK_TOLERANCE`]: the fallback is used only where the two differ.
//!
//! # Beyond Shaler's data
//!
//! Fig. 7 covers "the range from daylight down to starlight", from about 50 cycles/degree
//! at 3 log cd/m² to about 2 at −3.3 log cd/m² (Sec. 3.4). Outside
//! [[`SHALER_MIN_LOG`], [`SHALER_MAX_LOG`]] the cutoff is the fit's extrapolation, and
//! [`AcuityFilter::extrapolated`] says so.

use crate::mesopic::rod_weight;
use crate::tvi::{ROD_WEBER_OFFSET_LOG, cone_threshold_cd_m2, rod_threshold_scotopic_cd_m2};
use std::f64::consts::PI;

/// Ward Larson et al. 1997, Eq. 15: amplitude of the arctangent fit to Shaler (1937).
const FIT_AMPLITUDE: f64 = 17.25;
/// Ward Larson et al. 1997, Eq. 15: slope of log luminance inside the arctangent.
const FIT_SLOPE: f64 = 1.4;
/// Ward Larson et al. 1997, Eq. 15: offset inside the arctangent.
const FIT_OFFSET: f64 = 0.35;
/// Ward Larson et al. 1997, Eq. 15: additive constant, cycles/degree.
const FIT_BASE: f64 = 25.72;

/// Floor on the cutoff frequency where the fit would fall below it (under ~1e-8 cd/m², far
/// below the absolute threshold of vision); the value follows the project's model notes §2.1.
pub const MIN_CUTOFF_CYCLES_PER_DEGREE: f64 = 0.5;

/// Relative tolerance of the fallback test: the threshold contrast must exceed the rod
/// Weber fraction by more than rounding (a few ulps of `10^(log L − 0.395)/L`) to count as
/// below the Weber range. Our choice, far below any meaningful difference.
pub const FALLBACK_TOLERANCE: f64 = 1e-9;

/// Lowest background of Shaler's acuity data as the paper describes Fig. 7, log10 cd/m²
/// ("about 2 cycles/degree at −3.3 log cd/m²", Sec. 3.4).
pub const SHALER_MIN_LOG: f64 = -3.3;

/// Highest background of Shaler's acuity data as the paper describes Fig. 7, log10 cd/m²
/// ("about 50 cycles/degree at 3 log cd/m²", Sec. 3.4).
pub const SHALER_MAX_LOG: f64 = 3.0;

/// Grating frequency of 20/20 vision: a 1 arcminute stroke, i.e. 30 cycles/degree (Snellen
/// letters are 5 arcmin tall on a 5×5 stroke grid).
pub const SNELLEN_20_20_CYCLES_PER_DEGREE: f64 = 30.0;

/// The highest resolvable spatial frequency (cycles/degree) for an observer adapted to
/// `adaptation_cd_m2` (photopic cd/m²): Ward Larson et al. 1997 Eq. 15, fitted to Shaler 1937.
pub fn cutoff_cycles_per_degree(adaptation_cd_m2: f64) -> f64 {
    let l = adaptation_cd_m2.log10();
    let r = FIT_AMPLITUDE * (FIT_SLOPE * l + FIT_OFFSET).atan() + FIT_BASE;
    if r.is_nan() {
        return r;
    }
    r.max(MIN_CUTOFF_CYCLES_PER_DEGREE)
}

/// Snellen fraction "20/x" for a grating acuity in cycles/degree, x rounded to a whole
/// number (50 c/deg → "20/12", 2 c/deg → "20/300", as in paper Sec. 3.4).
pub fn snellen(cycles_per_degree: f64) -> String {
    let x = 20.0 * SNELLEN_20_20_CYCLES_PER_DEGREE / cycles_per_degree;
    format!("20/{:.0}", x)
}

/// How the rod and cone threshold contrasts combine into the one Eq. 7 uses (see the
/// module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AcuityThreshold {
    /// The visibility metric's threshold: rods weighted by `k` (Eq. 6) and pooled with the
    /// cones by probability summation, so that a full-contrast grating at the cutoff
    /// scores 1 JND in [`crate::visibility`] (the default; beyond the paper).
    #[default]
    Pooled,
    /// The paper's `t(L_wa)/L_wa` read as the envelope of the two t.v.i. curves (Sec. 3.2):
    /// the threshold contrast of the more sensitive system.
    Envelope,
}

impl AcuityThreshold {
    /// The combined threshold contrast of cone contrast `cone` (`t_p/L`), rod contrast
    /// `rod` (`t_s/L_s`) and rod weight `rod_weight` (`k` of Eq. 6).
    pub fn combine(self, cone: f64, rod: f64, rod_weight: f64) -> f64 {
        match self {
            AcuityThreshold::Envelope => cone.min(rod),
            AcuityThreshold::Pooled => {
                1.0 / crate::visibility::pool(cone.recip(), rod_weight / rod)
            }
        }
    }

    /// The rule's name, as the CLI and the reports spell it.
    pub fn name(self) -> &'static str {
        match self {
            AcuityThreshold::Pooled => "pooled",
            AcuityThreshold::Envelope => "envelope",
        }
    }
}

/// The cone and rod threshold contrasts `t_p(L)/L` (Eq. 4) and `t_s(L_s)/L_s` (Eq. 5).
fn contrasts(adaptation_cd_m2: f64, adaptation_scotopic_cd_m2: f64) -> (f64, f64) {
    (
        cone_threshold_cd_m2(adaptation_cd_m2) / adaptation_cd_m2,
        rod_threshold_scotopic_cd_m2(adaptation_scotopic_cd_m2) / adaptation_scotopic_cd_m2,
    )
}

/// The threshold contrast Eq. 7 asks for under `rule`, from the thresholds of Eq. 4 and 5
/// and `k` of Eq. 6 at these adaptation luminances (without the fallback).
pub fn threshold_contrast(
    adaptation_cd_m2: f64,
    adaptation_scotopic_cd_m2: f64,
    rule: AcuityThreshold,
) -> f64 {
    let (cone, rod) = contrasts(adaptation_cd_m2, adaptation_scotopic_cd_m2);
    rule.combine(cone, rod, rod_weight(adaptation_scotopic_cd_m2))
}

/// The rod Weber fraction `10^-0.395` (Eq. 5's upper branch), the threshold contrast held
/// below the rod Weber range (see the module docs).
pub fn rod_weber_fraction() -> f64 {
    10f64.powf(ROD_WEBER_OFFSET_LOG)
}

/// The acuity filter of Eq. 7 for a world adaptation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AcuityFilter {
    /// Highest resolvable frequency `ω_c`, cycles/degree.
    pub cutoff_cycles_per_degree: f64,
    /// The threshold contrast Eq. 7 asks for under [`AcuityFilter::rule`], as computed.
    pub threshold_contrast: f64,
    /// The contrast the filter passes at the cutoff (differs from `threshold_contrast`
    /// only in the fallback).
    pub gain_at_cutoff: f64,
    /// True when the fallback below the rod Weber range is in use.
    pub fallback: bool,
    /// True when the adaptation luminance is outside Fig. 7's data
    /// ([`SHALER_MIN_LOG`] to [`SHALER_MAX_LOG`]): the cutoff is extrapolated.
    pub extrapolated: bool,
    /// Standard deviation of the Gaussian, degrees of visual angle.
    pub sigma_deg: f64,
    /// How the rod and cone thresholds were combined.
    pub rule: AcuityThreshold,
}

impl AcuityFilter {
    /// The Eq. 7 Gaussian for photopic adaptation `adaptation_cd_m2` (sets the cutoff) and
    /// scotopic adaptation `adaptation_scotopic_cd_m2` (with it, the threshold contrast),
    /// under the default rule, [`AcuityThreshold::Pooled`].
    pub fn new(adaptation_cd_m2: f64, adaptation_scotopic_cd_m2: f64) -> Self {
        Self::with_rule(
            adaptation_cd_m2,
            adaptation_scotopic_cd_m2,
            AcuityThreshold::default(),
        )
    }

    /// The Eq. 7 Gaussian as [`AcuityFilter::new`], with the rods and cones combined by
    /// `rule`.
    pub fn with_rule(
        adaptation_cd_m2: f64,
        adaptation_scotopic_cd_m2: f64,
        rule: AcuityThreshold,
    ) -> Self {
        let cutoff = cutoff_cycles_per_degree(adaptation_cd_m2);
        let (cone, rod) = contrasts(adaptation_cd_m2, adaptation_scotopic_cd_m2);
        let k = rod_weight(adaptation_scotopic_cd_m2);
        let c = rule.combine(cone, rod, k);
        let weber = rod_weber_fraction();
        // NaN (no adaptation information) also takes the fallback.
        let fallback = c.is_nan() || rod > weber * (1.0 + FALLBACK_TOLERANCE);
        let gain = if c.is_nan() {
            weber
        } else if fallback {
            rule.combine(cone, weber, k)
        } else {
            c
        };
        let log_l = adaptation_cd_m2.log10();
        let extrapolated = !(SHALER_MIN_LOG..=SHALER_MAX_LOG).contains(&log_l);
        let sigma_deg = (gain.recip().ln() / 2.0).sqrt() / (PI * cutoff);
        AcuityFilter {
            cutoff_cycles_per_degree: cutoff,
            threshold_contrast: c,
            gain_at_cutoff: gain,
            fallback,
            extrapolated,
            sigma_deg,
            rule,
        }
    }

    /// Frequency response of the filter at `cycles_per_degree`.
    pub fn response(&self, cycles_per_degree: f64) -> f64 {
        (-2.0 * PI * PI * self.sigma_deg * self.sigma_deg * cycles_per_degree * cycles_per_degree)
            .exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cutoff_matches_fig7_and_ward_larson_examples() {
        // Paper Sec. 3.4 / Fig. 7: ~50 c/deg at 3 log cd/m², ~2 c/deg at −3.3 log cd/m².
        assert!((cutoff_cycles_per_degree(1e3) - 49.1).abs() < 0.1);
        assert!((cutoff_cycles_per_degree(10f64.powf(-3.3)) - 2.59).abs() < 0.05);
        // Ward Larson 1997 text: 25 cd/m² gives ~45 c/deg and 0.05 cd/m² gives ~9 c/deg.
        assert!((cutoff_cycles_per_degree(25.0) - 45.0).abs() < 1.0);
        assert!((cutoff_cycles_per_degree(0.05) - 9.0).abs() < 0.5);
        // Hand computation: 1 cd/m² → 17.25·atan(0.35) + 25.72 = 31.53.
        assert!((cutoff_cycles_per_degree(1.0) - 31.533).abs() < 0.01);
        assert_eq!(cutoff_cycles_per_degree(0.0), MIN_CUTOFF_CYCLES_PER_DEGREE);
    }

    /// Issue 8 §5 (failed before: `c > weber` was true by rounding for part of the rod
    /// Weber range). Wherever the rods are on Eq. 5's Weber branch and the more sensitive
    /// system, no fallback applies and the filter passes exactly Eq. 7's contrast.
    #[test]
    fn no_fallback_inside_the_rod_weber_range() {
        let mut checked = 0;
        for i in 0..=2000 {
            let l = 10f64.powf(-1.7 + i as f64 * 0.0008); // 0.02 .. 0.8 cd/m²
            let ls = l * 2.261; // above 10^-1.44 scotopic cd/m²: rod Weber range
            let f = AcuityFilter::new(l, ls);
            assert!(
                !f.fallback,
                "fallback at {l} cd/m²: c = {:e}",
                f.threshold_contrast
            );
            assert_eq!(f.gain_at_cutoff, f.threshold_contrast);
            checked += 1;
        }
        assert_eq!(checked, 2001);
        assert!(AcuityFilter::new(2e-3, 4.5e-3).fallback);
    }

    /// Issue 8 §5: outside Fig. 7's -3.3 to 3 log cd/m² the cutoff is extrapolated.
    #[test]
    fn extrapolation_beyond_shalers_data_is_flagged() {
        assert!(AcuityFilter::new(1e-6, 2.261e-6).extrapolated);
        assert!(AcuityFilter::new(1e4, 2.261e4).extrapolated);
        assert!(!AcuityFilter::new(1e-3, 2.261e-3).extrapolated);
        assert!(!AcuityFilter::new(1e3, 2.261e3).extrapolated);
    }

    /// The pooled rule's threshold contrast, computed by hand from Eq. 4-6 (values in the
    /// module docs): the envelope `min(c_p, c_s)` where one system alone sees, larger in
    /// the mesopic range where `k` discounts the rods.
    #[test]
    fn pooled_threshold_contrast_by_hand() {
        let pooled = |l: f64| AcuityFilter::new(l, 2.261 * l).threshold_contrast;
        let envelope = |l: f64| {
            AcuityFilter::with_rule(l, 2.261 * l, AcuityThreshold::Envelope).threshold_contrast
        };
        // 0.1 cd/m²: c_p = 10^((0.249·(−1) + 0.65)^2.7 − 0.72)/0.1 = 2.3164, c_s = 0.40272
        // (Weber branch), k(0.2261) = 1 − (3u² − 2u³) at u = 1/3: 0.74074.
        let (cp, cs, k): (f64, f64, f64) = (2.3164, 10f64.powf(-0.395), 20.0 / 27.0);
        let by_hand = 1.0 / (cp.powf(-3.5) + (k / cs).powf(3.5)).powf(1.0 / 3.5);
        assert!((by_hand - 0.5427).abs() < 1e-4, "{by_hand}");
        assert!((pooled(0.1) - by_hand).abs() < 1e-4, "{}", pooled(0.1));
        assert!((envelope(0.1) - cs).abs() < 1e-9);
        // 0.3 cd/m²: 0.6958 against the envelope's 0.4027.
        assert!((pooled(0.3) - 0.6958).abs() < 1e-3, "{}", pooled(0.3));
        // Daylight (k = 0) and below the mesopic range (cones negligible): the envelope.
        for l in [10.0, 100.0, 1e4] {
            assert!((pooled(l) / envelope(l) - 1.0).abs() < 1e-12);
        }
        assert!((pooled(1.0) / envelope(1.0) - 1.0).abs() < 3e-3);
        assert!((pooled(0.005) / envelope(0.005) - 1.0).abs() < 1e-4);
        // No solution only where the rods cannot see full contrast either.
        for i in 0..=700 {
            let l = 10f64.powf(-2.7 + i as f64 * 0.01);
            assert!(pooled(l) < 1.0, "{l}");
        }
    }

    #[test]
    fn snellen_fractions() {
        assert_eq!(snellen(30.0), "20/20");
        assert_eq!(snellen(2.0), "20/300");
        assert_eq!(snellen(49.1), "20/12");
    }

    #[test]
    fn eq7_response_at_cutoff_is_threshold_contrast() {
        for l in [0.5, 1.0, 3.0, 10.0, 100.0, 1e4] {
            let f = AcuityFilter::new(l, l * 2.261);
            assert!(!f.fallback);
            let got = f.response(f.cutoff_cycles_per_degree);
            assert!((got - f.threshold_contrast).abs() < 1e-12, "{l}: {got}");
        }
        // Hand computation at 10 cd/m²: c = t_p(10)/10 = 10^(0.02996-1) = 0.10714,
        // ω_c = 17.25·atan(1.75) + 25.72 = 43.90; s = sqrt(ln(1/c)/2)/(π ω_c) = 0.007655 deg.
        let f = AcuityFilter::new(10.0, 22.61);
        assert!((f.threshold_contrast - 0.107_14).abs() < 2e-4);
        assert!((f.sigma_deg - 0.007_655).abs() < 2e-5, "{}", f.sigma_deg);
    }

    #[test]
    fn fallback_below_rod_weber_range_is_continuous_and_monotone() {
        // Weber fraction 0.4027 in the rod Weber range, the envelope's contrast there.
        let f = AcuityFilter::with_rule(0.1, 0.2261, AcuityThreshold::Envelope);
        assert!((f.threshold_contrast - 0.402_7).abs() < 1e-3 && !f.fallback);
        // Where t/L ≥ 1 (1e-3 cd/m²) Eq. 7 has no solution: fallback, finite blur.
        let f = AcuityFilter::new(1e-3, 2.261e-3);
        assert!(f.threshold_contrast >= 1.0 && f.fallback);
        assert!(f.sigma_deg.is_finite() && f.sigma_deg > 0.0);
        // The rods' contrast held at the Weber fraction; the cones (c_p = 190) add
        // (0.40/190)^3.5/3.5 ≈ 1e-10 to the pooled sensitivity.
        assert!((f.response(f.cutoff_cycles_per_degree) - rod_weber_fraction()).abs() < 1e-9);
        let e = AcuityFilter::with_rule(1e-3, 2.261e-3, AcuityThreshold::Envelope);
        assert!((e.response(e.cutoff_cycles_per_degree) - rod_weber_fraction()).abs() < 1e-12);
        // Below the rod Weber range the blur never shrinks as the light falls. (Above it,
        // Eq. 7 itself is not monotone: between 10 and 1 cd/m² the threshold contrast
        // rises faster than the cutoff falls and sigma dips by ~10 %; that is the paper's.
        // The pooled rule moves the bottom of that dip down to 0.4 cd/m².)
        let mut prev = 0.0;
        for i in (0..=1000).rev() {
            let l = 10f64.powf(-8.0 + i as f64 * 0.0064); // 1e-8 .. 2.5e-2 cd/m²
            let s = AcuityFilter::new(l, l * 2.261).sigma_deg;
            assert!(s.is_finite());
            assert!(s >= prev, "blur shrinks at {l}: {s} < {prev}");
            prev = s;
        }
        assert!(
            AcuityFilter::new(1e-3, 2.261e-3).sigma_deg > AcuityFilter::new(0.1, 0.2261).sigma_deg
        );
    }
}
