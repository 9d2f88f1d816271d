//! Text renderings of what the model used (the JSON ones are the library's
//! [`visadapt::report`], shared with the Python package and the viewer).

use crate::numbers::{count, num};
use visadapt::observer::Observer;
use visadapt::operator::{PixelStats, Report};
use visadapt::report::{projection_label as projection, source_label as source};

pub fn observer_text(o: &Observer) -> String {
    format!(
        "observer adapted to {} cd/m² ({} scotopic cd/m²), display {} cd/m² (adapted to {})\n\
         cone threshold (Eq. 4)        {} cd/m²\n\
         rod threshold (Eq. 5)         {} scotopic cd/m²\n\
         photopic scale m_p (Eq. 3)    {}\n\
         scotopic scale m_s (Eq. 3)    {}\n\
         rod weight k (Eq. 6)          {:.4}\n\
         acuity (Fig. 7)               {:.2} cycles/degree ({})\n\
         acuity blur (Eq. 7)           sigma {:.4} deg, {}\n",
        num(o.adaptation_cd_m2),
        num(o.scotopic_adaptation_cd_m2),
        num(o.display_max_cd_m2),
        num(o.display_adaptation_cd_m2),
        num(o.cone_threshold_cd_m2),
        num(o.rod_threshold_scotopic_cd_m2),
        num(o.photopic_scale),
        num(o.scotopic_scale),
        o.rod_weight,
        o.acuity_cycles_per_degree(),
        o.snellen(),
        o.acuity.sigma_deg,
        acuity_contrast(&o.acuity),
    )
}

/// The contrast the acuity filter passes at the cutoff, the one Eq. 7 asks for when they
/// differ, and whether Fig. 7 was extrapolated.
pub fn acuity_contrast(a: &visadapt::acuity::AcuityFilter) -> String {
    let mut s = if a.fallback {
        format!(
            "contrast at the cutoff {:.4} (Eq. 7 asks for {:.4}: below the rod Weber range, \
             held at the rod Weber fraction)",
            a.gain_at_cutoff, a.threshold_contrast
        )
    } else {
        format!("contrast at the cutoff {:.4} (Eq. 7)", a.gain_at_cutoff)
    };
    if a.rule == visadapt::acuity::AcuityThreshold::Envelope {
        s += "; rods and cones by their envelope (the paper's rule)";
    }
    if a.extrapolated {
        s += &format!(
            "; Fig. 7 extrapolated: Shaler's data span 10^{} to 10^{} cd/m²",
            visadapt::acuity::SHALER_MIN_LOG,
            visadapt::acuity::SHALER_MAX_LOG
        );
    }
    s
}

/// The clipping lines of a map report: how many pixels, and when more than 1 % did, why
/// and what to do.
pub fn clipping_text(r: &Report, stats: &PixelStats) -> String {
    if stats.clipped == 0 {
        return String::new();
    }
    let n = (r.width * r.height).max(1);
    let share = 100.0 * stats.clipped as f64 / n as f64;
    let mut s = format!(
        "clipped                       {} ({share:.1} %) above the display maximum\n",
        count(stats.clipped, "pixel", "pixels")
    );
    if share > 1.0 {
        let m = &r.mapping;
        s += &format!(
            "  why: the model shows the highest visible luminance ({} cd/m²) at {:.1} cd/m² on \
             a {} cd/m² display adapted to {} cd/m²: Eq. 1-4 keep the world observer's \
             contrast steps, and this display has fewer\n",
            num(r.highest_visible_cd_m2),
            r.highest_visible_display_cd_m2(),
            num(m.display_max_cd_m2),
            num(r.display_adaptation_cd_m2),
        );
        s += &match r.display_max_to_show_highest_visible() {
            Some(d) => format!(
                "  what to do: --display-max {:.0} (or more) shows it unclipped; or accept the \
                 clipping (hues kept, highlights darkened)\n",
                d.ceil()
            ),
            None => {
                "  what to do: a brighter display does not help here (the highlight grows with \
                     the display maximum); raise --world-adaptation, or accept the clipping\n"
                    .to_string()
            }
        };
    }
    s
}

/// The chromatic adaptation used, in words.
pub fn white_point(r: &Report) -> String {
    match r.scene_white {
        None => "scene white shown as it is, no chromatic adaptation (--white-point none)".into(),
        Some(w) => format!(
            "scene white {} ({}) adapted to the display's D65 (CAT16)",
            visadapt::colour::white_name(w),
            source(r.scene_white_source)
        ),
    }
}

/// The glare lines of a report (empty without `--glare`).
pub fn glare_text(r: &Report) -> String {
    let Some(g) = &r.glare else {
        return String::new();
    };
    let v = &g.veil;
    format!(
        "glare (CIE 135/1)             age {} years, pigmentation {}: {:.1} % of the light scattered\n\
         veil at the fixation point    {} cd/m², {} scotopic cd/m² (mean {} cd/m²)\n\
         adaptation without glare      {} cd/m² (with glare {:.3}× that)\n",
        v.glare.age_years,
        v.glare.pigmentation,
        100.0 * v.scattered_fraction,
        num(v.veil_at_centre_cd_m2),
        num(v.veil_at_centre_scotopic_cd_m2),
        num(v.mean_veil_cd_m2),
        num(g.world_adaptation_without_glare_cd_m2),
        g.adaptation_ratio(r),
    )
}

pub fn map_text(r: &Report, stats: &PixelStats) -> String {
    let m = &r.mapping;
    let ppd = r
        .pixels_per_degree
        .map_or("n/a".to_string(), |p| format!("{p:.2}"));
    let blur = if !r.acuity_applied {
        "off (--no-acuity)".to_string()
    } else if m.blur_sigma_px > 0.0 {
        format!(
            "sigma {:.3} px ({:.4} deg)",
            m.blur_sigma_px, r.acuity.sigma_deg
        )
    } else {
        format!(
            "none (sigma {:.4} deg is below half a pixel's worth)",
            r.acuity.sigma_deg
        )
    };
    format!(
        "image                         {}x{}\n\
         highest visible luminance     {} cd/m², {} scotopic cd/m² (scotopic {})\n\
         world adaptation (Sec. 4.4)   {} cd/m² ({}), {} scotopic cd/m²\n\
         display                       max {} cd/m², adaptation {} cd/m²\n\
         thresholds (Eq. 4, 5)         cones {} cd/m², rods {} scotopic cd/m²\n\
         scale factors (Eq. 3)         m_p {}, m_s {}\n\
         rod weight k (Eq. 6)          {:.4}\n\
         acuity (Fig. 7, Eq. 7)        {:.2} cycles/degree ({}), {}\n\
         view                          {} {:.1} deg ({}), {} pixels/degree\n\
         acuity blur                   {}\n\
         white point                   {}\n",
        r.width,
        r.height,
        num(r.highest_visible_cd_m2),
        num(r.highest_visible_scotopic_cd_m2),
        source(r.scotopic_source),
        num(r.world_adaptation_cd_m2),
        source(r.world_adaptation_source),
        num(r.world_adaptation_scotopic_cd_m2),
        num(m.display_max_cd_m2),
        num(r.display_adaptation_cd_m2),
        num(r.cone_threshold_cd_m2),
        num(r.rod_threshold_scotopic_cd_m2),
        num(m.photopic_scale),
        num(m.scotopic_scale),
        m.rod_weight,
        r.acuity.cutoff_cycles_per_degree,
        r.snellen(),
        acuity_contrast(&r.acuity),
        projection(r.view.projection),
        r.view.horizontal_deg,
        source(r.view_source),
        ppd,
        blur,
        white_point(r),
    ) + &glare_text(r)
        + &local_text(r)
        + &clipping_text(r, stats)
}

/// The local-adaptation lines of the map report (nothing for global adaptation).
fn local_text(r: &Report) -> String {
    let Some(l) = &r.local else {
        return String::new();
    };
    let q = &l.adaptation_cd_m2;
    let k = &l.rod_weight;
    let blur = l.acuity_sigma_px.as_ref().map_or(String::new(), |s| {
        format!(
            "local acuity blur             sigma {:.3} to {:.3} px (median {:.3})\n",
            s.min, s.max, s.p50
        )
    });
    format!(
        "local adaptation              radius {} deg, map grid every {} px, rod saturation {}\n\
         local adaptation level        {} to {} cd/m² (1 %: {}, median {}, 99 %: {})\n\
         local rod weight k            {:.3} to {:.3} (median {:.3})\n{}",
        l.radius_deg,
        l.grid_step_px,
        if l.rod_saturation { "on" } else { "off" },
        num(q.min),
        num(q.max),
        num(q.p01),
        num(q.p50),
        num(q.p99),
        k.min,
        k.max,
        k.p50,
        blur,
    )
}

/// One file of a batch on one line: where it went, the adaptation and what it means.
pub fn map_line(input: &std::path::Path, output: &std::path::Path, r: &Report) -> String {
    format!(
        "{} -> {}: {}x{}, adapted to {} cd/m² ({}), rod weight {}, acuity {} cycles/degree",
        input.display(),
        output.display(),
        r.width,
        r.height,
        num(r.world_adaptation_cd_m2),
        source(r.world_adaptation_source),
        num(r.mapping.rod_weight),
        num(r.acuity.cutoff_cycles_per_degree),
    )
}
