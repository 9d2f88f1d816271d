//! The time course of adaptation (Sec. 3.5, Figs. 8–10, Eq. 8–9, Fig. 12): the paper's
//! statements as tests with stated tolerances, exactness for any step size, and the steady
//! state equal to the static operator.

mod common;

use visadapt::operator::{self, ViewingConditions};
use visadapt::scotopic::EQUAL_ENERGY_SP_RATIO;
use visadapt::sequence::{self, ApngWriter, Sequence};
use visadapt::timecourse::{self, Adaptation};
use visadapt::tvi::{log_cone_threshold, log_rod_threshold};
use visadapt::{HdrImage, Limits, io};

const SP: f64 = EQUAL_ENERGY_SP_RATIO;

/// An observer adapted to `from` meeting `to` (photopic, scotopic) at t = 0, sampled at
/// `times` with one exact step per sample.
fn sampled(from: (f64, f64), to: (f64, f64), times: &[f64]) -> Vec<Adaptation> {
    let mut eye = Adaptation::adapted(from.0, from.1).unwrap();
    eye.step(0.0, to.0, to.1).unwrap();
    let mut now = 0.0;
    times
        .iter()
        .map(|&t| {
            eye.step(t - now, to.0, to.1).unwrap();
            now = t;
            eye.clone()
        })
        .collect()
}

fn at(from: (f64, f64), to: (f64, f64), t: f64) -> Adaptation {
    sampled(from, to, &[t]).pop().unwrap()
}

fn grid(end: f64, n: usize) -> Vec<f64> {
    (0..=n).map(|i| end * i as f64 / n as f64).collect()
}

const DARK: (f64, f64) = (0.0, 0.0);

fn adelson() -> (f64, f64) {
    let bg = 10f64.powf(timecourse::ADELSON_BACKGROUND_LOG);
    (bg / SP, bg)
}

fn baker() -> (f64, f64) {
    let bg = 10f64.powf(timecourse::BAKER_BACKGROUND_LOG);
    (bg, bg * SP)
}

fn hecht() -> (f64, f64) {
    let l = timecourse::HECHT_PREADAPTATION_CD_M2;
    (l, l * SP)
}

/// Fig. 8 (Sec. 3.5.1): "More than 80% of sensitivity recovery occurs within the first 2
/// seconds, and nearly 75% happens within the first 200 ms." Recovery = fall of the log
/// threshold from its onset value, as a fraction of the whole fall.
#[test]
fn rods_recover_three_quarters_in_200_ms_and_over_80_percent_in_2_s() {
    let onset = at(DARK, adelson(), 0.0).rod_excess_log();
    assert!((onset - timecourse::ROD_ONSET_LOG).abs() < 1e-9, "{onset}");
    let recovered = |t| 1.0 - at(DARK, adelson(), t).rod_excess_log() / onset;
    let r200 = recovered(0.2);
    assert!((0.72..=0.78).contains(&r200), "200 ms: {r200}");
    let r2 = recovered(2.0);
    assert!(r2 > 0.80 && r2 < 0.85, "2 s: {r2}");
    // The threshold jumps at onset from the dark-adapted level (Eq. 5 floor, -2.86)...
    let t0 = at(DARK, adelson(), 0.0).log_rod_threshold();
    assert!(t0 > log_rod_threshold(timecourse::ADELSON_BACKGROUND_LOG) + 2.0);
    // ... and the fall in the first 2 s is the paper's 0.1 → -1.7 = 1.8 log units ± 0.05.
    let fall = t0 - at(DARK, adelson(), 2.0).log_rod_threshold();
    assert!((fall - 1.8).abs() < 0.05, "{fall}");
    // Monotone recovery, never below Eq. 5 (rods have no undershoot).
    let eyes = sampled(DARK, adelson(), &grid(60.0, 6000));
    for w in eyes.windows(2) {
        assert!(w[1].rod_excess_log() <= w[0].rod_excess_log() + 1e-15);
        assert!(w[1].rod_excess_log() >= 0.0);
    }
}

/// Fig. 9 (Sec. 3.5.1, Baker, 3.75 log cd/m²): highest at onset; "reaches a minimum after
/// about 3 minutes"; "drops more than 0.5 log units during this period"; "rises again
/// slightly and reaches its fully adapted level at about 10 minutes".
#[test]
fn cones_fall_to_a_minimum_at_three_minutes_then_settle_by_ten() {
    let ts = grid(1200.0, 2400); // every 0.5 s for 20 min
    let e: Vec<f64> = sampled(DARK, baker(), &ts)
        .iter()
        .map(Adaptation::cone_excess_log)
        .collect();
    let (imin, &emin) = e
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .unwrap();
    let tmin = ts[imin];
    // Highest at onset.
    assert!(e.iter().all(|&x| x <= e[0]));
    assert!((e[0] - timecourse::CONE_ONSET_LOG).abs() < 1e-9);
    // Minimum at about 3 minutes (±30 s).
    assert!((150.0..=210.0).contains(&tmin), "minimum at {tmin} s");
    // Falls by more than 0.5 log units to it (and not absurdly more: < 0.7).
    assert!(
        e[0] - emin > 0.5 && e[0] - emin < 0.7,
        "drop {}",
        e[0] - emin
    );
    // Falls all the way to the minimum, then only rises.
    assert!(e[..=imin].windows(2).all(|w| w[1] <= w[0]));
    assert!(e[imin..].windows(2).all(|w| w[1] >= w[0] - 1e-15));
    // Rises "slightly": by 0.05–0.15 log units in all.
    assert!((0.05..=0.15).contains(&-emin), "rise {}", -emin);
    // Fully adapted at about 10 minutes: within 0.02 log units from then on.
    let i10 = ts.iter().position(|&t| t >= 600.0).unwrap();
    assert!(e[i10..].iter().all(|x| x.abs() < 0.02), "{}", e[i10]);
    // But not long before: at 7 min the dip is still measurable (> 0.02).
    let i7 = ts.iter().position(|&t| t >= 420.0).unwrap();
    assert!(e[i7] < -0.02, "{}", e[i7]);
}

/// Sec. 5, Fig. 12a: 0.1 → 5623 cd/m²; "after 75 seconds ... adaptation is almost
/// complete": the cone excess is under a tenth of its onset value. The rods are not
/// measured here: at 5623 cd/m² the rod weight k is 0.
#[test]
fn light_sequence_of_figure_12a_is_almost_complete_after_75_s() {
    let from = (0.1, 0.1 * SP);
    let to = (5623.0, 5623.0 * SP);
    let e0 = at(from, to, 0.0).cone_excess_log();
    let e75 = at(from, to, 75.0).cone_excess_log();
    assert!(e0 > 0.35, "{e0}");
    assert!(e75.abs() < 0.1 * e0, "{e75} vs {e0}");
    assert_eq!(
        at(from, to, 75.0).mapping_for(80.0, 40.0, 0.0).rod_weight,
        0.0
    );
}

/// Fig. 10 (Sec. 3.5.2, Hecht): "In the first 5 minutes ... the threshold drops rapidly,
/// but then it levels off"; "After about 7 minutes rod system sensitivity surpasses that of
/// the cone system" (the Purkinje break); "Changes in the threshold can be measured out to
/// about 35 minutes"; "the threshold has dropped nearly 4 log units".
#[test]
fn dark_adaptation_has_the_hecht_plateau_break_and_depth() {
    let ts = grid(3600.0, 3600); // every second for an hour
    let eyes = sampled(hecht(), DARK, &ts);
    let cone: Vec<f64> = eyes.iter().map(Adaptation::log_cone_threshold).collect();
    let rod: Vec<f64> = eyes.iter().map(Adaptation::log_rod_threshold).collect();
    let env: Vec<f64> = cone.iter().zip(&rod).map(|(c, r)| c.min(*r)).collect();
    let min = |t: f64| (t * 60.0) as usize;
    // Fast cone drop to within 0.02 of the cone plateau (Eq. 4 floor) by 5 minutes, most of
    // it (> 90 %) in the first 3.
    let plateau = -0.72;
    assert!(cone[min(5.0)] - plateau < 0.02, "{}", cone[min(5.0)]);
    assert!((cone[0] - cone[min(3.0)]) / (cone[0] - plateau) > 0.9);
    // The cones limit the threshold until the break, and it is level: < 0.05 log change
    // from 5 minutes to the break.
    let brk = (0..ts.len()).find(|&i| rod[i] < cone[i]).unwrap();
    let tbrk = ts[brk] / 60.0;
    assert!((6.5..=7.5).contains(&tbrk), "Purkinje break at {tbrk} min");
    assert!(env[min(5.0)] - env[brk] < 0.05);
    // After the break the rods drop the threshold again, measurably until 35 minutes
    // (> 0.03 log from 30 to 35 min), with under 0.1 log left to go after that.
    assert!(env[min(30.0)] - env[min(35.0)] > 0.03);
    assert!(env[min(35.0)] - env[min(60.0)] < 0.1);
    assert!(env[min(35.0)] - env[min(60.0)] > 0.0);
    // Nearly 4 log units in all.
    let depth = env[0] - env[min(60.0)];
    assert!((3.7..4.0).contains(&depth), "{depth}");
    // Monotone: dark adaptation never overshoots.
    assert!(env.windows(2).all(|w| w[1] <= w[0]));
    assert!(rod.iter().all(|&r| r >= -2.86) && cone.iter().all(|&c| c >= -0.72));
}

/// Sec. 5, Fig. 12b: 1412 → 0.1 cd/m²: the cones' part is nearly done after 3.5 minutes
/// (under 5 % of their drop left); the rods, fitted to Hecht's 7-minute break, are not (the
/// documented tension) but are within 0.05 log after an hour.
#[test]
fn dark_sequence_of_figure_12b_is_cone_complete_after_3_5_minutes() {
    let from = (1412.0, 1412.0 * SP);
    let to = (0.1, 0.1 * SP);
    let drop = log_cone_threshold(1412f64.log10()) - log_cone_threshold(-1.0);
    let left = at(from, to, 210.0).cone_excess_log();
    assert!(left > 0.0 && left < 0.05 * drop, "{left} of {drop}");
    assert!(at(from, to, 210.0).rod_excess_log() > 1.0);
    assert!(at(from, to, 3600.0).rod_excess_log() < 0.05);
}

/// A list of scenarios covering light, dark, mesopic and flat-region steps.
fn scenarios() -> Vec<((f64, f64), (f64, f64))> {
    let ee = |l: f64| (l, l * SP);
    vec![
        (DARK, adelson()),
        (DARK, baker()),
        (hecht(), DARK),
        (ee(0.1), ee(5623.0)),
        (ee(1412.0), ee(0.1)),
        (ee(0.5), ee(2.0)),
        (ee(1e-5), ee(1e-4)), // both inside the flat part of Eq. 4: no cone transient
        (ee(40.0), ee(40.0)),
    ]
}

/// Exact updates: one 10 s step and a thousand 10 ms steps agree (1e-9 log units), for
/// every scenario and also for a second change in mid-transient.
#[test]
fn one_long_step_equals_many_short_ones() {
    for (from, to) in scenarios() {
        let mut one = Adaptation::adapted(from.0, from.1).unwrap();
        let mut many = one.clone();
        one.step(0.0, to.0, to.1).unwrap();
        many.step(0.0, to.0, to.1).unwrap();
        one.step(10.0, to.0, to.1).unwrap();
        for _ in 0..1000 {
            many.step(0.01, to.0, to.1).unwrap();
        }
        let d_c = (one.log_cone_threshold() - many.log_cone_threshold()).abs();
        let d_r = (one.log_rod_threshold() - many.log_rod_threshold()).abs();
        assert!(d_c < 1e-9 && d_r < 1e-9, "{from:?} → {to:?}: {d_c} {d_r}");
        // Then back to `from` and 600 s more, in one step or in 60 000 10 ms steps.
        one.step(0.0, from.0, from.1).unwrap();
        many.step(0.0, from.0, from.1).unwrap();
        one.step(600.0, from.0, from.1).unwrap();
        for _ in 0..60_000 {
            many.step(0.01, from.0, from.1).unwrap();
        }
        let d_c = (one.log_cone_threshold() - many.log_cone_threshold()).abs();
        let d_r = (one.log_rod_threshold() - many.log_rod_threshold()).abs();
        assert!(
            d_c < 1e-9 && d_r < 1e-9,
            "back {to:?} → {from:?}: {d_c} {d_r}"
        );
    }
}

/// No NaN and no overshoot for any step size from 1 ms to 10 minutes: every sampled state
/// lies on the continuous curve (sampled by one exact step from the switch) and within the
/// bounds the model allows: between the new steady state and the onset for rods and for
/// dark adaptation, and no further below the steady state than Baker's dip for cones.
#[test]
fn no_nan_or_overshoot_at_any_step_size() {
    for (from, to) in scenarios() {
        let th = |l: (f64, f64)| {
            (
                log_cone_threshold(l.0.log10()),
                log_rod_threshold(l.1.log10()),
            )
        };
        let (c0, r0) = th(from);
        let (c1, r1) = th(to);
        let onset = |t| at(from, to, t);
        let c_hi = onset(0.0).log_cone_threshold().max(c0);
        let r_hi = onset(0.0).log_rod_threshold().max(r0);
        for dt in [1e-3, 1e-2, 0.1, 1.0, 10.0, 60.0, 600.0] {
            let n = ((7200.0 / dt) as usize).min(20_000);
            let mut eye = Adaptation::adapted(from.0, from.1).unwrap();
            eye.step(0.0, to.0, to.1).unwrap();
            for i in 1..=n {
                eye.step(dt, to.0, to.1).unwrap();
                let (c, r) = (eye.log_cone_threshold(), eye.log_rod_threshold());
                let m = eye.mapping_for(80.0, 40.0, 0.0);
                let values = [
                    c,
                    r,
                    m.photopic_scale,
                    m.scotopic_scale,
                    m.photopic_offset_cd_m2,
                    m.scotopic_offset_cd_m2,
                    eye.acuity_cycles_per_degree(),
                ];
                assert!(
                    values.iter().all(|v| v.is_finite()),
                    "{from:?}→{to:?} dt {dt}: {values:?}"
                );
                assert!(
                    c <= c_hi + 1e-12 && c >= c1 - timecourse::CONE_DIP_LOG - 1e-12,
                    "cones {c} dt {dt}"
                );
                assert!(r <= r_hi + 1e-12 && r >= r1 - 1e-12, "rods {r} dt {dt}");
                if i % 97 == 0 || i == n {
                    let exact = onset(dt * i as f64);
                    assert!(
                        (exact.log_cone_threshold() - c).abs() < 1e-9,
                        "dt {dt} step {i}"
                    );
                    assert!(
                        (exact.log_rod_threshold() - r).abs() < 1e-9,
                        "dt {dt} step {i}"
                    );
                }
            }
        }
    }
}

/// Continuity in time: after the switch the thresholds move by no more than their fastest
/// rate allows between 1 ms samples (the rods' 50 ms recovery of at most 1.7 log units:
/// < 0.035 per ms), and the mapping obeys Eq. 9 at every moment.
#[test]
fn thresholds_are_continuous_and_eq9_holds_throughout() {
    for (from, to) in scenarios() {
        let eyes = sampled(from, to, &grid(5.0, 5000));
        for w in eyes.windows(2) {
            assert!((w[1].log_rod_threshold() - w[0].log_rod_threshold()).abs() < 0.035);
            assert!((w[1].log_cone_threshold() - w[0].log_cone_threshold()).abs() < 0.035);
        }
        // Eq. 9: the display value of the world adaptation luminance never changes.
        let steady = Adaptation::adapted(to.0, to.1)
            .unwrap()
            .mapping_for(80.0, 40.0, 0.0);
        let target =
            steady.photopic_scale * to.0 + steady.rod_weight * steady.scotopic_scale * to.1;
        for t in [0.0, 0.1, 1.0, 30.0, 180.0, 600.0, 3600.0] {
            let m = at(from, to, t).mapping_for(80.0, 40.0, 0.0);
            let shown = m.photopic_scale * to.0
                + m.photopic_offset_cd_m2
                + m.rod_weight * (m.scotopic_scale * to.1 + m.scotopic_offset_cd_m2);
            assert!(
                (shown - target).abs() <= 1e-9 * target.max(1e-9),
                "{from:?}→{to:?} at {t}: {shown} vs {target}"
            );
        }
    }
}

/// Continuity in the input: a tiny change of luminance gives a tiny transient (no jump from
/// the event rule), whether the observer is adapted or in mid-transient.
#[test]
fn a_tiny_change_of_luminance_changes_little() {
    for (from, to) in scenarios() {
        for t_mid in [0.0, 0.3, 30.0, 200.0] {
            let mut a = at(from, to, t_mid);
            let mut b = a.clone();
            let f = 1.0 + 1e-7;
            a.step(1.0, to.0, to.1).unwrap();
            b.step(0.0, to.0 * f, to.1 * f).unwrap();
            b.step(1.0, to.0 * f, to.1 * f).unwrap();
            assert!((a.log_cone_threshold() - b.log_cone_threshold()).abs() < 1e-6);
            assert!((a.log_rod_threshold() - b.log_rod_threshold()).abs() < 1e-6);
        }
    }
}

/// Restart from the current thresholds: a fall in luminance in mid-transient does not make
/// the thresholds jump; a rise after a fall first uses up the pending dark adaptation.
#[test]
fn changes_in_mid_transient_restart_from_the_current_thresholds() {
    let ee = |l: f64| (l, l * SP);
    for (from, to, t_mid) in [
        (ee(0.1), ee(5623.0), 20.0),
        (ee(0.1), ee(5623.0), 200.0),
        (ee(1412.0), ee(0.1), 60.0),
    ] {
        let mut eye = at(from, to, t_mid);
        let (c, r) = (eye.log_cone_threshold(), eye.log_rod_threshold());
        let dimmer = (to.0 / 10.0, to.1 / 10.0);
        eye.step(0.0, dimmer.0, dimmer.1).unwrap();
        assert!((eye.log_cone_threshold() - c).abs() < 1e-12);
        assert!((eye.log_rod_threshold() - r).abs() < 1e-12);
        // And it goes on to the new steady state.
        eye.step(7200.0, dimmer.0, dimmer.1).unwrap();
        assert!(eye.cone_excess_log().abs() < 1e-3 && eye.rod_excess_log().abs() < 1e-3);
    }
    // 1000 → 10 cd/m², and back 1 s later: the cones have hardly dark-adapted, so going back
    // up is no new light onset: the threshold stays within 0.01 of Eq. 4 at 1000.
    let mut eye = Adaptation::equal_energy(1000.0).unwrap();
    eye.step(0.0, 10.0, 10.0 * SP).unwrap();
    eye.step(1.0, 1000.0, 1000.0 * SP).unwrap();
    assert!(
        eye.cone_excess_log().abs() < 0.01,
        "{}",
        eye.cone_excess_log()
    );
}

fn mixtex() -> HdrImage {
    io::read(&common::data("mixtex.hdr"), &Limits::default()).unwrap()
}

/// Once adaptation is complete the mapping is exactly the static operator's, and so is the
/// image: whether the observer started adapted or came through a transient.
#[test]
fn steady_state_is_exactly_the_static_operator() {
    let mut scene = mixtex();
    for peak in [1e-3, 0.05, 3.0, 1e4] {
        let hv = visadapt::adaptation::highest_visible(&scene.y, 1e-3) as f64;
        scene.scale((peak / hv) as f32);
        let cond = ViewingConditions::default();
        let report = operator::plan(&scene, &cond).unwrap();
        let adapted = Adaptation::adapted(
            report.world_adaptation_cd_m2,
            report.world_adaptation_scotopic_cd_m2,
        )
        .unwrap();
        assert!(adapted.is_adapted());
        assert_eq!(adapted.mapping(&report), report.mapping);
        assert_eq!(
            adapted.acuity_cycles_per_degree(),
            report.acuity.cutoff_cycles_per_degree
        );
        for start in [0.0, 1e-4, 1.0, 1e5] {
            let mut eye = Adaptation::equal_energy(start).unwrap();
            eye.step_to(0.0, &report).unwrap();
            eye.step_to(1e6, &report).unwrap();
            assert!(eye.is_adapted(), "from {start} to {peak}");
            assert_eq!(eye.mapping(&report), report.mapping);
            let (img, _) = operator::apply(&scene, &eye.mapping(&report));
            let out = operator::map(&scene, &cond).unwrap();
            assert_eq!(img, out.image);
        }
    }
}

/// Eq. 9 in pixels: a uniform grey at the world adaptation luminance keeps its display
/// value while the rest of the image changes (contrast grows during light adaptation).
#[test]
fn display_value_of_the_adaptation_luminance_is_constant_in_pixels() {
    let mut scene = mixtex();
    let hv = visadapt::adaptation::highest_visible(&scene.y, 1e-3) as f64;
    scene.scale((5623.0 / hv) as f32);
    let report = operator::plan(
        &scene,
        &ViewingConditions {
            acuity: false,
            ..Default::default()
        },
    )
    .unwrap();
    let lwa = report.world_adaptation_cd_m2 as f32;
    let mut grey = HdrImage::zeros(4, 1);
    // The scene's white (E, the Radiance file's; the report adapts it to the display's
    // D65) at L_wa, and at 0 and 2 L_wa for contrast.
    for (i, l) in [lwa, lwa, 0.0, 2.0 * lwa].into_iter().enumerate() {
        (grey.x[i], grey.y[i], grey.z[i]) = (l, l, l);
    }
    grey.scotopic = Some(vec![
        report.world_adaptation_scotopic_cd_m2 as f32,
        report.world_adaptation_scotopic_cd_m2 as f32,
        0.0,
        2.0 * report.world_adaptation_scotopic_cd_m2 as f32,
    ]);
    let mut eye = Adaptation::equal_energy(0.05).unwrap();
    eye.step_to(0.0, &report).unwrap();
    let steady = operator::apply(&grey, &report.mapping).0;
    let mut contrast = Vec::new();
    for t in [0.0, 5.0, 20.0, 75.0] {
        eye.step_to(
            if t == 0.0 {
                0.0
            } else {
                t - eye.seconds_since_change()
            },
            &report,
        )
        .unwrap();
        let (d, _) = operator::apply(&grey, &eye.mapping(&report));
        assert!(
            (d.g[0] - steady.g[0]).abs() < 1e-5,
            "t {t}: {} vs {}",
            d.g[0],
            steady.g[0]
        );
        contrast.push(d.g[3] - d.g[2]);
    }
    assert!(contrast.windows(2).all(|w| w[1] > w[0]), "{contrast:?}");
}

/// Acuity during a transient: below the steady value after a switch, back to exactly it.
#[test]
fn acuity_is_lowered_during_transients_and_recovers() {
    let ee = |l: f64| (l, l * SP);
    for (from, to) in [(ee(0.1), ee(5623.0)), (ee(1412.0), ee(0.1))] {
        let steady = Adaptation::adapted(to.0, to.1)
            .unwrap()
            .acuity_cycles_per_degree();
        let a0 = at(from, to, 0.0).acuity_cycles_per_degree();
        assert!(a0 < 0.9 * steady, "{a0} vs {steady}");
        let a = at(from, to, 1e6).acuity_cycles_per_degree();
        assert_eq!(a, steady);
    }
    // Dark: at first nothing is resolvable ("only the major scene features").
    assert_eq!(at(ee(1412.0), ee(0.1), 0.0).acuity_cycles_per_degree(), 0.0);
}

/// `course` (the data of `visadapt timecourse`) agrees with stepping by hand and checks
/// its inputs.
#[test]
fn course_matches_the_state_and_checks_its_input() {
    let ee = |l: f64| (l, l * SP);
    let times = [0.0, 0.2, 2.0, 75.0, 600.0];
    let c = timecourse::course(ee(0.1), ee(5623.0), &times, 80.0, Default::default()).unwrap();
    assert_eq!(c.len(), times.len());
    for m in &c {
        let eye = at(ee(0.1), ee(5623.0), m.t_seconds);
        assert!((m.cone_threshold_cd_m2 / eye.cone_threshold_cd_m2() - 1.0).abs() < 1e-12);
        assert!(
            (m.rod_threshold_scotopic_cd_m2 / eye.rod_threshold_scotopic_cd_m2() - 1.0).abs()
                < 1e-12
        );
    }
    assert!(timecourse::course(ee(1.0), ee(2.0), &[1.0, 0.5], 80.0, Default::default()).is_err());
    assert!(timecourse::course(ee(1.0), ee(2.0), &[-1.0], 80.0, Default::default()).is_err());
    assert!(timecourse::course(ee(1.0), ee(2.0), &[f64::NAN], 80.0, Default::default()).is_err());
    assert!(
        timecourse::course((f64::NAN, 1.0), ee(2.0), &[1.0], 80.0, Default::default()).is_err()
    );
    assert!(timecourse::course(ee(1.0), ee(2.0), &[1.0], 0.0, Default::default()).is_err());
}

/// Figs. 8–10 as data: times from 0, increasing, finite thresholds, and the figure's
/// shape (Fig. 10's envelope is the lower of the two curves).
#[test]
fn figure_data_have_the_papers_shape() {
    for f in [
        timecourse::figure_8(),
        timecourse::figure_9(),
        timecourse::figure_10(),
    ] {
        for c in &f.curves {
            assert!(c.points.len() > 100);
            assert_eq!(c.points[0].0, 0.0);
            assert!(c.points.windows(2).all(|w| w[1].0 > w[0].0));
            assert!(c.points.iter().all(|p| p.1.is_finite()));
        }
    }
    let f8 = timecourse::figure_8();
    assert_eq!(f8.number, 8);
    let p = &f8.curves[0].points;
    assert!(p[0].1 > p.last().unwrap().1 + 1.5);
    let f10 = timecourse::figure_10();
    assert_eq!(f10.curves.len(), 3);
    for i in 0..f10.curves[0].points.len() {
        let (c, r, e) = (
            f10.curves[0].points[i].1,
            f10.curves[1].points[i].1,
            f10.curves[2].points[i].1,
        );
        assert_eq!(e, c.min(r));
    }
}

/// The Fig. 12 sequences: the first frame is the static operator at the first level; the
/// frame just after a switch up is washed out (lower contrast) and contrast grows; the last
/// frame approaches the static operator at the second level.
#[test]
fn figure_12_sequences_render_from_washed_out_to_steady() {
    let scene = mixtex();
    let cond = ViewingConditions::default();
    let hv = visadapt::adaptation::highest_visible(&scene.y, cond.hot_pixel_fraction) as f64;
    let lit_at = |l: f64| {
        let mut s = scene.clone();
        s.scale((l / hv) as f32);
        s
    };
    let spread = |g: &[f32]| {
        let mean = g.iter().sum::<f32>() / g.len() as f32;
        (g.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / g.len() as f32).sqrt()
    };
    for seq in [Sequence::figure_12a(), Sequence::figure_12b()] {
        let mut frames = Vec::new();
        sequence::render(&scene, &seq, &cond, |f| {
            frames.push((f.index, f.t_seconds, f.image.clone(), f.mapping));
            Ok(())
        })
        .unwrap();
        assert_eq!(frames.len(), seq.frame_count());
        assert_eq!(frames[0].1, None);
        assert_eq!(frames[1].1, Some(0.0));
        let first = operator::map(&lit_at(seq.from_cd_m2), &cond).unwrap();
        let diff = first
            .image
            .g
            .iter()
            .zip(&frames[0].2.g)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(diff < 1e-5, "first frame differs by {diff}");
        let s: Vec<f32> = frames[1..].iter().map(|f| spread(&f.2.g)).collect();
        assert!(s.windows(2).all(|w| w[1] >= w[0] * 0.999), "{s:?}");
        assert!(s[0] < 0.8 * s.last().unwrap(), "{s:?}");
    }
    // Fig. 12a ends near its steady state: the mean |difference| from the static operator
    // at 5623 cd/m² is under a fifth of what it was just after the switch.
    let mut frames = Vec::new();
    sequence::render(&scene, &Sequence::figure_12a(), &cond, |f| {
        frames.push(f.image.clone());
        Ok(())
    })
    .unwrap();
    let steady = operator::map(&lit_at(5623.0), &cond).unwrap().image;
    let mad = |im: &visadapt::DisplayImage| {
        im.g.iter()
            .zip(&steady.g)
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
            / im.len() as f32
    };
    let (early, late) = (mad(&frames[1]), mad(frames.last().unwrap()));
    assert!(late < 0.2 * early, "{late} vs {early}");
}

#[test]
fn sequence_refuses_bad_input() {
    assert!(Sequence::new(0.0, 1.0, vec![0.0]).is_err());
    assert!(Sequence::new(1.0, f64::NAN, vec![0.0]).is_err());
    assert!(Sequence::new(1.0, 2.0, vec![3.0, 1.0]).is_err());
    assert!(Sequence::new(1.0, 2.0, vec![-0.5]).is_err());
    let black = HdrImage::zeros(4, 4);
    let r = sequence::render(
        &black,
        &Sequence::figure_12a(),
        &ViewingConditions::default(),
        |_| Ok(()),
    );
    assert!(r.unwrap_err().to_string().contains("no visible luminance"));
}

/// The APNG writer: announced frame count, frames decoded back, nothing left behind on
/// failure.
#[test]
fn apng_writer_streams_frames_atomically() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.png");
    let mut frames = Vec::new();
    sequence::render(
        &mixtex(),
        &Sequence::new(0.1, 100.0, vec![0.0, 10.0]).unwrap(),
        &ViewingConditions::default(),
        |f| {
            frames.push(f.image.clone());
            Ok(())
        },
    )
    .unwrap();
    let (w, h) = (frames[0].width, frames[0].height);
    let mut apng = ApngWriter::create(&path, w, h, 3, 500).unwrap();
    for f in &frames {
        apng.push(f).unwrap();
    }
    apng.finish().unwrap();
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
    let mut reader = dec.read_info().unwrap();
    let actl = reader.info().animation_control.unwrap();
    assert_eq!(actl.num_frames, 3);
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let mut n = 0;
    while reader.next_frame(&mut buf).is_ok() {
        assert_eq!(&buf[..w * h * 3], &io::display::to_srgb8(&frames[n])[..]);
        n += 1;
    }
    assert_eq!(n, 3);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o644, "{mode:o}");
    }
    // A wrong-sized frame is refused; an unfinished animation leaves no file.
    let bad = dir.path().join("b.png");
    let mut apng = ApngWriter::create(&bad, w, h, 3, 500).unwrap();
    apng.push(&frames[0]).unwrap();
    let mut small = frames[0].clone();
    small.width = 1;
    small.height = 1;
    assert!(apng.push(&small).is_err());
    assert!(apng.finish().is_err());
    assert!(!bad.exists());
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 1, "{leftovers:?}");
}

/// Share of pixels shown pure black, (0, 0, 0) in 8-bit sRGB.
fn black_fraction(d: &visadapt::DisplayImage) -> f64 {
    let px = io::display::to_srgb8(d);
    let black = px.chunks_exact(3).filter(|p| *p == [0, 0, 0]).count();
    black as f64 / d.len() as f64
}

/// The frames of `sequence` of `scene` under `cond`: (time, black fraction, mapping), the
/// adapted first frame left out, and the steady-state frame at the second level last
/// (time `None`).
fn black_frames(
    scene: &HdrImage,
    from: f64,
    to: f64,
    times: &[f64],
    cond: &ViewingConditions,
) -> Vec<(Option<f64>, f64, operator::Mapping)> {
    let seq = Sequence::new(from, to, times.to_vec()).unwrap();
    let mut out = Vec::new();
    sequence::render(scene, &seq, cond, |f| {
        if f.index > 0 {
            out.push((f.t_seconds, black_fraction(f.image), f.mapping));
        }
        Ok(())
    })
    .unwrap();
    let hv = visadapt::adaptation::highest_visible(&scene.y, cond.hot_pixel_fraction) as f64;
    let mut lit = scene.clone();
    lit.scale((to / hv) as f32);
    let steady = operator::map(&lit, cond).unwrap();
    out.push((None, black_fraction(&steady.image), steady.report.mapping));
    out
}

/// Issue 8 §2 (failed before: the paper's rule was the only one). Baker's dip puts the cone
/// threshold below Eq. 4 for minutes after 0.1 → 5623 cd/m² (Fig. 12a); the paper's Eq. 8-9
/// then give m(t) > m_∞ and a negative offset b(t) that clips every world luminance under
/// |b|/m(t) to black. The default mapping follows max(T(t), t(L)): b ≥ 0, m ≤ m_∞, and no
/// frame has more black pixels than the steady-state image plus 1 % (on the built-in chart
/// and on sunset-fisheye.hdr). The dip stays in the thresholds; `Undershoot::InMapping`
/// still gives the paper's frames (the figures measured in the issue: b ≈ −2 cd/m² at
/// 75 s and −12 at 3 min; 61 % / 86 % / 52 % black at 75 s / 3 min / 10 min on the sunset).
#[test]
fn bakers_dip_does_not_crush_shadows() {
    use visadapt::timecourse::Undershoot;
    let ee = |l: f64| (l, l * SP);
    let times = [0.0, 1.0, 4.0, 15.0, 30.0, 75.0, 120.0, 180.0, 300.0, 600.0];
    // The state: the dip is in the threshold (Fig. 9), not in the mapping.
    let steady = Adaptation::equal_energy(5623.0 * 0.5)
        .unwrap()
        .mapping_for(80.0, 40.0, 0.0);
    for &t in &times {
        let clamped = at(ee(0.05), ee(5623.0 * 0.5), t);
        let paper = clamped.clone().with_undershoot(Undershoot::InMapping);
        let (mc, mp) = (
            clamped.mapping_for(80.0, 40.0, 0.0),
            paper.mapping_for(80.0, 40.0, 0.0),
        );
        assert!(
            mc.photopic_offset_cd_m2 >= 0.0,
            "t {t}: b {}",
            mc.photopic_offset_cd_m2
        );
        assert!(mc.photopic_scale <= steady.photopic_scale * (1.0 + 1e-12));
        if clamped.cone_excess_log() < 0.0 {
            // During the dip the default frame is the steady-state one; the paper's is not.
            assert!((mc.photopic_scale / steady.photopic_scale - 1.0).abs() < 1e-12);
            assert!(mp.photopic_offset_cd_m2 < 0.0);
        } else {
            assert_eq!(mc, mp);
        }
    }
    let dip = at(ee(0.05), ee(5623.0 * 0.5), 180.0);
    assert!(dip.cone_excess_log() < -0.05, "{}", dip.cone_excess_log());
    let b = |t: f64| {
        at(ee(0.05), ee(5623.0 * 0.5), t)
            .with_undershoot(Undershoot::InMapping)
            .mapping_for(80.0, 40.0, 0.0)
            .photopic_offset_cd_m2
    };
    // The issue's figures for the paper's rule, ±15 %.
    assert!((b(75.0) / -2.1 - 1.0).abs() < 0.15, "b(75 s) = {}", b(75.0));
    assert!(
        (b(180.0) / -12.0 - 1.0).abs() < 0.15,
        "b(3 min) = {}",
        b(180.0)
    );

    // The pictures.
    let chart = visadapt::chart::Chart::new(&Default::default())
        .unwrap()
        .image;
    let mut scenes = vec![("chart", chart)];
    if let Some(p) = common::shared("radiance/sunset-fisheye.hdr") {
        scenes.push(("sunset", io::read(&p, &Limits::default()).unwrap()));
    }
    for (name, scene) in &scenes {
        let cond = ViewingConditions::default();
        let frames = black_frames(scene, 0.1, 5623.0, &times, &cond);
        let steady = frames.last().unwrap().1;
        for (t, black, m) in &frames {
            assert!(
                *black <= steady + 0.01,
                "{name} at {t:?} s: {:.1} % black, steady state {:.1} %",
                100.0 * black,
                100.0 * steady
            );
            assert!(m.photopic_offset_cd_m2 >= 0.0 && m.scotopic_offset_cd_m2 >= 0.0);
        }
        let paper = ViewingConditions {
            undershoot: Undershoot::InMapping,
            ..cond
        };
        let frames = black_frames(scene, 0.1, 5623.0, &[75.0, 180.0, 600.0], &paper);
        let f: Vec<f64> = frames.iter().map(|f| 100.0 * f.1).collect();
        eprintln!("{name}, paper's rule, black % at 75 s, 3 min, 10 min, steady: {f:?}");
        if *name == "sunset" {
            // The issue: 61 %, 86 %, 52 %, 0 %.
            for (got, want) in f.iter().zip([61.0, 86.0, 52.0, 0.0]) {
                assert!((got - want).abs() < 3.0, "{f:?}");
            }
        }
    }
}

/// The same rule with local adaptation (a global state plus local offsets): each pixel's
/// mapping follows the state's excess clamped at 0, so Baker's dip does not clip the
/// chart's shadows either; with the paper's rule the local frames follow the dip.
#[test]
fn bakers_dip_does_not_crush_shadows_with_local_adaptation() {
    use visadapt::local::LocalAdaptation;
    use visadapt::operator::AdaptationMode;
    use visadapt::timecourse::Undershoot;
    let chart = visadapt::chart::Chart::new(&Default::default())
        .unwrap()
        .image;
    let cond = ViewingConditions {
        adaptation: AdaptationMode::Local(LocalAdaptation::default()),
        ..ViewingConditions::default()
    };
    let times = [0.0, 15.0, 75.0, 180.0, 600.0];
    let frames = black_frames(&chart, 0.1, 5623.0, &times, &cond);
    let steady = frames.last().unwrap().1;
    for (t, black, _) in &frames {
        assert!(
            *black <= steady + 0.01,
            "local, at {t:?} s: {:.1} % black, steady state {:.1} %",
            100.0 * black,
            100.0 * steady
        );
    }
    let paper = ViewingConditions {
        undershoot: Undershoot::InMapping,
        ..cond
    };
    let frames = black_frames(&chart, 0.1, 5623.0, &[180.0], &paper);
    println!(
        "local, paper's rule: {:.1} % black at 3 min, steady state {:.1} %",
        100.0 * frames[0].1,
        100.0 * frames[1].1
    );
    assert!(frames[0].1 > frames[1].1 + 0.001);
}

/// The local time course pixel by pixel, against Eq. 3 and Eq. 8-9 computed here (the
/// test above only counts black pixels: a time course that ignored the local offsets, or
/// applied the excess to some pixels only, passed it).
#[test]
fn local_time_course_follows_eq_8_9_at_each_pixels_level() {
    // Each pixel's mapping, against Eq. 3 and Eq. 8-9 computed here: two regions adapted
    // locally to 1000 and 100 cd/m² (a map of given levels, photopic: k = 0), the state of
    // an observer 30 s after 2000 → 200 cd/m² (its cone threshold still raised by a log
    // excess E > 0). Per pixel the display of a luminance L is m_∞(L_a)·L_a + m(t)·(L − L_a)
    // with m_∞ = Eq. 3 at the pixel's own L_a and m(t) = m_∞·10^(−E): so (a) a pixel's
    // own adaptation level is shown as in the steady state (Eq. 9), (b) contrast about it
    // is scaled by 10^(−E) in both regions alike (one state for the whole field), and (c)
    // the two regions' steady contrast gains stand as Eq. 3 at their own levels.
    use visadapt::local::{AdaptationMap, LocalMapping};
    use visadapt::mesopic::rod_weight;
    use visadapt::scale::photopic_scale;
    let levels = [1000.0f32, 100.0];
    for l in levels {
        assert_eq!(rod_weight(f64::from(l) * SP), 0.0, "{l}: photopic");
    }
    // Columns 0-2 at the first level, 3-5 at the second; rows: L = L_a, L_a/2.
    let (w, h) = (6, 2);
    let la: Vec<f32> = (0..w * h).map(|i| levels[(i % w) / 3]).collect();
    let las: Vec<f32> = la.iter().map(|&l| (f64::from(l) * SP) as f32).collect();
    let map = AdaptationMap::from_levels(w, h, &la, &las).unwrap();
    let mut image = HdrImage::zeros(w, h);
    for (i, &a) in la.iter().enumerate() {
        let l = a * if i < w { 1.0 } else { 0.5 };
        image.x[i] = 0.9505 * l;
        image.y[i] = l;
        image.z[i] = 1.089 * l;
    }
    image.absolute_units = true;
    let plain = ViewingConditions {
        acuity: false,
        ..ViewingConditions::default()
    };
    let report = operator::plan(&image, &plain).unwrap();
    let ee = |l: f64| (l, l * SP);
    let state = at(ee(2000.0), ee(200.0), 30.0);
    let excess = state.mapping_cone_excess_log();
    assert!(excess > 0.05, "E = {excess}");
    let show = |mapping: &LocalMapping| {
        let mut out = visadapt::DisplayImage::default();
        let stats = visadapt::local::apply_into(&image, &map, mapping, &mut out);
        assert_eq!(stats.clipped, 0);
        out.g
    };
    let now = show(&LocalMapping::for_time_course(&map, &state, &report, true));
    let steady = show(&LocalMapping::steady_state(&map, &report, true));
    let lda = report.display_adaptation_cd_m2;
    let mut gain = Vec::new();
    for (region, &level) in levels.iter().enumerate() {
        let (adapted, half) = (region * 3, w + region * 3);
        // (a) Eq. 9: the pixel's own level, as in the steady state.
        let rel = f64::from(now[adapted] / steady[adapted] - 1.0).abs();
        assert!(
            rel < 1e-4,
            "region {region}: {} vs {}",
            now[adapted],
            steady[adapted]
        );
        // (b) the contrast about it, scaled by 10^(−E).
        let c_now = f64::from(now[adapted] - now[half]);
        let c_steady = f64::from(steady[adapted] - steady[half]);
        let ratio = c_now / c_steady;
        assert!(
            (ratio / 10f64.powf(-excess) - 1.0).abs() < 1e-3,
            "region {region}: contrast ×{ratio}, 10^-E = {}",
            10f64.powf(-excess)
        );
        gain.push(c_steady / (0.5 * f64::from(level)));
    }
    // (c) Steady contrast gains (display per cd/m²) as Eq. 3 at each region's own level.
    let want = photopic_scale(100.0, lda) / photopic_scale(1000.0, lda);
    assert!(
        (gain[1] / gain[0] / want - 1.0).abs() < 1e-3,
        "gain ratio {} against Eq. 3's {want}",
        gain[1] / gain[0]
    );
}

/// Issue 8 §3 (failed before: a fall decayed the whole log excess toward the new level at
/// the dark-adaptation rate, leaving Fig. 12b's rods 2.68 / 2.22 / 1.19 / 0.64 log above
/// Eq. 5 at 3.5 / 5 / 10 / 15 min). The equivalent-background rule (Crawford 1947;
/// Stiles): T(t) = t(L_new + L_eq(t)), t(L_eq(t)) the Fig. 10 curve of an observer adapted
/// to L_old − L_new. Recomputed here independently (Eq. 5 inverted by bisection), and
/// against the figures of the issue (2.14 / 1.53 / 0.36 / 0.08, ±0.01).
#[test]
fn dark_adaptation_toward_a_lit_background_uses_the_equivalent_background() {
    let ee = |l: f64| (l, l * SP);
    // Fig. 12b's world adaptation: half of 1412 and of 0.1 cd/m² (Sec. 4.4).
    let (old, new) = (706.0 * SP, 0.05 * SP);
    let floor = log_rod_threshold(f64::NEG_INFINITY);
    let d0 = log_rod_threshold((old - new).log10()) - floor;
    let inverse = |y: f64| {
        let (mut lo, mut hi) = (-3.94, 8.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if log_rod_threshold(mid) < y {
                lo = mid
            } else {
                hi = mid
            }
        }
        0.5 * (lo + hi)
    };
    for (minutes, issue) in [(3.5, 2.14), (5.0, 1.53), (10.0, 0.36), (15.0, 0.08)] {
        let t = minutes * 60.0;
        let d = d0 * (-t / timecourse::ROD_DARK_TAU_SECONDS).exp();
        let leq = 10f64.powf(inverse(floor + d));
        let independent = log_rod_threshold((new + leq).log10()) - log_rod_threshold(new.log10());
        let got = at(ee(706.0), ee(0.05), t).rod_excess_log();
        assert!(
            (got - independent).abs() < 1e-6,
            "{minutes} min: {got} vs {independent}"
        );
        assert!(
            (got - issue).abs() < 0.01,
            "{minutes} min: {got} vs {issue}"
        );
    }
    // Near steady state by 20 minutes, cones long before.
    let late = at(ee(706.0), ee(0.05), 1200.0);
    assert!(late.rod_excess_log() < 0.03 && late.cone_excess_log() < 0.01);
    // Fig. 10 (a fall to darkness, L_new = 0) is the curve it was: log T = floor +
    // (log t(L_old) − floor)·e^{−t/τ} for each mechanism.
    for t in [0.0, 60.0, 300.0, 420.0, 1200.0, 2400.0] {
        let eye = at(hecht(), DARK, t);
        let l = timecourse::HECHT_PREADAPTATION_CD_M2;
        let rods = -2.86
            + (log_rod_threshold((l * SP).log10()) + 2.86)
                * (-t / timecourse::ROD_DARK_TAU_SECONDS).exp();
        let cones = -0.72
            + (log_cone_threshold(l.log10()) + 0.72)
                * (-t / timecourse::CONE_DARK_TAU_SECONDS).exp();
        assert!((eye.log_rod_threshold() - rods).abs() < 1e-12, "{t}");
        assert!((eye.log_cone_threshold() - cones).abs() < 1e-12, "{t}");
    }
}

/// Issue 8 §3 (failed before: the Fig. 12b frames at 0 s and 20 s were identical and the
/// 3.5 min frame a grey veil). The frames of 1412 → 0.1 cd/m² progress: the contrast (the
/// spread of the display values) never decreases, and by 20 minutes the frame is close to
/// the steady-state image: its mean difference from it is under 5 % of the first frame's.
#[test]
fn dark_adaptation_frames_progress_to_the_steady_state() {
    let times = [
        0.0, 20.0, 45.0, 90.0, 150.0, 210.0, 300.0, 450.0, 600.0, 900.0, 1200.0,
    ];
    let chart = visadapt::chart::Chart::new(&Default::default())
        .unwrap()
        .image;
    let mut scenes = vec![("chart", chart)];
    if let Some(p) = common::shared("openexr/Desk.exr") {
        scenes.push(("Desk.exr", io::read(&p, &Limits::default()).unwrap()));
    }
    let cond = ViewingConditions::default();
    for (name, scene) in &scenes {
        let seq = Sequence::new(1412.0, 0.1, times.to_vec()).unwrap();
        let mut frames = Vec::new();
        sequence::render(scene, &seq, &cond, |f| {
            if f.index > 0 {
                frames.push(f.image.clone());
            }
            Ok(())
        })
        .unwrap();
        let hv = visadapt::adaptation::highest_visible(&scene.y, cond.hot_pixel_fraction) as f64;
        let mut lit = scene.clone();
        lit.scale((0.1 / hv) as f32);
        let steady = operator::map(&lit, &cond).unwrap().image;
        // In f64: a million f32 additions would drown the first frames' tiny spread.
        let spread = |g: &[f32]| {
            let n = g.len() as f64;
            let mean = g.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
            (g.iter()
                .map(|&v| (f64::from(v) - mean).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        };
        let mad = |im: &visadapt::DisplayImage| {
            im.g.iter()
                .zip(&steady.g)
                .map(|(a, b)| f64::from((a - b).abs()))
                .sum::<f64>()
                / im.len() as f64
        };
        let s: Vec<f64> = frames.iter().map(|f| spread(&f.g)).collect();
        let d: Vec<f64> = frames.iter().map(mad).collect();
        eprintln!(
            "{name}: spread {s:?}, steady {}; distance {d:?}",
            spread(&steady.g)
        );
        assert!(s.windows(2).all(|w| w[1] >= w[0] * 0.999), "{name}: {s:?}");
        assert!(
            s[1] > s[0] * 1.001,
            "{name}: the 20 s frame is the 0 s frame: {s:?}"
        );
        assert!(d.last().unwrap() < &(0.05 * d[0]), "{name}: {d:?}");
    }
}

/// The delays of an APNG, ms, frame by frame (the fcTL chunk of each frame).
fn apng_delays_ms(path: &std::path::Path) -> Vec<f64> {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let mut delays = Vec::new();
    while reader.next_frame(&mut buf).is_ok() {
        let fc = reader.info().frame_control.unwrap();
        delays.push(1000.0 * f64::from(fc.delay_num) / f64::from(fc.delay_den));
    }
    delays
}

/// The animation keeps the sequence's real time: between the held first and last frames,
/// each frame's delay is its time step to the next frame over one speed-up, so the delays'
/// ratios are the time steps' ratios (to the rounding of whole milliseconds: ±0.5 ms on
/// each delay).
#[test]
fn playback_delays_follow_the_real_time_steps() {
    for (seq, seconds) in [
        (Sequence::figure_12a(), 6.0),
        (Sequence::figure_12b(), 6.0),
        (Sequence::figure_12b(), 20.0),
        (
            Sequence::new(1.0, 100.0, vec![2.0, 3.0, 10.0, 60.0, 61.0]).unwrap(),
            3.0,
        ),
    ] {
        let p = seq.playback(seconds).unwrap();
        let t = &seq.times_seconds;
        assert_eq!(p.delays_ms.len(), seq.frame_count());
        let hold = 1000.0 * seconds / 6.0;
        let (first, last) = (p.delays_ms[0], *p.delays_ms.last().unwrap());
        assert!(
            (f64::from(first) - hold).abs() <= 0.5 && first == last,
            "{p:?}"
        );
        let speedup = (t[t.len() - 1] - t[0]) / (seconds * 2.0 / 3.0);
        assert!((p.speedup.unwrap() / speedup - 1.0).abs() < 1e-12, "{p:?}");
        let steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let middle: Vec<f64> = p.delays_ms[1..p.delays_ms.len() - 1]
            .iter()
            .map(|&d| f64::from(d))
            .collect();
        assert_eq!(middle.len(), steps.len());
        for i in 0..steps.len() {
            // Each delay is its step over the speed-up, to half a millisecond, unless the
            // floor lengthened it.
            let exact = 1000.0 * steps[i] / speedup;
            if exact >= f64::from(sequence::MIN_FRAME_DELAY_MS) {
                assert!(
                    (middle[i] - exact).abs() <= 0.5,
                    "{i}: {middle:?} {steps:?}"
                );
            } else {
                assert_eq!(middle[i], f64::from(sequence::MIN_FRAME_DELAY_MS));
            }
            for j in 0..steps.len() {
                let floor = f64::from(sequence::MIN_FRAME_DELAY_MS);
                if 1000.0 * steps[i.min(j)].min(steps[i.max(j)]) / speedup < floor {
                    continue;
                }
                // The ratio, with the rounding of both delays as its tolerance.
                let ratio = steps[i] / steps[j];
                let tol = ratio * (0.5 / middle[i] + 0.5 / middle[j]) * 1.0001;
                assert!(
                    (middle[i] / middle[j] - ratio).abs() <= tol,
                    "{i}/{j}: {middle:?} {steps:?}"
                );
            }
        }
        // The whole lasts the playback asked for (each delay rounded to the millisecond).
        let total = 1000.0 * p.seconds();
        assert!(
            (total - 1000.0 * seconds).abs() <= 0.5 * p.delays_ms.len() as f64,
            "{total}"
        );
    }
    // Fig. 12a in 6 s: 75 s of the sequence in 4 s, 18.75 times real time; its first step
    // (1 s) lasts 53 ms, its last (45 s) 2.4 s.
    let p = Sequence::figure_12a().playback(6.0).unwrap();
    assert_eq!(p.delays_ms, [1000, 53, 160, 587, 800, 2400, 1000]);
    // A step shorter than the floor is lengthened to it (0.01 s in 150 s at 60 s).
    let p = Sequence::new(1.0, 100.0, vec![0.0, 0.01, 150.0])
        .unwrap()
        .playback(6.0)
        .unwrap();
    assert_eq!(p.delays_ms[1], sequence::MIN_FRAME_DELAY_MS);
    // Times that span no time: every frame the same share.
    for times in [vec![5.0], vec![3.0, 3.0, 3.0], vec![]] {
        let seq = Sequence::new(1.0, 100.0, times).unwrap();
        let p = seq.playback(6.0).unwrap();
        let share = (6000.0 / seq.frame_count() as f64).round() as u16;
        assert!(p.delays_ms.iter().all(|&d| d == share), "{p:?}");
        assert_eq!(p.speedup, None);
    }
    // Outside a minute, or not a length: refused.
    for s in [0.0, -1.0, 0.05, 61.0, f64::NAN, f64::INFINITY] {
        assert!(Sequence::figure_12a().playback(s).is_err(), "{s}");
    }
}

/// An APNG with per-frame delays carries them, frame by frame.
#[test]
fn apng_writer_keeps_each_frames_delay() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.png");
    let seq = Sequence::figure_12a();
    let p = seq.playback(6.0).unwrap();
    let mut apng = None;
    sequence::render(&mixtex(), &seq, &ViewingConditions::default(), |f| {
        let a = apng.get_or_insert_with(|| {
            ApngWriter::with_delays(&path, f.image.width, f.image.height, &p.delays_ms).unwrap()
        });
        a.push(f.image)
    })
    .unwrap();
    apng.unwrap().finish().unwrap();
    let expected: Vec<f64> = p.delays_ms.iter().map(|&d| f64::from(d)).collect();
    assert_eq!(apng_delays_ms(&path), expected);
    // A zero delay is refused before any file exists.
    let bad = dir.path().join("b.png");
    assert!(ApngWriter::with_delays(&bad, 4, 4, &[100, 0]).is_err());
    assert!(ApngWriter::with_delays(&bad, 4, 4, &[]).is_err());
    assert!(!bad.exists());
}

/// The time label of a frame: only the pixels of its box change, the box holds white ink
/// on black, and the glyphs of the font are distinct.
#[test]
fn label_changes_only_its_box() {
    use visadapt::label;
    let mut frames = Vec::new();
    let seq = Sequence::figure_12b();
    sequence::render(&mixtex(), &seq, &ViewingConditions::default(), |f| {
        frames.push(f.image.clone());
        Ok(())
    })
    .unwrap();
    for (index, frame) in frames.iter().enumerate() {
        let text = seq.frame_label(index).unwrap();
        let mut labelled = frame.clone();
        let b = label::draw(&mut labelled, &text).unwrap();
        // The box: 5x7 glyphs on 6-pixel advances, 2 font pixels of padding, clipped.
        let s = label::scale_for(frame.height);
        let width = s * (6 * text.chars().count() - 1 + 4);
        assert_eq!((b.x, b.y), (0, 0));
        assert_eq!(b.width, width.min(frame.width), "{text}");
        assert_eq!(b.height, (s * 11).min(frame.height));
        let (mut ink, mut black) = (0, 0);
        for y in 0..frame.height {
            for x in 0..frame.width {
                let i = y * frame.width + x;
                let (before, after) = (
                    [frame.r[i], frame.g[i], frame.b[i]],
                    [labelled.r[i], labelled.g[i], labelled.b[i]],
                );
                if b.contains(x, y) {
                    match after {
                        [1.0, 1.0, 1.0] => ink += 1,
                        [0.0, 0.0, 0.0] => black += 1,
                        other => panic!("({x}, {y}): {other:?}"),
                    }
                } else {
                    assert_eq!(before, after, "({x}, {y}) outside the box");
                }
            }
        }
        assert!(ink > 0 && black > ink, "{text}: {ink} ink, {black} black");
    }
    assert_eq!(seq.frame_label(7), None);
    // Every glyph is its own; a character the font lacks is refused, the image untouched.
    let chars: Vec<char> = "0123456789abcdefghijklmnopqrstuvwxyz.,:/=+-()²% "
        .chars()
        .collect();
    for (i, a) in chars.iter().enumerate() {
        let ga = label::glyph(*a).unwrap();
        for b in &chars[i + 1..] {
            assert_ne!(ga, label::glyph(*b).unwrap(), "{a} and {b}");
        }
    }
    let mut image = frames[0].clone();
    assert!(label::draw(&mut image, "t = 5 µs").is_err());
    assert_eq!(image, frames[0]);
}
