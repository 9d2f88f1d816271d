//! Bounded reads and the memory budget (issue 9, items 1 and 2).

use visadapt::io::{self, InputFormat};
use visadapt::{Error, Limits, LimitsExceeded};

fn radiance(w: usize, h: usize) -> Vec<u8> {
    let mut f = format!("#?RADIANCE\n\n-Y {h} +X {w}\n").into_bytes();
    for _ in 0..w * h {
        f.extend([128, 128, 128, 129]);
    }
    f
}

#[test]
fn a_stream_is_refused_after_its_first_bytes() {
    let mut bytes = Vec::new();
    let e = io::read_bytes("/dev/zero".as_ref(), &Limits::default(), &mut bytes).unwrap_err();
    assert!(matches!(e, Error::Unsupported(_)), "{e}");
    assert_eq!(bytes.len(), io::HEAD_LEN);
}

#[test]
fn no_more_is_read_than_the_header_allows() {
    let dir = tempfile::tempdir().unwrap();
    // Radiance: 28 bytes per pixel and 4 per scanline at most, after the header.
    let picture = radiance(3, 2);
    let header_len = picture.len() - 3 * 2 * 4;
    let mut padded = picture.clone();
    padded.resize(4 << 20, 7);
    let p = dir.path().join("padded.hdr");
    std::fs::write(&p, &padded).unwrap();
    let mut bytes = Vec::new();
    let f = io::read_bytes(&p, &Limits::default(), &mut bytes).unwrap();
    assert_eq!(f, InputFormat::Radiance);
    assert_eq!(bytes.len(), header_len + 3 * 2 * 28 + 2 * 4);
    assert_eq!(io::decode(&bytes, &Limits::default()).unwrap().width, 3);

    // PFM: exactly the declared data.
    let mut pfm = b"Pf\n2 1\n-1.0\n".to_vec();
    pfm.extend(1f32.to_le_bytes());
    pfm.extend(2f32.to_le_bytes());
    let exact = pfm.len();
    pfm.resize(2 << 20, 0);
    let p = dir.path().join("padded.pfm");
    std::fs::write(&p, &pfm).unwrap();
    assert_eq!(
        io::read_bytes(&p, &Limits::default(), &mut bytes).unwrap(),
        InputFormat::Pfm
    );
    assert_eq!(bytes.len(), exact);
}

#[test]
fn a_file_larger_than_the_budget_is_a_limits_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("big.hdr");
    std::fs::write(&p, radiance(256, 256)).unwrap();
    let limits = Limits {
        max_memory_bytes: 100_000,
        ..Limits::default()
    };
    let e = io::read(&p, &limits).unwrap_err();
    assert!(
        matches!(
            &e,
            Error::Limits(LimitsExceeded::Memory {
                max_memory_bytes: 100_000,
                ..
            })
        ),
        "{e}"
    );
    assert!(e.to_string().contains("--max-memory"), "{e}");
}
