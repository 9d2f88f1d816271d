//! PFM reader and writer: byte orders, grey and colour, the bottom-up row order, the scale
//! factor, damaged headers and data, limits, and round trips.
//!
//! Expected colours use the sRGB → XYZ matrix quoted (to 4 decimals) by IEC 61966-2-1,
//! Eq. (F.7); tolerances (2e-4 relative to the RGB magnitude) follow from those decimals.

use visadapt::io::pfm;
use visadapt::{Error, HdrImage, Limits};

/// IEC 61966-2-1 Eq. (F.7): linear sRGB → CIE XYZ.
const SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124, 0.3576, 0.1805],
    [0.2126, 0.7152, 0.0722],
    [0.0193, 0.1192, 0.9505],
];

/// A PFM file from a header and values written in file order (bottom row first).
fn pfm_bytes(header: &str, values: &[f32], little: bool) -> Vec<u8> {
    let mut b = header.as_bytes().to_vec();
    for v in values {
        b.extend_from_slice(&if little {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        });
    }
    b
}

fn assert_rgb(img: &HdrImage, i: usize, rgb: [f64; 3]) {
    let got = [img.x[i], img.y[i], img.z[i]].map(f64::from);
    let scale = rgb.iter().map(|v| v.abs()).sum::<f64>().max(1e-30);
    for (r, row) in SRGB_TO_XYZ.iter().enumerate() {
        let e = row[0] * rgb[0] + row[1] * rgb[1] + row[2] * rgb[2];
        assert!(
            (got[r] - e).abs() <= 2e-4 * scale,
            "pixel {i} component {r}: got {}, expected {e}",
            got[r]
        );
    }
}

#[test]
fn grey_both_byte_orders_and_bottom_up_rows() {
    // File order: bottom row (1, 2), then top row (3, 4).
    let values = [1.0f32, 2.0, 3.0, 4.0];
    for (header, little) in [("Pf\n2 2\n-1.0\n", true), ("Pf\n2 2\n1.0\n", false)] {
        let img = pfm::decode(&pfm_bytes(header, &values, little), &Limits::default()).unwrap();
        assert_eq!((img.width, img.height), (2, 2));
        assert_eq!(img.y, vec![3.0, 4.0, 1.0, 2.0], "top row first");
        assert!(!img.absolute_units);
        assert!(img.scotopic.is_none());
        for (i, &l) in img.y.iter().enumerate() {
            // D65 grey: X/Y = 0.3127/0.3290, Z/Y = 0.3583/0.3290.
            assert!((f64::from(img.x[i]) - 0.950_456 * f64::from(l)).abs() < 2e-4 * f64::from(l));
            assert!((f64::from(img.z[i]) - 1.089_058 * f64::from(l)).abs() < 2e-4 * f64::from(l));
        }
    }
}

#[test]
fn colour_both_byte_orders_and_bottom_up_rows() {
    // 2×2, distinct pixels; file order is bottom-left, bottom-right, top-left, top-right.
    let file = [
        [0.1f32, 0.2, 0.3],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 4.0],
    ];
    let flat: Vec<f32> = file.iter().flatten().copied().collect();
    for (header, little) in [("PF\n2 2\n-1\n", true), ("PF 2 2 1.0\n", false)] {
        let img = pfm::decode(&pfm_bytes(header, &flat, little), &Limits::default()).unwrap();
        // Top-first: file pixels 2, 3, 0, 1.
        for (out, src) in [(0usize, 2usize), (1, 3), (2, 0), (3, 1)] {
            assert_rgb(&img, out, file[src].map(f64::from));
        }
        // Y of pure red is 0.2126.
        assert!((img.y[3] - 0.2126).abs() < 1e-4);
    }
}

#[test]
fn arbitrary_whitespace_and_scale_factor() {
    let b = pfm_bytes("Pf \t\r\n 1\n\n 1 \n -2.5\n", &[4.0], true);
    let img = pfm::decode(&b, &Limits::default()).unwrap();
    assert_eq!(img.y, vec![10.0], "|scale| 2.5 multiplies the values");
}

#[test]
fn truncated_and_malformed_files_are_decode_errors() {
    let full = pfm_bytes("PF\n2 2\n-1.0\n", &[0.5; 12], true);
    for cut in [1, 3, 6, 10, full.len() - 1] {
        let e = pfm::decode(&full[..cut], &Limits::default()).unwrap_err();
        assert!(matches!(e, Error::Decode { .. }), "cut at {cut}: {e}");
        assert!(!e.to_string().contains('\n'));
    }
    for header in [
        "PF\n-2 2\n-1\n",
        "PF\n2x 2\n-1\n",
        "PF\n2 2\n0\n",
        "PF\n2 2\nnan\n",
        "PF\n2 2\ninf\n",
        "PF2 2\n-1\n",
        "PF\n2 2\n-1",
        "PF\n99999999999999999999999 2\n-1\n",
    ] {
        let e = pfm::decode(&pfm_bytes(header, &[0.5; 12], true), &Limits::default()).unwrap_err();
        assert!(matches!(e, Error::Decode { .. }), "{header:?}: {e}");
    }
    let e = pfm::decode(b"P6\n1 1\n255\n", &Limits::default()).unwrap_err();
    assert!(matches!(e, Error::Decode { .. }), "{e}");
}

#[test]
fn absurd_dimensions_hit_the_limits_before_allocating() {
    for header in [
        "PF\n4000000000 4000000000\n-1\n",
        "Pf\n18446744073709551615 2\n-1\n",
    ] {
        let e = pfm::decode(&pfm_bytes(header, &[0.0; 3], true), &Limits::default()).unwrap_err();
        assert!(matches!(e, Error::Limits(_)), "{header:?}: {e}");
    }
    let e = pfm::decode(&pfm_bytes("Pf\n0 5\n-1\n", &[], true), &Limits::default()).unwrap_err();
    assert!(matches!(e, Error::Decode { .. }), "{e}");
    let small = Limits {
        max_pixels: 3,
        ..Limits::default()
    };
    let e = pfm::decode(&pfm_bytes("Pf\n2 2\n-1\n", &[1.0; 4], true), &small).unwrap_err();
    assert!(matches!(e, Error::Limits(_)), "{e}");
}

#[test]
fn encode_decode_round_trip() {
    let (w, h) = (3, 2);
    let mut img = HdrImage::zeros(w, h);
    // XYZ of assorted colours, from the Rec. 709 matrix of linear RGB triples.
    let rgbs = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.5, 0.25, 0.125],
        [1e3, 2e3, 3e3],
        [1e-3, 0.0, 5e-4],
    ];
    for (i, rgb) in rgbs.iter().enumerate() {
        let xyz = SRGB_TO_XYZ.map(|row| row[0] * rgb[0] + row[1] * rgb[1] + row[2] * rgb[2]);
        img.x[i] = xyz[0] as f32;
        img.y[i] = xyz[1] as f32;
        img.z[i] = xyz[2] as f32;
    }
    let bytes = pfm::encode(&img);
    assert!(bytes.starts_with(b"PF\n3 2\n-1.0\n"));
    assert_eq!(bytes.len(), 12 + w * h * 12);
    let back = pfm::decode(&bytes, &Limits::default()).unwrap();
    assert_eq!((back.width, back.height), (w, h));
    for i in 0..w * h {
        for (a, b) in [
            (back.x[i], img.x[i]),
            (back.y[i], img.y[i]),
            (back.z[i], img.z[i]),
        ] {
            assert!(
                (a - b).abs() <= 1e-5 * b.abs().max(1e-3),
                "pixel {i}: {a} vs {b}"
            );
        }
    }
    // The stored RGB is Rec. 709: the first pixel written is the bottom-left, (0.5, 0.25,
    // 0.125) up to the 4-decimal matrix.
    let first: Vec<f32> = bytes[12..24]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    for (a, b) in first.iter().zip([0.5f32, 0.25, 0.125]) {
        assert!((a - b).abs() < 2e-4, "{first:?}");
    }
}

#[test]
fn format_detection_routes_pfm() {
    let b = pfm_bytes("Pf\n1 1\n-1\n", &[7.0], true);
    let img = visadapt::io::decode(&b, &Limits::default()).unwrap();
    assert_eq!(img.y, vec![7.0]);
}
