//! # visadapt
//!
//! What a human observer would actually see in a high-dynamic-range scene, from sunlight
//! down to starlight: an implementation of Ferwerda, Pattanaik, Shirley and Greenberg,
//! *A Model of Visual Adaptation for Realistic Image Synthesis*, SIGGRAPH 1996.
//!
//! The library is organised one module per idea of the model:
//!
//! | module | models | paper |
//! |---|---|---|
//! | [`tvi`] | cone and rod threshold-versus-intensity curves | Eq. 4, Eq. 5, Fig. 3 |
//! | [`scale`] | Ward's contrast scale factor, photopic and rod operators | Eq. 1–3, Sec. 4 |
//! | [`mesopic`] | the rod weight `k` of the mesopic combination | Eq. 6 |
//! | [`scotopic`] | scotopic luminance from XYZ when no scotopic channel exists | Sec. 2.2, Fig. 2 |
//! | [`spectral`] | CIE 1931, CIE 1951 V'(λ) and ColorChecker tables; spectral sensitivity | Sec. 2.2, 5, Fig. 2, 4 |
//! | [`adaptation`] | world and display adaptation luminances | Sec. 4.4 |
//! | [`glare`] | veiling glare: light scattered in the eye (CIE 135/1 glare spread function), before adaptation | Sec. 1 (cites Spencer et al. 1995) |
//! | [`acuity`] | highest resolvable frequency and the acuity Gaussian | Sec. 4.1, Eq. 7, Fig. 7 |
//! | [`blur`] | a Gaussian blur whose cost does not grow with sigma | Sec. 4.1 |
//! | [`colour`] | RGB primaries, XYZ, sRGB output | Sec. 4 |
//! | [`operator`] | the whole steady-state operator, with a report | Sec. 4 |
//! | [`local`] | local adaptation: adaptation map, per-pixel thresholds, rod saturation and acuity | Sec. 6 (future work), Eq. 3–7 |
//! | [`timecourse`] | thresholds over time after the light changes; the Eq. 8–9 mapping | Sec. 3.5, 4.2–4.3, Eq. 8–9, Figs. 8–10 |
//! | [`sequence`] | image sequences of light and dark adaptation, animated PNG | Sec. 5, Fig. 12 |
//! | [`video`] | a stream of frames through the time course, decoding and encoding overlapped | Sec. 4.4, Eq. 8–9 |
//! | [`chart`] | the paper's test scene: ColorChecker, Snellen chart, gratings, spectral | Sec. 5, Fig. 11 |
//! | [`observer`] | what an observer adapted to a luminance can see | Sec. 2–4 |
//! | [`preview`] | the operator at preview resolution, a plain exposure, one pixel probed | Sec. 4, Eq. 4–7 |
//! | [`visibility`] | thresholds per pixel, differences in JNDs, tolerance map, convergence test | Eq. 4–7, Sec. 6 |
//! | [`label`] | text labels drawn into display images (the time of a sequence's frame) | — |
//! | [`io`] | Radiance, OpenEXR and PFM in (and 8/16-bit PNG, JPEG, TIFF photographs); PNG, JPEG, EXR, float TIFF and Radiance out | — |
//! | `report` | the JSON reports of the CLI, Python and the viewer (feature `json`) | — |
//!
//! Units are in the names: `_cd_m2` is photopic cd/m², `_scotopic_cd_m2` is scotopic cd/m²
//! (CIE 1951 V'(λ), K'm = 1700 lm/W), `_deg` degrees of visual angle, `_px` pixels.
#![deny(unsafe_code)]
#![warn(missing_docs, missing_debug_implementations)]

pub mod acuity;
pub mod adaptation;
pub mod blur;
pub mod chart;
pub mod colour;
mod error;
pub mod glare;
mod image;
pub mod io;
pub mod label;
mod limits;
pub mod local;
pub mod mesopic;
pub mod observer;
pub mod operator;
pub mod pages;
pub mod preview;
#[cfg(feature = "json")]
pub mod report;
pub mod scale;
pub mod scotopic;
pub mod sequence;
mod simd;
pub mod spectral;
pub mod timecourse;
pub mod tvi;
pub mod video;
pub mod visibility;

pub use error::{Error, LimitsExceeded, Result};
pub use image::{DisplayImage, HdrImage, Projection, View};
pub use limits::{Limits, MAX_LUMINANCE_CD_M2, MIN_LUMINANCE_CD_M2, check_factor, check_luminance};

/// The README's Rust examples, compiled and run as doc tests (`cargo test --doc`); its
/// command lines are run by the CLI's `tests/readme.rs`.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
pub struct Readme;
