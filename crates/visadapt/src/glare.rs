//! Veiling glare: light scattered inside the eye, added to the scene before adaptation.
//!
//! The paper (Ferwerda et al. 1996, Sec. 1, previous work) cites Spencer, Shirley,
//! Zimmerman & Greenberg 1995's glare filter as the companion model. Light from a bright source is
//! scattered by the cornea, lens, vitreous and retina and lands all over the retina as a
//! veil of luminance that washes out what lies near the source and raises the adaptation
//! level (Radiance's `pcond -v` adds its veil to the adaptation for the same reason).
//!
//! # The point-spread function: CIE 135/1 (1999)
//!
//! We use the CIE 135/1-1999 *general disability glare equation* of Vos & van den Berg,
//! the age- and pigmentation-dependent glare spread function (GSF). With θ the angle
//! between the source and the point looked at, in degrees, `A` the age in years and `p`
//! the eye's pigmentation (0 for very dark eyes, 0.5 brown, 1 green, 1.2 light blue):
//!
//! ```text
//! L_veil/E = [1 − 0.08·(A/70)^4]·[9.2e6/(1+(θ/0.0046)²)^1.5 + 1.5e5/(1+(θ/0.045)²)^1.5]
//!          + [1 + 1.6·(A/70)^4]·{[400/(1+(θ/0.1)²) + 3e-8·θ²]
//!                                + p·[1300/(1+(θ/0.1)²)^1.5 + 0.8/(1+(θ/0.1)²)^0.5]}
//!          + 2.5e-3·p                                                        [sr⁻¹]
//! ```
//!
//! `E` is the illuminance (lux) the source makes at the eye, `L_veil` the equivalent veiling
//! luminance (cd/m²) it adds at angle θ. The constants are CIE 135/1's as spelled out in
//! HDR-VDP's `hdrvdp_otf_cie99.m` (the project's `beyond-the-paper.md` §7.2). The CIE gives
//! the equation for 0.1° < θ < 100°. Its classic special case is Stiles-Holladay,
//! `L_veil = 10·E/θ²` for 1° < θ < 30° ([`stiles_holladay_sr`]); for a 25-year-old with
//! brown eyes the GSF gives 19.3, 0.30 and 0.062 sr⁻¹ at 1°, 5° and 10° against 10, 0.4
//! and 0.1.
//!
//! **Near θ = 0** the equation stays finite (its first two terms, the optical core of the
//! eye's PSF, are Lorentzian-like bumps of width 0.0046° and 0.045°, peak 9.4e6 sr⁻¹):
//! below 0.1° it is Vos & van den Berg's fit of the core, outside the range the CIE
//! vouches for. The stage does not spread light closer than the *near radius* (1.5 cells
//! of its angular grid, reported): that part stays on the pixel it came from, where the
//! acuity stage (Eq. 7) sets the blur.
//! **Past 30°** the 1/θ² scatter has fallen to the level of the slowly varying terms
//! (`3e-8·θ²`, `0.8·p/(1+(θ/0.1)²)^0.5` and the constant `2.5e-3·p`, light that passes
//! through the eye wall), which dominate from about 40° on; the stage uses the equation up
//! to 90° (the hemisphere in front of the eye) and nothing beyond.
//!
//! # Energy
//!
//! A PSF redistributes the light entering the eye; it neither adds nor loses any. The
//! CIE equation integrates to 1.047 sr⁻¹·sr over the sphere for A = 25, p = 0.5 (the
//! project's check, reproduced in the tests); we divide it by its integral over the
//! hemisphere θ ≤ 90° ([`Glare::hemisphere_integral`]), so that it integrates to exactly
//! 1 there. A pixel then keeps the fraction `1 − s` of its light
//! ([`VeilReport::scattered_fraction`] is `s`, the normalised GSF's integral from the near
//! radius to 90°) and hands `s` to the veil. Light scattered to angles outside the image
//! leaves the image, as it leaves the field of view; none wraps around.
//!
//! # Geometry and convolution
//!
//! The veil at a pixel is the sum over all pixels `y` of `L(y)·Ω(y)·GSF(θ)`, with `Ω(y)`
//! the pixel's solid angle from the view (exact for perspective, angular and hemispherical
//! fisheye, planisphere and cylindrical views: the Jacobian of the projection, not a flat
//! `1/ppd²`) and θ the angle between the two pixels' directions. The flux `L·Ω` of every
//! pixel is splatted (bilinearly, conserving it exactly) onto a grid in the azimuthal
//! equidistant projection about the view axis, where the angle from the centre is exact
//! in every direction and angles between other points are off by at most
//! `1 − sin θ/θ` (4.5 % at 30° from the centre, against 25 % for a perspective image plane).
//! On that grid the GSF is a fixed kernel, the veil at a cell the sum of every cell's flux
//! times the GSF at their distance, applied by FFT (`realfft`/`rustfft`, f64 because
//! the veil far from a light is ~1e-9 of its flux): O(M log M) in the grid size M and
//! independent of the PSF's extent. The grid is zero-padded to at least twice the image's
//! angular extent so that nothing wraps around. Every pixel reads its veil from the grid
//! bilinearly. The kernel's spectrum depends only on the grid and the observer, and where
//! each pixel looks only on the view and the size: a [`Workspace`] keeps them, with the
//! FFT plans and buffers, for the next frame of a video or the viewer's next plan (the
//! free functions use a fresh one).
//!
//! The grid cell is the image's own pixel (at the centre) or, for large images, the angular
//! extent divided by [`MAX_GRID_CELLS`]: the veil is smooth beyond the near radius, so a
//! 4K image costs little more than a 1080p one.
//!
//! Every luminance plane gets the same veil: X, Y, Z (so that the veil shows in the image
//! with the source's colour) and the scotopic plane (from the file, or estimated from XYZ
//! before the veil, since that estimate is not linear), so the veil raises both the cone
//! and the rod adaptation.

use crate::limits::saturating_f32;
use crate::simd::Isa;
use crate::{Error, HdrImage, Projection, Result, View};
use realfft::RealFftPlanner;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;
use std::f64::consts::PI;

/// Age of the default observer, years: HDR-VDP's default (`hdrvdp_otf_cie99.m` callers use
/// 24) rounded to the 25 years at which the project checked the GSF's integral.
pub const DEFAULT_AGE_YEARS: f64 = 25.0;
/// Pigmentation of the default observer: 0.5, brown eyes (CIE 135/1 scale: 0 very dark,
/// 0.5 brown, 1 green, 1.2 light blue).
pub const DEFAULT_PIGMENTATION: f64 = 0.5;
/// Age at which CIE 135/1's age factors `(A/70)^4` reach 1, years.
const AGE_REFERENCE_YEARS: f64 = 70.0;
/// Highest age the stage accepts, years (the CIE equation was fitted to observers up to
/// about 80; beyond 120 the input is surely a mistake).
pub const MAX_AGE_YEARS: f64 = 120.0;
/// Highest pigmentation on the CIE scale (light blue eyes).
pub const MAX_PIGMENTATION: f64 = 1.2;
/// Largest number of grid cells along the longer angular extent of the image (a project
/// choice: 512 cells keep a 60° view at 0.12° per cell, 8 cells per degree, and the padded
/// FFT at or under 1024 × 1024).
pub const MAX_GRID_CELLS: usize = 512;
/// The GSF is not spread closer to its source than this many grid cells (see the module
/// docs); it stays on the pixel.
pub const NEAR_RADIUS_CELLS: f64 = 1.5;
/// The widest angle the stage spreads light to, degrees: the hemisphere in front of the eye.
pub const HEMISPHERE_DEG: f64 = 90.0;

/// Variance (cells², per axis) of the blur the grid adds to the kernel: the cell average
/// (1/12) and the bilinear splat and read (1/6 each).
const BLUR_VARIANCE_CELLS2: f64 = 1.0 / 12.0 + 1.0 / 6.0 + 1.0 / 6.0;

/// Radius (cells) out to which the kernel is corrected for that blur.
const SHARPEN_RADIUS_CELLS: f64 = 32.0;

/// Square degrees to steradians.
const SR_PER_DEG2: f64 = (PI / 180.0) * (PI / 180.0);

/// CIE 135/1 (1999) glare spread function `L_veil/E` in sr⁻¹ at `theta_deg` degrees from the
/// source, for an observer of `age_years` with `pigmentation` (see the module docs).
pub fn cie_glare_spread_sr(theta_deg: f64, age_years: f64, pigmentation: f64) -> f64 {
    let t2 = theta_deg * theta_deg;
    let age4 = (age_years / AGE_REFERENCE_YEARS).powi(4);
    let l01 = 1.0 + t2 / (0.1 * 0.1);
    let core = 9.2e6 / (1.0 + t2 / (0.0046 * 0.0046)).powf(1.5)
        + 1.5e5 / (1.0 + t2 / (0.045 * 0.045)).powf(1.5);
    let scatter = 400.0 / l01 + 3e-8 * t2;
    let pigment = 1300.0 / l01.powf(1.5) + 0.8 / l01.sqrt();
    (1.0 - 0.08 * age4) * core
        + (1.0 + 1.6 * age4) * (scatter + pigmentation * pigment)
        + 2.5e-3 * pigmentation
}

/// Stiles-Holladay disability glare, `L_veil/E = 10/θ²` sr⁻¹ with θ in degrees (valid from
/// about 1° to 30°): the classic special case of the CIE GSF.
pub fn stiles_holladay_sr(theta_deg: f64) -> f64 {
    10.0 / (theta_deg * theta_deg)
}

/// The glare stage's parameters: the observer's eye.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Glare {
    /// Age of the observer, years (CIE 135/1: scatter grows with `(A/70)^4`).
    pub age_years: f64,
    /// Eye pigmentation on the CIE 135/1 scale: 0 very dark, 0.5 brown, 1 green, 1.2 light
    /// blue (light through the eye wall).
    pub pigmentation: f64,
}

impl Default for Glare {
    fn default() -> Self {
        Glare {
            age_years: DEFAULT_AGE_YEARS,
            pigmentation: DEFAULT_PIGMENTATION,
        }
    }
}

impl Glare {
    /// Check the parameters' domains.
    pub fn validate(&self) -> Result<()> {
        if !(self.age_years.is_finite() && (0.0..=MAX_AGE_YEARS).contains(&self.age_years)) {
            return Err(Error::invalid(
                "age",
                self.age_years,
                format!("must be between 0 and {MAX_AGE_YEARS} years"),
            ));
        }
        if !(self.pigmentation.is_finite() && (0.0..=MAX_PIGMENTATION).contains(&self.pigmentation))
        {
            return Err(Error::invalid(
                "pigmentation",
                self.pigmentation,
                format!("must be between 0 (very dark eyes) and {MAX_PIGMENTATION} (light blue)"),
            ));
        }
        Ok(())
    }

    /// The CIE GSF for this observer, sr⁻¹ ([`cie_glare_spread_sr`]).
    pub fn spread_sr(&self, theta_deg: f64) -> f64 {
        cie_glare_spread_sr(theta_deg, self.age_years, self.pigmentation)
    }

    /// `∫ GSF dΩ` over the cone `from_deg ≤ θ ≤ to_deg` (sr⁻¹·sr, dimensionless), by
    /// Simpson's rule in log θ (the GSF varies over eight decades).
    pub fn integral(&self, from_deg: f64, to_deg: f64) -> f64 {
        // Below 1e-6° the GSF is flat at its peak: π·θ²·peak, in steradians.
        let floor = 1e-6_f64;
        let mut total = 0.0;
        let lo = if from_deg < floor {
            total += self.spread_sr(0.0)
                * PI
                * (floor * floor - from_deg.max(0.0).powi(2))
                * SR_PER_DEG2;
            floor
        } else {
            from_deg
        };
        if to_deg <= lo {
            return total;
        }
        let (u0, u1) = (lo.ln(), to_deg.ln());
        let n = 4000usize; // even
        let h = (u1 - u0) / n as f64;
        let f = |u: f64| {
            let t = u.exp();
            // dΩ = 2π sin θ dθ, dθ = θ du (θ in radians for the sine and the measure).
            self.spread_sr(t) * 2.0 * PI * t.to_radians().sin() * t.to_radians()
        };
        let mut s = f(u0) + f(u1);
        for i in 1..n {
            s += f(u0 + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        total + s * h / 3.0
    }

    /// `∫ GSF dΩ` over the hemisphere θ ≤ 90°, the stage's normaliser.
    pub fn hemisphere_integral(&self) -> f64 {
        self.integral(0.0, HEMISPHERE_DEG)
    }

    /// The normalised GSF (integral 1 over the hemisphere), sr⁻¹: the veiling luminance a
    /// unit illuminance at the eye makes at `theta_deg`, as the stage renders it.
    pub fn normalised_spread_sr(&self, theta_deg: f64) -> f64 {
        if theta_deg > HEMISPHERE_DEG {
            return 0.0;
        }
        self.spread_sr(theta_deg) / self.hemisphere_integral()
    }
}

/// What the glare stage did.
#[derive(Debug, Clone, PartialEq)]
pub struct VeilReport {
    /// The observer.
    pub glare: Glare,
    /// `∫ GSF dΩ` over the hemisphere (the normaliser; 1.04 for the default observer).
    pub hemisphere_integral: f64,
    /// Angular size of a cell of the convolution grid, degrees.
    pub cell_deg: f64,
    /// Light closer than this to its source stays on its pixel, degrees.
    pub near_radius_deg: f64,
    /// Fraction of every pixel's light spread into the veil (the normalised GSF from the
    /// near radius to 90°); the pixel keeps `1 − scattered_fraction`.
    pub scattered_fraction: f64,
    /// Cells of the padded FFT grid (width, height).
    pub fft_size: (usize, usize),
    /// Veiling luminance at the image centre (the fixation point), cd/m².
    pub veil_at_centre_cd_m2: f64,
    /// Scotopic veiling luminance at the image centre, scotopic cd/m².
    pub veil_at_centre_scotopic_cd_m2: f64,
    /// Mean veiling luminance over the image, cd/m².
    pub mean_veil_cd_m2: f64,
}

/// Run the glare stage: the scene as it reaches the retina, `(1 − s)·L + veil` on every
/// luminance plane (X, Y, Z and scotopic; the result always has a scotopic plane).
///
/// Pixels with a non-finite or negative channel give no light and are passed through
/// unchanged (the operator's bad-pixel rule then applies to them).
///
/// ```
/// use visadapt::{HdrImage, View, glare::{self, Glare}};
/// // A 0.05° bright spot (a distant headlight) at the centre of a dark 40° view.
/// let (w, h) = (401, 401);
/// let mut scene = HdrImage::zeros(w, h);
/// let c = h / 2 * w + w / 2;
/// scene.x[c] = 9.5e6; scene.y[c] = 1e7; scene.z[c] = 1.09e7;
/// let view = View::perspective(40.0, w, h);
/// let (retina, veil) = glare::apply(&scene, &view, &Glare::default())?;
/// // 5° to the right of the light the veil is L·Ω·GSF(5°)/∫GSF: within 10 % of the CIE value.
/// let ppd = view.pixels_per_degree(w).unwrap();
/// let e_lux = 1e7 * (1.0 / ppd).to_radians().powi(2);
/// let at_5 = retina.y[c + (5.0 * ppd).round() as usize] as f64;
/// let expected = e_lux * Glare::default().normalised_spread_sr(5.0);
/// assert!((at_5 / expected - 1.0).abs() < 0.1, "{at_5} vs {expected}");
/// assert!(veil.scattered_fraction > 0.05 && veil.scattered_fraction < 0.5);
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn apply(image: &HdrImage, view: &View, glare: &Glare) -> Result<(HdrImage, VeilReport)> {
    image.check_consistent()?;
    glare.validate()?;
    let mut retina = image.clone();
    let report = apply_in_place(&mut retina, view, glare)?;
    Ok((retina, report))
}

/// [`apply`] over the image's own planes: the veil is added in place (and a scotopic plane
/// estimated when the image has none), so that no second image is allocated. On an error
/// the image is unchanged. A fresh [`Workspace`]: for frames of one size, view and
/// observer, keep one and call [`Workspace::apply_in_place`].
pub fn apply_in_place(image: &mut HdrImage, view: &View, glare: &Glare) -> Result<VeilReport> {
    Workspace::new().apply_in_place(image, view, glare)
}

/// What the glare stage keeps from one call to the next: the frames of a video, and the
/// viewer's plans, share their size, view and observer, so each call would remake the
/// same things. Kept here: where every pixel looks (a quarter of the image's looks; the
/// rest follow by symmetry), the kernel's spectrum, the FFT plans, and the grids and FFT
/// buffers of every plane, reused instead of allocated (and page-faulted in) afresh.
/// Each is remade when what it depends on changes, so a workspace gives the same results
/// bit for bit as a fresh one for any sequence of calls (tested). With a 60° view on two
/// threads it holds about 48 MB at 1080p (the looks 17 MB, the kernel's and two planes'
/// spectra 5.4 MB each, the splat's two grids 5.1 MB each) and 98 MB at 4K (the looks
/// 66 MB; the grid is the same), and [`Workspace::apply`] keeps the retinal image
/// besides.
///
/// ```
/// use visadapt::{HdrImage, View, glare::{Glare, Workspace}};
/// let (w, h) = (160, 90);
/// let view = View::perspective(40.0, w, h);
/// let mut workspace = Workspace::new();
/// for frame in 0..3 {
///     let mut scene = HdrImage::zeros(w, h);
///     let c = h / 2 * w + 40 + 30 * frame; // a light moving to the right
///     scene.x[c] = 9.5e5; scene.y[c] = 1e6; scene.z[c] = 1.09e6;
///     let veil = workspace.apply_in_place(&mut scene, &view, &Glare::default())?;
///     assert!(scene.y[c + 3] > 0.0 && veil.scattered_fraction > 0.05);
/// }
/// # Ok::<(), visadapt::Error>(())
/// ```
#[derive(Clone, Default)]
pub struct Workspace {
    /// The looks of rows `0..⌈h/2⌉`, each its left `⌈w/2⌉` pixels, for the geometry of
    /// the key.
    looks: Option<(LooksKey, Vec<Look>)>,
    /// The kernel's spectrum, for the grid and observer of the key.
    kernel: Option<(KernelKey, Spectrum)>,
    /// The FFT plans, for their sizes.
    ffts: Option<Ffts>,
    /// Each splat band's grid (the first holds their sum after the splat, then the veil
    /// of the four planes).
    bands: Vec<Vec<Cell>>,
    /// The spectra being convolved, one per thread that convolves planes (at most one
    /// per plane).
    spectra: Vec<Vec<Complex<f64>>>,
    /// Each plane's veil on the grid.
    received: [Vec<f64>; PLANES],
    /// The image [`Workspace::apply`] returns, its planes reused.
    retina: Option<HdrImage>,
}

impl std::fmt::Debug for Workspace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Workspace")
            .field("looks", &self.looks.as_ref().map(|(k, l)| (k, l.len())))
            .field("kernel", &self.kernel.as_ref().map(|(k, _)| k))
            .field("fft_size", &self.ffts.as_ref().map(|f| (f.fw, f.fh)))
            .finish_non_exhaustive()
    }
}

impl Workspace {
    /// An empty workspace: the first call fills it.
    pub fn new() -> Self {
        Self::default()
    }

    /// [`apply`], into an image this workspace keeps (its planes reused from call to
    /// call): returns it, with the report.
    pub fn apply(
        &mut self,
        image: &HdrImage,
        view: &View,
        glare: &Glare,
    ) -> Result<(&HdrImage, VeilReport)> {
        image.check_consistent()?;
        glare.validate()?;
        let mut retina = self.retina.take().unwrap_or_else(|| HdrImage::zeros(0, 0));
        // The scotopic plane: the image's, or estimated into the kept one.
        if image.scotopic.is_some() {
            retina.clone_from(image);
        } else {
            let mut s = retina.scotopic.take().unwrap_or_default();
            retina.clone_from(image);
            estimate_scotopic(&image.x, &image.y, &image.z, &mut s);
            retina.scotopic = Some(s);
        }
        let report = self.apply_in_place(&mut retina, view, glare);
        let retina = self.retina.insert(retina);
        Ok((retina, report?))
    }

    /// [`apply_in_place`], reusing what this workspace kept from its last call.
    pub fn apply_in_place(
        &mut self,
        image: &mut HdrImage,
        view: &View,
        glare: &Glare,
    ) -> Result<VeilReport> {
        self.apply_in_place_at(Isa::detect(), image, view, glare)
    }

    /// [`Workspace::apply_in_place`] with the per-pixel loops compiled for `isa`.
    fn apply_in_place_at(
        &mut self,
        isa: Isa,
        image: &mut HdrImage,
        view: &View,
        glare: &Glare,
    ) -> Result<VeilReport> {
        image.check_consistent()?;
        glare.validate()?;
        let (w, h) = (image.width, image.height);
        let geometry = Geometry::new(view, w, h)?;
        let grid = Grid::new(&geometry, view, w, h)?;
        let norm = glare.hemisphere_integral();
        let near_radius_deg = NEAR_RADIUS_CELLS * grid.cell_deg;
        let scattered = glare.integral(near_radius_deg, HEMISPHERE_DEG) / norm;
        let Workspace {
            looks,
            kernel,
            ffts,
            bands,
            spectra,
            received,
            retina: _,
        } = self;
        let ffts = Ffts::for_grid(ffts, &grid);
        let kernel = grid.kernel(kernel, ffts, glare, norm, near_radius_deg);
        let looks = Looks::of(looks, &geometry, w, h);

        // The four planes the veil goes on; the scotopic one estimated before the veil.
        let scotopic: Vec<f32> = match image.scotopic.take() {
            Some(s) => s,
            None => {
                let mut s = Vec::new();
                estimate_scotopic(&image.x, &image.y, &image.z, &mut s);
                s
            }
        };
        let flux = grid.splat(
            isa,
            &looks,
            [&image.x, &image.y, &image.z, &scotopic],
            bands,
        );
        // The planes in as many groups as threads (up to one each), a spectrum buffer per
        // group (5.4 MB at 1080p): one per plane would hold twice what two threads use.
        #[cfg(feature = "rayon")]
        let threads = rayon::current_num_threads().clamp(1, PLANES);
        #[cfg(not(feature = "rayon"))]
        let threads = 1;
        let per_group = PLANES.div_ceil(threads);
        spectra.truncate(PLANES.div_ceil(per_group));
        spectra.resize_with(PLANES.div_ceil(per_group), Vec::new);
        let group = |(g, (outs, cols)): (usize, PlaneGroup)| {
            for (i, out) in outs.iter_mut().enumerate() {
                grid.convolve(flux, g * per_group + i, kernel, ffts, cols, out);
            }
        };
        #[cfg(feature = "rayon")]
        {
            use rayon::prelude::*;
            received
                .par_chunks_mut(per_group)
                .zip(spectra.par_iter_mut())
                .enumerate()
                .for_each(group);
        }
        #[cfg(not(feature = "rayon"))]
        received
            .chunks_mut(per_group)
            .zip(spectra.iter_mut())
            .enumerate()
            .for_each(group);
        // The flux is spent: its grid takes the veil.
        let veils = &mut bands[0];
        for (k, v) in veils.iter_mut().enumerate() {
            *v = std::array::from_fn(|p| received[p][k]);
        }

        let mut s_plane = scotopic;
        let keep = (1.0 - scattered) as f32;
        let mean_veil = grid.add_veil(
            isa,
            &looks,
            [&mut image.x, &mut image.y, &mut image.z, &mut s_plane],
            veils,
            keep,
        );
        image.scotopic = Some(s_plane);
        let centre = grid.sample(veils, grid.to_grid(0.0, 0.0));
        Ok(VeilReport {
            glare: *glare,
            hemisphere_integral: norm,
            cell_deg: grid.cell_deg,
            near_radius_deg,
            scattered_fraction: scattered,
            fft_size: (grid.fft_w, grid.fft_h),
            veil_at_centre_cd_m2: centre[1],
            veil_at_centre_scotopic_cd_m2: centre[3],
            mean_veil_cd_m2: mean_veil,
        })
    }
}

/// A group of planes' veils on the grid, and the spectrum buffer they are convolved in.
type PlaneGroup<'a> = (&'a mut [Vec<f64>], &'a mut Vec<Complex<f64>>);

/// The scotopic plane estimated from the `x`, `y`, `z` planes, into `out` (its memory
/// reused).
fn estimate_scotopic(x: &[f32], y: &[f32], z: &[f32], out: &mut Vec<f32>) {
    out.clear();
    out.extend(
        x.iter()
            .zip(y)
            .zip(z)
            .map(|((x, y), z)| crate::scotopic::from_xyz(*x, *y, *z)),
    );
}

/// Where a pixel looks: its azimuthal equidistant coordinates (degrees) and solid angle
/// (sr), `None` outside the projection's domain ([`Geometry::look`]).
type Look = Option<(f64, f64, f64)>;

/// Everything the looks depend on, as bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct LooksKey {
    projection: Projection,
    scales: [u64; 4],
    width: usize,
    height: usize,
}

/// The looks of a `width × height` image: those of the top-left quarter (rows
/// `0..⌈h/2⌉`, each its left `⌈w/2⌉` pixels), from which [`mirrored`] gives every pixel's.
struct Looks<'a> {
    quarter: &'a [Look],
    width: usize,
    height: usize,
}

impl<'a> Looks<'a> {
    /// The looks for `geometry` on a `w × h` image, kept in `slot` (made unless they are
    /// there for the same geometry).
    fn of(
        slot: &'a mut Option<(LooksKey, Vec<Look>)>,
        geometry: &Geometry,
        w: usize,
        h: usize,
    ) -> Self {
        let key = LooksKey {
            projection: geometry.projection,
            scales: [geometry.sx, geometry.sy, geometry.cx, geometry.cy].map(f64::to_bits),
            width: w,
            height: h,
        };
        if slot.as_ref().is_none_or(|(k, _)| *k != key) {
            let mut quarter = slot.take().map(|(_, v)| v).unwrap_or_default();
            let half = w.div_ceil(2);
            quarter.clear();
            quarter.resize(half * h.div_ceil(2), None);
            let row = |(j, row): (usize, &mut [Look])| geometry.row_looks(j, row);
            #[cfg(feature = "rayon")]
            {
                use rayon::prelude::*;
                quarter.par_chunks_mut(half).enumerate().for_each(row);
            }
            #[cfg(not(feature = "rayon"))]
            quarter.chunks_mut(half).enumerate().for_each(row);
            *slot = Some((key, quarter));
        }
        let (_, quarter) = slot.as_ref().expect("filled above");
        Looks {
            quarter,
            width: w,
            height: h,
        }
    }

    /// The left half of row `j`'s looks, and whether `b` is to be negated (the rows of
    /// the lower half are their mirror rows' with `b` negated).
    #[inline(always)]
    fn row(&self, j: usize) -> (&'a [Look], bool) {
        let half = self.width.div_ceil(2);
        let (q, flip_b) = if j < self.height.div_ceil(2) {
            (j, false)
        } else {
            (self.height - 1 - j, true)
        };
        (&self.quarter[q * half..(q + 1) * half], flip_b)
    }
}

/// Where every pixel looks: azimuthal equidistant coordinates about the view axis, in
/// degrees, and the pixel's solid angle.
#[derive(Debug, Clone, Copy)]
struct Geometry {
    projection: Projection,
    /// Pixel offsets from the centre to projection coordinates, per axis.
    sx: f64,
    sy: f64,
    /// Image centre in pixel coordinates.
    cx: f64,
    cy: f64,
}

impl Geometry {
    fn new(view: &View, w: usize, h: usize) -> Result<Self> {
        let (hd, vd) = (view.horizontal_deg, view.vertical_deg);
        let bad = || {
            Error::invalid(
                "glare",
                format!("{:?} view {hd}° × {vd}°", view.projection),
                "needs a view with an angular extent (not parallel, perspective under 180°)",
            )
        };
        if !(hd.is_finite() && hd > 0.0 && vd.is_finite() && vd > 0.0) {
            return Err(bad());
        }
        let (hw, hh) = (w as f64 / 2.0, h as f64 / 2.0);
        let half = |d: f64| (d / 2.0).to_radians();
        let (sx, sy) = match view.projection {
            // Image-plane units (focal length 1) per pixel.
            Projection::Perspective if hd < 180.0 && vd < 180.0 => {
                (half(hd).tan() / hw, half(vd).tan() / hh)
            }
            // Degrees per pixel.
            Projection::AngularFisheye => (hd / w as f64, vd / h as f64),
            // sin θ per pixel (θ ≤ 90°).
            Projection::HemisphericalFisheye => (
                half(hd.min(180.0)).sin() / hw,
                half(vd.min(180.0)).sin() / hh,
            ),
            // tan(θ/2) per pixel.
            Projection::Planisphere if hd < 360.0 && vd < 360.0 => {
                ((half(hd) / 2.0).tan() / hw, (half(vd) / 2.0).tan() / hh)
            }
            // Degrees of azimuth per pixel; image-plane units vertically.
            Projection::Cylindrical if vd < 180.0 => (hd / w as f64, half(vd).tan() / hh),
            _ => return Err(bad()),
        };
        Ok(Geometry {
            projection: view.projection,
            sx,
            sy,
            cx: hw,
            cy: hh,
        })
    }

    /// The azimuthal equidistant coordinates (degrees) and the solid angle (sr) of the
    /// pixel centred at `(px, py)` (pixel coordinates, 0.5 at the centre of the first
    /// pixel), or `None` outside the projection's domain.
    #[inline]
    fn look(&self, px: f64, py: f64) -> Option<(f64, f64, f64)> {
        let (x, y) = ((px - self.cx) * self.sx, (py - self.cy) * self.sy);
        let area = self.sx * self.sy;
        // θ (radians) and the unit vector of the azimuth in the image plane.
        let along = |theta: f64, r: f64, x: f64, y: f64| {
            let d = theta.to_degrees();
            if r > 0.0 {
                (d * x / r, d * y / r)
            } else {
                (0.0, 0.0)
            }
        };
        match self.projection {
            Projection::Perspective => {
                let r2 = x * x + y * y;
                let r = r2.sqrt();
                let (a, b) = along(r.atan(), r, x, y);
                // (1 + r²)^1.5, without the cost of `powf`.
                let q = 1.0 + r2;
                Some((a, b, area / (q * q.sqrt())))
            }
            Projection::AngularFisheye => {
                let t = (x * x + y * y).sqrt().to_radians();
                if t > PI {
                    return None;
                }
                let sinc = if t > 0.0 { t.sin() / t } else { 1.0 };
                Some((x, y, area * SR_PER_DEG2 * sinc))
            }
            Projection::HemisphericalFisheye => {
                let r = (x * x + y * y).sqrt();
                if r >= 1.0 {
                    return None;
                }
                let t = r.asin();
                let (a, b) = along(t, r, x, y);
                Some((a, b, area / t.cos()))
            }
            Projection::Planisphere => {
                let r2 = x * x + y * y;
                let r = r2.sqrt();
                let (a, b) = along(2.0 * r.atan(), r, x, y);
                Some((a, b, 4.0 * area / ((1.0 + r2) * (1.0 + r2))))
            }
            Projection::Cylindrical => {
                let phi = x.to_radians();
                if phi.abs() > PI {
                    return None;
                }
                // Direction (sin φ, v, cos φ)/√(1+v²).
                let n = (1.0 + y * y).sqrt();
                let (ex, ey) = (phi.sin(), y);
                let r = (ex * ex + ey * ey).sqrt();
                let t = (phi.cos() / n).clamp(-1.0, 1.0).acos();
                let (a, b) = along(t, r, ex, ey);
                Some((a, b, area * (PI / 180.0) / (n * n * n)))
            }
            Projection::Parallel => None,
        }
    }

    /// [`Geometry::look`] for the left half of row `j` of an image (the pixels
    /// `0..⌈w/2⌉` of a `w`-pixel-wide one: `looks.len()` of them). The image centre lies
    /// between the two middle pixels (or on the middle one), so pixel `w − 1 − i` sits at
    /// exactly the negated offsets of pixel `i`, and every projection's look is odd in
    /// each offset: the right half, and row `h − 1 − j`, follow by a change of sign
    /// ([`mirrored`]). Each transcendental is then evaluated once for four pixels.
    fn row_looks(&self, j: usize, looks: &mut [Look]) {
        let py = j as f64 + 0.5;
        for (i, look) in looks.iter_mut().enumerate() {
            *look = self.look(i as f64 + 0.5, py);
        }
    }
}

/// Pixel `i`'s look from the left half-row `looks` of [`Geometry::row_looks`] (of the
/// mirrored row when `flip_b`), for an image `w` pixels wide.
#[inline(always)]
fn mirrored(looks: &[Look], i: usize, w: usize, flip_b: bool) -> Look {
    let (q, flip_a) = if i < looks.len() {
        (i, false)
    } else {
        (w - 1 - i, true)
    };
    let sign = |flip: bool, v: f64| if flip { -v } else { v };
    looks[q].map(|(a, b, omega)| (sign(flip_a, a), sign(flip_b, b), omega))
}

/// Whether a pixel's four values are all finite and not negative: the pixels the stage
/// takes (others keep their values and spread nothing). In integers, with no early exit
/// (the form with `is_finite`, comparisons and `all` took about 60 instructions per
/// pixel on baseline x86-64, in the splat and again in the read-back): `c + 0.0` turns
/// `-0` into `+0` and keeps NaN and ±∞, and the bits of a finite, non-negative `f32`
/// are exactly those below the bits of `+∞` (negative values and NaN with the sign bit
/// set are above them, having the sign bit; +∞ and the other NaN are at or above them,
/// having the exponent all ones).
#[inline(always)]
fn valid(v: [f32; 4]) -> bool {
    let most = v.iter().fold(0u32, |m, &c| m.max((c + 0.0).to_bits()));
    most < f32::INFINITY.to_bits()
}

/// Whether a pixel spreads light: [`valid`] and not all zero.
#[inline(always)]
fn spreads(v: [f32; 4]) -> bool {
    valid(v) & v.iter().fold(false, |any, &c| any | (c != 0.0))
}

/// The luminance planes the stage spreads: X, Y, Z and scotopic.
const PLANES: usize = 4;

/// One grid cell's values for the four planes, kept together: a pixel's bilinear splat
/// and read-back then touch four cells of four lanes (one vector each) instead of
/// sixteen values in four grids, with one bounds check per cell.
type Cell = [f64; PLANES];

/// The angular grid the convolution runs on.
#[derive(Debug)]
struct Grid {
    cell_deg: f64,
    /// Azimuthal equidistant coordinates (degrees) of the centre of cell (0, 0).
    a0: f64,
    b0: f64,
    /// Cells holding the image (with a margin).
    nx: usize,
    ny: usize,
    /// The padded FFT size.
    fft_w: usize,
    fft_h: usize,
}

/// Spectrum of the kernel, column-major over the half spectrum (`fft_w/2+1` columns of
/// `fft_h`).
#[derive(Clone)]
struct Spectrum(Vec<Complex<f64>>);

/// Everything a kernel's spectrum depends on: the grid's size and cell and the observer
/// (the normaliser and the near radius follow from them), as bits, so that equal keys
/// give the same spectrum bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct KernelKey {
    nx: usize,
    ny: usize,
    fft_w: usize,
    fft_h: usize,
    cell_deg: u64,
    age_years: u64,
    pigmentation: u64,
}

/// The FFT plans for one padded grid size.
#[derive(Clone)]
struct Ffts {
    fw: usize,
    fh: usize,
    row_forward: std::sync::Arc<dyn realfft::RealToComplex<f64>>,
    row_inverse: std::sync::Arc<dyn realfft::ComplexToReal<f64>>,
    col_forward: std::sync::Arc<dyn rustfft::Fft<f64>>,
    col_inverse: std::sync::Arc<dyn rustfft::Fft<f64>>,
}

impl Ffts {
    /// The plans for `grid`'s FFT size, kept in `slot` (planned unless they are there).
    fn for_grid<'a>(slot: &'a mut Option<Ffts>, grid: &Grid) -> &'a Ffts {
        let (fw, fh) = (grid.fft_w, grid.fft_h);
        if slot.as_ref().is_none_or(|f| (f.fw, f.fh) != (fw, fh)) {
            let (mut rows, mut cols) = (RealFftPlanner::<f64>::new(), FftPlanner::<f64>::new());
            *slot = Some(Ffts {
                fw,
                fh,
                row_forward: rows.plan_fft_forward(fw),
                row_inverse: rows.plan_fft_inverse(fw),
                col_forward: cols.plan_fft_forward(fh),
                col_inverse: cols.plan_fft_inverse(fh),
            });
        }
        slot.as_ref().expect("filled above")
    }

    /// 2-D forward FFT of a real `fw × fh` array whose first `rows` rows `row(y, out)`
    /// writes (whole; the others are zero) into `cols`, column-major over the half
    /// spectrum (`fw/2 + 1` columns of `fh`). One row is held at a time, not the array.
    fn forward(&self, rows: usize, row: impl Fn(usize, &mut [f64]), cols: &mut Vec<Complex<f64>>) {
        let (fw, fh) = (self.fw, self.fh);
        let zero = Complex::new(0.0, 0.0);
        cols.clear();
        cols.resize((fw / 2 + 1) * fh, zero);
        let mut row_in = self.row_forward.make_input_vec();
        let mut row_out = self.row_forward.make_output_vec();
        let mut scratch = self.row_forward.make_scratch_vec();
        for y in 0..rows {
            // Written whole for every row: the transform uses it as scratch.
            row(y, &mut row_in);
            if row_in.iter().all(|v| *v == 0.0) {
                continue;
            }
            self.row_forward
                .process_with_scratch(&mut row_in, &mut row_out, &mut scratch)
                .expect("FFT buffers sized by their plan");
            for (x, v) in row_out.iter().enumerate() {
                cols[x * fh + y] = *v;
            }
        }
        let mut scratch = vec![zero; self.col_forward.get_inplace_scratch_len()];
        for col in cols.chunks_exact_mut(fh) {
            self.col_forward.process_with_scratch(col, &mut scratch);
        }
    }
}

impl Grid {
    fn new(geometry: &Geometry, view: &View, w: usize, h: usize) -> Result<Self> {
        // The footprint's extremes lie on the border or on the central row and column.
        let (mut amin, mut amax, mut bmin, mut bmax) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut visit = |i: usize, j: usize| {
            if let Some((a, b, _)) = geometry.look(i as f64 + 0.5, j as f64 + 0.5) {
                amin = amin.min(a);
                amax = amax.max(a);
                bmin = bmin.min(b);
                bmax = bmax.max(b);
            }
        };
        for i in 0..w {
            for j in [0, h / 2, h - 1] {
                visit(i, j);
            }
        }
        for j in 0..h {
            for i in [0, w / 2, w - 1] {
                visit(i, j);
            }
        }
        let extent = (amax - amin).max(bmax - bmin);
        let pixel_deg = view
            .pixels_per_degree(w)
            .map_or(extent / w.max(h) as f64, |p| 1.0 / p);
        let cell_deg = pixel_deg.max(extent / MAX_GRID_CELLS as f64);
        if !(cell_deg.is_finite() && cell_deg > 0.0) {
            return Err(Error::invalid(
                "glare",
                format!("{w}x{h}"),
                "the view has no angular extent",
            ));
        }
        // One cell of margin each side for the bilinear splat and read-back.
        let margin = 1.0;
        let nx = ((amax - amin) / cell_deg + 2.0 * margin).ceil() as usize + 1;
        let ny = ((bmax - bmin) / cell_deg + 2.0 * margin).ceil() as usize + 1;
        Ok(Grid {
            cell_deg,
            a0: amin - margin * cell_deg,
            b0: bmin - margin * cell_deg,
            nx,
            ny,
            fft_w: fft_friendly(2 * nx - 1),
            fft_h: fft_friendly(2 * ny - 1),
        })
    }

    #[inline(always)]
    fn to_grid(&self, a: f64, b: f64) -> (f64, f64) {
        ((a - self.a0) / self.cell_deg, (b - self.b0) / self.cell_deg)
    }

    /// Bilinear weights: the four cells around `(gx, gy)` as (index, weight).
    #[inline(always)]
    fn bilinear(&self, (gx, gy): (f64, f64)) -> [(usize, f64); 4] {
        // Through `i64`, not `usize`: on baseline x86-64 (no AVX-512) a conversion between
        // `f64` and an unsigned 64-bit integer is a sequence of instructions, one between
        // `f64` and `i64` a single one; the values are the same (the cells are counted
        // in `i64` exactly), and so are the weights.
        let gx = gx.clamp(0.0, (self.nx as i64 - 1) as f64 - 1e-9);
        let gy = gy.clamp(0.0, (self.ny as i64 - 1) as f64 - 1e-9);
        // Not negative, so truncation is the floor: `f64::floor` is a call of a software
        // `floor` (the compiler's runtime library) on baseline x86-64, which has no
        // rounding instruction (SSE4.1), twice per pixel in the splat and twice in the
        // read-back.
        let (i, j) = (gx as i64, gy as i64);
        let (fx, fy) = (gx - i as f64, gy - j as f64);
        let k = j as usize * self.nx + i as usize;
        [
            (k, (1.0 - fx) * (1.0 - fy)),
            (k + 1, fx * (1.0 - fy)),
            (k + self.nx, (1.0 - fx) * fy),
            (k + self.nx + 1, fx * fy),
        ]
    }

    /// The four planes' values at `at` (grid coordinates), read bilinearly from `cells`:
    /// each plane's four weighted cells summed in order from `-0.0` (as `f64`'s `Sum`).
    #[inline(always)]
    fn sample(&self, cells: &[Cell], at: (f64, f64)) -> Cell {
        let mut sum = [-0.0; PLANES];
        for (k, w) in self.bilinear(at) {
            let c = &cells[k];
            for p in 0..PLANES {
                sum[p] += c[p] * w;
            }
        }
        sum
    }

    /// The flux `L·Ω` (cd/m²·sr = lux) of every valid pixel, bilinearly splatted onto the
    /// grid, for the four planes together: one grid per band of rows in `bands` (reused),
    /// summed into the first, which is returned.
    fn splat<'a>(
        &self,
        isa: Isa,
        looks: &Looks,
        planes: [&[f32]; PLANES],
        bands: &'a mut Vec<Vec<Cell>>,
    ) -> &'a [Cell] {
        let h = looks.height;
        let cells = self.nx * self.ny;
        // Rows are taken in mirrored pairs (j, h − 1 − j), which share their looks.
        let pairs = h.div_ceil(2);
        // One band of row pairs per thread: each band fills a grid of its own (the four
        // planes of the whole grid), so more bands than threads would only add grids to
        // clear and to sum.
        #[cfg(feature = "rayon")]
        let count = rayon::current_num_threads().clamp(1, pairs.max(1));
        #[cfg(not(feature = "rayon"))]
        let count = 1;
        bands.truncate(count);
        bands.resize_with(count, Vec::new);
        let band = |(b, acc): (usize, &mut Vec<Cell>)| {
            acc.clear();
            acc.resize(cells, [0.0; PLANES]);
            let pairs = b * pairs / count..(b + 1) * pairs / count;
            crate::simd::at_level!(isa, self.splat_rows(looks, planes, pairs.clone(), acc));
        };
        #[cfg(feature = "rayon")]
        {
            use rayon::prelude::*;
            bands.par_iter_mut().enumerate().for_each(band);
        }
        #[cfg(not(feature = "rayon"))]
        bands.iter_mut().enumerate().for_each(band);
        // In band order, so that the sum does not depend on how the pool ran the bands.
        let (first, rest) = bands.split_first_mut().expect("at least one band");
        for other in rest.iter() {
            for (a, b) in first.iter_mut().zip(other) {
                for p in 0..PLANES {
                    a[p] += b[p];
                }
            }
        }
        first
    }

    /// The splat of the row pairs `pairs` (rows `j` and `h − 1 − j` for each `j`) into
    /// `acc`. Compiled for the dispatched instruction set, where a cell's four planes are
    /// one vector of `f64` (AVX2): the same operations in the same order, so the same
    /// results bit for bit (tested); on one thread at 1080p 119.5–120.7 → 105.4–107.0 ms
    /// per call with the read-back's loop dispatched too.
    #[inline(always)]
    fn splat_rows(
        &self,
        looks: &Looks,
        planes: [&[f32]; PLANES],
        pairs: std::ops::Range<usize>,
        acc: &mut [Cell],
    ) {
        let (w, h) = (looks.width, looks.height);
        for jp in pairs {
            let (row_looks, _) = looks.row(jp);
            let mirror = h - 1 - jp;
            for (j, flip_b) in [(jp, false), (mirror, true)] {
                if flip_b && mirror == jp {
                    continue;
                }
                for i in 0..w {
                    let k = j * w + i;
                    let v = [planes[0][k], planes[1][k], planes[2][k], planes[3][k]];
                    if !spreads(v) {
                        continue;
                    }
                    let Some((a, b, omega)) = mirrored(row_looks, i, w, flip_b) else {
                        continue;
                    };
                    let v = v.map(f64::from);
                    for (cell, wt) in self.bilinear(self.to_grid(a, b)) {
                        let f = wt * omega;
                        let acc = &mut acc[cell];
                        for p in 0..PLANES {
                            acc[p] += f * v[p];
                        }
                    }
                }
            }
        }
    }

    /// [`Grid::kernel_spectrum`] for `glare` (its normaliser `norm` and near radius
    /// `near_deg`), kept in `slot` (made unless it is there for the same grid and
    /// observer).
    fn kernel<'a>(
        &self,
        slot: &'a mut Option<(KernelKey, Spectrum)>,
        ffts: &Ffts,
        glare: &Glare,
        norm: f64,
        near_deg: f64,
    ) -> &'a Spectrum {
        let key = KernelKey {
            nx: self.nx,
            ny: self.ny,
            fft_w: self.fft_w,
            fft_h: self.fft_h,
            cell_deg: self.cell_deg.to_bits(),
            age_years: glare.age_years.to_bits(),
            pigmentation: glare.pigmentation.to_bits(),
        };
        if slot.as_ref().is_none_or(|(k, _)| *k != key) {
            *slot = None;
            *slot = Some((key, self.kernel_spectrum(ffts, glare, norm, near_deg)));
        }
        &slot.as_ref().expect("filled above").1
    }

    /// The kernel: the normalised GSF (sr⁻¹) at each cell offset, averaged over sub-samples
    /// near the centre where it is steep, zero within the near radius and past 90°;
    /// transformed. Convolved with the flux per cell (lux) it gives the veil (cd/m²).
    fn kernel_spectrum(&self, ffts: &Ffts, glare: &Glare, norm: f64, near_deg: f64) -> Spectrum {
        let (fw, fh) = (self.fft_w, self.fft_h);
        let mut k = vec![0.0f64; fw * fh];
        let g = self.cell_deg;
        let (rx, ry) = (self.nx as i64 - 1, self.ny as i64 - 1);
        // The kernel is even in both offsets (its sub-samples lie symmetrically about each
        // cell's centre): each value of the first quadrant goes to its four mirror images.
        for dy in 0..=ry {
            for dx in 0..=rx {
                let r = ((dx * dx + dy * dy) as f64).sqrt();
                // Sub-samples per axis.
                let n = if r < 4.0 {
                    16
                } else if r < 16.0 {
                    4
                } else {
                    1
                };
                let mut sum = 0.0;
                for sy in 0..n {
                    for sx in 0..n {
                        let ox = dx as f64 + (sx as f64 + 0.5) / n as f64 - 0.5;
                        let oy = dy as f64 + (sy as f64 + 0.5) / n as f64 - 0.5;
                        let t = g * (ox * ox + oy * oy).sqrt();
                        if t > near_deg && t <= HEMISPHERE_DEG {
                            sum += glare.spread_sr(t);
                        }
                    }
                }
                let value = sum / ((n * n) as f64 * norm);
                for (mx, my) in [(dx, dy), (-dx, dy), (dx, -dy), (-dx, -dy)] {
                    let x = mx.rem_euclid(fw as i64) as usize;
                    let y = my.rem_euclid(fh as i64) as usize;
                    k[y * fw + x] = value;
                }
            }
        }
        // The cell average (a box, variance 1/12 cell² per axis), the bilinear splat and
        // the bilinear read (tents, 1/6 each) blur the kernel by a variance of 5/12 cell²
        // per axis, which flattens its 1/θ³ core by ~1.9/r² (r in cells: 7 % at 5 cells).
        // Undo it to second order, K − (5/24)·∇²K, where the discrete Laplacian's stencil
        // lies beyond the near radius (the kernel stays positive) and within
        // SHARPEN_RADIUS_CELLS (beyond, the correction is under 0.2 %).
        let at = |dx: i64, dy: i64| {
            k[dy.rem_euclid(fh as i64) as usize * fw + dx.rem_euclid(fw as i64) as usize]
        };
        let near_cells = near_deg / g;
        let mut sharpened = k.clone();
        let mut inner = Vec::new();
        for dy in -ry..=ry {
            for dx in -rx..=rx {
                let r = ((dx * dx + dy * dy) as f64).sqrt();
                let index =
                    dy.rem_euclid(fh as i64) as usize * fw + dx.rem_euclid(fw as i64) as usize;
                if r > SHARPEN_RADIUS_CELLS {
                    continue;
                }
                if r - 1.0 <= near_cells + 0.5 {
                    inner.push(index);
                    continue;
                }
                let lap = at(dx + 1, dy) + at(dx - 1, dy) + at(dx, dy + 1) + at(dx, dy - 1)
                    - 4.0 * at(dx, dy);
                sharpened[index] = (at(dx, dy) - BLUR_VARIANCE_CELLS2 / 2.0 * lap).max(0.0);
            }
        }
        // What the correction took is what the blur moves across the near radius: give it
        // back to the innermost ring, so that the energy is unchanged and the far field
        // exact.
        let deficit: f64 = k.iter().sum::<f64>() - sharpened.iter().sum::<f64>();
        let ring: f64 = inner.iter().map(|i| k[*i]).sum();
        if ring > 0.0 {
            for i in inner {
                sharpened[i] += deficit * k[i] / ring;
            }
        }
        let mut spectrum = Vec::new();
        ffts.forward(
            fh,
            |y, row| row.copy_from_slice(&sharpened[y * fw..(y + 1) * fw]),
            &mut spectrum,
        );
        Spectrum(spectrum)
    }

    /// Linear convolution of plane `plane` of the grid's flux (lux) with the kernel: the
    /// veil (cd/m²), into `received`.
    fn convolve(
        &self,
        flux: &[Cell],
        plane: usize,
        kernel: &Spectrum,
        ffts: &Ffts,
        cols: &mut Vec<Complex<f64>>,
        received: &mut Vec<f64>,
    ) {
        let (fw, fh, nx, ny) = (self.fft_w, self.fft_h, self.nx, self.ny);
        // The grid's rows, zero-padded.
        let padded_row = |y: usize, row: &mut [f64]| {
            let (row, pad) = row.split_at_mut(nx);
            for (p, c) in row.iter_mut().zip(&flux[y * nx..(y + 1) * nx]) {
                *p = c[plane];
            }
            pad.fill(0.0);
        };
        ffts.forward(ny, padded_row, cols);
        let scale = 1.0 / (fw * fh) as f64;
        for (c, k) in cols.iter_mut().zip(&kernel.0) {
            *c *= k * scale;
        }
        let cw = fw / 2 + 1;
        let mut scratch = vec![Complex::new(0.0, 0.0); ffts.col_inverse.get_inplace_scratch_len()];
        for col in cols.chunks_exact_mut(fh) {
            ffts.col_inverse.process_with_scratch(col, &mut scratch);
        }
        let mut row_in = ffts.row_inverse.make_input_vec();
        let mut row_out = ffts.row_inverse.make_output_vec();
        let mut scratch = ffts.row_inverse.make_scratch_vec();
        received.clear();
        received.resize(nx * ny, 0.0);
        for y in 0..ny {
            for (x, v) in row_in.iter_mut().enumerate() {
                *v = cols[x * fh + y];
            }
            // A real signal's spectrum has real DC and Nyquist terms; drop the round-off.
            row_in[0].im = 0.0;
            if fw % 2 == 0 {
                row_in[cw - 1].im = 0.0;
            }
            ffts.row_inverse
                .process_with_scratch(&mut row_in, &mut row_out, &mut scratch)
                .expect("FFT buffers sized by their plan");
            // Round-off far from any light can dip just below zero.
            for (r, v) in received[y * nx..(y + 1) * nx].iter_mut().zip(&row_out) {
                *r = v.max(0.0);
            }
        }
    }

    /// `plane = keep·plane + veil` at every valid pixel with finite, non-negative channels;
    /// returns the mean photopic veil over the image.
    fn add_veil(
        &self,
        isa: Isa,
        looks: &Looks,
        planes: [&mut Vec<f32>; PLANES],
        veils: &[Cell],
        keep: f32,
    ) -> f64 {
        let [x, y, z, s] = planes;
        let n = x.len() as f64;
        let width = looks.width;
        let row = |(j, (((x, y), z), s)): RowPlanes| {
            crate::simd::at_level!(isa, self.veil_row(looks, j, [x, y, z, s], veils, keep))
        };
        // The rows' sums are added in row order: a parallel sum's order follows the work
        // stealing, so its rounding changed from run to run (seen in
        // `a_workspace_gives_fresh_results_bit_for_bit`: the mean veil off in its last bit).
        #[cfg(feature = "rayon")]
        let total: f64 = {
            use rayon::prelude::*;
            let rows: Vec<f64> = x
                .par_chunks_mut(width)
                .zip(y.par_chunks_mut(width))
                .zip(z.par_chunks_mut(width))
                .zip(s.par_chunks_mut(width))
                .enumerate()
                .map(row)
                .collect();
            rows.iter().sum()
        };
        #[cfg(not(feature = "rayon"))]
        let total: f64 = x
            .chunks_mut(width)
            .zip(y.chunks_mut(width))
            .zip(z.chunks_mut(width))
            .zip(s.chunks_mut(width))
            .enumerate()
            .map(row)
            .sum();
        total / n
    }
}

impl Grid {
    /// [`Grid::add_veil`] on row `j` (its four planes `row`): returns the row's sum of the
    /// photopic veil (compiled for the dispatched instruction set).
    #[inline(always)]
    fn veil_row(
        &self,
        looks: &Looks,
        j: usize,
        row: [&mut [f32]; PLANES],
        veils: &[Cell],
        keep: f32,
    ) -> f64 {
        let [x, y, z, s] = row;
        let (row_looks, flip_b) = looks.row(j);
        let mut sum = 0.0;
        for i in 0..x.len() {
            let px = [x[i], y[i], z[i], s[i]];
            if !valid(px) {
                continue;
            }
            let Some((a, b, _)) = mirrored(row_looks, i, looks.width, flip_b) else {
                continue;
            };
            let veil = self.sample(veils, self.to_grid(a, b));
            sum += veil[1];
            // In f64, saturating at f32::MAX: near several f32::MAX pixels the sum
            // exceeds the f32 range (it became +inf, then a black, "non-finite" pixel).
            let add = |c: f32, v: f64| saturating_f32(f64::from(keep) * f64::from(c) + v);
            x[i] = add(px[0], veil[0]);
            y[i] = add(px[1], veil[1]);
            z[i] = add(px[2], veil[2]);
            s[i] = add(px[3], veil[3]);
        }
        sum
    }
}

/// One row of the four planes, with its index.
type RowPlanes<'a> = (
    usize,
    (
        ((&'a mut [f32], &'a mut [f32]), &'a mut [f32]),
        &'a mut [f32],
    ),
);

/// The smallest `n ≥ min` of the form 2^a·3^b·5^c (fast FFT sizes).
fn fft_friendly(min: usize) -> usize {
    let mut n = min.max(1);
    loop {
        let mut m = n;
        for p in [2, 3, 5] {
            while m.is_multiple_of(p) {
                m /= p;
            }
        }
        if m == 1 {
            return n;
        }
        n += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The per-pixel loops give the same planes and report bit for bit at every
    /// instruction set this processor runs (they are compiled for each, with the same
    /// operations in the same order), on an image of odd size with a light, a textured
    /// field and pixels the stage passes through (negative, NaN, infinite).
    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        let (w, h) = (97, 61);
        let mut scene = HdrImage::zeros(w, h);
        let mut state = 12345u64;
        for k in 0..w * h {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let l = (state >> 40) as f32 / (1u64 << 24) as f32 * 50.0;
            (scene.x[k], scene.y[k], scene.z[k]) = (0.95 * l, l, 1.09 * l);
        }
        let source = 30 * w + 40;
        (scene.x[source], scene.y[source], scene.z[source]) = (9.5e6, 1e7, 1.09e7);
        scene.y[5] = -1.0;
        scene.z[w + 7] = f32::NAN;
        scene.x[2 * w + 9] = f32::INFINITY;
        let view = View::perspective(55.0, w, h);
        let run = |isa: Isa| {
            let mut image = scene.clone();
            let report = Workspace::new()
                .apply_in_place_at(isa, &mut image, &view, &Glare::default())
                .unwrap();
            let s = image.scotopic.take().unwrap();
            let bits: Vec<u32> = [image.x, image.y, image.z, s]
                .iter()
                .flat_map(|p| p.iter().map(|v| v.to_bits()))
                .collect();
            (bits, report)
        };
        let (bits, report) = run(Isa::Baseline);
        for isa in Isa::all_available() {
            let (other, other_report) = run(isa);
            assert!(other == bits, "{isa:?}: planes differ from the baseline's");
            assert_eq!(other_report, report, "{isa:?}");
        }
    }

    /// The kept kernel is the one made for the same grid and observer: after a kernel
    /// for one, a kernel for another that differs in one thing only (age, pigmentation,
    /// cell, grid or FFT size) is that one's own, bit for bit; asked again for the same,
    /// the same values.
    #[test]
    fn kept_kernel_is_the_one_for_its_grid_and_observer() {
        let base = Grid {
            cell_deg: 0.5,
            a0: -10.0,
            b0: -6.0,
            nx: 41,
            ny: 25,
            // Room for the wider and taller grids below (2n − 1 cells each way).
            fft_w: 90,
            fft_h: 60,
        };
        let observer = Glare::default();
        let (mut slot, mut plans) = (None, None);
        let mut fresh = |grid: &Grid, glare: &Glare| {
            let norm = glare.hemisphere_integral();
            let near = NEAR_RADIUS_CELLS * grid.cell_deg;
            let ffts = Ffts::for_grid(&mut plans, grid);
            let kept = grid.kernel(&mut slot, ffts, glare, norm, near);
            let made = grid.kernel_spectrum(Ffts::for_grid(&mut None, grid), glare, norm, near);
            assert_eq!(kept.0.len(), made.0.len());
            for (a, b) in kept.0.iter().zip(&made.0) {
                assert!(
                    a.re.to_bits() == b.re.to_bits() && a.im.to_bits() == b.im.to_bits(),
                    "{grid:?} {glare:?}: {a} against {b}"
                );
            }
        };
        let older = Glare {
            age_years: 70.0,
            ..observer
        };
        let bluer = Glare {
            pigmentation: 1.2,
            ..observer
        };
        let coarser = Grid {
            cell_deg: 0.6,
            ..base
        };
        let wider = Grid { nx: 45, ..base };
        let taller = Grid { ny: 27, ..base };
        let padded_across = Grid { fft_w: 96, ..base };
        let padded_down = Grid { fft_h: 64, ..base };
        let cases = [
            (&base, &older),
            (&base, &bluer),
            (&coarser, &observer),
            (&wider, &observer),
            (&taller, &observer),
            (&padded_across, &observer),
            (&padded_down, &observer),
        ];
        for (grid, glare) in cases {
            fresh(&base, &observer);
            fresh(grid, glare);
            fresh(grid, glare);
        }
    }

    /// The pixel tests in integers ([`valid`], [`spreads`]) are the tests they replace
    /// (`is_finite() && c >= 0.0` for all four values; and not all zero), on every
    /// pattern of the upper 16 bits of an `f32` with three patterns of the lower ones (all
    /// signs, exponents and the NaN and infinity classes, `-0` and subnormals included),
    /// in each of the four positions.
    #[test]
    fn integer_pixel_tests_are_the_float_ones() {
        let old_valid = |v: [f32; 4]| v.iter().all(|c| c.is_finite() && *c >= 0.0);
        let old_spreads = |v: [f32; 4]| old_valid(v) && !v.iter().all(|c| *c == 0.0);
        for high in 0..=u16::MAX {
            for low in [0u32, 1, 0xffff] {
                let c = f32::from_bits(u32::from(high) << 16 | low);
                for at in 0..4 {
                    for fill in [0.0, 1.5] {
                        let mut v = [fill; 4];
                        v[at] = c;
                        assert_eq!(valid(v), old_valid(v), "{v:?}");
                        assert_eq!(spreads(v), old_spreads(v), "{v:?}");
                    }
                }
            }
        }
    }

    /// The bilinear cells and weights (the floor by truncation, through `i64`) are those
    /// of `f64::floor`, inside the grid, on its last cell, clamped outside it and for NaN.
    #[test]
    fn bilinear_weights_are_those_of_the_floor() {
        let grid = Grid {
            cell_deg: 0.1,
            a0: 0.0,
            b0: 0.0,
            nx: 37,
            ny: 23,
            fft_w: 80,
            fft_h: 48,
        };
        let reference = |(gx, gy): (f64, f64)| {
            let gx = gx.clamp(0.0, (grid.nx - 1) as f64 - 1e-9);
            let gy = gy.clamp(0.0, (grid.ny - 1) as f64 - 1e-9);
            let (i, j) = (gx.floor(), gy.floor());
            let (fx, fy) = (gx - i, gy - j);
            let k = j as usize * grid.nx + i as usize;
            [
                (k, (1.0 - fx) * (1.0 - fy)),
                (k + 1, fx * (1.0 - fy)),
                (k + grid.nx, (1.0 - fx) * fy),
                (k + grid.nx + 1, fx * fy),
            ]
        };
        let mut seed = 5u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            f64::from(seed >> 8) / f64::from(1u32 << 24)
        };
        let mut points = vec![
            (0.0, 0.0),
            (36.0, 22.0),
            (35.999_999_999_9, 21.5),
            (-3.0, 50.0),
            (1e300, -1e300),
            (f64::NAN, 2.5),
            (2.5, f64::NAN),
            (7.0, 3.0),
        ];
        points.extend((0..2000).map(|_| (next() * 40.0 - 1.5, next() * 26.0 - 1.5)));
        for p in points {
            let (a, b) = (grid.bilinear(p), reference(p));
            for ((ka, wa), (kb, wb)) in a.iter().zip(&b) {
                assert_eq!(ka, kb, "{p:?}");
                assert!(wa.to_bits() == wb.to_bits(), "{p:?}: {wa} against {wb}");
            }
        }
    }

    /// The mirrored half-row looks are the direct looks of every pixel, bit for bit, for
    /// every projection with an angular extent, on images of odd and even sizes (the
    /// splat and the read-back rely on the looks being odd in each offset).
    #[test]
    fn mirrored_looks_equal_direct_looks_bit_for_bit() {
        let projections = [
            (Projection::Perspective, 70.0, 50.0),
            (Projection::AngularFisheye, 200.0, 180.0),
            (Projection::HemisphericalFisheye, 180.0, 180.0),
            (Projection::Cylindrical, 300.0, 80.0),
            (Projection::Planisphere, 250.0, 200.0),
        ];
        for (projection, horizontal_deg, vertical_deg) in projections {
            for (w, h) in [(17, 9), (16, 10), (1, 1), (2, 3)] {
                let view = View {
                    projection,
                    horizontal_deg,
                    vertical_deg,
                };
                let geometry = Geometry::new(&view, w, h).unwrap();
                let mut looks = vec![None; w.div_ceil(2)];
                let mut outside = 0;
                for j in 0..h.div_ceil(2) {
                    geometry.row_looks(j, &mut looks);
                    for (row, flip_b) in [(j, false), (h - 1 - j, true)] {
                        for i in 0..w {
                            let direct = geometry.look(i as f64 + 0.5, row as f64 + 0.5);
                            let bits = |l: Option<(f64, f64, f64)>| {
                                l.map(|(a, b, o)| (a.to_bits(), b.to_bits(), o.to_bits()))
                            };
                            // Zero offsets may differ in sign only (−0 and +0 land on
                            // the same grid position).
                            let clean = |l: Option<(f64, f64, f64)>| {
                                l.map(|(a, b, o)| (a + 0.0, b + 0.0, o))
                            };
                            assert_eq!(
                                bits(clean(mirrored(&looks, i, w, flip_b))),
                                bits(clean(direct)),
                                "{projection:?} {w}x{h} pixel ({i}, {row})"
                            );
                            outside += usize::from(direct.is_none());
                        }
                    }
                }
                // The wide fisheyes leave their corners outside their domain, so both
                // branches are exercised.
                if projection == Projection::HemisphericalFisheye && w == 17 {
                    assert!(outside > 0);
                }
            }
        }
    }
}
