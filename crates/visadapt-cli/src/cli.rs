//! Command-line definitions (clap derive): flags, their help texts and examples.

use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

/// What a human observer would actually see in a high-dynamic-range scene.
///
/// An implementation of Ferwerda, Pattanaik, Shirley & Greenberg, "A Model of Visual
/// Adaptation for Realistic Image Synthesis" (SIGGRAPH 1996): loss of contrast, colour and
/// acuity from daylight down to starlight. Luminances are in cd/m².
#[derive(Debug, Parser)]
#[command(name = "visadapt", version, propagate_version = true, max_term_width = 100)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Map an HDR image to what an observer adapted to the scene sees on a display.
    #[command(after_help = MAP_EXAMPLES)]
    Map(MapArgs),
    /// What an observer adapted to a luminance can see: thresholds, scale factors, acuity.
    #[command(after_help = OBSERVER_EXAMPLES)]
    Observer(ObserverArgs),
}

const MAP_EXAMPLES: &str = "\
Examples:
  visadapt map scene.hdr -o scene.png
  visadapt map render.exr --peak 0.05 -o moonlight.png     # the scene lit at moonlight level
  visadapt map photo.pfm --scale 179 -o out.jpg           # PFM in W/sr/m², to cd/m²
  visadapt map scene.hdr --fov 40 --json -o out.exr       # linear EXR + JSON report

Input: Radiance .hdr/.pic (RGBE/XYZE), OpenEXR (RGB, Y, or X/Y/Z/scotopic), PFM.
Output (by extension): .png (8 or 16 bit sRGB), .jpg, .exr (linear, 1.0 = --display-max).";

const OBSERVER_EXAMPLES: &str = "\
Examples:
  visadapt observer 0.001           # starlight
  visadapt observer 40 --json       # an office at 40 cd/m², as JSON";

#[derive(Debug, Args)]
pub struct MapArgs {
    /// Input HDR image (format detected from its contents).
    pub input: PathBuf,

    /// Output image; the format follows the extension (.png, .jpg/.jpeg, .exr).
    #[arg(short, long)]
    pub output: PathBuf,

    /// Multiply the input values by S to get cd/m² (e.g. 179 for radiance in W/sr/m²).
    #[arg(long, allow_negative_numbers = true, value_name = "S", conflicts_with = "peak")]
    pub scale: Option<f64>,

    /// Rescale so that the highest visible luminance is L cd/m² (the paper's "scene
    /// illuminated at L cd/m²").
    #[arg(long, allow_negative_numbers = true, value_name = "L")]
    pub peak: Option<f64>,

    /// World adaptation luminance in cd/m² [default: half the highest visible luminance].
    #[arg(long, allow_negative_numbers = true, value_name = "L")]
    pub world_adaptation: Option<f64>,

    /// World rod adaptation in scotopic cd/m² [default: half the highest visible scotopic
    /// luminance, or the world adaptation times the image's scotopic/photopic ratio].
    #[arg(long, allow_negative_numbers = true, value_name = "LS")]
    pub scotopic_adaptation: Option<f64>,

    /// Display maximum luminance in cd/m²; the display observer adapts to half of it.
    #[arg(long, allow_negative_numbers = true, value_name = "L", default_value_t = 80.0)]
    pub display_max: f64,

    /// Horizontal field of view of the image in degrees (perspective). Overrides the
    /// file's VIEW; without either, 60 degrees is assumed.
    #[arg(long, allow_negative_numbers = true, value_name = "DEG")]
    pub fov: Option<f64>,

    /// Skip the acuity blur (Eq. 7).
    #[arg(long)]
    pub no_acuity: bool,

    /// Fraction of pixels allowed to be brighter than the "highest visible" luminance,
    /// so that a few hot pixels do not set the adaptation.
    #[arg(long, allow_negative_numbers = true, value_name = "F", default_value_t = visadapt::adaptation::DEFAULT_HOT_PIXEL_FRACTION)]
    pub hot_pixel_fraction: f64,

    /// Bits per channel of PNG output.
    #[arg(long, value_name = "BITS", default_value_t = 8, value_parser = parse_bits)]
    pub bits: u8,

    /// JPEG quality (1-100).
    #[arg(long, value_name = "Q", default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub quality: u8,

    /// Largest accepted input in pixels (width x height); guards against corrupt headers.
    #[arg(long, value_name = "N", default_value_t = visadapt::Limits::default().max_pixels)]
    pub max_pixels: u64,

    /// Print the report as JSON on standard output instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct ObserverArgs {
    /// Adaptation luminance in cd/m².
    #[arg(value_name = "L", allow_negative_numbers = true)]
    pub adaptation: f64,

    /// Scotopic adaptation in scotopic cd/m² [default: L x 2.261, equal-energy white].
    #[arg(long, value_name = "LS", allow_negative_numbers = true)]
    pub scotopic: Option<f64>,

    /// Display maximum luminance in cd/m².
    #[arg(long, value_name = "L", default_value_t = 80.0, allow_negative_numbers = true)]
    pub display_max: f64,

    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

fn parse_bits(s: &str) -> Result<u8, String> {
    match s {
        "8" => Ok(8),
        "16" => Ok(16),
        _ => Err(format!("{s} is not 8 or 16")),
    }
}
