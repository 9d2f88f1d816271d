//! numpy arrays to and from the library's planar `f32` images, and JSON reports to dicts.

use numpy::ndarray::{Array2, Array3, ArrayViewD};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArrayDyn};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use serde_json::Value;

/// A float32 or float64 numpy array (any memory order) as `f32` samples in row-major
/// order, with its shape.
pub struct Samples {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// Read `obj` (a numpy array of float32 or float64, C or Fortran order or any strides).
pub fn samples(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Samples> {
    fn collect<T: Copy>(a: ArrayViewD<'_, T>, f: impl Fn(T) -> f32) -> Samples {
        let data = match a.as_slice() {
            // C order: one pass over memory.
            Some(s) => s.iter().map(|&v| f(v)).collect(),
            // Anything else: `iter` walks the logical (row-major) order whatever the strides.
            None => a.iter().map(|&v| f(v)).collect(),
        };
        Samples {
            shape: a.shape().to_vec(),
            data,
        }
    }
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        return Ok(collect(a.as_array(), |v| v));
    }
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        return Ok(collect(a.as_array(), |v| v as f32));
    }
    let what = match obj.getattr("dtype") {
        Ok(d) => format!("an array of dtype {d}"),
        Err(_) => format!("a {}", obj.get_type().name()?),
    };
    Err(PyTypeError::new_err(format!(
        "{name} must be a float32 or float64 numpy array, got {what}"
    )))
}

fn shape_text(shape: &[usize]) -> String {
    let parts: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// An H × W × 3 array as three planes; `(width, height, planes)`.
pub fn planes3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(usize, usize, [Vec<f32>; 3])> {
    let s = samples(obj, name)?;
    let &[h, w, 3] = s.shape.as_slice() else {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (H, W, 3), got {}",
            shape_text(&s.shape)
        )));
    };
    if h == 0 || w == 0 {
        return Err(PyValueError::new_err(format!(
            "{name} must not be empty, got {}",
            shape_text(&s.shape)
        )));
    }
    let n = w * h;
    let mut planes = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
    for (i, px) in s.data.chunks_exact(3).enumerate() {
        for c in 0..3 {
            planes[c][i] = px[c];
        }
    }
    Ok((w, h, planes))
}

/// An H × W array as one plane of `width × height` samples.
pub fn plane(
    obj: &Bound<'_, PyAny>,
    name: &str,
    width: usize,
    height: usize,
) -> PyResult<Vec<f32>> {
    let s = samples(obj, name)?;
    if s.shape != [height, width] {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape ({height}, {width}), got {}",
            shape_text(&s.shape)
        )));
    }
    Ok(s.data)
}

/// Three planes interleaved into H × W × 3 order (no GIL needed: call it detached).
pub fn interleave(planes: [&[f32]; 3]) -> Vec<f32> {
    let n = planes[0].len();
    let mut out = vec![0f32; 3 * n];
    for (i, px) in out.chunks_exact_mut(3).enumerate() {
        px[0] = planes[0][i];
        px[1] = planes[1][i];
        px[2] = planes[2][i];
    }
    out
}

/// Interleaved samples (from [`interleave`]) as an H × W × 3 float32 array, without a copy.
pub fn to_array3(
    py: Python<'_>,
    width: usize,
    height: usize,
    samples: Vec<f32>,
) -> PyResult<Bound<'_, PyArray3<f32>>> {
    let a = Array3::from_shape_vec((height, width, 3), samples)
        .map_err(|e| PyValueError::new_err(format!("internal shape error: {e}")))?;
    Ok(a.into_pyarray(py))
}

/// One plane as an H × W float32 array (no copy: the vector becomes the array's buffer).
pub fn to_array2(
    py: Python<'_>,
    width: usize,
    height: usize,
    plane: Vec<f32>,
) -> PyResult<Bound<'_, PyArray2<f32>>> {
    let a = Array2::from_shape_vec((height, width), plane)
        .map_err(|e| PyValueError::new_err(format!("internal shape error: {e}")))?;
    Ok(a.into_pyarray(py))
}

/// A JSON value as the Python object `json.loads` would give: dict, list, str, int, float,
/// bool or None.
pub fn json_to_py<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => {
            if let Some(i) = n.as_u64() {
                i.into_pyobject(py)?.into_any()
            } else if let Some(i) = n.as_i64() {
                i.into_pyobject(py)?.into_any()
            } else {
                n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any()
            }
        }
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(json_to_py(py, item)?)?;
            }
            list.into_any()
        }
        Value::Object(map) => {
            let dict = PyDict::new(py);
            for (k, item) in map {
                dict.set_item(k, json_to_py(py, item)?)?;
            }
            dict.into_any()
        }
    })
}
