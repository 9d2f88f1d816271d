//! Pictures the CLI draws itself (plots, the demo's contact sheet): the embedded font,
//! writing an RGB buffer as PNG, and text on RGB buffers.
//!
//! The font is DejaVu Sans (Bitstream Vera licence, `assets/fonts/LICENSE-DejaVu`),
//! compiled into the binary so that no system font is needed.

use anyhow::{Context, bail};
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::Once;

/// DejaVu Sans 2.37 (Debian fonts-dejavu-core), the one font of every picture.
pub static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

/// The family name the font is registered under with plotters.
pub const FAMILY: &str = "sans-serif";

/// Register the embedded font with plotters (once per process).
pub fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
            .unwrap_or_else(|_| panic!("the embedded font is a valid TrueType font"));
    });
}

/// The picture formats the CLI writes, from a file name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PictureFormat {
    /// Scalable vector graphics.
    Svg,
    /// 8-bit sRGB PNG.
    Png,
}

impl PictureFormat {
    /// The format of `path` by its extension (`.svg` or `.png`).
    pub fn from_path(path: &Path) -> anyhow::Result<Self> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("svg") => Ok(PictureFormat::Svg),
            Some("png") => Ok(PictureFormat::Png),
            _ => bail!(
                "{}: cannot tell the picture format (use .svg or .png)",
                path.display()
            ),
        }
    }
}

/// Write interleaved 8-bit sRGB pixels as a PNG, atomically (complete or not at all).
pub fn write_rgb_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> anyhow::Result<()> {
    visadapt::io::display::write_atomically(path, |w| {
        let mut enc = png::Encoder::new(w, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let io = |e: png::EncodingError| match e {
            png::EncodingError::IoError(e) => visadapt::Error::Io(e),
            other => visadapt::Error::Unsupported(format!("PNG encoder: {other}")),
        };
        let mut writer = enc.write_header().map_err(io)?;
        writer.write_image_data(rgb).map_err(io)?;
        writer.finish().map_err(io)
    })
    .with_context(|| path.display().to_string())
}

/// Write text to a file atomically.
pub fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    visadapt::io::display::write_atomically(path, |w| {
        std::io::Write::write_all(w, text.as_bytes())?;
        Ok(())
    })
    .with_context(|| path.display().to_string())
}

/// Draw `lines` of text in `colour` onto an RGB buffer of `width × height`, starting at
/// (`x`, `y`) pixels, `size` pixels high, one line below the other.
pub fn draw_text(
    rgb: &mut [u8],
    (width, height): (u32, u32),
    (x, y): (i32, i32),
    size: f64,
    colour: RGBColor,
    lines: &[String],
) -> anyhow::Result<()> {
    register_font();
    let root = BitMapBackend::with_buffer(rgb, (width, height)).into_drawing_area();
    let style = (FAMILY, size).into_font().color(&colour);
    for (k, line) in lines.iter().enumerate() {
        let pos = (x, y + (k as f64 * size * 1.3).round() as i32);
        root.draw_text(line, &style, pos)
            .map_err(|e| anyhow::anyhow!("drawing text: {e}"))?;
    }
    root.present()
        .map_err(|e| anyhow::anyhow!("drawing text: {e}"))?;
    Ok(())
}
