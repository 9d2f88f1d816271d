//! `visadapt timecourse`: thresholds, scale factors, offsets and acuity of an observer
//! adapted to one luminance at given times after it changes to another (Sec. 3.5, Eq. 8–9).

use crate::cli::TimecourseArgs;
use crate::numbers::num;
use anyhow::bail;
use visadapt::report;
use visadapt::scotopic::EQUAL_ENERGY_SP_RATIO;
use visadapt::timecourse::{Moment, course};

/// Check a luminance flag: from [`visadapt::MIN_LUMINANCE_CD_M2`] to
/// [`visadapt::MAX_LUMINANCE_CD_M2`] (the range
/// the f32 pipeline carries).
pub fn positive(flag: &'static str, v: f64) -> anyhow::Result<f64> {
    Ok(visadapt::check_luminance(flag, v)?)
}

/// Check a list of times: finite, non-negative, sorted.
pub fn sorted_times(times: &[f64]) -> anyhow::Result<()> {
    let mut prev = 0.0;
    for &t in times {
        if !(t.is_finite() && t >= 0.0) {
            bail!("invalid --times value {t}: times must be finite, non-negative seconds");
        }
        if t < prev {
            bail!("invalid --times: {t} comes after {prev}; times must be sorted");
        }
        prev = t;
    }
    Ok(())
}

/// Check a luminance flag that may be 0 (darkness).
pub fn non_negative(flag: &'static str, v: f64) -> anyhow::Result<f64> {
    if v == 0.0 { Ok(0.0) } else { positive(flag, v) }
}

pub fn run(args: TimecourseArgs) -> anyhow::Result<()> {
    let from = non_negative("--from", args.from)?;
    let to = non_negative("--to", args.to)?;
    positive("--display-max", args.display.display_max)?;
    sorted_times(&args.times)?;
    let sp = EQUAL_ENERGY_SP_RATIO;
    let moments = course(
        (from, from * sp),
        (to, to * sp),
        &args.times,
        args.display.display_max,
        args.time_course.undershoot(),
    )?;
    if args.json {
        let v = report::timecourse_json(&moments);
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", text(from, to, args.display.display_max, &moments));
    }
    Ok(())
}

fn text(from: f64, to: f64, display_max: f64, moments: &[Moment]) -> String {
    let mut s = format!(
        "observer adapted to {} cd/m², switched to {} cd/m² at t = 0 \
         (scotopic = photopic x {EQUAL_ENERGY_SP_RATIO}), display {} cd/m²\n\
         {:>10} {:>11} {:>11} {:>8} {:>8} {:>11} {:>11} {:>6} {:>11} {:>7}\n",
        num(from),
        num(to),
        num(display_max),
        "t (s)",
        "cone thr",
        "rod thr",
        "cone ex",
        "rod ex",
        "m_p",
        "m_s",
        "k",
        "b (cd/m²)",
        "c/deg",
    );
    for m in moments {
        let map = &m.mapping;
        s += &format!(
            "{:>10.3} {:>11} {:>11} {:>8.3} {:>8.3} {:>11} {:>11} {:>6.3} {:>11} {:>7.2}\n",
            m.t_seconds,
            num(m.cone_threshold_cd_m2),
            num(m.rod_threshold_scotopic_cd_m2),
            m.cone_excess_log,
            m.rod_excess_log,
            num(map.photopic_scale),
            num(map.scotopic_scale),
            map.rod_weight,
            num(map.photopic_offset_cd_m2 + map.rod_weight * map.scotopic_offset_cd_m2),
            m.acuity_cycles_per_degree,
        );
    }
    s
}
