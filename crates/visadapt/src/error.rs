//! The one error type of the library, split by who is at fault.
//!
//! Modelled on `image::ImageError` and `exr::Error`: a truncated or corrupt file is a
//! [`Error::Decode`] (the data is invalid), not an I/O failure; a valid file using a
//! feature we do not read is [`Error::Unsupported`]; a file whose size exceeds the
//! configured [`Limits`](crate::Limits) is [`Error::Limits`] and is rejected before
//! anything is allocated.

use std::fmt;

/// Everything that can go wrong in `visadapt`.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The operating system refused a read or write.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The data is not a valid file of the format (truncated, corrupt, inconsistent).
    #[error("invalid {format} data: {reason}")]
    Decode {
        /// The format being decoded, e.g. `"Radiance"`, `"OpenEXR"`, `"PFM"`.
        format: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The data is valid but uses something this library does not handle.
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// A caller-supplied parameter is out of its domain.
    #[error("invalid {name} {value}: {reason}")]
    InvalidParameter {
        /// Name of the parameter (as the CLI spells it, e.g. `"display-max"`).
        name: &'static str,
        /// The offending value, formatted.
        value: String,
        /// What the valid domain is.
        reason: String,
    },
    /// The image is larger than the configured [`Limits`](crate::Limits) allow.
    #[error("{0}")]
    Limits(LimitsExceeded),
}

/// Details of an [`Error::Limits`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LimitsExceeded {
    /// Width declared by the file, in pixels.
    pub width: u64,
    /// Height declared by the file, in pixels.
    pub height: u64,
    /// The pixel limit in force.
    pub max_pixels: u64,
}

impl fmt::Display for LimitsExceeded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "image of {}x{} pixels exceeds the limit of {} pixels (raise it with --max-pixels)",
            self.width, self.height, self.max_pixels
        )
    }
}

/// `Result` with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A [`Error::Decode`] for `format` with a reason.
    pub fn decode(format: &'static str, reason: impl Into<String>) -> Self {
        Error::Decode {
            format,
            reason: reason.into(),
        }
    }

    /// An [`Error::InvalidParameter`].
    pub fn invalid(
        name: &'static str,
        value: impl fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        Error::InvalidParameter {
            name,
            value: value.to_string(),
            reason: reason.into(),
        }
    }

    /// Turn an I/O error met while decoding into the right kind: running out of bytes
    /// means the file is truncated (invalid data), anything else is a real I/O error.
    pub fn from_read(format: &'static str, e: std::io::Error) -> Self {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            Error::decode(format, "file is truncated")
        } else {
            Error::Io(e)
        }
    }
}
