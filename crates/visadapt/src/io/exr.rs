//! TODO
use crate::{HdrImage, Limits, Result};
/// Decode.
pub fn decode(_bytes: &[u8], _limits: &Limits) -> Result<HdrImage> {
    Err(crate::Error::Unsupported("not yet".into()))
}
