//! The library's errors as Python exceptions, with the library's one-line message.
//!
//! * [`visadapt::Error::InvalidParameter`] and [`visadapt::Error::Limits`]: `ValueError`;
//! * [`visadapt::Error::Io`]: `OSError` (`FileNotFoundError`, `PermissionError`, ...);
//! * [`visadapt::Error::Decode`]: `visadapt.DecodeError` (a `ValueError`);
//! * [`visadapt::Error::Unsupported`]: `visadapt.UnsupportedError` (a `DecodeError`).
//!
//! Errors about a file carry its path in front, as the CLI prints them.

use pyo3::exceptions::{
    PyFileExistsError, PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError,
    PyRuntimeError, PyValueError,
};
use pyo3::prelude::*;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

pyo3::create_exception!(
    visadapt,
    DecodeError,
    PyValueError,
    "A file is not valid data of its format (truncated, corrupt or inconsistent)."
);
pyo3::create_exception!(
    visadapt,
    UnsupportedError,
    DecodeError,
    "A file uses something visadapt does not read (or is of no format it knows)."
);

/// The Python exception for a library error; `path` is prefixed to the message when the
/// error concerns a file.
pub fn to_py(e: visadapt::Error, path: Option<&Path>) -> PyErr {
    let msg = match path {
        Some(p) => format!("{}: {e}", p.display()),
        None => e.to_string(),
    };
    match e {
        visadapt::Error::Io(io) => {
            use std::io::ErrorKind as K;
            match io.kind() {
                K::NotFound => PyFileNotFoundError::new_err(msg),
                K::PermissionDenied => PyPermissionError::new_err(msg),
                K::AlreadyExists => PyFileExistsError::new_err(msg),
                K::IsADirectory => PyIsADirectoryError::new_err(msg),
                _ => PyOSError::new_err(msg),
            }
        }
        visadapt::Error::Decode { .. } => DecodeError::new_err(msg),
        visadapt::Error::Unsupported(_) => UnsupportedError::new_err(msg),
        _ => PyValueError::new_err(msg),
    }
}

/// Run `f` without the GIL, turning a panic into a `RuntimeError` (a bug in visadapt, never
/// the caller's fault) instead of letting it unwind into Python.
pub fn detached<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    T: Send,
    F: Send + FnOnce() -> PyResult<T>,
{
    py.detach(|| {
        catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|payload| {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "internal error in visadapt: {what}"
            )))
        })
    })
}
