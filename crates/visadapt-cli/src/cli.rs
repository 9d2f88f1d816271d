//! Command-line definitions (clap derive): flags, their help texts and examples.

use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

/// What a human observer would actually see in a high-dynamic-range scene.
///
/// An implementation of Ferwerda, Pattanaik, Shirley & Greenberg, "A Model of Visual
/// Adaptation for Realistic Image Synthesis" (SIGGRAPH 1996): loss of contrast, colour and
/// acuity from daylight down to starlight. Luminances are in cd/m².
#[derive(Debug, Parser)]
#[command(
    name = "visadapt",
    version,
    propagate_version = true,
    arg_required_else_help = true,
    max_term_width = 100
)]
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
    /// Thresholds, scale factors, offsets and acuity over time after the world luminance
    /// changes (Figs. 8-10, Eq. 8-9).
    #[command(after_help = TIMECOURSE_EXAMPLES)]
    Timecourse(TimecourseArgs),
    /// A scene lit at one level, then switched to another: frames over time (Fig. 12).
    #[command(after_help = SEQUENCE_EXAMPLES)]
    Sequence(SequenceArgs),
    /// A stream of numbered HDR frames through the time course of adaptation.
    #[command(after_help = VIDEO_EXAMPLES)]
    Video(VideoArgs),
    /// Write the paper's test scene (ColorChecker, Snellen chart, gratings) as an EXR.
    #[command(after_help = CHART_EXAMPLES)]
    Chart(ChartArgs),
    /// Render the built-in scene at the paper's four light levels (Fig. 11): panels, a
    /// labelled contact sheet and a table of what each observer can see.
    #[command(after_help = DEMO_EXAMPLES)]
    Demo(DemoArgs),
    /// Draw one of the paper's model figures from the library's own functions.
    #[command(after_help = PLOT_EXAMPLES)]
    Plot(PlotArgs),
    /// How visible the difference between two HDR images of one scene is, in JNDs, to an
    /// observer adapted to the first; optionally a heat map with a colour bar.
    #[command(after_help = VISIBLE_EXAMPLES)]
    Visible(VisibleArgs),
    /// Per pixel, the largest luminance error that stays invisible (cd/m², written as EXR).
    #[command(after_help = TOLERANCE_EXAMPLES)]
    Tolerance(ToleranceArgs),
    /// An interactive viewer in the browser: move the light level, play light and dark
    /// adaptation, inspect pixels (a local web server).
    #[cfg(feature = "serve")]
    #[command(after_help = SERVE_EXAMPLES)]
    Serve(ServeArgs),
}

// ---- flag groups shared by several commands (`#[command(flatten)]`) ----
//
// Each group is one idea; a command flattens the groups it uses, and
// [`ViewingArgs::conditions`] is the one place where flags become the library's
// `ViewingConditions`. New viewing flags go into these groups.

/// How the input's values become cd/m² (map, visible, tolerance).
#[derive(Debug, Clone, Args)]
pub struct UnitsArgs {
    /// Multiply the input values by S to get cd/m² (e.g. 179 for radiance in W/sr/m²).
    #[arg(
        long,
        allow_negative_numbers = true,
        value_parser = positive,
        value_name = "S",
        conflicts_with = "peak"
    )]
    pub scale: Option<f64>,

    /// Rescale so that the highest visible luminance is L cd/m² (the paper's "scene
    /// illuminated at L cd/m²").
    #[arg(long, allow_negative_numbers = true, value_parser = positive, value_name = "L")]
    pub peak: Option<f64>,
}

/// The display the image is shown on (map, observer, timecourse, sequence, video).
#[derive(Debug, Clone, Args)]
pub struct DisplayArgs {
    /// Display maximum luminance in cd/m²; the display observer adapts to half of it.
    #[arg(
        long,
        allow_negative_numbers = true,
        value_parser = positive,
        value_name = "L",
        default_value_t = visadapt::adaptation::DEFAULT_DISPLAY_MAX_CD_M2
    )]
    pub display_max: f64,
}

/// The world observer's adaptation, when not derived from the image (map, visible,
/// tolerance).
#[derive(Debug, Clone, Args)]
pub struct WorldAdaptationArgs {
    /// World adaptation luminance in cd/m² [default: half the highest visible luminance].
    #[arg(long, allow_negative_numbers = true, value_parser = positive, value_name = "L")]
    pub world_adaptation: Option<f64>,

    /// World rod adaptation in scotopic cd/m² [default: half the highest visible scotopic
    /// luminance, or the world adaptation times the image's scotopic/photopic ratio].
    #[arg(long, allow_negative_numbers = true, value_parser = positive, value_name = "LS")]
    pub scotopic_adaptation: Option<f64>,
}

/// The view of the image: how its pixels become degrees, for the acuity blur, the glare
/// spread function and the local adaptation radius (map, visible, sequence, video, serve,
/// tolerance).
#[derive(Debug, Clone, Args)]
pub struct FieldOfViewArgs {
    /// Horizontal field of view of the image in degrees. Overrides the file's view;
    /// without either, a 60-degree perspective view is assumed.
    #[arg(long, allow_negative_numbers = true, value_parser = positive, value_name = "DEG")]
    pub fov: Option<f64>,

    /// Projection of the image for --fov: perspective (under 180 degrees) or an angular
    /// fisheye (pixels uniform in angle, up to 360 degrees).
    #[arg(long, value_enum, value_name = "KIND", default_value_t = ProjectionArg::Perspective, requires = "fov")]
    pub projection: ProjectionArg,
}

/// The view of the image and the acuity blur (map, visible, sequence, video, serve).
#[derive(Debug, Clone, Args)]
pub struct ViewArgs {
    #[command(flatten)]
    pub field: FieldOfViewArgs,

    /// Skip the acuity blur (Eq. 7).
    #[arg(long)]
    pub no_acuity: bool,

    /// The threshold contrast of the acuity blur (Eq. 7): `pooled`, the visibility
    /// metric's (rods weighted by k, pooled with the cones: a full-contrast grating at the
    /// cutoff is exactly at threshold), or `envelope`, the paper's (the more sensitive
    /// system's alone; blurs more from 0.01 to 1 cd/m²).
    #[arg(long, value_enum, value_name = "RULE", default_value_t = AcuityThresholdArg::Pooled)]
    pub acuity_threshold: AcuityThresholdArg,
}

/// `--acuity-threshold`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum AcuityThresholdArg {
    /// The JND metric's threshold (the default).
    Pooled,
    /// The envelope of the rod and cone thresholds (the paper's Sec. 3.2).
    Envelope,
}

impl AcuityThresholdArg {
    /// The library's rule.
    pub fn rule(self) -> visadapt::acuity::AcuityThreshold {
        match self {
            AcuityThresholdArg::Pooled => visadapt::acuity::AcuityThreshold::Pooled,
            AcuityThresholdArg::Envelope => visadapt::acuity::AcuityThreshold::Envelope,
        }
    }
}

/// How the colours of the display image are formed (map, sequence, video, serve).
#[derive(Debug, Clone, Args)]
pub struct ColourArgs {
    /// Scene white the colours are adapted from to the display's D65 (CAT16): auto (the
    /// file's: Radiance PRIMARIES white, E by default; EXR adoptedNeutral or chromaticities;
    /// PFM D65), none (the paper: no chromatic adaptation), E, D65, or a chromaticity x,y.
    #[arg(
        long,
        value_name = "WHITE",
        default_value = "auto",
        allow_hyphen_values = true
    )]
    pub white_point: visadapt::colour::WhitePoint,
}

/// The projections `--projection` offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ProjectionArg {
    /// Planar perspective: uniform on the image plane, under 180 degrees.
    Perspective,
    /// Angular fisheye: uniform in angle from the centre, up to 360 degrees.
    Fisheye,
}

/// One adaptation level for the scene or one per pixel (map, visible, tolerance, sequence,
/// video, demo, serve).
#[derive(Debug, Clone, Args)]
pub struct AdaptationArgs {
    /// How the observer adapts: `global`, one level for the whole scene (the paper's
    /// model), or `local`, every point seen by an eye adapted to its own neighbourhood
    /// (see --adaptation-radius).
    #[arg(long, value_enum, value_name = "MODE", default_value_t = AdaptationKind::Global)]
    pub adaptation: AdaptationKind,

    /// With --adaptation local: radius of the neighbourhood the eye adapts to, degrees
    /// (the fovea and its surround).
    #[arg(long, allow_negative_numbers = true, value_parser = positive, value_name = "DEG",
          default_value_t = visadapt::local::DEFAULT_ADAPTATION_RADIUS_DEG)]
    pub adaptation_radius: f64,
}

/// The values of `--adaptation`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum AdaptationKind {
    /// One adaptation level for the scene (paper Sec. 4.4).
    Global,
    /// An adaptation level per pixel, from its neighbourhood.
    Local,
}

impl AdaptationArgs {
    /// The library's adaptation mode.
    pub fn mode(&self) -> visadapt::operator::AdaptationMode {
        match self.adaptation {
            AdaptationKind::Global => visadapt::operator::AdaptationMode::Global,
            AdaptationKind::Local => {
                visadapt::operator::AdaptationMode::Local(visadapt::local::LocalAdaptation {
                    radius_deg: self.adaptation_radius,
                    ..Default::default()
                })
            }
        }
    }
}

/// Model options every image command has (map, visible, tolerance, sequence, video, serve).
#[derive(Debug, Clone, Args)]
pub struct ViewingArgs {
    #[command(flatten)]
    pub adaptation: AdaptationArgs,

    /// Fraction of pixels allowed to be brighter than the "highest visible" luminance,
    /// so that a few hot pixels do not set the adaptation.
    #[arg(long, allow_negative_numbers = true, value_parser = fraction, value_name = "F", default_value_t = visadapt::adaptation::DEFAULT_HOT_PIXEL_FRACTION)]
    pub hot_pixel_fraction: f64,

    #[command(flatten)]
    pub glare: GlareArgs,
}

/// Veiling glare in the observer's eye (map, visible, tolerance, sequence, video, demo, serve).
#[derive(Debug, Clone, Args)]
pub struct GlareArgs {
    /// Add veiling glare: light scattered in the eye (CIE 135/1 glare spread function) is
    /// added to the scene before adaptation, so that bright lights bloom, veil what lies
    /// near them and raise the adaptation level.
    #[arg(long)]
    pub glare: bool,

    /// Age of the observer in years, for --glare (the eye scatters more with age).
    #[arg(long, value_name = "YEARS", requires = "glare", allow_negative_numbers = true,
          default_value_t = visadapt::glare::DEFAULT_AGE_YEARS)]
    pub age: f64,

    /// Eye pigmentation for --glare: 0 very dark, 0.5 brown, 1 green, 1.2 light blue (light
    /// through the eye wall).
    #[arg(long, value_name = "P", requires = "glare", allow_negative_numbers = true,
          default_value_t = visadapt::glare::DEFAULT_PIGMENTATION)]
    pub pigmentation: f64,
}

impl GlareArgs {
    /// The library's glare option: `None` without `--glare`.
    pub fn glare(&self) -> Option<visadapt::glare::Glare> {
        self.glare.then_some(visadapt::glare::Glare {
            age_years: self.age,
            pigmentation: self.pigmentation,
        })
    }
}

/// How a time course maps its frames (timecourse, sequence, video, demo).
#[derive(Debug, Clone, Args)]
pub struct TimeCourseArgs {
    /// What the display mapping does while the cone threshold is below its steady state
    /// (Baker's dip, minutes after a rise): `clamped` keeps the steady-state contrast (no
    /// shadows clipped to black; the dip stays in the thresholds, visibility and acuity);
    /// `in-mapping` is the paper's Eq. 8-9, whose negative offset clips shadows.
    #[arg(long, value_enum, value_name = "RULE", default_value_t = UndershootArg::Clamped)]
    pub undershoot: UndershootArg,
}

/// `--undershoot`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum UndershootArg {
    /// The mapping never asks for more contrast than the steady state (the default).
    Clamped,
    /// The paper's Eq. 8-9 during Baker's dip.
    InMapping,
}

impl TimeCourseArgs {
    /// The library's rule.
    pub fn undershoot(&self) -> visadapt::timecourse::Undershoot {
        match self.undershoot {
            UndershootArg::Clamped => visadapt::timecourse::Undershoot::Clamped,
            UndershootArg::InMapping => visadapt::timecourse::Undershoot::InMapping,
        }
    }
}

/// Guards on the input (map, visible, tolerance, sequence, video).
#[derive(Debug, Clone, Args)]
pub struct LimitsArgs {
    /// Largest accepted input in pixels (width x height); guards against corrupt headers.
    #[arg(long, value_name = "N", default_value_t = visadapt::Limits::default().max_pixels)]
    pub max_pixels: u64,

    /// Memory budget for what the input controls (the file's bytes, decoded planes,
    /// decompression buffers), in bytes or with a K, M, G or T suffix (powers of 1024).
    /// Checked before each allocation; the default is half of a 24 GiB machine.
    #[arg(long, value_name = "SIZE", default_value = "12G", value_parser = parse_memory)]
    pub max_memory: u64,
}

impl LimitsArgs {
    /// The library's limits.
    pub fn limits(&self) -> visadapt::Limits {
        visadapt::Limits {
            max_pixels: self.max_pixels,
            max_memory_bytes: self.max_memory,
        }
    }
}

/// Compression of PNG output (map, sequence, video).
#[derive(Debug, Clone, Args)]
pub struct PngArgs {
    /// Compression of PNG output, lossless at every level (the same pixels)
    /// [default: fast; fdeflate for video].
    #[arg(long, value_enum, value_name = "LEVEL")]
    pub png_compression: Option<PngLevel>,
}

impl PngArgs {
    /// The chosen level, or the command's `default`.
    pub fn level(&self, default: PngLevel) -> visadapt::io::display::PngCompression {
        self.png_compression.unwrap_or(default).into()
    }
}

impl ViewingArgs {
    /// The library's viewing conditions from these flags and the groups a command has
    /// (`None` for a group it lacks: the library default). The view needs the image's
    /// size: see [`ViewArgs::view`].
    pub fn conditions(
        &self,
        display: Option<&DisplayArgs>,
        world: Option<&WorldAdaptationArgs>,
        view: Option<&ViewArgs>,
        colour: Option<&ColourArgs>,
    ) -> visadapt::operator::ViewingConditions {
        let defaults = visadapt::operator::ViewingConditions::default();
        visadapt::operator::ViewingConditions {
            display_max_cd_m2: display.map_or(defaults.display_max_cd_m2, |d| d.display_max),
            world_adaptation_cd_m2: world.and_then(|w| w.world_adaptation),
            world_adaptation_scotopic_cd_m2: world.and_then(|w| w.scotopic_adaptation),
            hot_pixel_fraction: self.hot_pixel_fraction,
            acuity: view.is_none_or(|v| !v.no_acuity),
            acuity_threshold: view.map_or(defaults.acuity_threshold, |v| v.acuity_threshold.rule()),
            adaptation: self.adaptation.mode(),
            glare: self.glare.glare(),
            white_point: colour.map_or(defaults.white_point, |c| c.white_point),
            ..defaults
        }
    }
}

impl ViewArgs {
    /// The view `--fov` and `--projection` give an image of `width × height` pixels;
    /// `None` to use the file's.
    pub fn view(&self, width: usize, height: usize) -> Option<visadapt::View> {
        self.field.view(width, height)
    }

    /// [`FieldOfViewArgs::check`].
    pub fn check(&self) -> Result<(), String> {
        self.field.check()
    }
}

impl FieldOfViewArgs {
    /// The view `--fov` and `--projection` give an image of `width × height` pixels;
    /// `None` to use the file's.
    pub fn view(&self, width: usize, height: usize) -> Option<visadapt::View> {
        self.fov.map(|fov| match self.projection {
            ProjectionArg::Perspective => visadapt::View::perspective(fov, width, height),
            ProjectionArg::Fisheye => visadapt::View::angular_fisheye(fov, width, height),
        })
    }

    /// Check the flags together: a perspective view spans less than 180 degrees, a
    /// fisheye at most 360.
    pub fn check(&self) -> Result<(), String> {
        match (self.fov, self.projection) {
            (Some(fov), ProjectionArg::Perspective) if fov >= 180.0 => Err(format!(
                "invalid value '{fov}' for '--fov <DEG>': a perspective view spans less than 180 degrees (use --projection fisheye)"
            )),
            (Some(fov), ProjectionArg::Fisheye) if fov > 360.0 => Err(format!(
                "invalid value '{fov}' for '--fov <DEG>': a fisheye view spans at most 360 degrees"
            )),
            _ => Ok(()),
        }
    }
}

impl Cli {
    /// Checks of flags against each other that clap's parsers cannot make alone, as usage
    /// errors in clap's own style.
    pub fn check(&self) -> Result<(), clap::Error> {
        let (name, result) = match &self.command {
            Command::Map(a) => ("map", a.view.check().and_then(|()| a.check_format_flags())),
            Command::Visible(a) => ("visible", a.view.check()),
            Command::Sequence(a) => ("sequence", a.view.check()),
            Command::Video(a) => ("video", a.view.check()),
            Command::Tolerance(a) => ("tolerance", a.field.check()),
            #[cfg(feature = "serve")]
            Command::Serve(a) => ("serve", a.view.check()),
            _ => return Ok(()),
        };
        result.map_err(|message| {
            let mut cli = <Cli as clap::CommandFactory>::command();
            cli.build();
            let mut sub = cli
                .find_subcommand(name)
                .expect("the subcommand exists")
                .clone();
            sub.error(clap::error::ErrorKind::ArgumentConflict, message)
        })
    }
}

impl MapArgs {
    /// Whether `-o` names a folder: several inputs, a path ending in `/`, or an existing
    /// folder.
    pub fn output_is_folder(&self) -> bool {
        if self.output.as_os_str() == "-" {
            return false;
        }
        self.inputs.len() > 1
            || self.output.as_os_str().to_string_lossy().ends_with('/')
            || self.output.is_dir()
    }

    /// The output format: `--format`, else the output file's extension, else PNG (a
    /// folder). `None` for a file whose extension names no format we write.
    pub fn format_kind(&self) -> Option<FormatArg> {
        if let Some(f) = self.format {
            return Some(f);
        }
        if self.output_is_folder() || self.output.as_os_str() == "-" {
            return Some(FormatArg::Png);
        }
        let ext = self
            .output
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        FormatArg::from_extension(&ext)
    }

    /// `--bits` and `--png-compression` are for PNG output and `--quality` for JPEG: refuse
    /// them with another format;
    /// `--format` must agree with the output file's extension.
    fn check_format_flags(&self) -> Result<(), String> {
        if self.output.as_os_str() == "-" && self.inputs.len() > 1 {
            return Err("several inputs go into a folder, not to standard output ('-o -')".into());
        }
        if self.inputs.iter().filter(|i| i.as_os_str() == "-").count() > 1 {
            return Err("standard input ('-') can be read only once".into());
        }
        if let (Some(f), false) = (self.format, self.output_is_folder()) {
            let ext = self
                .output
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .unwrap_or_default();
            if let Some(by_name) = FormatArg::from_extension(&ext)
                && by_name != f
            {
                return Err(format!(
                    "--format {} contradicts the extension of '{}'",
                    f.name(),
                    self.output.display()
                ));
            }
        }
        let kind = self.format_kind();
        if self.bits.is_some() && kind != Some(FormatArg::Png) {
            return Err(format!(
                "--bits applies to PNG output only, not to '{}'",
                self.output.display()
            ));
        }
        if self.png.png_compression.is_some() && kind != Some(FormatArg::Png) {
            return Err(format!(
                "--png-compression applies to PNG output only, not to '{}'",
                self.output.display()
            ));
        }
        if self.quality.is_some() && kind != Some(FormatArg::Jpeg) {
            return Err(format!(
                "--quality applies to JPEG output only, not to '{}'",
                self.output.display()
            ));
        }
        Ok(())
    }
}

/// The values of `--format`: the display-image formats `map` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FormatArg {
    /// PNG, sRGB, 8 or 16 bits (--bits, --png-compression).
    Png,
    /// JPEG, sRGB (--quality).
    #[value(alias = "jpg")]
    Jpeg,
    /// OpenEXR, linear Rec. 709, 1.0 = --display-max.
    Exr,
    /// TIFF, 32-bit float linear Rec. 709, 1.0 = --display-max.
    #[value(alias = "tif")]
    Tiff,
    /// Radiance RGBE, linear Rec. 709, read back in cd/m².
    Hdr,
}

impl FormatArg {
    /// The format a file extension (lower case, without the dot) names.
    pub fn from_extension(ext: &str) -> Option<Self> {
        match ext {
            "png" => Some(FormatArg::Png),
            "jpg" | "jpeg" => Some(FormatArg::Jpeg),
            "exr" => Some(FormatArg::Exr),
            "tif" | "tiff" => Some(FormatArg::Tiff),
            "hdr" => Some(FormatArg::Hdr),
            _ => None,
        }
    }

    /// The name `--format` takes, also the extension of the files it writes into a folder.
    pub fn name(self) -> &'static str {
        match self {
            FormatArg::Png => "png",
            FormatArg::Jpeg => "jpg",
            FormatArg::Exr => "exr",
            FormatArg::Tiff => "tif",
            FormatArg::Hdr => "hdr",
        }
    }
}

const MAP_EXAMPLES: &str = "\
Examples:
  visadapt map scene.hdr -o scene.png
  visadapt map render.exr --peak 0.05 -o moonlight.png     # the scene lit at moonlight level
  visadapt map photo.pfm --scale 179 -o out.jpg           # PFM in W/sr/m², to cd/m²
  visadapt map photo.jpg --scale 0.05 -o night.png        # an LDR photo, its white at 0.05 cd/m²
  visadapt map scene.hdr --fov 40 --json -o out.exr       # linear EXR + JSON report
  visadapt map a.hdr b.exr c.pfm -o out/ --format jpg     # a batch: out/a.jpg, out/b.jpg, ...
  cat scene.hdr | visadapt map - -o - > scene.png         # a pipe (report on stderr)

Input: Radiance .hdr/.pic (RGBE/XYZE), OpenEXR (RGB, Y, or X/Y/Z/scotopic), PFM; and
8/16-bit PNG, JPEG, TIFF photographs, sRGB undone, white = 1 (give its luminance: --scale).
Output (by extension or --format): .png (8 or 16 bit sRGB), .jpg, .exr and .tif (linear
float, 1.0 = --display-max), .hdr (Radiance, reads back in cd/m²).
Batches: with several inputs, -o is a folder (created if missing) and each input is written
there under its own name with the format's extension; one line per file (JSON Lines with
--json), and the exit status is 1 if any input failed, the others still written.";

const OBSERVER_EXAMPLES: &str = "\
Examples:
  visadapt observer 0.001           # starlight
  visadapt observer 40 --json       # an office at 40 cd/m², as JSON";

#[derive(Debug, Args)]
pub struct MapArgs {
    /// Input HDR images (format detected from their contents); '-' reads standard input.
    #[arg(value_name = "INPUT", required = true)]
    pub inputs: Vec<PathBuf>,

    /// Output image, or a folder for several inputs (or a path ending in '/', or an
    /// existing folder); the format follows the extension (.png, .jpg/.jpeg, .exr, .tif, .hdr) or
    /// --format. '-' writes standard output (the report then goes to standard error).
    #[arg(short, long)]
    pub output: PathBuf,

    /// Output format [default: the output's extension; png into a folder or to '-'].
    #[arg(long, value_enum, value_name = "FORMAT")]
    pub format: Option<FormatArg>,

    /// Files mapped at the same time in a batch (each holds its own image in memory).
    #[arg(short, long, value_name = "N", default_value_t = std::num::NonZeroUsize::MIN)]
    pub jobs: std::num::NonZeroUsize,

    #[command(flatten)]
    pub units: UnitsArgs,

    #[command(flatten)]
    pub world: WorldAdaptationArgs,

    #[command(flatten)]
    pub display: DisplayArgs,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub colour: ColourArgs,

    #[command(flatten)]
    pub viewing: ViewingArgs,

    /// Bits per channel of PNG output [default: 8].
    #[arg(long, value_name = "BITS", value_parser = parse_bits)]
    pub bits: Option<u8>,

    /// JPEG quality (1-100) [default: 90].
    #[arg(long, value_name = "Q", value_parser = clap::value_parser!(u8).range(1..=100))]
    pub quality: Option<u8>,

    #[command(flatten)]
    pub png: PngArgs,

    #[command(flatten)]
    pub limits: LimitsArgs,

    /// Print the report as JSON on standard output instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct ObserverArgs {
    /// Adaptation luminance in cd/m².
    #[arg(value_name = "L", allow_negative_numbers = true, value_parser = positive)]
    pub adaptation: f64,

    /// Scotopic adaptation in scotopic cd/m² [default: L x 2.261, equal-energy white].
    #[arg(long, value_name = "LS", allow_negative_numbers = true, value_parser = positive)]
    pub scotopic: Option<f64>,

    #[command(flatten)]
    pub display: DisplayArgs,

    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// A memory size: bytes, or a number with a K, M, G or T suffix (powers of 1024).
fn parse_memory(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (digits, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                _ => return Err(format!("{s}: unknown unit (use K, M, G or T)")),
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    let n: u64 = digits
        .parse()
        .map_err(|_| format!("{s} is not a size such as 8G or 512M"))?;
    match n.checked_mul(1 << shift) {
        Some(0) | None => Err(format!("{s}: must be between 1 byte and 16 EiB")),
        Some(v) => Ok(v),
    }
}

/// A positive, finite number: luminances, factors, angles, rates; from
/// [`visadapt::MIN_LUMINANCE_CD_M2`] to [`visadapt::MAX_LUMINANCE_CD_M2`], the range the
/// f32 pipeline carries.
fn positive(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (visadapt::MIN_LUMINANCE_CD_M2..=visadapt::MAX_LUMINANCE_CD_M2).contains(&v) => {
            Ok(v)
        }
        Ok(_) => Err(format!(
            "must be a positive number from {:e} to {:e} (the range the f32 pipeline carries)",
            visadapt::MIN_LUMINANCE_CD_M2,
            visadapt::MAX_LUMINANCE_CD_M2
        )),
        Err(_) => Err("not a number".into()),
    }
}

/// A finite number of zero or more, e.g. a time in seconds.
fn non_negative(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(_) => Err("must be a finite number, zero or more".into()),
        Err(_) => Err("not a number".into()),
    }
}

/// A fraction in [0, 1).
fn fraction(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..1.0).contains(&v) => Ok(v),
        Ok(_) => Err("must be in [0, 1)".into()),
        Err(_) => Err("not a number".into()),
    }
}

fn parse_bits(s: &str) -> Result<u8, String> {
    match s {
        "8" => Ok(8),
        "16" => Ok(16),
        _ => Err(format!("{s} is not 8 or 16")),
    }
}

const CHART_EXAMPLES: &str = "\
Examples:
  visadapt chart -o chart.exr --white 0.04            # the chart lit at moonlight level
  visadapt chart -o near.exr --white 100 --fov 30     # seen from nearer (scene spans 30 degrees)

The EXR holds X, Y, Z (cd/m²) and scotopic (scotopic cd/m²), the paper's layout, and the view
in its visadaptView attribute (Radiance view options), which map and visible read back.";

const DEMO_EXAMPLES: &str = "\
Examples:
  visadapt demo                       # writes visadapt-demo/
  visadapt demo -o out --levels 100,1,0.01 --no-sequences

Writes panel-L.png per level, contact-sheet.png, and the paper's Fig. 12 sequences on the
same scene: fig12a-N.png / fig12a.apng (light adaptation, 0.1 -> 5623 cd/m²) and
fig12b-N.png / fig12b.apng (dark adaptation, 1412 -> 0.1 cd/m²).";

const PLOT_EXAMPLES: &str = "\
Examples:
  visadapt plot tvi -o tvi.svg
  visadapt plot fig4 -o spectral-sensitivity.png";

#[derive(Debug, Args)]
pub struct ChartArgs {
    /// Output OpenEXR file.
    #[arg(short, long)]
    pub output: PathBuf,

    /// Luminance of the white patch and the Snellen chart's paper, cd/m².
    #[arg(long, value_name = "L", allow_negative_numbers = true, value_parser = positive)]
    pub white: f64,

    /// Horizontal field of view of the scene in degrees: the viewer stands where the scene
    /// spans DEG, the image keeps its size [default: 20 ft (6.096 m), the Snellen design
    /// distance, where line 20/x tests 20/x acuity].
    #[arg(long, value_name = "DEG", allow_negative_numbers = true, value_parser = positive)]
    pub fov: Option<f64>,

    /// Leave out the square-wave gratings.
    #[arg(long)]
    pub no_gratings: bool,
}

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Directory for the panels and the contact sheet (created if missing).
    #[arg(short, long, value_name = "DIR", default_value = "visadapt-demo")]
    pub output: PathBuf,

    /// Luminances of the white patch to render, cd/m², comma-separated.
    #[arg(long, value_name = "L,...", value_delimiter = ',', allow_negative_numbers = true, value_parser = positive,
          default_values_t = [1000.0, 10.0, 0.04, 0.001])]
    pub levels: Vec<f64>,

    /// Skip the Fig. 12 light- and dark-adaptation sequences.
    #[arg(long)]
    pub no_sequences: bool,

    #[command(flatten)]
    pub adaptation: AdaptationArgs,

    #[command(flatten)]
    pub time_course: TimeCourseArgs,

    #[command(flatten)]
    pub glare: GlareArgs,
}

#[derive(Debug, Args)]
pub struct PlotArgs {
    /// The figure to draw, by name or by the paper's figure number: fig2, fig3, fig4, fig7,
    /// fig8, fig9 or fig10 (figs. 8-10 are one plot).
    #[arg(value_name = "NAME", value_parser = PlotNameParser)]
    pub name: PlotName,

    /// Output picture; the format follows the extension (.svg or .png).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// The model figures `visadapt plot` draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PlotName {
    /// Fig. 2: photopic V(λ) and scotopic V'(λ) luminous efficiency.
    #[value(name = "luminous-efficiency", alias = "fig2")]
    LuminousEfficiency,
    /// Fig. 3: cone and rod threshold-versus-intensity curves (Eq. 4, 5).
    #[value(name = "tvi", alias = "fig3")]
    Tvi,
    /// Fig. 4: spectral sensitivity at scotopic, mesopic and photopic levels.
    #[value(name = "spectral-sensitivity", alias = "fig4")]
    SpectralSensitivity,
    /// Fig. 7: highest resolvable grating frequency against luminance.
    #[value(name = "acuity", alias = "fig7")]
    Acuity,
    /// Figs. 8-10: the time course of light (rods, cones) and dark adaptation.
    #[value(name = "timecourse", aliases = ["fig8-10", "fig8", "fig9", "fig10"])]
    Timecourse,
}

/// [`PlotName`]'s parser: clap's own, except that a refused name is answered with every
/// accepted one, the short figure names included (clap lists only the long ones).
#[derive(Clone)]
struct PlotNameParser;

impl clap::builder::TypedValueParser for PlotNameParser {
    type Value = PlotName;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<PlotName, clap::Error> {
        use clap::ValueEnum;
        use clap::error::{ContextKind, ContextValue};
        clap::builder::EnumValueParser::<PlotName>::new()
            .parse_ref(cmd, arg, value)
            .map_err(|mut e| {
                let names = PlotName::value_variants()
                    .iter()
                    .filter_map(PlotName::to_possible_value)
                    .flat_map(|v| {
                        v.get_name_and_aliases()
                            .map(str::to_string)
                            .collect::<Vec<_>>()
                    })
                    .collect();
                e.insert(ContextKind::ValidValue, ContextValue::Strings(names));
                e
            })
    }

    fn possible_values(
        &self,
    ) -> Option<Box<dyn Iterator<Item = clap::builder::PossibleValue> + '_>> {
        Some(Box::new(
            <PlotName as clap::ValueEnum>::value_variants()
                .iter()
                .filter_map(clap::ValueEnum::to_possible_value),
        ))
    }
}

const VISIBLE_EXAMPLES: &str = "\
Examples:
  visadapt visible reference.exr render.exr                 # fraction visible, mean and max JND
  visadapt visible a.hdr b.hdr -o jnd.png --json            # heat map with colour bar + JSON
  visadapt visible a.hdr b.hdr --peak 0.01 --fov 40         # the same pair lit at night

JND: a difference's photopic and scotopic parts after the acuity Gaussian (Eq. 7), each in
units of its threshold (Eq. 4 cones, Eq. 5 rods weighted by k of Eq. 6), combined by
probability summation (exponent 3.5). A pixel is visibly different at 1 JND or more.
--scale and --peak rescale both images by one factor (for --peak, the reference's), and the
observer adapts to the reference (--world-adaptation overrides it).";

const TOLERANCE_EXAMPLES: &str = "\
Examples:
  visadapt tolerance render.exr -o tolerance.exr
  visadapt tolerance scene.hdr --peak 0.05 -o night-tolerance.exr --json
  visadapt tolerance render.exr --adaptation local --fov 50 -o tolerance.exr

The map holds, per pixel, the luminance threshold in cd/m² for a change of that pixel's
colour (Eq. 4-6 at the observer's adaptation): errors below it are invisible. Acuity does not
enter it; the view (--fov) sets the degrees of --glare and of --adaptation local.";

#[derive(Debug, Args)]
pub struct VisibleArgs {
    /// Reference HDR image; the observer adapts to it.
    #[arg(value_name = "REF")]
    pub reference: PathBuf,

    /// Test HDR image of the same scene, same size.
    #[arg(value_name = "TEST")]
    pub test: PathBuf,

    /// Write the JNDs: a heat map with a colour bar (.png) or the JND of every pixel as
    /// 32-bit floats, one channel Y (.exr).
    #[arg(short, long, value_name = "MAP")]
    pub output: Option<PathBuf>,

    #[command(flatten)]
    pub world: WorldAdaptationArgs,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub units: UnitsArgs,

    #[command(flatten)]
    pub viewing: ViewingArgs,

    #[command(flatten)]
    pub limits: LimitsArgs,

    /// Print the result as JSON on standard output instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct ToleranceArgs {
    /// Input HDR image (format detected from its contents).
    pub input: PathBuf,

    /// Output OpenEXR file: one channel `Y`, the tolerance in cd/m².
    #[arg(short, long, value_name = "TOL.exr")]
    pub output: PathBuf,

    #[command(flatten)]
    pub world: WorldAdaptationArgs,

    #[command(flatten)]
    pub field: FieldOfViewArgs,

    #[command(flatten)]
    pub units: UnitsArgs,

    #[command(flatten)]
    pub viewing: ViewingArgs,

    #[command(flatten)]
    pub limits: LimitsArgs,

    /// Print the summary as JSON on standard output instead of text.
    #[arg(long)]
    pub json: bool,
}

// ---- time course of adaptation (timecourse, sequence, video) ----

const TIMECOURSE_EXAMPLES: &str = "\
Examples:
  visadapt timecourse --from 0.1 --to 5623 --times 0,1,10,75      # light adaptation (Fig. 12a)
  visadapt timecourse --from 1412 --to 0.1 --times 0,60,210,1800 --json

The observer is adapted to --from cd/m² (scotopic luminance 2.261 times the photopic, equal-energy
white) and meets --to at t = 0. Thresholds follow curves fitted to the paper's Figs. 8-10.";

const SEQUENCE_EXAMPLES: &str = "\
Examples:
  visadapt sequence scene.hdr --from 0.1 --to 5623 --times 0,1,4,15,30,75 -o light/ --apng light.png
  visadapt sequence scene.hdr --from 1412 --to 0.1 --times 0,20,45,90,150,210 -o dark/
  visadapt sequence scene.hdr --from 1412 --to 0.1 --times 0,60,300,900 -o dark/ --label-time

Frame 0 (frame_000.png) shows the scene at --from, adapted; frame i the scene at --to, the i-th
time after the switch. Levels are the scene's highest visible luminance, as with map --peak.
The animation keeps the real time between frames, sped up to last --apng-seconds (6 s: Fig.
12a's 75 s play 18.75 times faster, between a 1 s hold of the first and of the last frame).";

const VIDEO_EXAMPLES: &str = "\
Examples:
  visadapt video 'render/f_%04d.exr' --fps 24 -o out/
  visadapt video 'frames/shot%d.hdr' --fps 30 --scale 179 --format exr -o mapped/ --json
  ffmpeg -i 'render/f_%04d.exr' -f rawvideo -pix_fmt gbrpf32le - |
    visadapt video - --size 1920x1080 --fps 24 --scale 100 -o - --format rgb48le |
    ffmpeg -f rawvideo -pix_fmt rgb48le -s 1920x1080 -r 24 -i - -pix_fmt yuv420p out.mp4

IN_PATTERN holds one %d or %0Nd (printf style, as ffmpeg); the frames are the files it names, in
numerical order, consecutive. The observer starts adapted to the first frame. Output frames are
OUT_DIR/<input name>.<format>, each written as soon as it is done. With - as input, frames are
raw gbrpf32le (planes G, B, R of little-endian floats, linear Rec. 709, relative: give --scale)
of --size, until the stream ends; with -o -, raw rgb48le or rgb24 frames go to standard output
and the progress and report to standard error.";

#[derive(Debug, Args)]
pub struct TimecourseArgs {
    /// Luminance the observer is adapted to before t = 0, cd/m² (0: dark-adapted, as in
    /// Figs. 8 and 9).
    #[arg(long, value_name = "L0", allow_negative_numbers = true, value_parser = non_negative)]
    pub from: f64,

    /// Luminance from t = 0 on, cd/m² (0: darkness, as in Fig. 10).
    #[arg(long, value_name = "L1", allow_negative_numbers = true, value_parser = non_negative)]
    pub to: f64,

    /// Times after the change, seconds, comma-separated, sorted.
    #[arg(long, value_name = "T1,T2,...", value_delimiter = ',', required = true)]
    #[arg(allow_hyphen_values = true, value_parser = non_negative)]
    pub times: Vec<f64>,

    #[command(flatten)]
    pub display: DisplayArgs,

    #[command(flatten)]
    pub time_course: TimeCourseArgs,

    /// Print a JSON array (one object per time) instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct SequenceArgs {
    /// Input HDR image (format detected from its contents).
    pub input: PathBuf,

    /// Highest visible luminance of the scene before the switch, cd/m².
    #[arg(long, value_name = "L0", allow_negative_numbers = true, value_parser = positive)]
    pub from: f64,

    /// Highest visible luminance after the switch, cd/m².
    #[arg(long, value_name = "L1", allow_negative_numbers = true, value_parser = positive)]
    pub to: f64,

    /// Times after the switch, seconds, comma-separated, sorted; one frame each.
    #[arg(long, value_name = "T1,T2,...", value_delimiter = ',', required = true)]
    #[arg(allow_hyphen_values = true, value_parser = non_negative)]
    pub times: Vec<f64>,

    /// Directory for the numbered PNG frames (created if missing).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,

    /// Also write all frames as one animated PNG, in the real time of the sequence sped
    /// up to play in --apng-seconds: each frame shows until the next frame's time; the
    /// first (before the switch) and the last are held for a sixth of the playback each.
    /// The speed-up is printed. (--png-compression applies to the frames; the animation
    /// is always compressed at the png crate's fast level.)
    #[arg(long, value_name = "FILE")]
    pub apng: Option<PathBuf>,

    /// Length of the animated PNG, seconds (0.1 to 60).
    #[arg(long, value_name = "S", default_value_t = 6.0, allow_negative_numbers = true, value_parser = positive)]
    pub apng_seconds: f64,

    /// Show every frame of the animated PNG for the same time, milliseconds, instead of
    /// the real time steps.
    #[arg(long, value_name = "MS", conflicts_with = "apng_seconds")]
    pub apng_delay_ms: Option<u16>,

    /// Write the light level and the time after the switch into each frame (and the
    /// animation), in a box in the top-left corner.
    #[arg(long)]
    pub label_time: bool,

    #[command(flatten)]
    pub display: DisplayArgs,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub colour: ColourArgs,

    #[command(flatten)]
    pub viewing: ViewingArgs,

    #[command(flatten)]
    pub limits: LimitsArgs,

    #[command(flatten)]
    pub png: PngArgs,

    #[command(flatten)]
    pub time_course: TimeCourseArgs,

    /// Print the list of frames as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Output format of `video` frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum VideoFormat {
    /// 8-bit sRGB PNG.
    Png,
    /// JPEG, quality 90.
    Jpg,
    /// Linear display-referred OpenEXR (1.0 = --display-max).
    Exr,
    /// Raw interleaved 16-bit little-endian sRGB, the 16-bit PNG's codes (-o - only).
    Rgb48le,
    /// Raw interleaved 8-bit sRGB, the 8-bit PNG's codes (-o - only).
    Rgb24,
}

impl VideoFormat {
    /// The raw stream format, for `-o -`; `None` for the file formats.
    pub fn raw(self) -> Option<visadapt::io::raw::RawFormat> {
        use visadapt::io::raw::RawFormat;
        match self {
            VideoFormat::Rgb48le => Some(RawFormat::Rgb48le),
            VideoFormat::Rgb24 => Some(RawFormat::Rgb24),
            VideoFormat::Png | VideoFormat::Jpg | VideoFormat::Exr => None,
        }
    }
}

/// A PNG compression level (all lossless: the same pixels; see
/// `visadapt::io::display::PngCompression`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PngLevel {
    /// Adaptive row filter, then deflate level 1 in parallel row bands (the default of
    /// map and sequence).
    Fast,
    /// Up filter, then deflate level 1 in row bands: larger files than fast.
    Fastest,
    /// Up filter, then run-length deflate in row bands: the smallest files on smooth
    /// frames, the most CPU time on textured ones.
    Rle,
    /// Adaptive row filter, then fdeflate (the png crate's fast path): the least CPU
    /// time per frame on textured and photographic frames, files about the size of rle's
    /// (the default of video).
    Fdeflate,
}

impl From<PngLevel> for visadapt::io::display::PngCompression {
    fn from(level: PngLevel) -> Self {
        match level {
            PngLevel::Fast => Self::Fast,
            PngLevel::Fastest => Self::Fastest,
            PngLevel::Rle => Self::Rle,
            PngLevel::Fdeflate => Self::Fdeflate,
        }
    }
}

/// A frame size, `WxH` (e.g. `1920x1080`).
fn frame_size(s: &str) -> Result<(u64, u64), String> {
    let bad = || format!("{s}: a frame size is WIDTHxHEIGHT, e.g. 1920x1080");
    let (w, h) = s.trim().split_once(['x', 'X']).ok_or_else(bad)?;
    let side = |v: &str| v.parse::<u64>().ok().filter(|&v| v > 0).ok_or_else(bad);
    Ok((side(w)?, side(h)?))
}

/// The library's default decoder and encoder threads for `video`.
fn default_threads() -> (std::num::NonZeroUsize, std::num::NonZeroUsize) {
    let t = visadapt::video::Threads::default();
    let n = |v: usize| std::num::NonZeroUsize::new(v).unwrap_or(std::num::NonZeroUsize::MIN);
    (n(t.decoders), n(t.encoders))
}

#[derive(Debug, Args)]
pub struct VideoArgs {
    /// Input frames: a path whose file name holds one %d or %0Nd, e.g. frames/f_%04d.exr;
    /// or - for raw gbrpf32le frames on standard input (needs --size).
    #[arg(value_name = "IN_PATTERN")]
    pub pattern: String,

    /// Frames per second of the input: the time step of the adaptation is 1/F.
    #[arg(long, value_name = "F", allow_negative_numbers = true, value_parser = positive)]
    pub fps: f64,

    /// Size of the raw frames on standard input (input -), e.g. 1920x1080.
    #[arg(long, value_name = "WxH", value_parser = frame_size)]
    pub size: Option<(u64, u64)>,

    /// Stop after N frames (the first N of the pattern or of the stream).
    #[arg(long, value_name = "N")]
    pub max_frames: Option<u64>,

    /// Output directory (created if missing), or - for raw frames on standard output
    /// (--format rgb48le or rgb24).
    #[arg(short, long, value_name = "OUT_DIR")]
    pub output: PathBuf,

    /// Format of the output frames.
    #[arg(long, value_enum, default_value_t = VideoFormat::Png)]
    pub format: VideoFormat,

    #[command(flatten)]
    pub png: PngArgs,

    /// Multiply every frame's values by S to get cd/m² (one factor for all frames, so the
    /// changes between frames are kept).
    #[arg(long, allow_negative_numbers = true, value_parser = positive, value_name = "S")]
    pub scale: Option<f64>,

    #[command(flatten)]
    pub display: DisplayArgs,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub colour: ColourArgs,

    #[command(flatten)]
    pub viewing: ViewingArgs,

    #[command(flatten)]
    pub limits: LimitsArgs,

    #[command(flatten)]
    pub time_course: TimeCourseArgs,

    /// Print one JSON object per frame (JSON Lines) on standard output as frames are written.
    #[arg(long)]
    pub json: bool,

    /// Threads decoding frames at once (files only: a stream on standard input is read by
    /// one).
    #[arg(long, value_name = "N", default_value_t = default_threads().0)]
    pub decoders: std::num::NonZeroUsize,

    /// Threads encoding and writing frames at once (each frame is still written whole and
    /// in order).
    #[arg(long, value_name = "N", default_value_t = default_threads().1)]
    pub encoders: std::num::NonZeroUsize,

    /// At the end, print on standard error the frame rate and where the time went: each
    /// stage's time per frame and how long the operator waited for frames and for encoders.
    #[arg(long)]
    pub timings: bool,
}

// ---- the viewer in the browser ----

#[cfg(feature = "serve")]
const SERVE_EXAMPLES: &str = "\
Examples:
  visadapt serve scene.hdr                      # opens http://127.0.0.1:8765/ in the browser
  visadapt serve render.exr --port 0 --no-open  # any free port; the URL is printed
  visadapt serve photo.pfm --scale 179 --fov 40
  visadapt serve night.exr --glare --adaptation local   # start with glare and local adaptation

The page maps the image as the controls move (all model work is the library's); glare and the
adaptation (global or local) switch on the page, the flags set how it starts. Its API, for
scripts: GET /api/frame?peak=L&t=S&from=L0&display_max=D&fov=F&acuity=0|1&glare=0|1&
adaptation=global|local&width=W&mode=model|exposure (PNG), /api/report?... (JSON, the keys of
map --json), /api/pixel?x=&y=&change=C&... (JSON).
Ctrl-C stops the server.";

#[cfg(feature = "serve")]
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Input HDR image (format detected from its contents).
    pub input: PathBuf,

    /// TCP port to listen on; 0 for any free port.
    #[arg(long, value_name = "P", default_value_t = 8765)]
    pub port: u16,

    /// Address to listen on. The default is loopback: only this machine can connect.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1")]
    pub host: String,

    /// Do not open the page in a web browser.
    #[arg(long)]
    pub no_open: bool,

    // --scale gives the input's units; --peak the level the page starts at.
    #[command(flatten)]
    pub units: UnitsArgs,

    // The display maximum, field of view and acuity the page starts with.
    #[command(flatten)]
    pub display: DisplayArgs,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub colour: ColourArgs,

    #[command(flatten)]
    pub viewing: ViewingArgs,

    #[command(flatten)]
    pub limits: LimitsArgs,
}
