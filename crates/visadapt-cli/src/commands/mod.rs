//! One module per subcommand.
pub mod chart;
pub mod demo;
pub mod map;
pub mod observer;
pub mod plot;
pub mod sequence;
pub mod timecourse;
pub mod tolerance;
pub mod video;
pub mod visible;

use anyhow::bail;
use std::path::Path;
use visadapt::HdrImage;
use visadapt::adaptation::highest_visible;

/// The factor that turns an input's values into cd/m²: `--scale S`, or `--peak L` over its
/// highest visible luminance, or 1 (with a warning when the file does not state its units).
pub fn input_scale(
    path: &Path,
    image: &HdrImage,
    scale: Option<f64>,
    peak: Option<f64>,
    hot_pixel_fraction: f64,
) -> anyhow::Result<f64> {
    Ok(match (scale, peak) {
        (Some(s), _) => s,
        (None, Some(peak)) => {
            let hv = highest_visible(&image.y, hot_pixel_fraction) as f64;
            if hv <= 0.0 {
                bail!(
                    "{}: --peak: the image has no visible luminance to rescale",
                    path.display()
                );
            }
            peak / hv
        }
        (None, None) => {
            warn_if_relative(path, image);
            1.0
        }
    })
}

/// Warn that a file without stated units is read as cd/m².
pub fn warn_if_relative(path: &Path, image: &HdrImage) {
    if !image.absolute_units {
        log::warn!(
            "{}: the file does not say its units; its values are taken as cd/m² (use --scale or --peak)",
            path.display()
        );
    }
}
