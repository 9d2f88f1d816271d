//! `visadapt sequence`: a scene lit at one level, then switched to another, as numbered PNG
//! frames (and optionally one animated PNG), as in the paper's Fig. 12.

use super::timecourse::{positive, sorted_times};
use crate::cli::{PngLevel, SequenceArgs};
use crate::numbers::num;
use anyhow::{Context, bail};
use std::path::PathBuf;
use visadapt::operator::ViewingConditions;
use visadapt::sequence::{ApngWriter, Playback, Sequence, render_owned};
use visadapt::{DisplayImage, io, label};

/// File name of frame `index` of `count`: `frame_000.png`, zero-padded to at least 3 digits.
pub fn frame_name(index: usize, count: usize) -> String {
    let width = (count.saturating_sub(1)).to_string().len().max(3);
    format!("frame_{index:0width$}.png")
}

pub fn run(args: SequenceArgs) -> anyhow::Result<()> {
    let from = positive("--from", args.from)?;
    let to = positive("--to", args.to)?;
    sorted_times(&args.times)?;
    if args.apng_delay_ms == Some(0) {
        bail!("invalid --apng-delay-ms 0: must be at least 1");
    }
    let sequence = Sequence::new(from, to, args.times.clone())?;
    let playback = match args.apng_delay_ms {
        Some(ms) => Playback {
            delays_ms: vec![ms; sequence.frame_count()],
            speedup: None,
        },
        None => sequence.playback(args.apng_seconds).map_err(|e| match e {
            visadapt::Error::InvalidParameter { reason, .. } => {
                anyhow::anyhow!("invalid --apng-seconds {}: {reason}", args.apng_seconds)
            }
            e => e.into(),
        })?,
    };
    // No output may be the input, under any name: the animation, and every frame.
    let count = sequence.frame_count();
    if let Some(apng) = &args.apng {
        io::output::refuse_same_file(apng, &[&args.input])?;
    }
    for index in 0..count {
        let frame = args.output.join(frame_name(index, count));
        io::output::refuse_same_file(&frame, &[&args.input])?;
    }
    let conditions = args.viewing.conditions(
        Some(&args.display),
        None,
        Some(&args.view),
        Some(&args.colour),
    );
    conditions.validate()?;

    let scene = io::read(&args.input, &args.limits.limits())
        .with_context(|| args.input.display().to_string())?;
    let conditions = ViewingConditions {
        view: args.view.view(scene.width, scene.height),
        undershoot: args.time_course.undershoot(),
        ..conditions
    };
    super::warn_if_default_view(&args.input, &scene, &conditions);
    std::fs::create_dir_all(&args.output).with_context(|| {
        format!(
            "{}: cannot create the output directory",
            args.output.display()
        )
    })?;

    let mut apng = match &args.apng {
        Some(path) => Some(
            ApngWriter::with_delays(path, scene.width, scene.height, &playback.delays_ms)
                .with_context(|| path.display().to_string())?,
        ),
        None => None,
    };
    let mut written: Vec<(PathBuf, Option<f64>, f64, f64)> = Vec::new();
    // The chromatic adaptation (the same for every frame: it depends on the file only).
    let mut white: Option<(String, Option<String>)> = None;
    // The file an error happened on, to name it in the message.
    let mut failed: Option<PathBuf> = None;
    // With --label-time, the frame is labelled in a copy (the sequence reuses its image).
    let mut labelled = DisplayImage::default();
    let format = io::OutputFormat::png(8).with_png_compression(args.png.level(PngLevel::Fast));
    let result = render_owned(scene, &sequence, &conditions, |frame| {
        let path = args.output.join(frame_name(frame.index, count));
        let image = match sequence.frame_label(frame.index) {
            Some(text) if args.label_time => {
                labelled.clone_from(frame.image);
                label::draw(&mut labelled, &text)?;
                &labelled
            }
            _ => frame.image,
        };
        io::write_display(image, &path, format).inspect_err(|_| failed = Some(path.clone()))?;
        if let (Some(a), Some(apng_path)) = (apng.as_mut(), &args.apng) {
            a.push(image)
                .inspect_err(|_| failed = Some(apng_path.clone()))?;
        }
        white.get_or_insert_with(|| {
            (
                crate::report::white_point(frame.report),
                frame.report.scene_white.map(visadapt::colour::white_name),
            )
        });
        let m = &frame.mapping;
        let offset = m.photopic_offset_cd_m2 + m.rod_weight * m.scotopic_offset_cd_m2;
        written.push((path, frame.t_seconds, m.photopic_scale, offset));
        Ok(())
    });
    let named = failed.unwrap_or_else(|| args.input.clone());
    result.with_context(|| named.display().to_string())?;
    if let (Some(a), Some(path)) = (apng, &args.apng) {
        a.finish().with_context(|| path.display().to_string())?;
    }

    if args.json {
        let frames: Vec<_> = written
            .iter()
            .map(|(p, t, mp, b)| {
                serde_json::json!({
                    "file": p.display().to_string(),
                    "t_seconds": t,
                    "photopic_scale": mp,
                    "offset_cd_m2": b,
                })
            })
            .collect();
        let v = serde_json::json!({
            "from_cd_m2": from,
            "to_cd_m2": to,
            "frames": frames,
            "scene_white": white.as_ref().and_then(|w| w.1.clone()),
            "apng": args.apng.as_ref().map(|p| p.display().to_string()),
            "apng_delays_ms": args.apng.as_ref().map(|_| &playback.delays_ms),
            "apng_speedup": args.apng.as_ref().and(playback.speedup),
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "scene lit at {} cd/m², then {} cd/m² (highest visible luminance)",
            num(from),
            num(to)
        );
        if let Some((text, _)) = &white {
            println!("white point: {text}");
        }
        for (p, t, mp, b) in &written {
            let when = match t {
                Some(t) => format!("t = {} s", num(*t)),
                None => "adapted, before the switch".to_string(),
            };
            println!(
                "{:<40} {when:<28} m_p {}  b {} cd/m²",
                p.display().to_string(),
                num(*mp),
                num(*b)
            );
        }
        if let Some(p) = &args.apng {
            let pace = match playback.speedup {
                Some(x) => format!(
                    "the real time steps {} times faster, first and last frames held {} s",
                    num(x),
                    num(f64::from(playback.delays_ms[0]) / 1000.0)
                ),
                None => "every frame for the same time".to_string(),
            };
            println!(
                "animation: {} ({} frames in {} s: {pace})",
                p.display(),
                count,
                num(playback.seconds())
            );
        }
    }
    Ok(())
}
