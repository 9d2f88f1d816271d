//! Keyword arguments to viewing conditions: one parser shared by `map`, `visible`,
//! `tolerance` and `Adaptation`, so that every function takes the same names.

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::borrow::Cow;
use visadapt::operator::ViewingConditions;
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
        Ok(o)
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
