//! The two images of the model: the world as the world observer sees it ([`HdrImage`],
//! absolute CIE XYZ and scotopic luminance), and what the display shows
//! ([`DisplayImage`], linear display RGB relative to the display maximum).
//!
//! Both are stored as flat, planar `f32` buffers (one `Vec<f32>` per channel, row-major,
//! top row first), the layout every hot loop of the library works on.

/// A plane as `Debug` shows it: its number of samples, not the samples (a 1080p plane
/// has two million), so that `{:?}` of an image, a map or anything that holds one (a
/// video observer, a failed `assert_eq!`) stays short.
pub(crate) struct Samples<'a>(pub(crate) &'a [f32]);

impl std::fmt::Debug for Samples<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "<{} samples>", self.0.len())
    }
}

/// Samples per parallel piece of [`scale_plane`].
const SCALE_CHUNK: usize = 1 << 16;

/// `v · factor` for every sample of `plane`, a finite product too large for `f32` saturated
/// at ±`f32::MAX` (NaN and infinite samples, and every product by a non-finite factor,
/// stay what the multiplication makes them). Without branches, so that it vectorises,
/// and in pieces on the `rayon` pool: a pass bound by memory. A `video` run's decoder
/// once made it for every frame (5 % of a `.exr` run's CPU time with `--scale`); the
/// decoders now fold such a factor into their conversion (`io::read_scaled_into`), and
/// this pass serves `--peak`, images already in memory, and inputs without a conversion.
fn scale_plane(plane: &mut [f32], factor: f32) {
    let piece = |piece: &mut [f32]| {
        if factor.is_finite() {
            for v in piece {
                let p = *v * factor;
                // A finite sample times a finite factor overflows only to ±∞: clamped.
                *v = if v.abs() <= f32::MAX {
                    p.clamp(-f32::MAX, f32::MAX)
                } else {
                    p
                };
            }
        } else {
            piece.iter_mut().for_each(|v| *v *= factor);
        }
    };
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        plane.par_chunks_mut(SCALE_CHUNK).for_each(piece);
    }
    #[cfg(not(feature = "rayon"))]
    plane.chunks_mut(SCALE_CHUNK).for_each(piece);
}

/// A high-dynamic-range image in absolute photometric units.
///
/// * `x`, `y`, `z`: CIE 1931 tristimulus values with `y` the photopic luminance in cd/m².
/// * `scotopic`: the scotopic luminance in scotopic cd/m² (CIE 1951 V'(λ), K'm = 1700 lm/W),
///   when the source carried it (the paper's own file format does). When it is `None`, the
///   operator estimates it from XYZ (see [`scotopic`](crate::scotopic)).
///
/// `clone_from` reuses the target's planes (no allocation when they are large enough).
#[derive(PartialEq)]
pub struct HdrImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// CIE X plane (same scale as `y`).
    pub x: Vec<f32>,
    /// CIE Y plane: photopic luminance in cd/m².
    pub y: Vec<f32>,
    /// CIE Z plane (same scale as `y`).
    pub z: Vec<f32>,
    /// Scotopic luminance plane in scotopic cd/m², if the file had one.
    pub scotopic: Option<Vec<f32>>,
    /// The camera view, when the file records it (Radiance `VIEW=`).
    pub view: Option<View>,
    /// True when the values are known to be absolute (cd/m²): Radiance files (179 lm/W
    /// convention), EXR files with `whiteLuminance` or the paper's X/Y/Z/scotopic layout.
    /// False when the file only holds relative values (PFM, plain EXR RGB), which the
    /// caller should scale (the CLI's `--scale` / `--peak`).
    pub absolute_units: bool,
    /// The chromaticity the scene's observer takes as white, as the file declares it
    /// (Radiance `PRIMARIES=` white, E by default; OpenEXR `adoptedNeutral`, else the
    /// `chromaticities` white; D65 for PFM; E for the built-in chart and the paper's XYZ
    /// layout), or `None` when nothing says. The operator adapts the cone image from it to
    /// the display white ([`colour::WhitePoint::Auto`](crate::colour::WhitePoint)).
    pub adopted_white: Option<crate::colour::Xy>,
}

impl Clone for HdrImage {
    fn clone(&self) -> Self {
        let mut out = HdrImage::zeros(0, 0);
        out.clone_from(self);
        out
    }

    fn clone_from(&mut self, source: &Self) {
        // Every field named, so that a field added to the image is not forgotten here.
        let HdrImage {
            width,
            height,
            x,
            y,
            z,
            scotopic,
            view,
            absolute_units,
            adopted_white,
        } = source;
        self.width = *width;
        self.height = *height;
        self.x.clone_from(x);
        self.y.clone_from(y);
        self.z.clone_from(z);
        self.scotopic.clone_from(scotopic);
        self.view = *view;
        self.absolute_units = *absolute_units;
        self.adopted_white = *adopted_white;
    }
}

/// The image's size, units, view and white, and of each plane its number of samples
/// (not its samples).
impl std::fmt::Debug for HdrImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let HdrImage {
            width,
            height,
            x,
            y,
            z,
            scotopic,
            view,
            absolute_units,
            adopted_white,
        } = self;
        f.debug_struct("HdrImage")
            .field("width", width)
            .field("height", height)
            .field("x", &Samples(x))
            .field("y", &Samples(y))
            .field("z", &Samples(z))
            .field("scotopic", &scotopic.as_deref().map(Samples))
            .field("view", view)
            .field("absolute_units", absolute_units)
            .field("adopted_white", adopted_white)
            .finish()
    }
}

impl HdrImage {
    /// An image of `width × height` pixels, all zero, without a scotopic plane.
    pub fn zeros(width: usize, height: usize) -> Self {
        let n = width * height;
        HdrImage {
            width,
            height,
            x: vec![0.0; n],
            y: vec![0.0; n],
            z: vec![0.0; n],
            scotopic: None,
            view: None,
            absolute_units: false,
            adopted_white: None,
        }
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// True if the image has no pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Multiply every luminance (X, Y, Z and scotopic) by `factor`, e.g. to turn relative
    /// values into cd/m².
    /// Finite products too large for f32 saturate at ±`f32::MAX` instead of becoming
    /// infinite (NaN and Inf samples stay what they are).
    pub fn scale(&mut self, factor: f32) {
        let planes = [&mut self.x, &mut self.y, &mut self.z]
            .into_iter()
            .chain(self.scotopic.as_mut());
        for plane in planes {
            scale_plane(plane, factor);
        }
    }

    /// The factor that rescales the image so that its highest visible luminance (the
    /// quantile of Sec. 4.4, [`highest_visible`](crate::adaptation::highest_visible), with
    /// `hot_pixel_fraction` of the pixels allowed above it) becomes `peak_cd_m2`: the
    /// paper's "scene illuminated at `peak_cd_m2`" (Sec. 5, Fig. 11).
    ///
    /// Errors if `peak_cd_m2` is not positive and finite, or if the image has no visible
    /// luminance to rescale.
    ///
    /// ```
    /// use visadapt::HdrImage;
    /// let mut scene = HdrImage::zeros(4, 1);
    /// scene.y.copy_from_slice(&[1.0, 2.0, 4.0, 8.0]);
    /// let moonlit = scene.with_peak(0.04, 0.0)?;          // highest visible 8 -> 0.04 cd/m²
    /// assert!((moonlit.y[3] - 0.04).abs() < 1e-7);
    /// # Ok::<(), visadapt::Error>(())
    /// ```
    pub fn peak_factor(&self, peak_cd_m2: f64, hot_pixel_fraction: f64) -> crate::Result<f64> {
        crate::check_luminance("peak", peak_cd_m2)?;
        if !(0.0..1.0).contains(&hot_pixel_fraction) {
            return Err(crate::Error::invalid(
                "hot-pixel-fraction",
                hot_pixel_fraction,
                "must be in [0, 1)",
            ));
        }
        let highest = crate::adaptation::highest_visible(&self.y, hot_pixel_fraction) as f64;
        if !(highest.is_finite() && highest > 0.0) {
            return Err(crate::Error::invalid(
                "peak",
                peak_cd_m2,
                "the image has no visible luminance to rescale",
            ));
        }
        Ok(peak_cd_m2 / highest)
    }

    /// The image rescaled by [`peak_factor`](Self::peak_factor): lit so that its highest
    /// visible luminance is `peak_cd_m2`. The result's values are absolute cd/m².
    pub fn with_peak(mut self, peak_cd_m2: f64, hot_pixel_fraction: f64) -> crate::Result<Self> {
        let factor = self.peak_factor(peak_cd_m2, hot_pixel_fraction)?;
        self.scale(factor as f32);
        self.absolute_units = true;
        Ok(self)
    }

    /// The X, Y, Z planes and the scotopic plane, taken out of the image, for the stages
    /// that write their result over the input's own planes ([`operator::apply_owned`],
    /// [`local::apply_owned`]).
    ///
    /// # Panics
    /// If the planes are inconsistent ([`HdrImage::check_consistent`]).
    ///
    /// [`operator::apply_owned`]: crate::operator::apply_owned
    /// [`local::apply_owned`]: crate::local::apply_owned
    pub(crate) fn into_planes(self) -> ([Vec<f32>; 3], Option<Vec<f32>>) {
        self.check_consistent()
            .expect("an image with consistent planes");
        ([self.x, self.y, self.z], self.scotopic)
    }

    /// Check that every plane has `width × height` samples.
    pub fn check_consistent(&self) -> crate::Result<()> {
        let n = self.len();
        let bad = self.x.len() != n
            || self.y.len() != n
            || self.z.len() != n
            || self.scotopic.as_ref().is_some_and(|s| s.len() != n);
        if bad || n == 0 {
            return Err(crate::Error::invalid(
                "image",
                format!("{}x{}", self.width, self.height),
                "planes must be non-empty and hold width*height samples",
            ));
        }
        Ok(())
    }
}

/// How the image maps directions to pixels, as far as acuity needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// The projection.
    pub projection: Projection,
    /// Full horizontal field of view in degrees.
    pub horizontal_deg: f64,
    /// Full vertical field of view in degrees.
    pub vertical_deg: f64,
}

/// Camera projections (the Radiance `-vt` view types).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Projection {
    /// Planar perspective (`-vtv`): pixels are uniform on the image plane.
    Perspective,
    /// Angular fisheye (`-vta`): pixels are uniform in angle from the centre.
    AngularFisheye,
    /// Hemispherical fisheye (`-vth`): pixels are uniform in sin(angle).
    HemisphericalFisheye,
    /// Cylindrical panorama (`-vtc`): uniform in angle horizontally.
    Cylindrical,
    /// Stereographic planisphere (`-vts`).
    Planisphere,
    /// Parallel (`-vtl`): no angular extent, acuity cannot be derived from it.
    Parallel,
}

impl View {
    /// A perspective view with the given horizontal field of view, the vertical one
    /// following from the aspect ratio.
    pub fn perspective(horizontal_deg: f64, width: usize, height: usize) -> Self {
        let half = (horizontal_deg.to_radians() / 2.0).tan() * height as f64 / width as f64;
        View {
            projection: Projection::Perspective,
            horizontal_deg,
            vertical_deg: 2.0 * half.atan().to_degrees(),
        }
    }

    /// An angular fisheye view (Radiance `-vta`) with the given horizontal field of view,
    /// the vertical one in proportion to the image's height (pixels uniform in angle).
    pub fn angular_fisheye(horizontal_deg: f64, width: usize, height: usize) -> Self {
        View {
            projection: Projection::AngularFisheye,
            horizontal_deg,
            vertical_deg: horizontal_deg * height as f64 / width as f64,
        }
    }

    /// Pixels per degree of visual angle at the image centre, where the eye looks, for an
    /// image `width` pixels wide. `None` for a parallel view or a degenerate angle.
    ///
    /// * perspective: `(W/2) / tan(fov/2) · π/180` (the derivative of the projection at the centre);
    /// * angular fisheye and cylindrical: `W / fov` (uniform in angle);
    /// * hemispherical fisheye (`r ∝ sin θ`, `r = W/2` at `θ = fov/2`): `(W/2)/sin(fov/2) · π/180`;
    /// * planisphere (`r ∝ tan(θ/2)`): `(W/2)/(2 tan(fov/4)) · π/180`.
    pub fn pixels_per_degree(&self, width: usize) -> Option<f64> {
        let w = width as f64;
        let fov = self.horizontal_deg;
        if !(fov.is_finite() && fov > 0.0) {
            return None;
        }
        let deg = std::f64::consts::PI / 180.0;
        let half = (fov / 2.0).to_radians();
        let ppd = match self.projection {
            Projection::Perspective if fov < 180.0 => (w / 2.0) / half.tan() * deg,
            Projection::Perspective => return None,
            Projection::AngularFisheye | Projection::Cylindrical => w / fov,
            Projection::HemisphericalFisheye => (w / 2.0) / half.sin().max(1e-9) * deg,
            Projection::Planisphere => (w / 2.0) / (2.0 * (half / 2.0).tan()) * deg,
            Projection::Parallel => return None,
        };
        (ppd.is_finite() && ppd > 0.0).then_some(ppd)
    }
}

/// What the display shows: linear display RGB (Rec. 709 / sRGB primaries, D65 white),
/// planar, relative to the display maximum luminance (1.0 = `L_dmax`), each value in
/// `[0, 1]`. `DisplayImage::default()` is an empty image, for buffers that
/// [`operator::apply_into`](crate::operator::apply_into) fills and reuses.
#[derive(Clone, Default, PartialEq)]
pub struct DisplayImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear red plane.
    pub r: Vec<f32>,
    /// Linear green plane.
    pub g: Vec<f32>,
    /// Linear blue plane.
    pub b: Vec<f32>,
    /// The display maximum luminance in cd/m² that 1.0 stands for.
    pub display_max_cd_m2: f32,
}

/// The image's size and display maximum, and of each plane its number of samples (not
/// its samples).
impl std::fmt::Debug for DisplayImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let DisplayImage {
            width,
            height,
            r,
            g,
            b,
            display_max_cd_m2,
        } = self;
        f.debug_struct("DisplayImage")
            .field("width", width)
            .field("height", height)
            .field("r", &Samples(r))
            .field("g", &Samples(g))
            .field("b", &Samples(b))
            .field("display_max_cd_m2", display_max_cd_m2)
            .finish()
    }
}

impl DisplayImage {
    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// True if the image has no pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Check what every display writer needs (PNG, JPEG, raw frames, and through
    /// [`validate`](Self::validate) OpenEXR, TIFF and Radiance): a non-empty image whose
    /// three planes hold `width × height` samples.
    pub fn validate_planes(&self) -> crate::Result<()> {
        let n = self.width.checked_mul(self.height).unwrap_or(0);
        if n == 0 || [&self.r, &self.g, &self.b].iter().any(|p| p.len() != n) {
            return Err(crate::Error::invalid(
                "image",
                format!("{}x{}", self.width, self.height),
                "planes must be non-empty and hold width*height samples",
            ));
        }
        Ok(())
    }

    /// Check what the writers that record the display maximum need (OpenEXR, TIFF,
    /// Radiance): [`validate_planes`](Self::validate_planes), and a positive, finite
    /// [`display_max_cd_m2`](Self::display_max_cd_m2). (The sRGB encodings, PNG, JPEG and
    /// raw frames, do not depend on it: a display maximum below the smallest `f32`, which
    /// rounds to 0, still encodes.)
    ///
    /// ```
    /// use visadapt::DisplayImage;
    /// let mut image = DisplayImage { width: 2, height: 1, r: vec![0.5; 2], g: vec![0.5; 2],
    ///                                b: vec![0.5; 2], display_max_cd_m2: 100.0 };
    /// assert!(image.validate().is_ok());
    /// image.display_max_cd_m2 = 0.0;
    /// assert!(image.validate().is_err() && image.validate_planes().is_ok());
    /// image.b.pop();
    /// assert!(image.validate_planes().is_err());
    /// ```
    pub fn validate(&self) -> crate::Result<()> {
        self.validate_planes()?;
        let l = self.display_max_cd_m2;
        if !(l.is_finite() && l > 0.0) {
            return Err(crate::Error::invalid(
                "display-max",
                l,
                "must be a positive, finite luminance in cd/m²",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `clone_from` gives an image equal to its source in every field, whatever the
    /// target held before (larger or smaller planes, a scotopic plane or none, another
    /// view, units and white), and reuses the target's planes when they are large enough.
    #[test]
    fn clone_from_copies_every_field_and_reuses_planes() {
        let mut a = HdrImage::zeros(4, 3);
        a.x[5] = 2.0;
        a.scotopic = Some(vec![1.5; 12]);
        a.view = Some(View::perspective(40.0, 4, 3));
        a.absolute_units = true;
        a.adopted_white = Some([0.3127, 0.329]);
        let b = HdrImage::zeros(2, 2);
        let mut target = HdrImage::zeros(5, 5);
        for source in [&a, &b, &a, &a] {
            target.clone_from(source);
            assert!(target == *source);
        }
        let plane = target.y.as_ptr();
        target.clone_from(&a);
        assert_eq!(target.y.as_ptr(), plane, "the plane was reallocated");
        assert!(a.clone() == a);
    }

    /// `Debug` shows each plane's number of samples, not the samples (it printed all of
    /// them: megabytes of text for a photograph).
    #[test]
    fn debug_shows_each_planes_size_not_its_samples() {
        let (w, h) = (640, 480);
        let mut hdr = HdrImage::zeros(w, h);
        hdr.scotopic = Some(vec![1.0; w * h]);
        let shown = format!("{hdr:?}");
        assert_eq!(shown.matches("<307200 samples>").count(), 4, "{shown}");
        assert!(shown.len() < 300 && shown.contains("width: 640"), "{shown}");
        let display = DisplayImage {
            width: w,
            height: h,
            r: vec![0.5; w * h],
            g: vec![0.5; w * h],
            b: vec![0.5; w * h],
            display_max_cd_m2: 100.0,
        };
        let shown = format!("{display:?}");
        assert_eq!(shown.matches("<307200 samples>").count(), 3, "{shown}");
        assert!(
            shown.len() < 200 && shown.contains("display_max_cd_m2: 100.0"),
            "{shown}"
        );
    }

    #[test]
    fn scale_is_the_saturating_product_of_every_sample() {
        // The rule one sample at a time: the product, or ±MAX where a finite sample times
        // a finite factor overflowed.
        let rule = |v: f32, f: f32| {
            let p = v * f;
            if p.is_infinite() && v.is_finite() && f.is_finite() {
                f32::MAX.copysign(p)
            } else {
                p
            }
        };
        let specials = [
            0.0f32,
            -0.0,
            1.0,
            -2.5,
            f32::MAX,
            -f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            3e38,
            -1e30,
            f32::MIN_POSITIVE,
            1e-45,
        ];
        // Longer than one parallel piece, with the specials spread through it.
        let n = 3 * SCALE_CHUNK + 17;
        let plane: Vec<f32> = (0..n)
            .map(|i| {
                if i % 101 == 0 {
                    specials[(i / 101) % specials.len()]
                } else {
                    (i as f32 * 0.37).sin() * 1e3
                }
            })
            .collect();
        for f in [
            0.0f32,
            1.0,
            179.0,
            1e10,
            -3.0,
            1e-40,
            f32::INFINITY,
            f32::NAN,
        ] {
            let mut image = HdrImage::zeros(n, 1);
            image.x.clone_from(&plane);
            image.y.clone_from(&plane);
            image.z.clone_from(&plane);
            image.scotopic = Some(plane.clone());
            image.scale(f);
            for got in [
                &image.x,
                &image.y,
                &image.z,
                image.scotopic.as_ref().unwrap(),
            ] {
                for (i, (&g, &v)) in got.iter().zip(&plane).enumerate() {
                    let want = rule(v, f);
                    assert!(
                        g.to_bits() == want.to_bits() || (g.is_nan() && want.is_nan()),
                        "{v} × {f} at {i}: {g}, not {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn with_peak_rescales_the_highest_visible_luminance() {
        // 1000 pixels, one hot pixel at 1e6: with the default 0.1 % allowed above, the
        // highest visible luminance is the largest of the others, 998.
        let mut scene = HdrImage::zeros(1000, 1);
        for (i, v) in scene.y.iter_mut().enumerate() {
            *v = i as f32;
        }
        scene.y[999] = 1e6;
        scene.x = scene.y.clone();
        let f = scene.peak_factor(0.05, 1e-3).unwrap();
        assert!((f - 0.05 / 998.0).abs() < 1e-12, "{f}");
        let lit = scene.clone().with_peak(0.05, 1e-3).unwrap();
        assert!((lit.y[998] as f64 - 0.05).abs() < 1e-8);
        assert!((lit.x[500] as f64 - 500.0 * 0.05 / 998.0).abs() < 1e-8);
        assert!(lit.absolute_units);
    }

    #[test]
    fn with_peak_refuses_what_it_cannot_do() {
        let dark = HdrImage::zeros(4, 4);
        assert!(matches!(
            dark.peak_factor(1.0, 0.0),
            Err(crate::Error::InvalidParameter { name: "peak", .. })
        ));
        let mut lit = HdrImage::zeros(4, 4);
        lit.y.fill(1.0);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(lit.peak_factor(bad, 0.0).is_err(), "{bad}");
        }
        assert!(lit.peak_factor(1.0, 1.0).is_err());
    }
}
