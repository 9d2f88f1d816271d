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
#[non_exhaustive]
pub enum LimitsExceeded {
    /// The image declares more pixels than [`Limits::max_pixels`](crate::Limits::max_pixels).
    Pixels {
        /// Width declared by the file, in pixels.
        width: u64,
        /// Height declared by the file, in pixels.
        height: u64,
        /// The pixel limit in force.
        max_pixels: u64,
    },
    /// Something would need more memory than
    /// [`Limits::max_memory_bytes`](crate::Limits::max_memory_bytes).
    Memory {
        /// What needs it, e.g. `"the decoded planes"`.
        what: String,
        /// Bytes it needs.
        bytes: u64,
        /// The budget in force.
        max_memory_bytes: u64,
    },
}

/// `bytes` in the largest binary unit that keeps a number of at least 1 (e.g. `12.0 GiB`).
pub(crate) fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["bytes", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} bytes")
    } else {
        format!("{v:.1} {}", UNITS[unit])
    }
}

impl fmt::Display for LimitsExceeded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LimitsExceeded::Pixels {
                width,
                height,
                max_pixels,
            } => write!(
                f,
                "image of {width}x{height} pixels exceeds the limit of {max_pixels} pixels (raise it with --max-pixels)"
            ),
            LimitsExceeded::Memory {
                what,
                bytes,
                max_memory_bytes,
            } => write!(
                f,
                "{what} would need {}, more than the memory budget of {} (raise it with --max-memory)",
                human_bytes(*bytes),
                human_bytes(*max_memory_bytes)
            ),
        }
    }
}

/// `Result` with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A [`Error::Decode`] for `format` with a reason, folded to one line: runs of
    /// whitespace (newlines included) become one space and the ends are trimmed, so that
    /// a foreign decoder's message (some end in a newline or span several lines) makes a
    /// one-line error.
    pub fn decode(format: &'static str, reason: impl Into<String>) -> Self {
        let reason = reason
            .into()
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        Error::Decode { format, reason }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decode_errors_are_one_line() {
        let e = Error::decode("JPEG", "No more bytes\n\tat offset 12\r\n  ");
        assert_eq!(
            e.to_string(),
            "invalid JPEG data: No more bytes at offset 12"
        );
        let e = Error::decode("PNG", "  two  spaces\u{2028}and a separator");
        assert_eq!(
            e.to_string(),
            "invalid PNG data: two spaces and a separator"
        );
        // A message that is one line already is kept as it is.
        let e = Error::decode("PFM", "invalid scale \"x\"");
        assert_eq!(e.to_string(), "invalid PFM data: invalid scale \"x\"");
    }
}
