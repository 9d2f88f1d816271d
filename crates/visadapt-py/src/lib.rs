//! `import visadapt`: the visadapt library for Python, with numpy arrays in and out.
//!
//! A thin layer: it turns numpy arrays into the library's planar images and back, keyword
//! arguments into [`ViewingConditions`](visadapt::operator::ViewingConditions), the
//! library's reports into dicts (the same [`visadapt::report`] objects the CLI prints with
//! `--json`) and its errors into Python exceptions. No model code lives here.
//!
//! Every call that touches pixels runs with the GIL released, inside a guard that turns a
//! Rust panic into a `RuntimeError` rather than letting it cross into Python.

mod conditions;
mod convert;
mod errors;
mod image;
mod model;

use pyo3::prelude::*;

/// What a human observer sees in an HDR scene (Ferwerda et al. 1996), with numpy arrays in
/// and out. Luminances are in cd/m² (photopic) or scotopic cd/m², times in seconds, angles
/// in degrees.
#[pymodule]
#[pyo3(name = "visadapt")]
fn visadapt_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("DecodeError", py.get_type::<errors::DecodeError>())?;
    m.add(
        "UnsupportedError",
        py.get_type::<errors::UnsupportedError>(),
    )?;
    m.add_class::<image::HdrImage>()?;
    m.add_class::<model::Adaptation>()?;
    m.add_function(wrap_pyfunction!(image::read, m)?)?;
    m.add_function(wrap_pyfunction!(image::from_array, m)?)?;
    m.add_function(wrap_pyfunction!(image::from_rgb, m)?)?;
    m.add_function(wrap_pyfunction!(image::chart, m)?)?;
    m.add_function(wrap_pyfunction!(image::write, m)?)?;
    m.add_function(wrap_pyfunction!(model::map, m)?)?;
    m.add_function(wrap_pyfunction!(model::observer, m)?)?;
    m.add_function(wrap_pyfunction!(model::timecourse, m)?)?;
    m.add_function(wrap_pyfunction!(model::visible, m)?)?;
    m.add_function(wrap_pyfunction!(model::tolerance, m)?)?;
    Ok(())
}
