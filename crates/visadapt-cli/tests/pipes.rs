//! `visadapt video` on pipes: raw `gbrpf32le` frames in, raw `rgb48le`/`rgb24` frames out.
//!
//! Without ffmpeg, raw bytes are fed to the command and the frames it writes are compared
//! with `map` and `video` on the same frames as PFM files: the same 16-bit and 8-bit codes.
//! With Debian's ffmpeg (skipped when it is missing, unless `VISADAPT_REQUIRE_FFMPEG=1`,
//! which CI sets), an EXR sequence goes through ffmpeg, visadapt and ffmpeg again (the
//! README's recipes, run as they are written) into PNG, H.264 and ProRes files whose frames
//! are decoded and compared.

mod common;

use common::{files_in, one_line_error, visadapt};

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const W: usize = 64;
const H: usize = 48;
/// The factor that makes the frames' relative values cd/m² (`--scale`).
const SCALE: &str = "100";

/// Linear Rec. 709 RGB of frame `k` at pixel `(x, y)`: ramps and a texture, each frame
/// 10^0.5 brighter than the one before, so that the observer's adaptation moves.
fn rgb(k: usize, x: usize, y: usize) -> [f32; 3] {
    let b = 10f32.powf(0.5 * k as f32 - 1.0);
    [
        b * (0.02 + x as f32 / W as f32),
        b * (0.02 + y as f32 / H as f32),
        b * (0.05 + ((x * 7 + y * 3) % 11) as f32 / 11.0),
    ]
}

/// `frames` frames as raw `gbrpf32le`: per frame the G, B and R planes.
fn raw_stream(frames: usize) -> Vec<u8> {
    let mut out = Vec::new();
    for k in 0..frames {
        for c in [1, 2, 0] {
            for y in 0..H {
                for x in 0..W {
                    out.extend_from_slice(&rgb(k, x, y)[c].to_le_bytes());
                }
            }
        }
    }
    out
}

/// Frame `k` as a little-endian colour PFM (rows bottom to top).
fn pfm(k: usize) -> Vec<u8> {
    let mut out = format!("PF\n{W} {H}\n-1.0\n").into_bytes();
    for y in (0..H).rev() {
        for x in 0..W {
            for v in rgb(k, x, y) {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    out
}

/// The flags every run here shares: the scale and a field of view (no default-view
/// warning on standard error).
fn common_flags() -> [&'static str; 6] {
    ["--fps", "24", "--scale", SCALE, "--fov", "40"]
}

/// Run `video -` on `input` with `extra` flags; (status ok, stdout, stderr).
fn video_stream(input: Vec<u8>, extra: &[&str]) -> (bool, Vec<u8>, Vec<u8>) {
    let size = format!("{W}x{H}");
    let out = visadapt()
        .args(["video", "-", "--size", &size])
        .args(common_flags())
        .args(extra)
        .write_stdin(input)
        .output()
        .unwrap();
    (out.status.success(), out.stdout, out.stderr)
}

/// The samples of a PNG file (8-bit: one per byte; 16-bit: big-endian pairs), RGB.
fn png_samples(path: &Path) -> (png::BitDepth, Vec<u16>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(
        (info.width as usize, info.height as usize),
        (W, H),
        "{path:?}"
    );
    assert_eq!(info.color_type, png::ColorType::Rgb, "{path:?}");
    let buf = &buf[..info.buffer_size()];
    let samples = match info.bit_depth {
        png::BitDepth::Sixteen => buf
            .chunks_exact(2)
            .map(|b| u16::from_be_bytes([b[0], b[1]]))
            .collect(),
        _ => buf.iter().map(|&b| u16::from(b)).collect(),
    };
    (info.bit_depth, samples)
}

/// Little-endian 16-bit samples.
fn le16(bytes: &[u8]) -> Vec<u16> {
    bytes
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect()
}

#[test]
fn raw_frames_have_the_codes_of_map_and_video_on_the_same_frames() {
    let dir = tempfile::tempdir().unwrap();
    let frames = 3;
    for k in 0..frames {
        std::fs::write(dir.path().join(format!("f_{k}.pfm")), pfm(k)).unwrap();
    }
    // 16 bits: frame 0 (the observer adapted to it) is what `map` makes of the frame.
    let (ok, out48, err) = video_stream(raw_stream(frames), &["-o", "-", "--format", "rgb48le"]);
    assert!(ok, "{}", String::from_utf8_lossy(&err));
    assert_eq!(out48.len(), frames * W * H * 6);
    assert_eq!(
        String::from_utf8_lossy(&err).trim_end(),
        "wrote 3 frames to standard output"
    );
    let png16 = dir.path().join("map16.png");
    visadapt()
        .arg("map")
        .arg(dir.path().join("f_0.pfm"))
        .args(["--scale", SCALE, "--fov", "40", "--bits", "16", "-o"])
        .arg(&png16)
        .assert()
        .success();
    let (depth, want) = png_samples(&png16);
    assert_eq!(depth, png::BitDepth::Sixteen);
    assert_eq!(le16(&out48[..W * H * 6]), want, "16-bit codes of frame 0");

    // 8 bits: every frame is what `video` makes of the PFM sequence, code for code.
    let (ok, out24, err) = video_stream(raw_stream(frames), &["-o", "-", "--format", "rgb24"]);
    assert!(ok, "{}", String::from_utf8_lossy(&err));
    assert_eq!(out24.len(), frames * W * H * 3);
    let mapped = dir.path().join("mapped");
    visadapt()
        .arg("video")
        .arg(dir.path().join("f_%d.pfm"))
        .args(common_flags())
        .arg("-o")
        .arg(&mapped)
        .assert()
        .success();
    for k in 0..frames {
        let (depth, want) = png_samples(&mapped.join(format!("f_{k}.png")));
        assert_eq!(depth, png::BitDepth::Eight);
        let got: Vec<u16> = out24[k * W * H * 3..(k + 1) * W * H * 3]
            .iter()
            .map(|&b| u16::from(b))
            .collect();
        assert_eq!(got, want, "8-bit codes of frame {k}");
    }
    // The frames differ: the scene brightens and the observer's state follows it.
    let frame = |k: usize| &out24[k * W * H * 3..(k + 1) * W * H * 3];
    assert_ne!(frame(0), frame(1));
    assert_ne!(frame(1), frame(2));

    // A stream into a folder: frame_000000.png, ..., the same images.
    let folder = dir.path().join("from-stream");
    let (ok, out, err) = video_stream(raw_stream(frames), &["-o", folder.to_str().unwrap()]);
    assert!(ok, "{}", String::from_utf8_lossy(&err));
    assert_eq!(
        files_in(&folder),
        ["frame_000000.png", "frame_000001.png", "frame_000002.png"]
    );
    assert_eq!(
        String::from_utf8_lossy(&out).trim_end(),
        format!("wrote 3 frames to {}", folder.display())
    );
    for k in 0..frames {
        assert_eq!(
            std::fs::read(folder.join(format!("frame_{k:06}.png"))).unwrap(),
            std::fs::read(mapped.join(format!("f_{k}.png"))).unwrap()
        );
    }
}

/// The pipeline's threads (`--decoders`, `--encoders`) change nothing in what is written:
/// files and streams, byte for byte, in order; a damaged frame stops the video after the
/// frames before it, whatever the threads; `--timings` reports the run on standard error.
#[test]
fn decoder_and_encoder_threads_write_the_same_frames_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let frames = 9;
    for k in 0..frames {
        std::fs::write(dir.path().join(format!("f_{k}.pfm")), pfm(k % 4)).unwrap();
    }
    let pattern = dir.path().join("f_%d.pfm");
    let run = |threads: [&str; 2], out: &Path| {
        visadapt()
            .arg("video")
            .arg(&pattern)
            .args(common_flags())
            .args([
                "--decoders",
                threads[0],
                "--encoders",
                threads[1],
                "--timings",
            ])
            .arg("-o")
            .arg(out)
            .output()
            .unwrap()
    };
    let one = dir.path().join("one");
    let out = run(["1", "1"], &one);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let names: Vec<String> = (0..frames).map(|k| format!("f_{k}.png")).collect();
    assert_eq!(files_in(&one), names);
    for threads in [["3", "1"], ["1", "3"], ["4", "4"]] {
        let many = dir
            .path()
            .join(format!("many-{}-{}", threads[0], threads[1]));
        let out = run(threads, &many);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("timings: 9 frames in ")
                && err.contains(&format!("({} threads)", threads[0]))
                && err.contains("frames/s"),
            "{err}"
        );
        assert_eq!(files_in(&many), names);
        for name in &names {
            let same =
                std::fs::read(many.join(name)).unwrap() == std::fs::read(one.join(name)).unwrap();
            assert!(
                same,
                "{name} with {threads:?} threads differs from one thread each"
            );
        }
    }
    // Raw frames on standard output, several encoders: the same stream as one encoder.
    let (ok, want, err) = video_stream(raw_stream(frames), &["-o", "-", "--format", "rgb24"]);
    assert!(ok, "{}", String::from_utf8_lossy(&err));
    let (ok, got, err) = video_stream(
        raw_stream(frames),
        &["-o", "-", "--format", "rgb24", "--encoders", "4"],
    );
    assert!(ok, "{}", String::from_utf8_lossy(&err));
    assert!(got == want, "the stream differs with four encoders");
    // A damaged frame 5: frames 0-4 are written, whole, nothing after, with many threads.
    std::fs::write(dir.path().join("f_5.pfm"), b"PF\n64 48\n-1.0\ntruncated").unwrap();
    let broken = dir.path().join("broken");
    let out = run(["4", "4"], &broken);
    assert!(!out.status.success());
    assert!(one_line_error(&out.stderr).contains("f_5.pfm"));
    assert_eq!(files_in(&broken), names[..5]);
    for name in &names[..5] {
        let same =
            std::fs::read(broken.join(name)).unwrap() == std::fs::read(one.join(name)).unwrap();
        assert!(same, "{name}");
    }
}

#[test]
fn a_truncated_stream_is_one_line_after_the_whole_frames() {
    let mut bytes = raw_stream(3);
    bytes.truncate(2 * W * H * 12 + 1000);
    let (ok, out, err) = video_stream(bytes, &["-o", "-", "--format", "rgb24"]);
    assert!(!ok);
    let err = one_line_error(&err);
    assert!(
        err.contains("standard input: frame 2 is truncated")
            && err.contains(&format!("1000 of its {} bytes", W * H * 12)),
        "{err}"
    );
    // The two whole frames went out before the error.
    assert_eq!(out.len(), 2 * W * H * 3);
}

#[test]
fn flags_that_do_not_fit_a_stream_are_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("f_0.pfm"), pfm(0)).unwrap();
    let pattern = dir.path().join("f_%d.pfm");
    let pattern = pattern.to_str().unwrap();
    let size = format!("{W}x{H}");
    let folder = dir.path().join("out");
    let folder = folder.to_str().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (
            &["video", "-", "-o", "-", "--format", "rgb24"],
            "needs --size",
        ),
        (
            &["video", "-", "--size", &size, "-o", "-"],
            "--format rgb48le",
        ),
        (
            &[
                "video", "-", "--size", &size, "-o", folder, "--format", "rgb48le",
            ],
            "raw stream for -o -",
        ),
        (
            &[
                "video", pattern, "--size", &size, "-o", "-", "--format", "rgb24",
            ],
            "--size is for raw frames",
        ),
        (
            &[
                "video", "-", "--size", &size, "-o", "-", "--format", "rgb24", "--json",
            ],
            "--json",
        ),
    ];
    for (args, says) in cases {
        let out = visadapt()
            .args(args)
            .args(common_flags())
            .write_stdin(raw_stream(1))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        assert!(out.stdout.is_empty(), "{args:?}");
        let err = one_line_error(&out.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    }
    assert!(
        !Path::new(folder).exists(),
        "nothing is created for a refused run"
    );
}

#[test]
fn an_endless_stream_stops_at_the_frame_limit_and_absurd_sizes_before_reading() {
    let zeros = || std::fs::File::open("/dev/zero").unwrap();
    // std's Command: the stream is handed to the child as it is, not read first.
    let visadapt = || Command::new(assert_cmd::cargo::cargo_bin("visadapt"));
    let out = visadapt()
        .args(["video", "-", "--size", "32x16", "--max-frames", "3"])
        .args(common_flags())
        .args(["-o", "-", "--format", "rgb24"])
        .stdin(zeros())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(out.stdout.len(), 3 * 32 * 16 * 3);
    assert!(out.stdout.iter().all(|&b| b == 0), "black frames");
    assert_eq!(
        String::from_utf8_lossy(&out.stderr).trim_end(),
        "wrote 3 frames to standard output"
    );
    for (size, extra, says) in [
        ("100000x100000", None, "exceeds the limit"),
        ("4096x4096", Some("--max-memory=64M"), "memory budget"),
    ] {
        let out = visadapt()
            .args(["video", "-", "--size", size])
            .args(common_flags())
            .args(extra)
            .args(["-o", "-", "--format", "rgb24"])
            .stdin(zeros())
            .output()
            .unwrap();
        assert!(!out.status.success(), "{size}");
        assert!(out.stdout.is_empty());
        let err = one_line_error(&out.stderr);
        assert!(err.contains(says), "{size}: {err}");
    }
}

#[test]
fn the_report_counts_one_frame_and_several_frames() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("f_0.pfm"), pfm(0)).unwrap();
    let out_dir = dir.path().join("out");
    let run = || {
        visadapt()
            .arg("video")
            .arg(dir.path().join("f_%d.pfm"))
            .args(common_flags())
            .arg("-o")
            .arg(&out_dir)
            .output()
            .unwrap()
    };
    let out = run();
    assert!(out.status.success());
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).trim_end(),
        format!("wrote 1 frame to {}", out_dir.display())
    );
    std::fs::write(dir.path().join("f_1.pfm"), pfm(1)).unwrap();
    let out = run();
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).trim_end(),
        format!("wrote 2 frames to {}", out_dir.display())
    );
    // And on a stream, on standard error.
    let (ok, _, err) = video_stream(raw_stream(1), &["-o", "-", "--format", "rgb24"]);
    assert!(ok);
    assert_eq!(
        String::from_utf8_lossy(&err).trim_end(),
        "wrote 1 frame to standard output"
    );
}

// ---- with ffmpeg ----

/// Whether ffmpeg is here; panics when CI requires it and it is missing.
fn have_ffmpeg() -> bool {
    let found = Command::new("ffmpeg")
        .arg("-version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !found && std::env::var_os("VISADAPT_REQUIRE_FFMPEG").is_some_and(|v| v == "1") {
        panic!("VISADAPT_REQUIRE_FFMPEG=1 but ffmpeg is not on PATH");
    }
    if !found {
        eprintln!("skipped: ffmpeg is not installed (VISADAPT_REQUIRE_FFMPEG=1 makes this fail)");
    }
    found
}

/// Write frames `0..frames` as float RGB EXRs `render/f_0001.exr`, ... (linear Rec. 709,
/// the values of [`rgb`]).
fn exr_sequence(dir: &Path, frames: usize) {
    let render = dir.join("render");
    std::fs::create_dir_all(&render).unwrap();
    for k in 0..frames {
        let mut image = visadapt::DisplayImage {
            width: W,
            height: H,
            display_max_cd_m2: 1.0,
            ..Default::default()
        };
        for y in 0..H {
            for x in 0..W {
                let [r, g, b] = rgb(k, x, y);
                image.r.push(r);
                image.g.push(g);
                image.b.push(b);
            }
        }
        let mut file = std::fs::File::create(render.join(format!("f_{:04}.exr", k + 1))).unwrap();
        visadapt::io::exr::write_display(&image, &mut file).unwrap();
    }
}

/// The frames of a video file decoded by ffmpeg as `rgb24`.
fn decode_rgb24(path: &Path) -> Vec<u8> {
    let out = Command::new("ffmpeg")
        .args(["-v", "error", "-i"])
        .arg(path)
        .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "-"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// The README's ffmpeg recipes, as a shell script (the block after its marker comment).
fn readme_recipes() -> String {
    let readme =
        std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../README.md"))
            .unwrap();
    let start = readme
        .find("<!-- ffmpeg recipes:")
        .expect("the README has the recipes");
    let block = &readme[start..];
    let body = &block[block.find("```sh\n").unwrap() + 6..];
    body[..body.find("```").unwrap()].to_string()
}

#[test]
fn ffmpeg_exr_sequence_through_visadapt_to_png_h264_and_prores() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let frames = 4;
    exr_sequence(dir.path(), frames);
    // What visadapt makes of the same frames fed as raw bytes, without ffmpeg.
    let (ok, want48, err) = video_stream(raw_stream(frames), &["-o", "-", "--format", "rgb48le"]);
    assert!(ok, "{}", String::from_utf8_lossy(&err));
    let (ok, want24, _) = video_stream(raw_stream(frames), &["-o", "-", "--format", "rgb24"]);
    assert!(ok);
    let bin_dir = assert_cmd::cargo::cargo_bin("visadapt")
        .parent()
        .unwrap()
        .to_path_buf();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let bash = |script: &str| {
        let out = Command::new("bash")
            .args(["-c", &format!("set -euo pipefail\n{script}")])
            .current_dir(dir.path())
            .env("PATH", &path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{script}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };

    // Lossless: EXR -> ffmpeg gbrpf32le -> visadapt rgb48le -> ffmpeg 16-bit PNGs carries
    // every code.
    let size = format!("{W}x{H}");
    bash(&format!(
        "mkdir png && ffmpeg -v error -i 'render/f_%04d.exr' -f rawvideo -pix_fmt gbrpf32le - | \
         visadapt video - --size {size} --fps 24 --scale {SCALE} --fov 40 -o - --format rgb48le | \
         ffmpeg -v error -f rawvideo -pix_fmt rgb48le -s {size} -r 24 -i - png/m_%04d.png"
    ));
    assert_eq!(files_in(&dir.path().join("png")).len(), frames);
    for k in 0..frames {
        let (depth, got) = png_samples(&dir.path().join(format!("png/m_{:04}.png", k + 1)));
        assert_eq!(depth, png::BitDepth::Sixteen);
        assert_eq!(
            got,
            le16(&want48[k * W * H * 6..(k + 1) * W * H * 6]),
            "frame {k}"
        );
    }

    // The README's recipes, as written there, at this test's size and field of view.
    let recipes = readme_recipes()
        .replace("1920x1080", &size)
        .replace("--scale 100", &format!("--scale {SCALE} --fov 40"))
        .replace("ffmpeg -", "ffmpeg -v error -");
    bash(&recipes);
    // PNG frames out of a decode piped in: the 8-bit codes of the raw path.
    let mapped = dir.path().join("mapped");
    assert_eq!(files_in(&mapped).len(), frames);
    for k in 0..frames {
        let (_, got) = png_samples(&mapped.join(format!("frame_{k:06}.png")));
        let want: Vec<u16> = want24[k * W * H * 3..(k + 1) * W * H * 3]
            .iter()
            .map(|&b| u16::from(b))
            .collect();
        assert_eq!(got, want, "frame {k}");
    }
    // H.264 (4:2:0, 8 bits) and ProRes (4:2:2, 10 bits) are lossy, and their chroma is
    // subsampled (the blue texture's single-pixel steps do not survive): the frames come
    // back at the size and in the number written, and the means of 8 × 8 blocks, per
    // channel, stay within `tol` codes of the raw path's.
    for (file, tol) in [("mapped.mp4", TOL_H264), ("mapped.mov", TOL_PRORES)] {
        let got = decode_rgb24(&dir.path().join(file));
        assert_eq!(got.len(), frames * W * H * 3, "{file}");
        for k in 0..frames {
            let range = k * W * H * 3..(k + 1) * W * H * 3;
            let worst = worst_block_difference(&got[range.clone()], &want24[range]);
            eprintln!("{file} frame {k}: worst 8x8 block mean difference {worst:.2} codes");
            assert!(worst < tol, "{file} frame {k}: {worst}");
        }
    }
}

/// Tolerances of the lossy files, in 8-bit codes of an 8 × 8 block's mean: ffmpeg's
/// conversions to and from Y'CbCr (limited range) and the codecs' quantisation. Our bounds,
/// twice the worst measured here (3.0 codes for H.264, 1.7 for ProRes).
const TOL_H264: f64 = 6.0;
const TOL_PRORES: f64 = 4.0;

/// The largest difference between the means of one channel over an 8 × 8 block of two
/// `rgb24` frames.
fn worst_block_difference(a: &[u8], b: &[u8]) -> f64 {
    let mut worst = 0f64;
    for by in (0..H).step_by(8) {
        for bx in (0..W).step_by(8) {
            for c in 0..3 {
                let mut d = 0.0;
                for y in by..by + 8 {
                    for x in bx..bx + 8 {
                        let i = (y * W + x) * 3 + c;
                        d += f64::from(a[i]) - f64::from(b[i]);
                    }
                }
                worst = worst.max((d / 64.0).abs());
            }
        }
    }
    worst
}
