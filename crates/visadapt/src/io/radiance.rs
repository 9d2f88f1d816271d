//! TODO
use crate::{HdrImage, Limits, Result};
/// Decode.
pub fn decode(_bytes: &[u8], _limits: &Limits) -> Result<HdrImage> {
    Err(crate::Error::Unsupported("not yet".into()))
}
/// Header sniff.
pub fn looks_like_header(_b: &[u8]) -> bool { false }
