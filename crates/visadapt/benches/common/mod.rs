//! The frames the benchmarks share.
#![allow(dead_code)] // Each bench uses some of them.

use visadapt::HdrImage;

/// A textured HDR frame of `w × h` pixels: smooth gradients times a fine checker (4-pixel
/// squares, 1 and 0.3), highest luminance about `peak` cd/m², with a D65-like colour cast
/// that varies over the frame. Our choice: texture at the acuity blur's scale; the
/// gradient spans 20:1 (about 67:1 with the checker).
pub fn frame(w: usize, h: usize, peak: f32) -> HdrImage {
    textured(w, h, |u, v| peak * (0.05 + 0.95 * u * v))
}

/// A `w × h` frame whose luminance at the relative position `(u, v)` in `[0, 1)²` is
/// `luminance(u, v)` cd/m² times the checker of [`frame`], with its colour cast.
pub fn textured(w: usize, h: usize, luminance: impl Fn(f32, f32) -> f32) -> HdrImage {
    let mut im = HdrImage::zeros(w, h);
    for j in 0..h {
        for i in 0..w {
            let k = j * w + i;
            let u = i as f32 / w as f32;
            let v = j as f32 / h as f32;
            let check = if (i / 4 + j / 4).is_multiple_of(2) {
                1.0
            } else {
                0.3
            };
            let l = luminance(u, v) * check;
            im.x[k] = l * (0.8 + 0.3 * v);
            im.y[k] = l;
            im.z[k] = l * (1.2 - 0.4 * u);
        }
    }
    im.absolute_units = true;
    im
}
