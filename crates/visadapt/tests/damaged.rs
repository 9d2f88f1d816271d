//! Damaged input: the OpenEXR project's corpus of files that once crashed EXR readers, and
//! mutated copies of small valid files. Every input must give either a consistent image or
//! an error with a one-line message; no panic may escape, and no file may take long.

mod common;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::{Duration, Instant};
use visadapt::{Error, Limits};

/// Longest time one damaged input may take to decode. Our bound: the slowest corpus file
/// decodes in well under a millisecond; a second means something loops.
const MAX_DECODE_TIME: Duration = Duration::from_secs(2);

/// Decode `bytes` and check the outcome; returns the time taken and whether it decoded.
fn check(name: &str, bytes: &[u8], limits: &Limits) -> (Duration, bool) {
    let start = Instant::now();
    let result = catch_unwind(AssertUnwindSafe(|| visadapt::io::decode(bytes, limits)));
    let elapsed = start.elapsed();
    let result = result.unwrap_or_else(|_| panic!("{name}: a panic escaped the decoder"));
    let ok = match result {
        Ok(img) => {
            img.check_consistent()
                .unwrap_or_else(|e| panic!("{name}: inconsistent image: {e}"));
            assert_eq!(img.x.len(), img.width * img.height, "{name}");
            true
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.trim().is_empty(), "{name}: empty error message");
            assert!(
                !msg.contains('\n'),
                "{name}: multi-line error message {msg:?}"
            );
            false
        }
    };
    assert!(elapsed < MAX_DECODE_TIME, "{name}: took {elapsed:?}");
    (elapsed, ok)
}

fn corpus() -> Option<Vec<(String, Vec<u8>)>> {
    let dir = common::shared("openexr-damaged")?;
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    Some(
        files
            .into_iter()
            .map(|p| {
                let name = p.file_name().unwrap().to_string_lossy().into_owned();
                (name, std::fs::read(&p).unwrap())
            })
            .collect(),
    )
}

#[test]
fn openexr_damaged_corpus() {
    let Some(files) = corpus() else {
        return;
    };
    assert!(
        files.len() >= 186,
        "185 damaged files and README.rst, found {}",
        files.len()
    );
    let mut slowest = (Duration::ZERO, String::new());
    let mut decoded = 0;
    for (name, bytes) in &files {
        let (t, ok) = check(name, bytes, &Limits::default());
        decoded += usize::from(ok);
        if t > slowest.0 {
            slowest = (t, name.clone());
        }
    }
    eprintln!(
        "{} files, {decoded} decoded, slowest {} in {:?}",
        files.len(),
        slowest.1,
        slowest.0
    );
    // The README is not an image: format detection refuses it.
    let readme = &files.iter().find(|(n, _)| n == "README.rst").unwrap().1;
    assert!(matches!(
        visadapt::io::decode(readme, &Limits::default()),
        Err(Error::Unsupported(_))
    ));
}

#[test]
fn openexr_damaged_corpus_without_limits() {
    // Even with no pixel limit, a damaged header must not lead to a huge allocation: the
    // offset table and chunks are checked against the file before pixels are allocated.
    let Some(files) = corpus() else {
        return;
    };
    for (name, bytes) in &files {
        check(name, bytes, &Limits::none());
    }
}

/// Small valid inputs of every kind the readers handle.
fn seeds() -> Vec<(String, Vec<u8>)> {
    use exr::prelude::*;
    let mut seeds = Vec::new();
    let (w, h) = (19usize, 13usize);
    let samples = |k: f32| {
        (0..w * h)
            .map(|i| (i as f32 * 0.37 + k).sin().abs() * 10.0)
            .collect::<Vec<f32>>()
    };
    for compression in [
        Compression::Uncompressed,
        Compression::RLE,
        Compression::ZIP1,
        Compression::ZIP16,
        Compression::PIZ,
        Compression::PXR24,
        Compression::B44,
        Compression::B44A,
    ] {
        for blocks in [Blocks::ScanLines, Blocks::Tiles(Vec2(8, 8))] {
            let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::from_vec(vec![
                AnyChannel::new(
                    "R",
                    FlatSamples::F16(samples(0.0).into_iter().map(f16::from_f32).collect()),
                ),
                AnyChannel::new("G", FlatSamples::F32(samples(1.0))),
                AnyChannel::new(
                    "B",
                    FlatSamples::F16(samples(2.0).into_iter().map(f16::from_f32).collect()),
                ),
            ]);
            let layer = Layer::new(
                (w, h),
                LayerAttributes::default(),
                Encoding {
                    compression,
                    blocks,
                    line_order: LineOrder::Increasing,
                },
                AnyChannels::sort(channels),
            );
            let mut out = std::io::Cursor::new(Vec::new());
            Image::from_layer(layer)
                .write()
                .to_buffered(&mut out)
                .unwrap();
            seeds.push((format!("{compression:?} {blocks:?}"), out.into_inner()));
        }
    }
    let mut hdr = visadapt::HdrImage::zeros(7, 5);
    hdr.y
        .iter_mut()
        .enumerate()
        .for_each(|(i, v)| *v = i as f32);
    hdr.scotopic = Some(vec![1.0; 35]);
    let mut out = std::io::Cursor::new(Vec::new());
    visadapt::io::exr::write_hdr(&hdr, &mut out).unwrap();
    seeds.push(("X/Y/Z/scotopic".into(), out.into_inner()));
    seeds.push(("PFM".into(), visadapt::io::pfm::encode(&hdr)));
    if let Some(p) = common::shared("openexr/StarField.exr") {
        // Subsampled luminance/chroma: our own code path. Keep only the header and the
        // first chunks so that each mutation decodes quickly.
        let bytes = std::fs::read(p).unwrap();
        seeds.push((
            "StarField".into(),
            bytes[..bytes.len().min(60_000)].to_vec(),
        ));
    }
    seeds
}

#[test]
fn mutated_valid_files() {
    // xorshift64, fixed seed: the same mutations on every run.
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut slowest = (Duration::ZERO, String::new());
    for (name, seed) in seeds() {
        for round in 0..150 {
            let mut bytes = seed.clone();
            let len = bytes.len() as u64;
            // Mostly the header (first 400 bytes), sometimes anywhere; sometimes truncate.
            let kind = rnd() % 4;
            for _ in 0..1 + rnd() % 6 {
                let at = if kind == 0 {
                    rnd() % len
                } else {
                    rnd() % len.min(400)
                };
                bytes[at as usize] = rnd() as u8;
            }
            if kind == 3 {
                bytes.truncate((rnd() % len).max(4) as usize);
            }
            let label = format!("{name} mutation {round}");
            let (t, _) = check(&label, &bytes, &Limits::default());
            if t > slowest.0 {
                slowest = (t, label);
            }
        }
    }
    eprintln!("mutations: slowest {} in {:?}", slowest.1, slowest.0);
}
