//! A test sequence for `visadapt video`: one HDR image resampled to a frame size and
//! written as numbered Radiance (`f_0001.hdr`, ...) and OpenEXR (`f_0001.exr`, ...) frames
//! whose light rises over two log units, as when a camera moves from shade into the sun
//! (each frame 10^(2/(N−1)) brighter than the one before), so that the observer's
//! adaptation moves from frame to frame.
//!
//! Both are written by the library's display writers with linear Rec. 709 RGB in cd/m²:
//! the Radiance frames as RLE RGBE with `EXPOSURE=`, the EXR frames as 32-bit float RLE
//! with `whiteLuminance` = 1, so `visadapt video` reads both in cd/m². Resampling is
//! nearest-neighbour (the frames are for timing, not for looking at).
//!
//! `cargo run --release --example video_frames -- IN.hdr OUT_DIR [WxH] [FRAMES]`
//! (defaults 1920x1080, 24 frames); the README's video benchmark uses
//! `office-fisheye.hdr` from the shared data set.

use visadapt::colour::{self, xyz_to_linear_srgb_matrix};
use visadapt::{DisplayImage, Limits, io};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, out_dir, rest @ ..] = args.as_slice() else {
        return Err("usage: video_frames IN.hdr OUT_DIR [WxH] [FRAMES]".into());
    };
    let (width, height) = match rest.first() {
        Some(size) => {
            let (w, h) = size.split_once('x').ok_or("the size is WxH")?;
            (w.parse::<usize>()?, h.parse::<usize>()?)
        }
        None => (1920, 1080),
    };
    let frames: usize = rest.get(1).map_or(Ok(24), |n| n.parse())?;
    let scene = io::read(std::path::Path::new(input), &Limits::default())?;
    let m = xyz_to_linear_srgb_matrix();
    let mut base = DisplayImage {
        width,
        height,
        display_max_cd_m2: 1.0,
        ..Default::default()
    };
    for y in 0..height {
        let sy = y * scene.height / height;
        for x in 0..width {
            let i = sy * scene.width + x * scene.width / width;
            let xyz = [scene.x[i], scene.y[i], scene.z[i]].map(f64::from);
            let [r, g, b] = colour::mul_vec(&m, xyz).map(|v| v.max(0.0) as f32);
            base.r.push(r);
            base.g.push(g);
            base.b.push(b);
        }
    }
    std::fs::create_dir_all(out_dir)?;
    let dir = std::path::Path::new(out_dir);
    for k in 0..frames {
        let log_step = if frames > 1 {
            2.0 * k as f32 / (frames - 1) as f32
        } else {
            0.0
        };
        let factor = 10f32.powf(log_step - 1.0);
        let frame = DisplayImage {
            r: base.r.iter().map(|v| v * factor).collect(),
            g: base.g.iter().map(|v| v * factor).collect(),
            b: base.b.iter().map(|v| v * factor).collect(),
            ..base.clone()
        };
        let name = format!("f_{:04}", k + 1);
        io::write_display(
            &frame,
            &dir.join(format!("{name}.hdr")),
            io::OutputFormat::Radiance,
        )?;
        io::write_display(
            &frame,
            &dir.join(format!("{name}.exr")),
            io::OutputFormat::Exr,
        )?;
    }
    println!(
        "wrote {frames} frames of {width}x{height} to {} (f_0001.hdr/.exr, ...)",
        dir.display()
    );
    Ok(())
}
