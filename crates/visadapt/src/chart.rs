//! The paper's test scene, built in: a ColorChecker and a Snellen chart on an office wall,
//! rendered spectrally under equal-energy light.
//!
//! Ferwerda et al. 1996, Sec. 5 and Fig. 11: "an office that contains a Snellen chart, and a
//! Macbeth Colorchecker chart ... rendered ... with a spectral color model, diffuse
//! illumination that is uniform across the visible spectrum, and the standard reflectivities
//! for the Macbeth chart". The scene here is flat (a wall facing the viewer), which keeps
//! every size exact:
//!
//! * **ColorChecker**: the 24 patches (N. Ohta's reflectances, [`spectral`]), 40 mm square
//!   with 6 mm gaps on a black card (282 × 190 mm, close to the ColorChecker Classic's
//!   279 × 216 mm).
//! * **Snellen chart**: Sloan's optotypes ([`sloan`]: a square of 5 stroke widths, round
//!   strokes where the letters are round; a letter of line 20/x is 5·x/20 arcminutes tall
//!   at the design distance of 20 ft = 6.096 m, its strokes a fifth of that), lines 20/200
//!   to 20/10 ([`SNELLEN_LINES`]), black ink (the ColorChecker's "black 2") on white paper
//!   ("white 9.5").
//! * **Gratings** (optional): square-wave gratings of 2 to 32 cycles/degree at the design
//!   distance ([`GRATING_CYCLES_PER_DEGREE`]), the stimulus of Shaler's acuity data (Fig. 7).
//! * **Wall**: the reflectance of the ColorChecker's "neutral 5".
//!
//! Every surface reflects the equal-energy illuminant E; radiance is integrated at 5 nm to
//! CIE X, Y, Z (cd/m²) and scotopic luminance (scotopic cd/m², K'm = 1700 lm/W), scaled so
//! that the white patch (and the paper) has luminance `white_cd_m2`. Edges are area-sampled:
//! the rectangles (patches, paper, gratings) exactly, each pixel getting the fraction of its
//! area each surface covers; the letters to 1/256 of a pixel ([`sloan::SAMPLES`]), exactly
//! where their straight edges fall on pixel boundaries.
//!
//! # Geometry
//!
//! The viewer stands `viewing_distance_m` from the wall and looks at the scene's centre
//! through a perspective camera of `pixels_per_degree` at the centre. A flat wall facing a
//! perspective camera maps millimetres to pixels linearly, so "degrees" below are angles at
//! the centre of view: one degree is `distance·π/180` on the wall. The [`HdrImage::view`] is
//! the matching perspective view, so the operator's acuity blur uses the same scale.
//!
//! Line letters are placed on whole pixels (their origins are rounded), which keeps the
//! strokes of the 20/20 (2 px) and 20/10 (1 px) lines pixel-aligned at the default
//! 120 pixels/degree.

use crate::colour::{REC709, mul_vec};
use crate::spectral::{self, EQUAL_ENERGY, Photometry, integrate, reflected};
use crate::{DisplayImage, Error, HdrImage, Result, View};
use std::f64::consts::PI;

pub mod sloan;
pub use sloan::Optotype;

/// The distance for which a Snellen chart is designed: 20 feet, in metres (Snellen 1862; the
/// "20" of "20/20").
pub const SNELLEN_DESIGN_DISTANCE_M: f64 = 6.096;

/// Default resolution: 120 pixels per degree, so that the 20/10 line's strokes (0.5 arcmin)
/// are one pixel wide and a 60 cycles/degree grating is at the Nyquist limit (a project
/// choice).
pub const DEFAULT_PIXELS_PER_DEGREE: f64 = 120.0;

/// The Snellen lines drawn, as the denominators `x` of "20/x" (the usual clinical series).
pub const SNELLEN_LINES: [u32; 10] = [200, 100, 70, 50, 40, 30, 25, 20, 15, 10];

/// Letters of each line (Sloan's ten letters C D H K N O R S V Z, with the traditional E on
/// top), in the order of [`SNELLEN_LINES`].
const LINE_LETTERS: [&str; 10] = [
    "E", "DK", "NRS", "HVZO", "CKDNR", "ZSHOVK", "RDNCZHS", "OKVHDNSC", "NZRKCODH", "VSHZDKNO",
];

/// Frequencies of the square-wave gratings at the design distance, cycles/degree.
pub const GRATING_CYCLES_PER_DEGREE: [f64; 5] = [2.0, 4.0, 8.0, 16.0, 32.0];

/// Height of a 20/20 letter at the design distance: 5 arcminutes (Snellen 1862).
pub const SNELLEN_20_20_LETTER_ARCMIN: f64 = 5.0;

/// Index of the white patch ("white 9.5 (.05 D)") in ColorChecker order.
pub const WHITE_PATCH: usize = 18;
/// Index of the black patch ("black 2 (1.5 D)") in ColorChecker order.
pub const BLACK_PATCH: usize = 23;
/// Index of the blue patch in ColorChecker order.
pub const BLUE_PATCH: usize = 12;
/// Index of the green patch in ColorChecker order.
pub const GREEN_PATCH: usize = 13;
/// Index of the red patch in ColorChecker order.
pub const RED_PATCH: usize = 14;
/// The wall's reflectance: "neutral 5 (.70 D)" (a project choice: a mid-grey office wall).
const WALL_PATCH: usize = 21;

// Layout on the wall, millimetres (project choices, see the module docs).
const MARGIN_MM: f64 = 60.0;
const PATCH_MM: f64 = 40.0;
const PATCH_GAP_MM: f64 = 6.0;
const PAPER_MARGIN_MM: f64 = 20.0;
const COLUMN_GAP_MM: f64 = 60.0;
const GRATING_ROW_GAP_MM: f64 = 50.0;
/// Grating squares are 1 degree (at the design distance) on a side, 0.15 degree apart.
const GRATING_SIZE_DEG: f64 = 1.0;
const GRATING_GAP_DEG: f64 = 0.15;

/// How the chart is lit, seen and sampled.
#[derive(Debug, Clone, PartialEq)]
pub struct ChartOptions {
    /// Luminance of the white patch and the Snellen paper, cd/m².
    pub white_cd_m2: f64,
    /// Distance from the viewer to the wall, metres (default: the Snellen design distance,
    /// where line 20/x tests 20/x acuity).
    pub viewing_distance_m: f64,
    /// Pixels per degree at the centre of view (default 120).
    pub pixels_per_degree: f64,
    /// Draw the square-wave gratings.
    pub gratings: bool,
}

impl Default for ChartOptions {
    fn default() -> Self {
        ChartOptions {
            white_cd_m2: 100.0,
            viewing_distance_m: SNELLEN_DESIGN_DISTANCE_M,
            pixels_per_degree: DEFAULT_PIXELS_PER_DEGREE,
            gratings: true,
        }
    }
}

impl ChartOptions {
    /// Options with the white at `white_cd_m2` and the viewer placed so that the whole
    /// scene spans `fov_deg` horizontally, with the pixel width of the default chart (the
    /// same picture, seen from nearer or farther away).
    pub fn with_fov(white_cd_m2: f64, fov_deg: f64, gratings: bool) -> Result<Self> {
        if !(fov_deg.is_finite() && fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(Error::invalid(
                "fov",
                fov_deg,
                "must be in (0, 180) degrees",
            ));
        }
        let defaults = ChartOptions {
            gratings,
            ..ChartOptions::default()
        };
        let (width_mm, _) = scene_size_mm(gratings);
        let width_px = (width_mm * px_per_mm(&defaults)).round();
        let half = (fov_deg / 2.0).to_radians().tan();
        Ok(ChartOptions {
            white_cd_m2,
            viewing_distance_m: width_mm / 1000.0 / (2.0 * half),
            pixels_per_degree: (width_px / 2.0) / half * PI / 180.0,
            gratings,
        })
    }

    /// Check every parameter's domain.
    pub fn validate(&self) -> Result<()> {
        let positive = |name, v: f64| crate::check_luminance(name, v).map(|_| ());
        positive("white", self.white_cd_m2)?;
        positive("distance", self.viewing_distance_m)?;
        positive("pixels-per-degree", self.pixels_per_degree)?;
        let (w, h) = scene_size_mm(self.gratings);
        let s = px_per_mm(self);
        if w * s > 16384.0 || h * s > 16384.0 || (w * s).round() < 1.0 || (h * s).round() < 1.0 {
            return Err(Error::invalid(
                "pixels-per-degree",
                self.pixels_per_degree,
                format!(
                    "makes a chart of {:.0}x{:.0} pixels (1 to 16384 per side)",
                    w * s,
                    h * s
                ),
            ));
        }
        Ok(())
    }
}

/// Pixels per millimetre on the wall: the focal length in pixels over the distance.
fn px_per_mm(o: &ChartOptions) -> f64 {
    o.pixels_per_degree * 180.0 / PI / (o.viewing_distance_m * 1000.0)
}

/// Millimetres on the wall per degree at the centre of view, at the design distance.
fn design_mm_per_degree() -> f64 {
    SNELLEN_DESIGN_DISTANCE_M * 1000.0 * PI / 180.0
}

/// Letter height of line 20/x, mm (sized for the design distance).
fn letter_mm(denominator: u32) -> f64 {
    SNELLEN_20_20_LETTER_ARCMIN * denominator as f64 / 20.0 / 60.0 * design_mm_per_degree()
}

/// Vertical space after a line of letters of height `h` mm.
fn line_gap_mm(h: f64) -> f64 {
    0.5 * h + 4.0
}

fn checker_size_mm() -> (f64, f64) {
    (
        6.0 * PATCH_MM + 7.0 * PATCH_GAP_MM,
        4.0 * PATCH_MM + 5.0 * PATCH_GAP_MM,
    )
}

fn paper_size_mm() -> (f64, f64) {
    let width = SNELLEN_LINES
        .iter()
        .zip(LINE_LETTERS)
        .map(|(&d, s)| (2 * s.len() - 1) as f64 * letter_mm(d))
        .fold(0.0, f64::max);
    let height: f64 = SNELLEN_LINES.iter().map(|&d| letter_mm(d)).sum::<f64>()
        + SNELLEN_LINES[..SNELLEN_LINES.len() - 1]
            .iter()
            .map(|&d| line_gap_mm(letter_mm(d)))
            .sum::<f64>();
    (
        width + 2.0 * PAPER_MARGIN_MM,
        height + 2.0 * PAPER_MARGIN_MM,
    )
}

fn grating_row_mm() -> (f64, f64) {
    let n = GRATING_CYCLES_PER_DEGREE.len() as f64;
    let size = GRATING_SIZE_DEG * design_mm_per_degree();
    let gap = GRATING_GAP_DEG * design_mm_per_degree();
    (n * size + (n - 1.0) * gap, size)
}

/// Width and height of the scene on the wall, mm.
fn scene_size_mm(gratings: bool) -> (f64, f64) {
    let (cw, ch) = checker_size_mm();
    let (pw, ph) = paper_size_mm();
    let (gw, gh) = grating_row_mm();
    let mut w = cw + COLUMN_GAP_MM + pw;
    let mut h = ch.max(ph);
    if gratings {
        w = w.max(gw);
        h += GRATING_ROW_GAP_MM + gh;
    }
    (w + 2.0 * MARGIN_MM, h + 2.0 * MARGIN_MM)
}

/// An axis-aligned rectangle in pixel coordinates (x right, y down; pixel `(i, j)` covers
/// `[i, i+1] × [j, j+1]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    /// Left edge, pixels.
    pub x0: f64,
    /// Top edge, pixels.
    pub y0: f64,
    /// Right edge, pixels.
    pub x1: f64,
    /// Bottom edge, pixels.
    pub y1: f64,
}

impl Rect {
    /// The middle part of the rectangle, `fraction` of its width and height.
    pub fn centre(&self, fraction: f64) -> Rect {
        let (cx, cy) = ((self.x0 + self.x1) / 2.0, (self.y0 + self.y1) / 2.0);
        let (hw, hh) = (
            (self.x1 - self.x0) * fraction / 2.0,
            (self.y1 - self.y0) * fraction / 2.0,
        );
        Rect {
            x0: cx - hw,
            y0: cy - hh,
            x1: cx + hw,
            y1: cy + hh,
        }
    }

    fn scaled(x0: f64, y0: f64, x1: f64, y1: f64, s: f64) -> Rect {
        Rect {
            x0: x0 * s,
            y0: y0 * s,
            x1: x1 * s,
            y1: y1 * s,
        }
    }
}

/// A ColorChecker patch in the image.
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    /// Index in chart order (0 = dark skin … 23 = black).
    pub index: usize,
    /// Name (colour-science's spelling).
    pub name: &'static str,
    /// Where it is, pixels.
    pub rect: Rect,
    /// Its photometry in the rendered scene (cd/m², scotopic cd/m²).
    pub photometry: Photometry,
}

/// A grid cell counts as ink (or paper) in stroke contrasts when at least this fraction of
/// it is ink (or paper): a project choice, so that the cells a curve or a slanted stroke
/// crosses do not mix ink and paper into either reading.
pub const SOLID_CELL: f64 = 0.9;

/// One letter of the Snellen chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Letter {
    /// The letter.
    pub letter: char,
    /// Top-left corner of its 5 × 5 grid, pixels.
    pub x: f64,
    /// Top-left corner of its 5 × 5 grid, pixels.
    pub y: f64,
    /// Side of one grid cell (the stroke width), pixels.
    pub cell_px: f64,
}

impl Letter {
    /// The fraction of grid cell (`row`, `col`) that is ink ([`sloan`]: 0 or 1 for the cells
    /// of the bars, between for those a curve or a slanted stroke crosses).
    pub fn cell_coverage(&self, row: usize, col: usize) -> f64 {
        Optotype::new(self.letter).map_or(0.0, |o| o.coverage(col, row, 0.0, 0.0, 1.0))
    }

    /// Whether grid cell (`row`, `col`) is ink: at least [`SOLID_CELL`] of it.
    pub fn is_ink(&self, row: usize, col: usize) -> bool {
        self.cell_coverage(row, col) >= SOLID_CELL
    }

    /// Whether grid cell (`row`, `col`) is paper: at most `1 −` [`SOLID_CELL`] of it ink.
    /// Cells neither ink nor paper (crossed by an edge) are left out of stroke contrasts.
    pub fn is_paper(&self, row: usize, col: usize) -> bool {
        self.cell_coverage(row, col) <= 1.0 - SOLID_CELL
    }

    /// The fraction of pixel (`i`, `j`) the letter's ink covers ([`sloan`]).
    pub fn coverage(&self, i: usize, j: usize) -> f64 {
        Optotype::new(self.letter).map_or(0.0, |o| o.coverage(i, j, self.x, self.y, self.cell_px))
    }

    /// The rectangle of grid cell (`row`, `col`).
    pub fn cell(&self, row: usize, col: usize) -> Rect {
        Rect {
            x0: self.x + col as f64 * self.cell_px,
            y0: self.y + row as f64 * self.cell_px,
            x1: self.x + (col + 1) as f64 * self.cell_px,
            y1: self.y + (row + 1) as f64 * self.cell_px,
        }
    }

    /// The whole letter's box.
    pub fn rect(&self) -> Rect {
        Rect {
            x0: self.x,
            y0: self.y,
            x1: self.x + 5.0 * self.cell_px,
            y1: self.y + 5.0 * self.cell_px,
        }
    }
}

/// One line of the Snellen chart.
#[derive(Debug, Clone, PartialEq)]
pub struct SnellenLine {
    /// The `x` of "20/x": the acuity the line tests at the design distance.
    pub denominator: u32,
    /// Stroke width at the actual viewing distance, arcminutes.
    pub stroke_arcmin: f64,
    /// The letters.
    pub letters: Vec<Letter>,
    /// Clear paper between this line and the line (or paper edge) above, pixels.
    pub space_above_px: f64,
    /// Clear paper between this line and the line (or paper edge) below, pixels.
    pub space_below_px: f64,
}

impl SnellenLine {
    /// The grating frequency whose half-period is one stroke, at the actual viewing
    /// distance, cycles/degree (30 for the 20/20 line at the design distance).
    pub fn stroke_cycles_per_degree(&self) -> f64 {
        30.0 / self.stroke_arcmin
    }

    /// The acuity this line tests at the actual viewing distance, as "20/x".
    pub fn effective_snellen(&self) -> String {
        crate::acuity::snellen(self.stroke_cycles_per_degree())
    }
}

/// A square-wave grating: black bars on white, varying along x.
#[derive(Debug, Clone, PartialEq)]
pub struct Grating {
    /// Frequency at the design distance, cycles/degree.
    pub design_cycles_per_degree: f64,
    /// Frequency at the actual viewing distance, cycles/degree.
    pub cycles_per_degree: f64,
    /// Period, pixels.
    pub period_px: f64,
    /// The grating's extent (a whole number of periods wide), pixels.
    pub rect: Rect,
}

/// Where everything is in the chart image.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// The 24 ColorChecker patches, chart order.
    pub patches: Vec<Patch>,
    /// The Snellen chart's paper.
    pub paper: Rect,
    /// The Snellen lines, largest first.
    pub lines: Vec<SnellenLine>,
    /// The gratings (empty when not drawn), lowest frequency first.
    pub gratings: Vec<Grating>,
    /// Pixels per degree at the centre of view.
    pub pixels_per_degree: f64,
    /// Viewing distance, metres.
    pub viewing_distance_m: f64,
}

/// The rendered scene and its layout.
#[derive(Debug, Clone)]
pub struct Chart {
    /// X, Y, Z in cd/m² and the scotopic channel, absolute units, with its view.
    pub image: HdrImage,
    /// Where the patches, letters and gratings are.
    pub layout: Layout,
    /// The options it was made with.
    pub options: ChartOptions,
}

/// A planar XYZ + scotopic canvas that surfaces are painted onto with exact area coverage.
struct Canvas {
    width: usize,
    height: usize,
    planes: [Vec<f64>; 4],
}

impl Canvas {
    /// Paint `material` over the union of `rects` (which must not overlap each other):
    /// each pixel becomes `(1 − c)·old + c·material` with `c` the covered fraction of its area.
    fn paint(&mut self, rects: &[Rect], material: &Photometry) {
        let clamp_x = |v: f64| v.clamp(0.0, self.width as f64);
        let clamp_y = |v: f64| v.clamp(0.0, self.height as f64);
        let (mut bx0, mut by0, mut bx1, mut by1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for r in rects {
            bx0 = bx0.min(clamp_x(r.x0));
            by0 = by0.min(clamp_y(r.y0));
            bx1 = bx1.max(clamp_x(r.x1));
            by1 = by1.max(clamp_y(r.y1));
        }
        if rects.is_empty() || bx1 <= bx0 || by1 <= by0 {
            return;
        }
        let (i0, j0) = (bx0.floor() as usize, by0.floor() as usize);
        let (i1, j1) = (bx1.ceil() as usize, by1.ceil() as usize);
        let w = i1 - i0;
        let mut coverage = vec![0.0f64; w * (j1 - j0)];
        for r in rects {
            let (ri0, rj0) = (
                clamp_x(r.x0).floor() as usize,
                clamp_y(r.y0).floor() as usize,
            );
            let (ri1, rj1) = (clamp_x(r.x1).ceil() as usize, clamp_y(r.y1).ceil() as usize);
            for j in rj0..rj1 {
                let oy = overlap(j as f64, r.y0, r.y1);
                for i in ri0..ri1 {
                    coverage[(j - j0) * w + (i - i0)] += oy * overlap(i as f64, r.x0, r.x1);
                }
            }
        }
        let m = [material.x, material.y, material.z, material.scotopic];
        for j in j0..j1 {
            for i in i0..i1 {
                let c = coverage[(j - j0) * w + (i - i0)].min(1.0);
                if c > 0.0 {
                    let p = j * self.width + i;
                    for (plane, m) in self.planes.iter_mut().zip(m) {
                        plane[p] = (1.0 - c) * plane[p] + c * m;
                    }
                }
            }
        }
    }
}

impl Canvas {
    /// Paint `material` over the pixels of `bounds` in the fractions `coverage(i, j)`.
    fn paint_coverage(
        &mut self,
        bounds: &Rect,
        material: &Photometry,
        coverage: impl Fn(usize, usize) -> f64,
    ) {
        let (i0, j0) = (
            bounds.x0.max(0.0).floor() as usize,
            bounds.y0.max(0.0).floor() as usize,
        );
        let i1 = (bounds.x1.max(0.0).ceil() as usize).min(self.width);
        let j1 = (bounds.y1.max(0.0).ceil() as usize).min(self.height);
        let m = [material.x, material.y, material.z, material.scotopic];
        for j in j0..j1 {
            for i in i0..i1 {
                let c = coverage(i, j).min(1.0);
                if c > 0.0 {
                    let p = j * self.width + i;
                    for (plane, m) in self.planes.iter_mut().zip(m) {
                        plane[p] = (1.0 - c) * plane[p] + c * m;
                    }
                }
            }
        }
    }
}

/// Length of `[a, b]` inside the pixel `[i, i + 1]`.
fn overlap(i: f64, a: f64, b: f64) -> f64 {
    ((i + 1.0).min(b) - i.max(a)).max(0.0)
}

impl Chart {
    /// Render the scene (see the module docs).
    pub fn new(options: &ChartOptions) -> Result<Chart> {
        options.validate()?;
        let s = px_per_mm(options);
        let (scene_w, scene_h) = scene_size_mm(options.gratings);
        let (width, height) = (
            (scene_w * s).round() as usize,
            (scene_h * s).round() as usize,
        );
        let mut canvas = Canvas {
            width,
            height,
            planes: std::array::from_fn(|_| vec![0.0; width * height]),
        };

        // Materials: ColorChecker reflectances under E, the white patch at white_cd_m2.
        let raw = |i: usize| integrate(&reflected(&EQUAL_ENERGY, spectral::colorchecker(i)));
        let norm = options.white_cd_m2 / raw(WHITE_PATCH).y;
        let material = |i: usize| raw(i).scaled(norm);
        let (paper, ink) = (material(WHITE_PATCH), material(BLACK_PATCH));

        let full = Rect {
            x0: 0.0,
            y0: 0.0,
            x1: width as f64,
            y1: height as f64,
        };
        canvas.paint(&[full], &material(WALL_PATCH));

        // The ColorChecker: a black card with the 24 patches.
        let (cw, ch) = checker_size_mm();
        let (pw, ph) = paper_size_mm();
        let top = MARGIN_MM;
        let left = (scene_w - (cw + COLUMN_GAP_MM + pw)) / 2.0;
        canvas.paint(&[Rect::scaled(left, top, left + cw, top + ch, s)], &ink);
        let mut patches = Vec::with_capacity(24);
        for index in 0..24 {
            let (row, col) = ((index / 6) as f64, (index % 6) as f64);
            let x0 = left + PATCH_GAP_MM + col * (PATCH_MM + PATCH_GAP_MM);
            let y0 = top + PATCH_GAP_MM + row * (PATCH_MM + PATCH_GAP_MM);
            let rect = Rect::scaled(x0, y0, x0 + PATCH_MM, y0 + PATCH_MM, s);
            let photometry = material(index);
            canvas.paint(&[rect], &photometry);
            patches.push(Patch {
                index,
                name: spectral::tables::COLORCHECKER_NAMES[index],
                rect,
                photometry,
            });
        }

        // The Snellen chart.
        let px0 = left + cw + COLUMN_GAP_MM;
        let paper_rect = Rect::scaled(px0, top, px0 + pw, top + ph, s);
        canvas.paint(&[paper_rect], &paper);
        let arcmin_per_mm = 60.0 / (options.viewing_distance_m * 1000.0 * PI / 180.0);
        let mut lines = Vec::with_capacity(SNELLEN_LINES.len());
        let mut y_mm = top + PAPER_MARGIN_MM;
        let mut space_above = PAPER_MARGIN_MM;
        for (&denominator, text) in SNELLEN_LINES.iter().zip(LINE_LETTERS) {
            let h = letter_mm(denominator);
            let n = text.len() as f64;
            let x_start = px0 + (pw - (2.0 * n - 1.0) * h) / 2.0;
            let cell_px = h * s / 5.0;
            let letters: Vec<Letter> = text
                .chars()
                .enumerate()
                .map(|(k, letter)| Letter {
                    letter,
                    x: ((x_start + 2.0 * k as f64 * h) * s).round(),
                    y: (y_mm * s).round(),
                    cell_px,
                })
                .collect();
            for l in &letters {
                let optotype = Optotype::new(l.letter).expect("the chart's letters are Sloan's");
                canvas.paint_coverage(&l.rect(), &ink, |i, j| {
                    optotype.coverage(i, j, l.x, l.y, l.cell_px)
                });
            }
            let last = lines.len() + 1 == SNELLEN_LINES.len();
            lines.push(SnellenLine {
                denominator,
                stroke_arcmin: h / 5.0 * arcmin_per_mm,
                letters,
                space_above_px: space_above * s,
                space_below_px: if last {
                    PAPER_MARGIN_MM
                } else {
                    line_gap_mm(h)
                } * s,
            });
            space_above = line_gap_mm(h);
            y_mm += h + space_above;
        }

        // The gratings, centred in a row below.
        let mut gratings = Vec::new();
        if options.gratings {
            let (gw, gh) = grating_row_mm();
            let size = GRATING_SIZE_DEG * design_mm_per_degree();
            let gap = GRATING_GAP_DEG * design_mm_per_degree();
            let gy = top + ch.max(ph) + GRATING_ROW_GAP_MM;
            let gx = (scene_w - gw) / 2.0;
            for (k, &f) in GRATING_CYCLES_PER_DEGREE.iter().enumerate() {
                let x0 = gx + k as f64 * (size + gap);
                canvas.paint(&[Rect::scaled(x0, gy, x0 + size, gy + gh, s)], &paper);
                let period_mm = design_mm_per_degree() / f;
                let periods = (size / period_mm + 1e-9).floor();
                let bx0 = x0 + (size - periods * period_mm) / 2.0;
                let bars: Vec<Rect> = (0..periods as usize)
                    .map(|b| {
                        let a = bx0 + b as f64 * period_mm;
                        Rect::scaled(a, gy, a + period_mm / 2.0, gy + gh, s)
                    })
                    .collect();
                canvas.paint(&bars, &ink);
                gratings.push(Grating {
                    design_cycles_per_degree: f,
                    cycles_per_degree: f * options.viewing_distance_m / SNELLEN_DESIGN_DISTANCE_M,
                    period_px: period_mm * s,
                    rect: Rect::scaled(bx0, gy, bx0 + periods * period_mm, gy + gh, s),
                });
            }
        }

        let ppd = options.pixels_per_degree;
        let focal_px = ppd * 180.0 / PI;
        let fov_deg = 2.0 * (width as f64 / 2.0 / focal_px).atan().to_degrees();
        let [x, y, z, v] = canvas
            .planes
            .map(|p| p.into_iter().map(|v| v as f32).collect());
        let image = HdrImage {
            width,
            height,
            x,
            y,
            z,
            scotopic: Some(v),
            view: Some(View::perspective(fov_deg, width, height)),
            absolute_units: true,
            // The chart is lit by the paper's equal-energy illuminant (Sec. 5).
            adopted_white: Some(crate::colour::EQUAL_ENERGY),
        };
        Ok(Chart {
            image,
            layout: Layout {
                patches,
                paper: paper_rect,
                lines,
                gratings,
                pixels_per_degree: ppd,
                viewing_distance_m: options.viewing_distance_m,
            },
            options: options.clone(),
        })
    }

    /// Measure the rendered chart in a display image of the same size (the operator's output
    /// for [`Chart::image`]): patch colours, letter and grating contrasts.
    pub fn read(&self, display: &DisplayImage) -> Result<Readings> {
        Readings::measure(&self.layout, display, self.image.width, self.image.height)
    }
}

/// The display's luminance and colour at the places of the chart.
///
/// Display luminances are in cd/m² (linear display value × `L_dmax`, Rec. 709 luminance
/// weights). Colours are CIELAB (CIE 15:2004) relative to the *displayed white patch*: the
/// reference white has that patch's chromaticity and the display maximum's luminance, so a
/// neutral patch has zero chroma at every level even though the scene's equal-energy white
/// is shown slightly warm on a D65 display, and lightness is relative to `L_dmax`.
#[derive(Debug, Clone, PartialEq)]
pub struct Readings {
    /// Mean display luminance of the whole image, cd/m².
    pub mean_luminance_cd_m2: f64,
    /// One per ColorChecker patch, chart order: the middle half of the patch.
    pub patches: Vec<PatchReading>,
    /// One per Snellen line, largest first.
    pub lines: Vec<LineReading>,
    /// One per grating.
    pub gratings: Vec<GratingReading>,
}

/// A patch's displayed colour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PatchReading {
    /// Display luminance, cd/m².
    pub luminance_cd_m2: f64,
    /// CIELAB L*, a*, b* (see [`Readings`]).
    pub lab: [f64; 3],
}

impl PatchReading {
    /// CIELAB chroma C*ab.
    pub fn chroma(&self) -> f64 {
        self.lab[1].hypot(self.lab[2])
    }
}

/// Contrast of a Snellen line's strokes on the display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineReading {
    /// The `x` of "20/x".
    pub denominator: u32,
    /// Mean display luminance at the centres of the paper cells inside the letters, cd/m².
    pub paper_cd_m2: f64,
    /// Mean display luminance at the centres of the ink cells, cd/m².
    pub ink_cd_m2: f64,
    /// Mean display luminance over the letters' boxes, cd/m².
    pub letter_box_cd_m2: f64,
    /// Mean display luminance of the paper around the line (a band one letter high above
    /// and below it, clear of the letters), cd/m².
    pub surround_cd_m2: f64,
}

impl LineReading {
    /// Michelson contrast of the strokes, `(paper − ink)/(paper + ink)` at the cell centres:
    /// about 0.93 in the scene, 0 when the letters are blurred to uniform blobs.
    pub fn stroke_contrast(&self) -> f64 {
        michelson(self.paper_cd_m2, self.ink_cd_m2)
    }

    /// Michelson contrast of the letters as blobs against the surrounding paper.
    pub fn form_contrast(&self) -> f64 {
        michelson(self.surround_cd_m2, self.letter_box_cd_m2)
    }
}

/// Contrast of a grating on the display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GratingReading {
    /// Frequency at the viewing distance, cycles/degree.
    pub cycles_per_degree: f64,
    /// Highest column mean in the middle of the grating, cd/m².
    pub max_cd_m2: f64,
    /// Lowest column mean in the middle of the grating, cd/m².
    pub min_cd_m2: f64,
}

impl GratingReading {
    /// Michelson contrast `(max − min)/(max + min)`.
    pub fn contrast(&self) -> f64 {
        michelson(self.max_cd_m2, self.min_cd_m2)
    }
}

fn michelson(a: f64, b: f64) -> f64 {
    if a + b > 0.0 { (a - b) / (a + b) } else { 0.0 }
}

/// The mean of a plane over a rectangle, each pixel weighted by the area it shares with it.
fn box_mean(plane: &[f64], width: usize, height: usize, r: &Rect) -> f64 {
    let (i0, j0) = (
        r.x0.max(0.0).floor() as usize,
        r.y0.max(0.0).floor() as usize,
    );
    let (i1, j1) = (
        (r.x1.ceil().max(0.0) as usize).min(width),
        (r.y1.ceil().max(0.0) as usize).min(height),
    );
    let (mut sum, mut weight) = (0.0, 0.0);
    for j in j0..j1 {
        let oy = overlap(j as f64, r.y0, r.y1);
        for i in i0..i1 {
            let w = oy * overlap(i as f64, r.x0, r.x1);
            sum += w * plane[j * width + i];
            weight += w;
        }
    }
    if weight > 0.0 { sum / weight } else { f64::NAN }
}

impl Readings {
    fn measure(layout: &Layout, d: &DisplayImage, width: usize, height: usize) -> Result<Self> {
        if d.width != width || d.height != height || d.len() != d.r.len() {
            return Err(Error::invalid(
                "display image",
                format!("{}x{}", d.width, d.height),
                format!("must be the chart's size, {width}x{height}"),
            ));
        }
        let m = REC709.rgb_to_xyz().expect("Rec.709 primaries are valid");
        let dmax = d.display_max_cd_m2 as f64;
        // Display XYZ planes relative to L_dmax.
        let xyz: [Vec<f64>; 3] = std::array::from_fn(|c| {
            (0..d.len())
                .map(|i| {
                    m[c][0] * d.r[i] as f64 + m[c][1] * d.g[i] as f64 + m[c][2] * d.b[i] as f64
                })
                .collect()
        });
        let lum: Vec<f64> = xyz[1].iter().map(|v| v * dmax).collect();
        let mean_luminance_cd_m2 = lum.iter().sum::<f64>() / lum.len() as f64;
        let patch_xyz = |r: &Rect| -> [f64; 3] {
            let c = r.centre(0.5);
            std::array::from_fn(|k| box_mean(&xyz[k], width, height, &c))
        };
        let white = patch_xyz(&layout.patches[WHITE_PATCH].rect);
        // Reference white: the displayed white patch's chromaticity at Y = 1 (L_dmax); the
        // display white if that patch is black.
        let reference = if white[1] > 0.0 {
            [white[0] / white[1], 1.0, white[2] / white[1]]
        } else {
            mul_vec(&m, [1.0, 1.0, 1.0])
        };
        let patches = layout
            .patches
            .iter()
            .map(|p| {
                let v = patch_xyz(&p.rect);
                PatchReading {
                    luminance_cd_m2: v[1] * dmax,
                    lab: lab(v, reference),
                }
            })
            .collect();

        let lines = layout
            .lines
            .iter()
            .map(|line| {
                let (mut ink, mut n_ink, mut paper, mut n_paper) = (0.0, 0, 0.0, 0);
                let (mut boxes, mut surround) = (0.0, 0.0);
                for l in &line.letters {
                    // Sample one pixel's area centred on each cell centre.
                    let half = 0.5;
                    for row in 0..5 {
                        for col in 0..5 {
                            let c = l.cell(row, col);
                            let (cx, cy) = ((c.x0 + c.x1) / 2.0, (c.y0 + c.y1) / 2.0);
                            let r = Rect {
                                x0: cx - half,
                                y0: cy - half,
                                x1: cx + half,
                                y1: cy + half,
                            };
                            let v = box_mean(&lum, width, height, &r);
                            if l.is_ink(row, col) {
                                ink += v;
                                n_ink += 1;
                            } else if l.is_paper(row, col) {
                                paper += v;
                                n_paper += 1;
                            }
                        }
                    }
                    let b = l.rect();
                    boxes += box_mean(&lum, width, height, &b);
                    // Clear paper above and below the letter: the middle half of the space
                    // between this line and its neighbours (or the paper's edge).
                    let (a, b_) = (line.space_above_px, line.space_below_px);
                    let above = Rect {
                        y0: b.y0 - 0.75 * a,
                        y1: b.y0 - 0.25 * a,
                        ..b
                    };
                    let below = Rect {
                        y0: b.y1 + 0.25 * b_,
                        y1: b.y1 + 0.75 * b_,
                        ..b
                    };
                    surround += 0.5
                        * (box_mean(&lum, width, height, &above)
                            + box_mean(&lum, width, height, &below));
                }
                let n = line.letters.len() as f64;
                LineReading {
                    denominator: line.denominator,
                    paper_cd_m2: paper / n_paper as f64,
                    ink_cd_m2: ink / n_ink as f64,
                    letter_box_cd_m2: boxes / n,
                    surround_cd_m2: surround / n,
                }
            })
            .collect();

        let gratings = layout
            .gratings
            .iter()
            .map(|g| {
                let c = g.rect.centre(0.5);
                let (i0, i1) = (c.x0.floor() as usize, c.x1.ceil() as usize);
                let (mut hi, mut lo) = (f64::MIN, f64::MAX);
                for i in i0..i1 {
                    let col = Rect {
                        x0: i as f64,
                        x1: i as f64 + 1.0,
                        ..c
                    };
                    let v = box_mean(&lum, width, height, &col);
                    hi = hi.max(v);
                    lo = lo.min(v);
                }
                GratingReading {
                    cycles_per_degree: g.cycles_per_degree,
                    max_cd_m2: hi,
                    min_cd_m2: lo,
                }
            })
            .collect();
        Ok(Readings {
            mean_luminance_cd_m2,
            patches,
            lines,
            gratings,
        })
    }
}

/// CIELAB (CIE 15:2004 §8.2.1) of `xyz` relative to the reference white `n`.
fn lab(xyz: [f64; 3], n: [f64; 3]) -> [f64; 3] {
    let f = |t: f64| {
        let d: f64 = 6.0 / 29.0;
        if t > d * d * d {
            t.cbrt()
        } else {
            t / (3.0 * d * d) + 4.0 / 29.0
        }
    };
    let (fx, fy, fz) = (f(xyz[0] / n[0]), f(xyz[1] / n[1]), f(xyz[2] / n[2]));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart() -> Chart {
        Chart::new(&ChartOptions {
            white_cd_m2: 10.0,
            ..ChartOptions::default()
        })
        .unwrap()
    }

    fn mean(plane: &[f32], c: &Chart, r: &Rect) -> f64 {
        let p: Vec<f64> = plane.iter().map(|&v| v as f64).collect();
        box_mean(&p, c.image.width, c.image.height, &r.centre(0.5))
    }

    #[test]
    fn white_patch_and_paper_have_the_stated_luminance() {
        let c = chart();
        let white = &c.layout.patches[WHITE_PATCH];
        assert!((mean(&c.image.y, &c, &white.rect) - 10.0).abs() < 1e-4);
        assert!((mean(&c.image.y, &c, &c.layout.paper.centre(0.02)) - 10.0).abs() < 1e-4);
        // The scene's highest visible luminance is the white (nothing brighter).
        let max = c.image.y.iter().fold(0.0f32, |a, &b| a.max(b));
        assert!((max - 10.0).abs() < 1e-4, "{max}");
        assert!(c.image.absolute_units);
        c.image.check_consistent().unwrap();
    }

    /// The S/P ratios of the spectral data survive into the image: red 0.845, blue 5.66.
    #[test]
    fn red_and_blue_patches_keep_their_scotopic_ratios() {
        let c = chart();
        let v = c.image.scotopic.as_ref().unwrap();
        let sp = |i: usize| {
            let r = &c.layout.patches[i].rect;
            mean(v, &c, r) / mean(&c.image.y, &c, r)
        };
        assert!(
            (sp(RED_PATCH) - 0.845).abs() < 0.005,
            "red {}",
            sp(RED_PATCH)
        );
        assert!(
            (sp(BLUE_PATCH) - 5.663).abs() < 0.01,
            "blue {}",
            sp(BLUE_PATCH)
        );
        assert!(
            (sp(WHITE_PATCH) - 2.255).abs() < 0.005,
            "white {}",
            sp(WHITE_PATCH)
        );
        // The linear XYZ estimate the operator would otherwise use gets red badly wrong
        // (0.54, see scotopic.rs): the spectral channel matters.
        let r = &c.layout.patches[RED_PATCH].rect;
        let est = crate::scotopic::from_xyz(
            mean(&c.image.x, &c, r) as f32,
            mean(&c.image.y, &c, r) as f32,
            mean(&c.image.z, &c, r) as f32,
        ) as f64
            / mean(&c.image.y, &c, r);
        assert!(est < 0.6, "{est}");
    }

    /// Letter sizes: 5·x/20 arcmin at the design distance, i.e. 10 px for 20/20 and 100 px
    /// for 20/200 at 120 pixels/degree; the view gives the same pixels per degree.
    #[test]
    fn snellen_letters_subtend_their_design_angles() {
        let c = chart();
        let ppd = c
            .image
            .view
            .unwrap()
            .pixels_per_degree(c.image.width)
            .unwrap();
        assert!((ppd - 120.0).abs() < 1e-9, "{ppd}");
        for line in &c.layout.lines {
            let h = 5.0 * line.letters[0].cell_px;
            let expected = 5.0 * line.denominator as f64 / 20.0 / 60.0 * 120.0;
            assert!((h - expected).abs() < 1e-9, "20/{}: {h}", line.denominator);
            assert!((line.stroke_arcmin - line.denominator as f64 / 20.0).abs() < 1e-9);
            assert_eq!(line.effective_snellen(), format!("20/{}", line.denominator));
        }
        let names: Vec<u32> = c.layout.lines.iter().map(|l| l.denominator).collect();
        assert_eq!(names, SNELLEN_LINES);
        // The 20/20 letters are pixel-aligned: each pixel is paper and ink in the fractions
        // the letter covers, and the H (bars only) has pure ink and pure paper cells.
        let line = &c.layout.lines[7];
        let (ink, paper) = (c.layout.patches[BLACK_PATCH].photometry.y, 10.0);
        for l in &line.letters {
            let r = l.rect();
            for j in r.y0 as usize..r.y1 as usize {
                for i in r.x0 as usize..r.x1 as usize {
                    let cover = l.coverage(i, j);
                    let want = (1.0 - cover) * paper + cover * ink;
                    let v = c.image.y[j * c.image.width + i] as f64;
                    assert!((v - want).abs() < 1e-4, "{} ({i},{j}): {v}", l.letter);
                }
            }
            if l.letter == 'H' {
                for row in 0..5 {
                    for col in 0..5 {
                        let v = mean(&c.image.y, &c, &l.cell(row, col));
                        let want = if l.is_ink(row, col) { ink } else { paper };
                        assert!((v - want).abs() < 1e-4, "H ({row},{col}): {v}");
                    }
                }
            }
        }
    }

    #[test]
    fn gratings_have_their_frequencies() {
        let c = chart();
        assert_eq!(c.layout.gratings.len(), 5);
        for g in &c.layout.gratings {
            assert!((g.period_px - 120.0 / g.cycles_per_degree).abs() < 1e-9);
            let periods = (g.rect.x1 - g.rect.x0) / g.period_px;
            assert!(
                (periods - periods.round()).abs() < 1e-9 && periods > 1.999,
                "{periods}"
            );
        }
        // Unblurred, the 2 c/deg grating spans the full ink/paper range.
        let y: Vec<f64> = c.image.y.iter().map(|&v| v as f64).collect();
        let g = &c.layout.gratings[0];
        let col = |i: f64| {
            box_mean(
                &y,
                c.image.width,
                c.image.height,
                &Rect {
                    x0: i,
                    x1: i + 1.0,
                    ..g.rect.centre(0.5)
                },
            )
        };
        let x0 = g.rect.x0.ceil();
        assert!((col(x0 + 5.0) - c.layout.patches[BLACK_PATCH].photometry.y).abs() < 1e-4);
        assert!((col(x0 + 35.0) - 10.0).abs() < 1e-4);
        let no = Chart::new(&ChartOptions {
            gratings: false,
            ..ChartOptions::default()
        })
        .unwrap();
        assert!(no.layout.gratings.is_empty() && no.image.height < c.image.height);
    }

    /// `with_fov` keeps the image size and moves the viewer: at twice the default field of
    /// view the viewer stands at about half the distance and the 20/20 line tests 20/40.
    #[test]
    fn field_of_view_moves_the_viewer() {
        let d = chart();
        let fov = d.image.view.unwrap().horizontal_deg;
        let o = ChartOptions::with_fov(10.0, 2.0 * fov, true).unwrap();
        let c = Chart::new(&o).unwrap();
        assert_eq!(
            (c.image.width, c.image.height),
            (d.image.width, d.image.height)
        );
        assert!((c.image.view.unwrap().horizontal_deg - 2.0 * fov).abs() < 1e-6);
        assert!((o.viewing_distance_m / SNELLEN_DESIGN_DISTANCE_M - 0.5).abs() < 0.01);
        assert_eq!(c.layout.lines[7].effective_snellen(), "20/40");
        let ppd = c
            .image
            .view
            .unwrap()
            .pixels_per_degree(c.image.width)
            .unwrap();
        assert!((ppd - o.pixels_per_degree).abs() < 1e-6);
    }

    #[test]
    fn bad_options_are_rejected() {
        for white in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let o = ChartOptions {
                white_cd_m2: white,
                ..ChartOptions::default()
            };
            assert!(Chart::new(&o).is_err(), "{white}");
        }
        let huge = ChartOptions {
            pixels_per_degree: 1e5,
            ..ChartOptions::default()
        };
        assert!(Chart::new(&huge).is_err());
        assert!(ChartOptions::with_fov(1.0, 0.0, true).is_err());
        assert!(ChartOptions::with_fov(1.0, 180.0, true).is_err());
        assert!(ChartOptions::with_fov(1.0, f64::NAN, true).is_err());
    }

    #[test]
    fn cielab_of_the_reference_white_and_black() {
        assert_eq!(lab([0.5, 1.0, 0.25], [0.5, 1.0, 0.25]), [100.0, 0.0, 0.0]);
        let l = lab([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
        assert!(l[0].abs() < 1e-12);
        // Y/Yn = 0.18 gives L* = 49.50 (CIE 15:2004 formula).
        let l = lab([0.18, 0.18, 0.18], [1.0, 1.0, 1.0]);
        assert!((l[0] - 49.496).abs() < 1e-3, "{l:?}");
    }
}
