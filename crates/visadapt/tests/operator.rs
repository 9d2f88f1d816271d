//! The whole operator against values computed independently from the paper's equations.

mod common;

use common::{tp, ts};
use visadapt::operator::{ViewingConditions, map, plan};
use visadapt::{HdrImage, View};

/// D65 white of luminance 1 in XYZ (CIE 15:2004).
const D65: [f32; 3] = [0.950_47, 1.0, 1.088_83];

fn uniform(w: usize, h: usize, xyz: [f32; 3], scotopic: Option<f32>) -> HdrImage {
    let mut im = HdrImage::zeros(w, h);
    im.x.fill(xyz[0]);
    im.y.fill(xyz[1]);
    im.z.fill(xyz[2]);
    im.scotopic = scotopic.map(|s| vec![s; w * h]);
    im.absolute_units = true;
    im
}

fn no_blur() -> ViewingConditions {
    ViewingConditions {
        acuity: false,
        ..ViewingConditions::default()
    }
}

/// A uniform D65 grey at 1 cd/m² with a scotopic channel of 2 scotopic cd/m²: every
/// display channel must be (m_p·1 + k·m_s·2)/80 with L_wa = 0.5, L_wa,s = 1 (Sec. 4.4).
#[test]
fn uniform_grey_maps_to_paper_value() {
    let im = uniform(16, 8, D65, Some(2.0));
    let out = map(&im, &no_blur()).unwrap();
    let r = &out.report;
    assert!((r.world_adaptation_cd_m2 - 0.5).abs() < 1e-9);
    assert!((r.world_adaptation_scotopic_cd_m2 - 1.0).abs() < 1e-9);
    assert_eq!(r.display_adaptation_cd_m2, 40.0);
    let mp = tp(40.0) / tp(0.5);
    let ms = tp(40.0) / ts(1.0); // paper: photopic display observer for the rod operator
    assert!((r.mapping.photopic_scale / mp - 1.0).abs() < 1e-9);
    assert!((r.mapping.scotopic_scale / ms - 1.0).abs() < 1e-9);
    let k = r.mapping.rod_weight;
    assert!(k > 0.0 && k < 1.0, "mesopic at 1 scotopic cd/m²: {k}");
    let expected = (mp * 1.0 + k * ms * 2.0) / 80.0;
    for ch in [&out.image.r, &out.image.g, &out.image.b] {
        for &v in ch.iter() {
            assert!(
                (v as f64 / expected - 1.0).abs() < 2e-4,
                "{v} vs {expected}"
            );
        }
    }
}

/// No renormalisation: with the adaptation fixed, the output is linear in the scene, and a
/// dim scene (starlight) stays dim on the display relative to the model's prediction.
#[test]
fn output_is_absolute_not_renormalised() {
    let cond = ViewingConditions {
        world_adaptation_cd_m2: Some(0.001),
        world_adaptation_scotopic_cd_m2: Some(0.002),
        ..no_blur()
    };
    let a = map(&uniform(4, 4, [0.0019, 0.002, 0.0022], Some(0.004)), &cond).unwrap();
    let b = map(&uniform(4, 4, [0.00095, 0.001, 0.0011], Some(0.002)), &cond).unwrap();
    for i in 0..16 {
        assert!((a.image.g[i] / b.image.g[i] - 2.0).abs() < 1e-4);
    }
    // m_s at 0.002 scotopic = t_p(40)/t_s(0.002); white well below the display maximum.
    let expected = (tp(40.0) / tp(0.001) * 0.002 + tp(40.0) / ts(0.002) * 0.004) / 80.0;
    assert!(
        (a.image.g[0] as f64 / expected - 1.0).abs() < 2e-3,
        "{} {}",
        a.image.g[0],
        expected
    );
    assert!(a.image.g[0] < 1.0);
}

/// Daylight (k = 0): the display keeps the scene's chromaticity. Starlight (k = 1): the
/// rods' grey swamps colour.
#[test]
fn colour_survives_daylight_and_fades_at_night() {
    // A saturated red in Rec.709 (linear 0.6, 0.1, 0.05), scaled to a luminance level.
    let rgb = [0.6f64, 0.1, 0.05];
    let m = [
        [0.4124, 0.3576, 0.1805],
        [0.2126, 0.7152, 0.0722],
        [0.0193, 0.1192, 0.9505],
    ];
    let xyz: Vec<f32> = m
        .iter()
        .map(|row| (0..3).map(|j| row[j] * rgb[j]).sum::<f64>() as f32)
        .collect();
    let chroma = |level: f32| {
        let mut im = uniform(8, 8, [xyz[0] * level, xyz[1] * level, xyz[2] * level], None);
        // Put a white patch so the adaptation is set by white at 4x the red's level.
        for i in 0..8 {
            im.x[i] = D65[0] * 4.0 * level;
            im.y[i] = 4.0 * level;
            im.z[i] = D65[2] * 4.0 * level;
        }
        let out = map(
            &im,
            &ViewingConditions {
                hot_pixel_fraction: 0.0,
                ..no_blur()
            },
        )
        .unwrap();
        let i = 40;
        let (r, g, b) = (
            out.image.r[i] as f64,
            out.image.g[i] as f64,
            out.image.b[i] as f64,
        );
        ((r - b) / (r + g + b), r / g, out.report.mapping.rod_weight)
    };
    let (_, ratio_day, k_day) = chroma(1000.0);
    assert_eq!(k_day, 0.0);
    // 0.6/0.1: hue kept, up to the 4-decimal rounding of the IEC matrix used above.
    assert!((ratio_day / 6.0 - 1.0).abs() < 2e-3, "r/g {ratio_day}");
    let (c_night, _, k_night) = chroma(0.0005);
    assert_eq!(k_night, 1.0);
    let (c_day, _, _) = chroma(1000.0);
    assert!(
        c_night < 0.1 * c_day,
        "night chroma {c_night} vs day {c_day}"
    );
}

/// NaN, infinities and negative values never reach the output and are counted.
#[test]
fn bad_pixels_are_counted_and_neutralised() {
    let mut im = uniform(4, 4, D65, None);
    im.y[0] = f32::NAN;
    im.x[1] = f32::INFINITY;
    im.z[2] = -3.0;
    im.y[3] = f32::NEG_INFINITY;
    let out = map(&im, &no_blur()).unwrap();
    assert_eq!(out.stats.non_finite, 3);
    assert_eq!(out.stats.negative, 1);
    for ch in [&out.image.r, &out.image.g, &out.image.b] {
        assert!(ch.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
    }
    assert_eq!(out.image.g[0], 0.0);
    // The adaptation ignores them: half of the 1 cd/m² grey.
    assert!((out.report.world_adaptation_cd_m2 - 0.5).abs() < 1e-9);
}

/// A handful of very hot pixels (a glint) does not set the adaptation.
#[test]
fn hot_pixels_do_not_set_adaptation() {
    let mut im = uniform(100, 100, D65, None);
    for i in [5, 500, 5000] {
        im.y[i] = 1e6;
    }
    let r = plan(&im, &ViewingConditions::default()).unwrap();
    assert!((r.world_adaptation_cd_m2 - 0.5).abs() < 1e-9);
}

/// Values above the display maximum are scaled to it, keeping the chromaticity.
#[test]
fn clipping_keeps_chromaticity() {
    let mut im = uniform(4, 1, [0.4124 * 500.0, 0.2126 * 500.0, 0.0193 * 500.0], None);
    im.scotopic = Some(vec![0.0; 4]);
    let out = map(
        &im,
        &ViewingConditions {
            world_adaptation_cd_m2: Some(1.0),
            world_adaptation_scotopic_cd_m2: Some(1000.0),
            ..no_blur()
        },
    )
    .unwrap();
    assert_eq!(out.stats.clipped, 4);
    assert!((out.image.r[0] - 1.0).abs() < 1e-6);
    assert!(out.image.g[0] < 1e-3 && out.image.b[0] < 1e-3);
}

/// The view sets pixels per degree: a 60° perspective view 1920 px wide has
/// (960 / tan 30°)·π/180 = 29.02 px/deg at its centre.
#[test]
fn view_and_fov() {
    let im = uniform(1920, 4, D65, None);
    let cond = ViewingConditions {
        view: Some(View::perspective(60.0, 1920, 4)),
        ..ViewingConditions::default()
    };
    let r = plan(&im, &cond).unwrap();
    assert!((r.pixels_per_degree.unwrap() - 29.02).abs() < 0.01);
    let s = r.acuity.sigma_deg * 29.02;
    assert!((r.mapping.blur_sigma_px - s).abs() / s < 1e-3);
}

#[test]
fn invalid_conditions_are_rejected() {
    let im = uniform(2, 2, D65, None);
    for cond in [
        ViewingConditions {
            display_max_cd_m2: 0.0,
            ..Default::default()
        },
        ViewingConditions {
            display_max_cd_m2: f64::NAN,
            ..Default::default()
        },
        ViewingConditions {
            world_adaptation_cd_m2: Some(-1.0),
            ..Default::default()
        },
        ViewingConditions {
            hot_pixel_fraction: 1.5,
            ..Default::default()
        },
    ] {
        let e = map(&im, &cond).unwrap_err();
        assert!(matches!(e, visadapt::Error::InvalidParameter { .. }), "{e}");
    }
    let mut bad = uniform(2, 2, D65, None);
    bad.y.pop();
    assert!(map(&bad, &ViewingConditions::default()).is_err());
}

/// Eq. 7, measured: a grating at the cutoff frequency, blurred by the operator, keeps
/// exactly the threshold contrast t(L_wa)/L_wa of its amplitude (Sec. 4.1: "a high contrast
/// scene grating at frequency ω_c(L_wa) will be displayed at the threshold of visibility").
#[test]
fn grating_at_cutoff_is_attenuated_to_threshold_contrast() {
    use visadapt::Projection;
    let (w, h) = (1024usize, 48usize);
    let period_px = 16.0f64;
    for (lwa, lwa_s) in [(10.0f64, 22.61f64), (0.2, 0.4522), (300.0, 678.3)] {
        let filter = visadapt::acuity::AcuityFilter::new(lwa, lwa_s);
        // Uniform-in-angle projection so that pixels per degree are the same everywhere:
        // the cutoff lands at one cycle per `period_px` pixels.
        let ppd = filter.cutoff_cycles_per_degree * period_px;
        let view = View {
            projection: Projection::AngularFisheye,
            horizontal_deg: w as f64 / ppd,
            vertical_deg: h as f64 / ppd,
        };
        let mut im = HdrImage::zeros(w, h);
        for j in 0..h {
            for i in 0..w {
                let l =
                    lwa * (1.0 + 0.5 * (2.0 * std::f64::consts::PI * i as f64 / period_px).sin());
                let k = j * w + i;
                im.x[k] = (D65[0] as f64 * l) as f32;
                im.y[k] = l as f32;
                im.z[k] = (D65[2] as f64 * l) as f32;
            }
        }
        let cond = ViewingConditions {
            world_adaptation_cd_m2: Some(lwa),
            world_adaptation_scotopic_cd_m2: Some(lwa_s),
            view: Some(view),
            display_max_cd_m2: 1e6, // no clipping: measure the linear response
            ..ViewingConditions::default()
        };
        let out = map(&im, &cond).unwrap();
        assert!(out.report.mapping.blur_sigma_px > 1.0);
        // Amplitude of the fundamental over whole periods away from the borders, relative to
        // the mean, in the output and in the input.
        let amplitude = |row: &[f32]| {
            let (mut s, mut c, mut m) = (0.0, 0.0, 0.0);
            let range = 128..(w - 128);
            let n = range.len() as f64;
            for i in range {
                let t = 2.0 * std::f64::consts::PI * i as f64 / period_px;
                s += row[i] as f64 * t.sin();
                c += row[i] as f64 * t.cos();
                m += row[i] as f64;
            }
            (2.0 * (s * s + c * c).sqrt() / n) / (m / n)
        };
        let row = h / 2 * w;
        let before = amplitude(&im.y[row..row + w]);
        let after = amplitude(&out.image.g[row..row + w]);
        let ratio = after / before;
        let c = filter.threshold_contrast;
        // The response is exp(−2π²σ²f²): a 2 % error in sigma (the blur's stated accuracy)
        // moves it by 4·|ln c| % relative. Check the sigma the measurement implies, and the
        // response itself within 0.01 absolute.
        let f = 1.0 / period_px;
        let sigma_measured = (-ratio.ln() / (2.0 * std::f64::consts::PI.powi(2) * f * f)).sqrt();
        let sigma = out.report.mapping.blur_sigma_px;
        assert!(
            (sigma_measured / sigma - 1.0).abs() < 0.02,
            "L_wa {lwa}: sigma {sigma_measured} vs {sigma}"
        );
        assert!(
            (ratio - c).abs() < 0.01,
            "L_wa {lwa}: response {ratio} vs t/L {c}"
        );
    }
}
