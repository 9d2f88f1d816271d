//! `visadapt.HdrImage` and the functions that make or write images: `read`, `from_array`,
//! `from_rgb`, `chart`, `write`.

use crate::convert::{interleave, plane, planes3, samples, to_array2, to_array3};
use crate::errors::{detached, to_py};
use numpy::{PyArray2, PyArray3};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use visadapt::chart::{Chart, ChartOptions};
use visadapt::colour::{self, Chromaticities};
use visadapt::io::{self, OutputFormat};
use visadapt::report::projection_label;
use visadapt::{DisplayImage, Limits, Projection, View};

/// An HDR image in absolute units: CIE XYZ with Y in cd/m², and optionally a scotopic
/// luminance plane in scotopic cd/m². Immutable; build one with `read`, `from_array`,
/// `from_rgb` or `chart`.
#[pyclass(frozen, module = "visadapt")]
pub struct HdrImage {
    pub inner: visadapt::HdrImage,
}

#[pymethods]
impl HdrImage {
    /// CIE XYZ, an H × W × 3 float32 array, Y in cd/m² (a new copy on each access).
    #[getter]
    fn xyz<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let i = &self.inner;
        let samples = detached(py, || Ok(interleave([&i.x, &i.y, &i.z])))?;
        to_array3(py, i.width, i.height, samples)
    }

    /// The scotopic luminance, an H × W float32 array in scotopic cd/m², or `None` when the
    /// image has no scotopic plane (the model then estimates it from XYZ).
    #[getter]
    fn scotopic<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f32>>>> {
        let i = &self.inner;
        i.scotopic
            .as_ref()
            .map(|s| to_array2(py, i.width, i.height, s.clone()))
            .transpose()
    }

    /// The camera view recorded with the image, as a dict with `projection`,
    /// `horizontal_fov_deg` and `vertical_fov_deg` (degrees), or `None`.
    #[getter]
    fn view<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.inner.view.map(|v| view_dict(py, &v)).transpose()
    }

    /// Width in pixels.
    #[getter]
    fn width(&self) -> usize {
        self.inner.width
    }

    /// Height in pixels.
    #[getter]
    fn height(&self) -> usize {
        self.inner.height
    }

    /// Whether the values are known to be absolute (cd/m²): true for Radiance files, EXR
    /// files that say so, and images built from arrays; false for PFM and plain EXR RGB,
    /// which `map(..., scale=...)` or `peak=...` should bring to cd/m².
    #[getter]
    fn absolute_units(&self) -> bool {
        self.inner.absolute_units
    }

    fn __repr__(&self) -> String {
        let i = &self.inner;
        format!(
            "<visadapt.HdrImage {}x{}{}{}>",
            i.width,
            i.height,
            if i.scotopic.is_some() {
                ", with scotopic plane"
            } else {
                ""
            },
            match &i.view {
                Some(v) => format!(
                    ", {} {} deg",
                    projection_label(v.projection),
                    v.horizontal_deg
                ),
                None => String::new(),
            }
        )
    }
}

fn view_dict<'py>(py: Python<'py>, v: &View) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("projection", projection_label(v.projection))?;
    d.set_item("horizontal_fov_deg", v.horizontal_deg)?;
    d.set_item("vertical_fov_deg", v.vertical_deg)?;
    Ok(d)
}

const PROJECTIONS: [Projection; 6] = [
    Projection::Perspective,
    Projection::AngularFisheye,
    Projection::HemisphericalFisheye,
    Projection::Cylindrical,
    Projection::Planisphere,
    Projection::Parallel,
];

/// A view from a dict like the one `HdrImage.view` returns (`projection` defaults to
/// perspective, `vertical_fov_deg` to the one the aspect ratio gives), or from a number:
/// the horizontal field of view of a perspective view, degrees.
fn parse_view(obj: &Bound<'_, PyAny>, width: usize, height: usize) -> PyResult<View> {
    if let Ok(fov) = obj.extract::<f64>() {
        return Ok(View::perspective(fov, width, height));
    }
    let d = obj
        .cast::<PyDict>()
        .map_err(|_| PyTypeError::new_err("view must be a dict or a field of view in degrees"))?;
    for key in d.keys() {
        let key: String = key.extract()?;
        if !["projection", "horizontal_fov_deg", "vertical_fov_deg"].contains(&key.as_str()) {
            return Err(PyValueError::new_err(format!(
                "view: unknown key '{key}' (projection, horizontal_fov_deg, vertical_fov_deg)"
            )));
        }
    }
    let fov: f64 = d
        .get_item("horizontal_fov_deg")?
        .ok_or_else(|| PyValueError::new_err("view needs 'horizontal_fov_deg'"))?
        .extract()?;
    let projection = match d.get_item("projection")? {
        None => Projection::Perspective,
        Some(p) => {
            let name: String = p.extract()?;
            PROJECTIONS
                .into_iter()
                .find(|&p| projection_label(p) == name)
                .ok_or_else(|| {
                    let names: Vec<&str> =
                        PROJECTIONS.iter().map(|&p| projection_label(p)).collect();
                    PyValueError::new_err(format!(
                        "view: unknown projection '{name}' ({})",
                        names.join(", ")
                    ))
                })?
        }
    };
    let mut view = match projection {
        Projection::AngularFisheye => View::angular_fisheye(fov, width, height),
        _ => View::perspective(fov, width, height),
    };
    view.projection = projection;
    if let Some(v) = d.get_item("vertical_fov_deg")? {
        view.vertical_deg = v.extract()?;
    }
    Ok(view)
}

fn wrap(inner: visadapt::HdrImage) -> PyResult<HdrImage> {
    inner.check_consistent().map_err(|e| to_py(e, None))?;
    Ok(HdrImage { inner })
}

/// Read an HDR image: Radiance (.hdr, .pic), OpenEXR or PFM, detected from the file's first
/// bytes; or an 8/16-bit PNG, JPEG or TIFF photograph (LDR input).
///
/// A photograph is display-referred: its sRGB curve is undone (IEC 61966-2-1), its
/// primaries taken as Rec. 709 with a D65 white, and code-value white read as Y = 1 in
/// relative units (`HdrImage.absolute_units` is False). State the luminance of that white
/// with `map(image, scale=...)` (e.g. `scale=0.05`: the photo's white at 0.05 cd/m²) or
/// `peak=`. Such a photo is already tone-mapped and clipped by its camera, so the result
/// is an illustration, not a prediction. No ICC profile is read.
///
/// Args:
///     path: the file.
///     max_pixels: refuse images larger than this many pixels (default 2**28), before
///         anything is allocated.
///     max_memory_bytes: memory budget for reading, bytes (default 12 GiB).
///     scale: multiply every value by this (keyword only; the file's unit in cd/m², e.g.
///         179 for Radiance-style radiance in W/sr/m²), as `map(image, scale=...)` would,
///         but applied by the decoder as it converts (no pass of its own for Radiance and
///         OpenEXR files). `absolute_units` stays what the file says.
///
/// Returns:
///     HdrImage: XYZ in cd/m² (see `HdrImage.absolute_units` for files without units).
///
/// Raises:
///     OSError: the file cannot be read.
///     DecodeError: the file is corrupt or truncated (UnsupportedError: a format or feature
///         visadapt does not read).
///     ValueError: the image exceeds `max_pixels` or `max_memory_bytes`, or `scale` is
///         not a positive finite number.
#[pyfunction]
#[pyo3(signature = (path, max_pixels = None, max_memory_bytes = None, *, scale = None))]
pub fn read(
    py: Python<'_>,
    path: PathBuf,
    max_pixels: Option<u64>,
    max_memory_bytes: Option<u64>,
    scale: Option<f64>,
) -> PyResult<HdrImage> {
    let factor = match scale {
        None => 1.0,
        Some(s) if s.is_finite() && s > 0.0 && (s as f32).is_finite() => s as f32,
        Some(s) => {
            let e = visadapt::Error::invalid("scale", s, "must be a positive, finite number");
            return Err(to_py(e, Some(&path)));
        }
    };
    let defaults = Limits::default();
    let limits = Limits {
        max_pixels: max_pixels.unwrap_or(defaults.max_pixels),
        max_memory_bytes: max_memory_bytes.unwrap_or(defaults.max_memory_bytes),
    };
    let image = detached(py, || {
        io::read_scaled(&path, &limits, factor).map_err(|e| to_py(e, Some(&path)))
    })?;
    wrap(image)
}

/// An image from numpy arrays in absolute units.
///
/// Args:
///     xyz: CIE XYZ, H × W × 3, float32 or float64 (any memory order), Y in cd/m².
///     scotopic: scotopic luminance, H × W, scotopic cd/m²; `None` to let the model
///         estimate it from XYZ.
///     view: a dict as `HdrImage.view` returns, or the horizontal field of view in degrees
///         of a perspective view; `None` for none (the model then assumes 60 degrees).
///
/// NaN, infinite and negative values are kept: `map` shows non-finite pixels black and
/// reads negative channels as 0, and counts both in its report.
#[pyfunction]
#[pyo3(signature = (xyz, scotopic = None, view = None))]
pub fn from_array(
    xyz: &Bound<'_, PyAny>,
    scotopic: Option<&Bound<'_, PyAny>>,
    view: Option<&Bound<'_, PyAny>>,
) -> PyResult<HdrImage> {
    let (width, height, [x, y, z]) = planes3(xyz, "xyz")?;
    build(width, height, [x, y, z], scotopic, view)
}

fn build(
    width: usize,
    height: usize,
    [x, y, z]: [Vec<f32>; 3],
    scotopic: Option<&Bound<'_, PyAny>>,
    view: Option<&Bound<'_, PyAny>>,
) -> PyResult<HdrImage> {
    let scotopic = scotopic
        .map(|s| plane(s, "scotopic", width, height))
        .transpose()?;
    let view = view.map(|v| parse_view(v, width, height)).transpose()?;
    wrap(visadapt::HdrImage {
        width,
        height,
        x,
        y,
        z,
        scotopic,
        view,
        absolute_units: true,
        // Arrays from numpy declare no white: shown as they are (D65 assumed).
        adopted_white: None,
    })
}

fn parse_primaries(obj: &Bound<'_, PyAny>) -> PyResult<Chromaticities> {
    if let Ok(name) = obj.extract::<String>() {
        return match name.to_ascii_lowercase().as_str() {
            "rec709" | "srgb" | "bt709" => Ok(colour::REC709),
            "radiance" => Ok(colour::RADIANCE_DEFAULT),
            _ => Err(PyValueError::new_err(format!(
                "unknown primaries '{name}' (rec709, srgb, radiance, or ((xr, yr), (xg, yg), (xb, yb), (xw, yw)))"
            ))),
        };
    }
    let [red, green, blue, white]: [[f64; 2]; 4] = obj.extract().map_err(|_| {
        PyTypeError::new_err(
            "primaries must be a name or ((xr, yr), (xg, yg), (xb, yb), (xw, yw)) chromaticities",
        )
    })?;
    Ok(Chromaticities {
        red,
        green,
        blue,
        white,
    })
}

/// An image from linear RGB in given primaries, converted to XYZ.
///
/// Args:
///     rgb: linear RGB, H × W × 3, float32 or float64 (any memory order).
///     primaries: "rec709" (also "srgb"), "radiance" (Radiance's default primaries with
///         an equal-energy white), or CIE xy chromaticities
///         ((xr, yr), (xg, yg), (xb, yb), (xw, yw)).
///     scale: multiplies the values to give cd/m² (e.g. 179 for Radiance's W/sr/m²).
///     scotopic, view: as in `from_array` (the scotopic plane is not scaled).
#[pyfunction]
#[pyo3(signature = (rgb, primaries = None, scale = 1.0, scotopic = None, view = None))]
pub fn from_rgb(
    rgb: &Bound<'_, PyAny>,
    primaries: Option<&Bound<'_, PyAny>>,
    scale: f64,
    scotopic: Option<&Bound<'_, PyAny>>,
    view: Option<&Bound<'_, PyAny>>,
) -> PyResult<HdrImage> {
    let chromaticities = match primaries {
        Some(p) => parse_primaries(p)?,
        None => colour::REC709,
    };
    if !(scale.is_finite() && scale > 0.0) {
        return Err(to_py(
            visadapt::Error::invalid("scale", scale, "must be a positive, finite number"),
            None,
        ));
    }
    let m = chromaticities.rgb_to_xyz().ok_or_else(|| {
        PyValueError::new_err("primaries are degenerate (collinear, or a white with y = 0)")
    })?;
    let (width, height, [mut r, mut g, mut b]) = planes3(rgb, "rgb")?;
    colour::rgb_planes_to_xyz(&m, scale, &mut r, &mut g, &mut b);
    build(width, height, [r, g, b], scotopic, view)
}

/// The paper's test scene (Sec. 5, Fig. 11): a Macbeth ColorChecker, a Snellen chart and
/// square-wave gratings under an equal-energy illuminant, with its scotopic plane and view.
///
/// Args:
///     white: luminance of the white patch and the chart's paper, cd/m².
///     fov: horizontal field of view of the whole scene, degrees (default: 120 pixels per
///         degree at the Snellen design distance of 6.096 m).
///     gratings: draw the gratings.
#[pyfunction]
#[pyo3(signature = (white = 100.0, fov = None, gratings = true))]
pub fn chart(py: Python<'_>, white: f64, fov: Option<f64>, gratings: bool) -> PyResult<HdrImage> {
    let image = detached(py, || {
        let options = match fov {
            Some(fov) => ChartOptions::with_fov(white, fov, gratings),
            None => Ok(ChartOptions {
                white_cd_m2: white,
                gratings,
                ..ChartOptions::default()
            }),
        }
        .map_err(|e| to_py(e, None))?;
        Ok(Chart::new(&options).map_err(|e| to_py(e, None))?.image)
    })?;
    wrap(image)
}

/// Write an image, atomically (the file appears complete or not at all).
///
/// Args:
///     path: .png, .jpg/.jpeg or .exr.
///     data: a display image (H × W × 3 linear sRGB relative to the display maximum, as
///         `map` returns) for any format; an `HdrImage` (.exr only: X, Y, Z in cd/m² and
///         scotopic); or one H × W plane in cd/m², e.g. a `tolerance` map (.exr only).
///     bits: 8 or 16 bits per channel for PNG.
///     png_compression: "fast" (the default), "fastest", "rle" or "fdeflate" for PNG:
///         lossless at every level (the same pixels), different file sizes and times.
///     quality: 1 to 100 for JPEG.
///     display_max: the display maximum in cd/m² that 1.0 stands for, recorded in an EXR
///         display image (`whiteLuminance`); give the one passed to `map`.
#[pyfunction]
#[pyo3(signature = (path, data, *, bits = 8, png_compression = "fast", quality = 90, display_max = 80.0))]
pub fn write(
    py: Python<'_>,
    path: PathBuf,
    data: &Bound<'_, PyAny>,
    bits: u8,
    png_compression: &str,
    quality: u8,
    display_max: f64,
) -> PyResult<()> {
    // An unknown extension is the caller's parameter, not a file's content.
    let format =
        OutputFormat::from_path(&path).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let compression: io::display::PngCompression = png_compression
        .parse()
        .map_err(|e: visadapt::Error| PyValueError::new_err(e.to_string()))?;
    let exr_only = || {
        PyValueError::new_err(format!(
            "{}: HDR images and luminance planes are written as OpenEXR (use .exr)",
            path.display()
        ))
    };
    if let Ok(image) = data.cast::<HdrImage>() {
        if format != OutputFormat::Exr {
            return Err(exr_only());
        }
        let image = &image.get().inner;
        return detached(py, || {
            io::display::write_atomically(&path, |w| io::exr::write_hdr(image, w))
                .map_err(|e| to_py(e, Some(&path)))
        });
    }
    let s = samples(data, "data")?;
    match s.shape.as_slice() {
        &[height, width] => {
            if format != OutputFormat::Exr {
                return Err(exr_only());
            }
            detached(py, || {
                io::display::write_atomically(&path, |w| {
                    io::exr::write_luminance(width, height, &s.data, w)
                })
                .map_err(|e| to_py(e, Some(&path)))
            })
        }
        &[_, _, 3] => {
            let (width, height, [r, g, b]) = planes3(data, "data")?;
            let image = DisplayImage {
                width,
                height,
                r,
                g,
                b,
                display_max_cd_m2: display_max as f32,
            };
            let format = match format {
                OutputFormat::Png { .. } => OutputFormat::Png { bits, compression },
                OutputFormat::Jpeg { .. } => OutputFormat::Jpeg { quality },
                f => f,
            };
            detached(py, || {
                io::write_display(&image, &path, format).map_err(|e| to_py(e, Some(&path)))
            })
        }
        other => Err(PyValueError::new_err(format!(
            "data must be an HdrImage, an H x W x 3 display image or an H x W plane, got shape {other:?}"
        ))),
    }
}
