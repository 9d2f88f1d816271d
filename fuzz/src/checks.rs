//! What each fuzz target checks, on any input bytes. A failed check panics (libFuzzer
//! records the input as a crash); a panic inside the library is a failure too.
//!
//! * Decoders (`radiance`, `exr`, `pfm`): the result is a consistent image (every plane
//!   `width × height` samples, both non-zero) or an error whose message is one non-empty
//!   line.
//! * `sniff`: the same for [`visadapt::io::read`] on a file holding the bytes (format
//!   detection, the bounded read of [`visadapt::io::read_bytes`], then the decoder), which
//!   must agree with [`visadapt::io::decode`] on the bytes in memory: what the bounded read
//!   leaves unread cannot change the image.
//! * `operator`: an image and viewing conditions decoded from the bytes ([`operator_case`]),
//!   with finite pixels (any sign or size up to `f32::MAX`) and parameters in their
//!   documented domains: [`visadapt::operator::map`] succeeds and every display sample is
//!   finite and in [0, 1].
//!
//! This file is also compiled into the library's stable test `tests/fuzz_replay.rs`.

use visadapt::operator::ViewingConditions;
use visadapt::{Error, HdrImage, Limits, Projection, View};

/// The fuzz targets, by name (the folder names under `fuzz/seeds/` and `fuzz/regressions/`).
pub const TARGETS: [&str; 5] = ["radiance", "exr", "pfm", "sniff", "operator"];

/// Run the check of target `name` on `data`.
pub fn by_name(name: &str, data: &[u8]) {
    match name {
        "radiance" => radiance(data),
        "exr" => exr(data),
        "pfm" => pfm(data),
        "sniff" => sniff(data),
        "operator" => operator(data),
        other => panic!("no fuzz target {other}"),
    }
}

/// Limits for fuzzing: small enough that no input can exhaust the fuzzer's memory (its
/// default RSS limit is 2 GiB), large enough for every seed.
pub fn limits() -> Limits {
    Limits {
        max_pixels: 1 << 22,
        max_memory_bytes: 512 << 20,
    }
}

/// The outcome of a decoder: a consistent image or a one-line error.
fn check_decoded(result: &visadapt::Result<HdrImage>) {
    match result {
        Ok(img) => {
            assert!(img.width > 0 && img.height > 0, "empty image");
            img.check_consistent().expect("consistent planes");
        }
        Err(e) => check_error(e),
    }
}

fn check_error(e: &Error) {
    let msg = e.to_string();
    assert!(
        !msg.trim().is_empty() && !msg.contains('\n'),
        "error message not one line: {msg:?}"
    );
}

/// Fuzz target `radiance`: the Radiance RGBE/XYZE decoder.
pub fn radiance(data: &[u8]) {
    check_decoded(&visadapt::io::radiance::decode(data, &limits()));
}

/// Fuzz target `exr`: the OpenEXR decoder.
pub fn exr(data: &[u8]) {
    check_decoded(&visadapt::io::exr::decode(data, &limits()));
}

/// Fuzz target `pfm`: the PFM decoder.
pub fn pfm(data: &[u8]) {
    check_decoded(&visadapt::io::pfm::decode(data, &limits()));
}

/// The planes of an image as bits (NaN equals NaN).
fn bits(img: &HdrImage) -> Vec<Vec<u32>> {
    let mut planes = vec![&img.x, &img.y, &img.z];
    planes.extend(&img.scotopic);
    planes
        .into_iter()
        .map(|p| p.iter().map(|v| v.to_bits()).collect())
        .collect()
}

/// Fuzz target `sniff`: format detection and the bounded file read, through a file.
pub fn sniff(data: &[u8]) {
    use std::io::Write;
    // One scratch file per thread (the replay test runs checks in parallel).
    let thread = format!("{:?}", std::thread::current().id());
    let thread: String = thread.chars().filter(char::is_ascii_digit).collect();
    let path = std::env::temp_dir().join(format!(
        "visadapt-fuzz-sniff-{}-{thread}",
        std::process::id()
    ));
    // Rewritten in place (same inode): the library remembers every input it read.
    let mut file = std::fs::File::create(&path).expect("a scratch file");
    file.write_all(data).expect("scratch file written");
    drop(file);
    let from_file = visadapt::io::read(&path, &limits());
    check_decoded(&from_file);
    let in_memory = visadapt::io::decode(data, &limits());
    if visadapt::io::detect(data).is_none() {
        assert!(
            from_file.is_err() && in_memory.is_err(),
            "unrecognised bytes decoded"
        );
    }
    match (&from_file, &in_memory) {
        (Ok(a), Ok(b)) => {
            assert_eq!((a.width, a.height), (b.width, b.height));
            assert!(
                bits(a) == bits(b),
                "the file and the bytes decode differently"
            );
        }
        (Err(_), Err(_)) => {}
        (a, b) => panic!(
            "the file and the bytes disagree: {:?} / {:?}",
            a.as_ref().err().map(ToString::to_string),
            b.as_ref().err().map(ToString::to_string)
        ),
    }
}

/// A reader of little-endian numbers from the fuzzer's bytes; zeros once they run out.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        let (first, rest) = self.0.split_first().unwrap_or((&0, &[]));
        self.0 = rest;
        *first
    }

    fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }

    /// A finite f32: NaN becomes 0, ±Inf ±`f32::MAX`.
    fn finite_f32(&mut self) -> f32 {
        let v = f32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()]);
        if v.is_nan() {
            0.0
        } else {
            v.clamp(-f32::MAX, f32::MAX)
        }
    }

    /// `10^e`, `e` spread evenly over `[lo, hi]` by the next two bytes.
    fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        10f64.powf(lo + (hi - lo) * f64::from(self.u16()) / f64::from(u16::MAX))
    }
}

/// The image and viewing conditions the `operator` target decodes from `data`: a byte each
/// for width and height (1–32 pixels), a byte of switches (acuity, glare, chromatic
/// adaptation off, world adaptation given, scotopic plane, fisheye view, display adaptation
/// given), the display maximum (1e-2 to 1e19 cd/m²), the world and display adaptations
/// (1e-6 to 1e19), the field of view, the hot-pixel fraction, then X, Y, Z (and scotopic)
/// per pixel as f32, made finite.
pub fn operator_case(data: &[u8]) -> (HdrImage, ViewingConditions) {
    let mut b = Bytes(data);
    let width = 1 + usize::from(b.u8() % 32);
    let height = 1 + usize::from(b.u8() % 32);
    let switches = b.u8();
    let on = |bit: u8| switches & (1 << bit) != 0;
    let display_max = b.log_uniform(-2.0, 19.0);
    let world = b.log_uniform(-6.0, 19.0);
    let display_adaptation = b.log_uniform(-6.0, 19.0);
    let fisheye = on(5);
    let fov = if fisheye {
        1.0 + f64::from(b.u8()) * 359.0 / 255.0
    } else {
        1.0 + f64::from(b.u8()) * 178.0 / 255.0
    };
    let hot_pixel_fraction = f64::from(b.u8()) / 256.0 * 0.5;
    let mut img = HdrImage::zeros(width, height);
    img.absolute_units = true;
    if on(4) {
        img.scotopic = Some(vec![0.0; width * height]);
    }
    for i in 0..width * height {
        img.x[i] = b.finite_f32();
        img.y[i] = b.finite_f32();
        img.z[i] = b.finite_f32();
        if let Some(s) = &mut img.scotopic {
            s[i] = b.finite_f32();
        }
    }
    let conditions = ViewingConditions {
        display_max_cd_m2: display_max,
        display_adaptation_cd_m2: on(6).then_some(display_adaptation),
        world_adaptation_cd_m2: on(3).then_some(world),
        hot_pixel_fraction,
        acuity: on(0),
        view: Some(View {
            projection: if fisheye {
                Projection::AngularFisheye
            } else {
                Projection::Perspective
            },
            horizontal_deg: fov,
            vertical_deg: if fisheye {
                fov * height as f64 / width as f64
            } else {
                let half = (fov / 2.0).to_radians().tan() * height as f64 / width as f64;
                2.0 * half.atan().to_degrees()
            },
        }),
        glare: on(1).then(visadapt::glare::Glare::default),
        white_point: if on(2) {
            visadapt::colour::WhitePoint::Off
        } else {
            visadapt::colour::WhitePoint::Auto
        },
        ..ViewingConditions::default()
    };
    (img, conditions)
}

/// Fuzz target `operator`: finite input gives finite display samples in [0, 1].
pub fn operator(data: &[u8]) {
    let (img, conditions) = operator_case(data);
    conditions
        .validate()
        .expect("the case's parameters are in their domains");
    let out = visadapt::operator::map(&img, &conditions)
        .unwrap_or_else(|e| panic!("map failed on a valid case: {e}"));
    let d = &out.image;
    assert_eq!((d.width, d.height), (img.width, img.height));
    for (name, plane) in [("r", &d.r), ("g", &d.g), ("b", &d.b)] {
        assert_eq!(plane.len(), img.width * img.height);
        if let Some((i, v)) = plane
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && (0.0..=1.0).contains(*v)))
        {
            panic!("display {name}[{i}] = {v} for finite input");
        }
    }
    assert_eq!(
        out.stats.non_finite, 0,
        "finite input counted as non-finite"
    );
}
