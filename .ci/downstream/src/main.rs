//! Runs every vector kernel of visadapt once (the exact and the recursive acuity blur,
//! the fused mapping pass, local adaptation, the sRGB encoding), so that the linked
//! binary holds each of them as a user's crate builds it. `check.sh` then inspects the
//! binary; the printed sums only show that the work was done.

use visadapt::io::display::to_srgb8;
use visadapt::local::LocalAdaptation;
use visadapt::operator::{AdaptationMode, ViewingConditions, map};
use visadapt::{HdrImage, View};

fn main() -> Result<(), visadapt::Error> {
    let (w, h) = (640, 360);
    let mut im = HdrImage::zeros(w, h);
    for k in 0..w * h {
        let (i, j) = (k % w, k / w);
        let check = if (i / 4 + j / 4) % 2 == 0 { 1.0 } else { 0.3 };
        let l = 0.05 * (1.0 + i as f32) * check;
        im.x[k] = 0.95 * l;
        im.y[k] = l;
        im.z[k] = 1.09 * l;
    }
    im.absolute_units = true;
    // A wide view (a sigma of a few pixels: the exact kernel), a narrow one (the recursive
    // filter), and local adaptation.
    for (fov_degrees, adaptation) in [
        (40.0, AdaptationMode::Global),
        (2.0, AdaptationMode::Global),
        (40.0, AdaptationMode::Local(LocalAdaptation::default())),
    ] {
        let conditions = ViewingConditions {
            acuity: true,
            view: Some(View::perspective(fov_degrees, w, h)),
            adaptation,
            ..ViewingConditions::default()
        };
        let out = map(&im, &conditions)?;
        let bytes = to_srgb8(&out.image);
        let sum: u64 = bytes.iter().map(|&b| u64::from(b)).sum();
        println!("{fov_degrees}° {adaptation:?}: sum of sRGB codes {sum}");
    }
    Ok(())
}
