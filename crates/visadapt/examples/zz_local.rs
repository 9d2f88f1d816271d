use std::time::Instant;
use visadapt::local::{self, LocalAdaptation};
use visadapt::operator::{AdaptationMode, ViewingConditions, local_map, plan};
use visadapt::{HdrImage, View};
fn main() {
    let (w, h) = (1920usize, 1080usize);
    let mut im = HdrImage::zeros(w, h);
    for j in 0..h {
        for i in 0..w {
            let k = j * w + i;
            let u = i as f32 / w as f32;
            let v = j as f32 / h as f32;
            let check = if (i / 4 + j / 4) % 2 == 0 { 1.0 } else { 0.3 };
            let l = 100.0 * 10f32.powf(-4.0 * u) * (0.5 + 0.5 * v) * check;
            im.x[k] = l * (0.8 + 0.3 * v);
            im.y[k] = l;
            im.z[k] = l * (1.2 - 0.4 * u);
        }
    }
    im.absolute_units = true;
    let cond = ViewingConditions {
        acuity: true,
        view: Some(View::perspective(20.0, w, h)),
        adaptation: AdaptationMode::Local(LocalAdaptation::default()),
        ..ViewingConditions::default()
    };
    let AdaptationMode::Local(options) = cond.adaptation else {
        unreachable!()
    };
    let report = plan(&im, &cond).unwrap();
    let map = local_map(&im, &report, &cond, &options).unwrap();
    let s = map.acuity_sigma_px.clone().unwrap();
    let lv = local::acuity::levels(&s);
    println!("levels {:?}", lv);
    let mut hist = vec![0usize; lv.len() + 1];
    for &x in &s {
        let k = lv.partition_point(|&l| l <= x);
        hist[k] += 1;
    }
    println!("pixels below each level {:?}", hist);
    let mut t = vec![];
    let (mut a, mut b, mut c) = (im.x.clone(), im.y.clone(), im.z.clone());
    let n: usize = std::env::var("ZN")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(9);
    for _ in 0..n {
        a.copy_from_slice(&im.x);
        b.copy_from_slice(&im.y);
        c.copy_from_slice(&im.z);
        let st = Instant::now();
        local::acuity::varying_gaussian_blur(&mut [&mut a, &mut b, &mut c], w, h, &s);
        t.push(st.elapsed().as_secs_f64() * 1e3);
    }
    let mut hh: u64 = 0xcbf29ce484222325;
    for v in a.iter().chain(&b).chain(&c) {
        hh ^= v.to_bits() as u64;
        hh = hh.wrapping_mul(0x100000001b3);
    }
    println!("hash {hh:016x}");
    t.sort_by(|a, b| a.partial_cmp(b).unwrap());
    println!("varying blur median {:.2} ms", t[n / 2]);
}
