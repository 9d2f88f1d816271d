//! Keyword arguments to viewing conditions: one parser shared by `map`, `visible`,
//! `tolerance` and `Adaptation`, so that every function takes the same names.

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::borrow::Cow;
use visadapt::acuity::AcuityThreshold;
use visadapt::glare::Glare;
use visadapt::local::LocalAdaptation;
use visadapt::operator::{AdaptationMode, ViewingConditions};
use visadapt::timecourse::Undershoot;
use visadapt::{Error, HdrImage, Projection, View};

/// The keyword arguments every function that maps an image accepts, with their meaning
/// (the `.pyi` stubs and docstrings say the same).
pub const KEYWORDS: &[&str] = &[
    "peak",                // scale the image so that its highest visible luminance is this, cd/m²
    "scale",               // multiply the image by this to get cd/m²
    "display_max",         // L_dmax, cd/m²
    "display_adaptation",  // L_da, cd/m²
    "world_adaptation",    // L_wa, cd/m²
    "scotopic_adaptation", // world rod adaptation, scotopic cd/m²
    "hot_pixel_fraction",  // fraction of pixels allowed above the highest visible luminance
    "fov",                 // horizontal field of view, degrees
    "projection",          // of the fov: "perspective" (default) or "fisheye" (angular)
    "acuity",              // apply the acuity blur (Eq. 7)
    "acuity_threshold", // Eq. 7's threshold contrast: "pooled" (default) or "envelope" (the paper)
    "white_point",      // scene white for CAT16: "auto" (default), "none", "E", "D65", "x,y"
    "adaptation",       // "global" (the paper, default) or "local" (per pixel)
    "adaptation_radius", // neighbourhood of local adaptation, degrees
    "glare",            // veiling glare in the eye (CIE 135/1), off by default
    "age",              // glare observer's age, years
    "pigmentation",     // glare observer's eye pigmentation (0 dark to 1.2 light blue)
    "undershoot",       // time course: "clamped" (default) or "in-mapping" (the paper)
];

/// Parsed keyword arguments.
#[derive(Debug, Clone)]
pub struct Options {
    /// Everything but the view (it needs the image's size).
    pub conditions: ViewingConditions,
    pub fov_deg: Option<f64>,
    /// The projection of `fov_deg`'s view (perspective or angular fisheye).
    pub projection: Option<Projection>,
    pub scale: Option<f64>,
    pub peak: Option<f64>,
    /// `adaptation_radius`, degrees (with `adaptation="local"`).
    pub adaptation_radius_deg: Option<f64>,
    /// `glare`, with the observer's `age` and `pigmentation`.
    pub glare: bool,
    pub age_years: Option<f64>,
    pub pigmentation: Option<f64>,
}

/// The options of local adaptation: those already set, or the defaults.
fn local_options(current: &AdaptationMode) -> LocalAdaptation {
    match current {
        AdaptationMode::Local(l) => *l,
        AdaptationMode::Global => LocalAdaptation::default(),
    }
}

impl Options {
    /// Parse `kwargs` for the function `function` (named in errors). `None` values mean the
    /// default; an unknown name is a `TypeError`, as Python's own calls give.
    pub fn parse(function: &str, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut o = Options {
            conditions: ViewingConditions::default(),
            fov_deg: None,
            projection: None,
            scale: None,
            peak: None,
            adaptation_radius_deg: None,
            glare: false,
            age_years: None,
            pigmentation: None,
        };
        let Some(kwargs) = kwargs else {
            return Ok(o);
        };
        for (key, value) in kwargs.iter() {
            let key: String = key.extract()?;
            if !KEYWORDS.contains(&key.as_str()) {
                return Err(PyTypeError::new_err(format!(
                    "{function}() got an unexpected keyword argument '{key}'"
                )));
            }
            if value.is_none() {
                continue;
            }
            let c = &mut o.conditions;
            match key.as_str() {
                "peak" => o.peak = Some(value.extract()?),
                "scale" => o.scale = Some(value.extract()?),
                "display_max" => c.display_max_cd_m2 = value.extract()?,
                "display_adaptation" => c.display_adaptation_cd_m2 = Some(value.extract()?),
                "world_adaptation" => c.world_adaptation_cd_m2 = Some(value.extract()?),
                "scotopic_adaptation" => c.world_adaptation_scotopic_cd_m2 = Some(value.extract()?),
                "hot_pixel_fraction" => c.hot_pixel_fraction = value.extract()?,
                "fov" => o.fov_deg = Some(value.extract()?),
                "acuity" => c.acuity = value.extract()?,
                "acuity_threshold" => {
                    let name: String = value.extract()?;
                    c.acuity_threshold = match name.as_str() {
                        "pooled" => AcuityThreshold::Pooled,
                        "envelope" => AcuityThreshold::Envelope,
                        _ => {
                            return Err(PyValueError::new_err(format!(
                                "invalid acuity_threshold '{name}': pooled or envelope"
                            )));
                        }
                    }
                }
                "white_point" => {
                    let name: String = value.extract()?;
                    c.white_point = name.parse().map_err(|e: String| {
                        PyValueError::new_err(format!("invalid white_point: {e}"))
                    })?;
                }
                "adaptation" => {
                    let name: String = value.extract()?;
                    c.adaptation = match name.as_str() {
                        "global" => AdaptationMode::Global,
                        "local" => AdaptationMode::Local(local_options(&c.adaptation)),
                        _ => {
                            return Err(PyValueError::new_err(format!(
                                "invalid adaptation '{name}': global or local"
                            )));
                        }
                    }
                }
                "adaptation_radius" => o.adaptation_radius_deg = Some(value.extract()?),
                "glare" => o.glare = value.extract()?,
                "age" => o.age_years = Some(value.extract()?),
                "pigmentation" => o.pigmentation = Some(value.extract()?),
                "undershoot" => {
                    let name: String = value.extract()?;
                    c.undershoot = match name.as_str() {
                        "clamped" => Undershoot::Clamped,
                        "in-mapping" => Undershoot::InMapping,
                        _ => {
                            return Err(PyValueError::new_err(format!(
                                "invalid undershoot '{name}': clamped or in-mapping"
                            )));
                        }
                    }
                }
                "projection" => {
                    let name: String = value.extract()?;
                    o.projection = Some(match name.as_str() {
                        "perspective" => Projection::Perspective,
                        "fisheye" => Projection::AngularFisheye,
                        _ => {
                            return Err(PyValueError::new_err(format!(
                                "invalid projection '{name}': perspective or fisheye"
                            )));
                        }
                    })
                }
                _ => {} // checked against KEYWORDS above
            }
        }
        o.finish()?;
        Ok(o)
    }

    /// The keywords that refine others: the radius of local adaptation, the glare
    /// observer. Each needs the option it refines.
    fn finish(&mut self) -> PyResult<()> {
        let c = &mut self.conditions;
        if let Some(r) = self.adaptation_radius_deg {
            match &mut c.adaptation {
                AdaptationMode::Local(l) => l.radius_deg = r,
                AdaptationMode::Global => {
                    return Err(PyValueError::new_err(
                        "adaptation_radius: give adaptation='local' too",
                    ));
                }
            }
        }
        if self.glare {
            let mut g = Glare::default();
            if let Some(a) = self.age_years {
                g.age_years = a;
            }
            if let Some(p) = self.pigmentation {
                g.pigmentation = p;
            }
            c.glare = Some(g);
        } else if self.age_years.is_some() || self.pigmentation.is_some() {
            return Err(PyValueError::new_err(
                "age and pigmentation describe the glare observer: give glare=True too",
            ));
        }
        Ok(())
    }

    /// Check every value before any pixel is touched.
    fn validate(&self) -> visadapt::Result<()> {
        let positive = |name, v: Option<f64>| match v {
            Some(v) if !(v.is_finite() && v > 0.0) => {
                Err(Error::invalid(name, v, "must be a positive, finite number"))
            }
            _ => Ok(()),
        };
        positive("scale", self.scale)?;
        positive("peak", self.peak)?;
        positive("fov", self.fov_deg)?;
        if self.projection.is_some() && self.fov_deg.is_none() {
            return Err(Error::invalid(
                "projection",
                "without fov",
                "give the field of view (fov) it projects",
            ));
        }
        if self.scale.is_some() && self.peak.is_some() {
            return Err(Error::invalid(
                "peak",
                self.peak.unwrap_or_default(),
                "give either scale or peak, not both",
            ));
        }
        self.conditions.validate()
    }

    /// The factor that turns `image`'s values into cd/m²: `scale`, or `peak` over its highest
    /// visible luminance ([`HdrImage::peak_factor`]), or 1.
    pub fn input_scale(&self, image: &HdrImage) -> visadapt::Result<f64> {
        match (self.scale, self.peak) {
            (Some(s), _) => Ok(s),
            (None, Some(peak)) => image.peak_factor(peak, self.conditions.hot_pixel_fraction),
            (None, None) => Ok(1.0),
        }
    }

    /// Check the options, bring `image` to cd/m² and give the viewing conditions for it
    /// (the `fov` becomes a perspective view of its size).
    pub fn prepare<'a>(&self, image: &'a HdrImage) -> visadapt::Result<Prepared<'a>> {
        self.validate()?;
        let scale = self.input_scale(image)?;
        let image = scaled(image, scale);
        let conditions = ViewingConditions {
            view: self.fov_deg.map(|fov| match self.projection {
                Some(Projection::AngularFisheye) => {
                    View::angular_fisheye(fov, image.width, image.height)
                }
                _ => View::perspective(fov, image.width, image.height),
            }),
            ..self.conditions.clone()
        };
        Ok(Prepared {
            image,
            conditions,
            scale,
        })
    }
}

/// An image in cd/m² with the conditions to view it under.
pub struct Prepared<'a> {
    /// The image, scaled (a copy) or as given.
    pub image: Cow<'a, HdrImage>,
    pub conditions: ViewingConditions,
    /// The factor applied to the caller's values.
    pub scale: f64,
}

/// `image` multiplied by `scale` (borrowed when the scale is 1: the caller's image is never
/// changed).
pub fn scaled(image: &HdrImage, scale: f64) -> Cow<'_, HdrImage> {
    if scale == 1.0 {
        Cow::Borrowed(image)
    } else {
        let mut copy = image.clone();
        copy.scale(scale as f32);
        Cow::Owned(copy)
    }
}
