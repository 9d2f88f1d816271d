//! One module per subcommand.
pub mod chart;
pub mod demo;
pub mod map;
pub mod observer;
pub mod plot;
pub mod sequence;
#[cfg(feature = "serve")]
pub mod serve;
pub mod timecourse;
pub mod tolerance;
pub mod video;
pub mod visible;

use crate::cli::UnitsArgs;
use anyhow::{Context, bail};
use std::path::Path;
use visadapt::{HdrImage, Limits, io};

impl UnitsArgs {
    /// Read the file at `path` in cd/m², and the factor that took it there
    /// ([`UnitsArgs::factor`]): `--scale` applied by the decoder in its own conversion pass
    /// ([`io::read_scaled`]), `--peak` once the image is read.
    pub fn read(
        &self,
        path: &Path,
        limits: &Limits,
        hot_pixel_fraction: f64,
    ) -> anyhow::Result<(HdrImage, f64)> {
        let mut image = io::read_scaled(path, limits, self.decoder_factor())
            .with_context(|| path.display().to_string())?;
        let factor = self.factor(path, &image, hot_pixel_fraction)?;
        self.apply(&mut image, factor);
        Ok((image, factor))
    }

    /// The factor for a decoder to apply in its conversion ([`io::read_scaled`]):
    /// `--scale`, or 1.
    pub fn decoder_factor(&self) -> f32 {
        self.scale.unwrap_or(1.0) as f32
    }

    /// `image`, read with [`UnitsArgs::decoder_factor`], brought into cd/m² by `factor`
    /// ([`UnitsArgs::factor`]): with `--scale` the decoder did it, with `--peak` it is
    /// done here.
    pub fn apply(&self, image: &mut HdrImage, factor: f64) {
        if self.scale.is_none() && factor != 1.0 {
            image.scale(factor as f32);
        }
    }

    /// The factor that turns an input's values into cd/m²: `--scale S`, or `--peak L` over
    /// its highest visible luminance ([`HdrImage::peak_factor`]), or 1 (with a warning when
    /// the file does not state its units).
    pub fn factor(
        &self,
        path: &Path,
        image: &HdrImage,
        hot_pixel_fraction: f64,
    ) -> anyhow::Result<f64> {
        Ok(match (self.scale, self.peak) {
            (Some(s), _) => s,
            (None, Some(peak)) => match image.peak_factor(peak, hot_pixel_fraction) {
                Ok(f) => f,
                Err(visadapt::Error::InvalidParameter { reason, .. }) => {
                    bail!("{}: --peak: {reason}", path.display())
                }
                Err(e) => return Err(e.into()),
            },
            (None, None) => {
                warn_if_relative(path, image);
                1.0
            }
        })
    }

    /// True when neither `--scale` nor `--peak` is given.
    pub fn is_unset(&self) -> bool {
        self.scale.is_none() && self.peak.is_none()
    }
}

/// The folder an output goes into must exist: checked before any work, naming the folder.
pub fn check_output_folder(output: &Path) -> anyhow::Result<()> {
    if let Some(dir) = output.parent()
        && !dir.as_os_str().is_empty()
        && !dir.is_dir()
    {
        bail!(
            "{}: the output folder {} does not exist",
            output.display(),
            dir.display()
        );
    }
    Ok(())
}

/// Warn that the model is about to use the default view: the file records none and `--fov`
/// is not given, so degrees become pixels by a guess. Only when a stage works in degrees:
/// the acuity blur, the glare spread function, the local adaptation radius.
pub fn warn_if_default_view(
    path: &Path,
    image: &HdrImage,
    conditions: &visadapt::operator::ViewingConditions,
) {
    if conditions.view.is_some() || image.view.is_some() {
        return;
    }
    let local = matches!(
        conditions.adaptation,
        visadapt::operator::AdaptationMode::Local(_)
    );
    let stages: Vec<&str> = [
        (conditions.acuity, "the acuity blur"),
        (conditions.glare.is_some(), "the glare"),
        (local, "the local adaptation"),
    ]
    .into_iter()
    .filter_map(|(on, name)| on.then_some(name))
    .collect();
    if let Some((last, rest)) = stages.split_last() {
        let named = if rest.is_empty() {
            last.to_string()
        } else {
            format!("{} and {last}", rest.join(", "))
        };
        log::warn!(
            "{}: the file does not record its view; {} assume{} a {} degree perspective view (give --fov)",
            path.display(),
            named,
            if rest.is_empty() { "s" } else { "" },
            visadapt::operator::DEFAULT_FOV_DEG
        );
    }
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
