//! `visadapt serve`: the viewer's HTTP API over loopback, against the binary.
#![cfg(feature = "serve")]

mod common;

use common::{data, json, tp, visadapt};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A `visadapt serve` child process on a free loopback port, killed when dropped.
struct Server {
    child: Child,
    url: String,
}

impl Server {
    fn start(image: &Path, extra: &[&str]) -> Server {
        let mut child = Command::new(assert_cmd::cargo::cargo_bin("visadapt"))
            .arg("serve")
            .arg(image)
            .args(["--port", "0", "--no-open"])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.as_mut().unwrap())
            .read_line(&mut line)
            .unwrap();
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("http://127.0.0.1:"))
            .unwrap_or_else(|| panic!("no URL in {line:?}"))
            .trim_end_matches('/')
            .to_string();
        Server { child, url }
    }

    fn get(&self, path_and_query: &str) -> Reply {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(Duration::from_secs(120)))
            .build()
            .into();
        let mut r = agent
            .get(format!("{}{path_and_query}", self.url))
            .call()
            .unwrap();
        let header = |name: &str| {
            r.headers()
                .get(name)
                .map(|v| v.to_str().unwrap().to_string())
                .unwrap_or_default()
        };
        let content_type = header("content-type");
        let showing = header("x-visadapt-showing");
        let body = r
            .body_mut()
            .with_config()
            .limit(1 << 28)
            .read_to_vec()
            .unwrap();
        Reply {
            status: r.status().as_u16(),
            content_type,
            showing,
            body,
        }
    }

    fn json(&self, path_and_query: &str) -> serde_json::Value {
        let r = self.get(path_and_query);
        assert_eq!(r.status, 200, "{path_and_query}: {}", r.text());
        assert_eq!(r.content_type, "application/json");
        json(&r.body)
    }

    fn png(&self, path_and_query: &str) -> (u32, u32, Vec<u8>) {
        let r = self.get(path_and_query);
        assert_eq!(r.status, 200, "{path_and_query}: {}", r.text());
        assert_eq!(r.content_type, "image/png");
        decode_png(&r.body)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

struct Reply {
    status: u16,
    content_type: String,
    /// What a frame shows (`x-visadapt-showing`).
    showing: String,
    body: Vec<u8>,
}

impl Reply {
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

fn decode_png(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// The paper's test scene (807 × 815, X/Y/Z/scotopic, absolute units), written by `chart`.
fn chart(dir: &Path) -> PathBuf {
    let path = dir.join("chart.exr");
    visadapt()
        .args(["chart", "--white", "100", "-o"])
        .arg(&path)
        .assert()
        .success();
    path
}

/// `visadapt map IMAGE ARGS --json -o OUT.png`: (report, decoded PNG).
fn map(image: &Path, args: &[&str], dir: &Path) -> (serde_json::Value, (u32, u32, Vec<u8>)) {
    let out = dir.join("map.png");
    let run = visadapt()
        .arg("map")
        .arg(image)
        .args(args)
        .arg("--json")
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    (json(&run.stdout), decode_png(&std::fs::read(&out).unwrap()))
}

fn mean(v: &[u8]) -> f64 {
    v.iter().map(|&b| f64::from(b)).sum::<f64>() / v.len() as f64
}

#[test]
fn report_and_full_frame_equal_map() {
    let dir = tempfile::tempdir().unwrap();
    let image = chart(dir.path());
    let server = Server::start(&image, &[]);
    for (query, args) in [
        ("", vec![]),
        (
            "peak=0.04&fov=6.7173",
            vec!["--peak", "0.04", "--fov", "6.7173"],
        ),
        (
            "peak=1000&display_max=200&acuity=0",
            vec!["--peak", "1000", "--display-max", "200", "--no-acuity"],
        ),
        ("peak=0.001&fov=20", vec!["--peak", "0.001", "--fov", "20"]),
    ] {
        let (report, png) = map(&image, &args, dir.path());
        assert_eq!(
            server.json(&format!("/api/report?{query}")),
            report,
            "{query}"
        );
        // The full-resolution frame is map's PNG, byte for byte in its pixels.
        assert_eq!(server.png(&format!("/api/frame?{query}")), png, "{query}");
    }
    // The flags set the page's starting point: `serve --peak` is `map --peak`.
    let started = Server::start(&image, &["--peak", "0.04", "--display-max", "120"]);
    let (report, _) = map(
        &image,
        &["--peak", "0.04", "--display-max", "120"],
        dir.path(),
    );
    assert_eq!(started.json("/api/report"), report);
}

#[test]
fn preview_frames_have_the_asked_width_and_the_full_frames_brightness() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&chart(dir.path()), &[]);
    for level in ["1000", "0.04"] {
        let (w, h, full) = server.png(&format!("/api/frame?peak={level}&fov=6.7173"));
        assert_eq!((w, h), (807, 815));
        let (pw, ph, small) = server.png(&format!("/api/frame?peak={level}&fov=6.7173&width=200"));
        // 815 × 200 / 807 = 201.98.
        assert_eq!((pw, ph), (200, 202));
        // A box average of the scene, the same mapping: the mean code value agrees to a few
        // percent (sRGB encoding is not linear, so small-scale contrast shifts it a little).
        let (a, b) = (mean(&full), mean(&small));
        assert!((a - b).abs() < 0.04 * a, "{level}: full {a}, preview {b}");
    }
    // Lower light, darker frame.
    let bright = mean(&server.png("/api/frame?peak=1000&width=100").2);
    let dark = mean(&server.png("/api/frame?peak=0.01&width=100").2);
    assert!(dark < 0.5 * bright, "{dark} vs {bright}");
    // The plain exposure puts the highest visible luminance at the display maximum
    // whatever the level: the same frame at two levels.
    let e1 = server.png("/api/frame?peak=1000&width=100&mode=exposure");
    let e2 = server.png("/api/frame?peak=0.01&width=100&mode=exposure");
    let diff =
        e1.2.iter()
            .zip(&e2.2)
            .filter(|(a, b)| a.abs_diff(**b) > 1)
            .count();
    assert!(diff < e1.2.len() / 1000, "{diff}");
}

#[test]
fn pixel_reads_the_scene_and_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let image = chart(dir.path());
    let server = Server::start(&image, &[]);
    let scene = visadapt::io::read(&image, &visadapt::Limits::default()).unwrap();
    // Photopic: at 10^4 cd/m² the rods are saturated (k = 0), the threshold is Eq. 4.
    let report = server.json("/api/report?peak=10000");
    let lwa = report["adaptation_cd_m2"].as_f64().unwrap();
    let scale = report["input_scale"].as_f64().unwrap();
    assert_eq!(report["rod_weight"].as_f64().unwrap(), 0.0);
    let (x, y) = (400usize, 300usize);
    let p = server.json(&format!("/api/pixel?peak=10000&x={x}&y={y}&change=0.25"));
    let l = f64::from(scene.y[y * scene.width + x]) * scale;
    let got = p["luminance_cd_m2"].as_f64().unwrap();
    assert!((got - l).abs() <= 1e-6 * l, "{got} vs {l}");
    let s = f64::from(scene.scotopic.as_ref().unwrap()[y * scene.width + x]) * scale;
    let got_s = p["scotopic_cd_m2"].as_f64().unwrap();
    assert!((got_s - s).abs() <= 1e-6 * s, "{got_s} vs {s}");
    let threshold = p["threshold_cd_m2"].as_f64().unwrap();
    assert!((threshold - tp(lwa)).abs() < 1e-9 * tp(lwa), "{threshold}");
    let jnd = p["change_jnd"].as_f64().unwrap();
    assert!((jnd - 0.25 * l / tp(lwa)).abs() < 1e-6 * jnd, "{jnd}");
    assert_eq!(p["change_visible"].as_bool().unwrap(), jnd >= 1.0);
    // The displayed value is the full frame's pixel.
    let (w, _, full) = server.png("/api/frame?peak=10000");
    let i = (y * w as usize + x) * 3;
    let srgb: Vec<u64> = p["display"]["srgb8"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(
        srgb,
        full[i..i + 3]
            .iter()
            .map(|&b| u64::from(b))
            .collect::<Vec<_>>()
    );
    // At a preview width the displayed value is that frame's pixel at the same place.
    let q = server.json(&format!("/api/pixel?peak=10000&x={x}&y={y}&width=200"));
    assert_eq!(q["display"]["x"], 400 * 200 / 807);
    assert_eq!(q["luminance_cd_m2"], p["luminance_cd_m2"]);
}

fn spread(v: &[u8]) -> f64 {
    let m = mean(v);
    (v.iter().map(|&b| (f64::from(b) - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

#[test]
fn time_course_frames_are_the_sequence_frames() {
    let dir = tempfile::tempdir().unwrap();
    let image = chart(dir.path());
    let server = Server::start(&image, &[]);
    // Fig. 12b: the lights go from 1412 to 0.1 cd/m²; `sequence` renders the same switch.
    let frames = dir.path().join("frames");
    visadapt()
        .arg("sequence")
        .arg(&image)
        .args(["--from", "1412", "--to", "0.1", "--times", "0,60,210", "-o"])
        .arg(&frames)
        .assert()
        .success();
    let mut names = common::files_in(&frames);
    names.sort();
    assert_eq!(names.len(), 4, "{names:?}");
    let steady = server.json("/api/report?peak=0.1");
    assert!(steady.get("time_course").is_none());
    let mut excess = Vec::new();
    let mut contrast = Vec::new();
    for (t, name) in [(0.0, &names[1]), (60.0, &names[2]), (210.0, &names[3])] {
        let q = format!("peak=0.1&from=1412&t={t}");
        let frame = server.png(&format!("/api/frame?{q}"));
        let expected = decode_png(&std::fs::read(frames.join(name)).unwrap());
        assert_eq!((frame.0, frame.1), (expected.0, expected.1));
        // One step of t seconds against steps of 60 and 150: the same state to rounding.
        let off = frame
            .2
            .iter()
            .zip(&expected.2)
            .map(|(a, b)| a.abs_diff(*b))
            .max();
        assert!(off <= Some(1), "t = {t}: frames differ by {off:?}");
        contrast.push(spread(&frame.2));
        let r = server.json(&format!("/api/report?{q}"));
        // The keys of map --json stay, for the level after the switch.
        assert_eq!(r["adaptation_cd_m2"], steady["adaptation_cd_m2"]);
        let tc = &r["time_course"];
        assert_eq!(tc["t_seconds"].as_f64().unwrap(), t);
        excess.push(tc["rod_excess_log"].as_f64().unwrap());
    }
    // Dark adaptation: the rods start far above their threshold and recover; the scene's
    // contrast comes back as they do.
    assert!(excess[0] > 1.0, "{excess:?}");
    assert!(excess.windows(2).all(|w| w[1] < w[0]), "{excess:?}");
    assert!(contrast.windows(2).all(|w| w[1] > w[0]), "{contrast:?}");
    // An hour later the mapping is the steady state's.
    let late = server.json("/api/report?peak=0.1&from=1412&t=3600");
    let (a, b) = (
        late["time_course"]["photopic_scale"].as_f64().unwrap(),
        steady["photopic_scale"].as_f64().unwrap(),
    );
    assert!((a - b).abs() < 1e-3 * b, "after an hour {a} vs {b}");
}

#[test]
fn bad_parameters_are_400_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&chart(dir.path()), &[]);
    for (query, says) in [
        ("/api/frame?peak=abc", "invalid peak \"abc\": not a number"),
        ("/api/frame?peak=-1", "invalid peak -1"),
        ("/api/frame?peak=0", "invalid peak 0"),
        ("/api/frame?peak=NaN", "invalid peak NaN"),
        ("/api/frame?peak=inf", "invalid peak inf"),
        ("/api/report?display_max=0", "invalid display_max 0"),
        ("/api/report?fov=180", "invalid fov 180"),
        ("/api/report?fov=-3", "invalid fov -3"),
        ("/api/frame?acuity=yes", "invalid acuity \"yes\""),
        ("/api/frame?width=0", "invalid width 0"),
        (
            "/api/frame?width=808",
            "invalid width 808: must be between 1 and the image width 807",
        ),
        ("/api/frame?width=1.5", "invalid width \"1.5\""),
        ("/api/frame?width=99999999999999999999999", "invalid width"),
        ("/api/frame?t=5", "parameter \"t\" needs \"from\""),
        ("/api/frame?from=5", "parameter \"from\" needs \"t\""),
        ("/api/frame?from=5&t=-1", "invalid t -1"),
        ("/api/frame?mode=hdr", "invalid mode \"hdr\""),
        (
            "/api/frame?glare=yes",
            "invalid glare \"yes\": must be 0 or 1",
        ),
        (
            "/api/report?adaptation=Local",
            "invalid adaptation \"Local\": must be global or local",
        ),
        ("/api/pixel?x=1&y=1&glare=2", "invalid glare \"2\""),
        ("/api/frame?peak=1&peak=2", "parameter \"peak\" given twice"),
        ("/api/frame?Peak=1", "unknown parameter \"Peak\""),
        ("/api/frame?x=1", "unknown parameter \"x\""),
        ("/api/pixel?y=3", "missing parameter \"x\""),
        (
            "/api/pixel?x=807&y=0",
            "invalid pixel (807, 0): outside the 807x815 image",
        ),
        ("/api/pixel?x=-1&y=0", "invalid x \"-1\""),
        ("/api/pixel?x=1&y=1&change=inf", "invalid change inf"),
        ("/api/report?peak=%ff%fe", "invalid peak"),
    ] {
        let r = server.get(query);
        assert_eq!(r.status, 400, "{query}: {}", r.text());
        let text = r.text();
        assert_eq!(text.trim_end().lines().count(), 1, "{query}: {text:?}");
        assert!(text.starts_with(says), "{query}: {text:?}");
    }
    assert_eq!(server.get("/nothing").status, 404);
    // A name other than loopback's (DNS rebinding) is refused; localhost is fine.
    let port = server.url.rsplit(':').next().unwrap();
    for (host, status) in [
        (format!("evil.example:{port}"), 403),
        (format!("localhost:{port}"), 200),
        (format!("127.0.0.1:{port}"), 200),
        (format!("[::1]:{port}"), 200),
    ] {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .build()
            .into();
        let r = agent
            .get(format!("{}/", server.url))
            .header("host", &host)
            .call()
            .unwrap();
        assert_eq!(r.status().as_u16(), status, "{host}");
    }
    // The server is still well after all that.
    assert_eq!(server.png("/api/frame?width=50").0, 50);
}

#[test]
fn odd_but_valid_requests_never_fail_the_server() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&chart(dir.path()), &[]);
    for query in [
        "peak=1e-300",
        "peak=1e300",
        "peak=3.4e38&from=1e-30&t=1e300",
        "from=1e300&t=0&width=1",
        "display_max=1e-300&width=3",
        "display_max=1e300&width=3",
        "fov=1e-9&width=7",
        "fov=179.9999&width=7",
        "peak=1e-4&from=1e5&t=1e-300&width=807&mode=exposure",
        "width=1&acuity=false",
    ] {
        for api in ["frame", "report"] {
            let r = server.get(&format!("/api/{api}?{query}"));
            assert!(
                r.status == 200 || r.status == 400,
                "{api}?{query}: {} {}",
                r.status,
                r.text()
            );
        }
        let r = server.get(&format!("/api/pixel?x=806&y=814&{query}"));
        assert!(
            r.status == 200 || r.status == 400,
            "pixel?{query}: {}",
            r.text()
        );
    }
    assert_eq!(server.png("/api/frame?width=50").0, 50);
}

#[test]
fn page_is_self_contained() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&chart(dir.path()), &[]);
    let page = server.get("/");
    assert_eq!(page.status, 200);
    assert!(page.content_type.starts_with("text/html"));
    let html = page.text();
    assert!(html.contains("<script src=\"/viewer.js\">"), "{html}");
    for (path, kind) in [
        ("/viewer.js", "text/javascript"),
        ("/viewer.css", "text/css"),
    ] {
        let r = server.get(path);
        assert_eq!(r.status, 200, "{path}");
        assert!(
            r.content_type.starts_with(kind),
            "{path}: {}",
            r.content_type
        );
        // Offline: nothing is fetched from elsewhere.
        let text = r.text();
        assert!(
            !text.contains("http://") && !text.contains("https://"),
            "{path}"
        );
    }
    assert!(!html.contains("http://") && !html.contains("https://"));
}

#[test]
fn ctrl_c_stops_the_server_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let mut server = Server::start(&chart(dir.path()), &[]);
    assert_eq!(server.get("/api/frame?width=10").status, 200);
    let status = Command::new("kill")
        .args(["-INT", &server.child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let started = Instant::now();
    let code = loop {
        if let Some(code) = server.child.try_wait().unwrap() {
            break code;
        }
        assert!(started.elapsed() < Duration::from_secs(30), "still running");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(code.success(), "{code:?}");
    let mut rest = String::new();
    std::io::Read::read_to_string(server.child.stdout.as_mut().unwrap(), &mut rest).unwrap();
    assert!(rest.contains("visadapt: stopped"), "{rest:?}");
}

#[test]
fn serve_refuses_a_bad_file_or_flag() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.exr");
    std::fs::write(&bad, b"v/1\x01 truncated").unwrap();
    let ramps = data("GrayRampsHorizontal.exr");
    let ramps = ramps.to_str().unwrap();
    // Run-time errors: one line naming the file, exit 1.
    for (args, says) in [
        (vec![bad.to_str().unwrap()], "bad.exr"),
        (vec!["/nonexistent/x.hdr"], "x.hdr"),
    ] {
        let out = visadapt()
            .arg("serve")
            .args(&args)
            .args(["--port", "0", "--no-open"])
            .timeout(Duration::from_secs(60))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        let err = common::one_line_error(&out.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    }
    // Usage errors: clap's, exit 2, naming the flag.
    for (args, says) in [
        (vec![ramps, "--fov", "200"], "'--fov <DEG>'"),
        (vec![ramps, "--scale", "-1"], "'--scale <S>'"),
        (vec![ramps, "--port", "70000"], "'--port <P>'"),
    ] {
        let out = visadapt()
            .arg("serve")
            .args(&args)
            .arg("--no-open")
            .timeout(Duration::from_secs(60))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

/// The largest difference of two decoded PNGs' code values (their sizes must agree).
fn max_diff(a: &(u32, u32, Vec<u8>), b: &(u32, u32, Vec<u8>)) -> u8 {
    assert_eq!((a.0, a.1), (b.0, b.1));
    a.2.iter()
        .zip(&b.2)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap_or(0)
}

/// With glare and local adaptation switched on by the API, the report is `map --json`'s
/// with the same flags and the full-resolution frame is `map`'s PNG pixel for pixel; the
/// caches keep the settings apart: switching back and forth gives each setting's own
/// frame, and the frame says what it shows.
#[test]
fn glare_and_local_adaptation_equal_map() {
    let dir = tempfile::tempdir().unwrap();
    let image = chart(dir.path());
    let server = Server::start(&image, &["--fov", "6.7173"]);
    let view = ["--fov", "6.7173"];
    let cases: [(&str, &[&str]); 5] = [
        ("peak=0.04", &[]),
        ("peak=0.04&glare=1", &["--glare"]),
        ("peak=0.04&adaptation=local", &["--adaptation", "local"]),
        (
            "peak=0.04&glare=1&adaptation=local",
            &["--glare", "--adaptation", "local"],
        ),
        (
            "peak=1000&glare=1&adaptation=local&acuity=0",
            &["--glare", "--adaptation", "local", "--no-acuity"],
        ),
    ];
    let mut expected = Vec::new();
    for (query, flags) in cases {
        let peak = query.split('&').next().unwrap().trim_start_matches("peak=");
        let args: Vec<&str> = ["--peak", peak]
            .into_iter()
            .chain(view)
            .chain(flags.iter().copied())
            .collect();
        expected.push(map(&image, &args, dir.path()));
    }
    // Twice through, in an order that changes one setting at a time.
    for round in 0..2 {
        for (i, (query, flags)) in cases.iter().enumerate() {
            let (report, png) = &expected[i];
            let got = server.json(&format!("/api/report?{query}"));
            assert_eq!(&got, report, "round {round}: {query}");
            assert_eq!(
                got["adaptation"],
                if query.contains("local") {
                    "local"
                } else {
                    "global"
                }
            );
            assert_eq!(
                got["glare"].is_null(),
                !flags.contains(&"--glare"),
                "{query}"
            );
            let r = server.get(&format!("/api/frame?{query}"));
            assert_eq!(r.status, 200, "{query}: {}", r.text());
            assert_eq!(&decode_png(&r.body), png, "round {round}: {query}");
            let local = query.contains("adaptation=local");
            let glare = query.contains("glare=1");
            assert_eq!(
                r.showing.contains("local adaptation"),
                local,
                "{}",
                r.showing
            );
            assert_eq!(
                r.showing.contains("global adaptation"),
                !local,
                "{}",
                r.showing
            );
            assert_eq!(r.showing.contains("veiling glare"), glare, "{}", r.showing);
            assert_eq!(r.showing.contains("no glare"), !glare, "{}", r.showing);
        }
    }
    // The four settings at moonlight give four different pictures.
    for i in 0..4 {
        for j in i + 1..4 {
            assert!(max_diff(&expected[i].1, &expected[j].1) > 10, "{i} vs {j}");
        }
    }
    // The plain exposure is a camera's: the same whatever the observer's glare and
    // adaptation.
    let plain = server.get("/api/frame?peak=0.04&mode=exposure&width=100");
    let both = server.get("/api/frame?peak=0.04&mode=exposure&width=100&glare=1&adaptation=local");
    assert_eq!(plain.body, both.body);
    assert!(
        both.showing.starts_with("plain exposure"),
        "{}",
        both.showing
    );
}

/// The flags set where the page starts: `serve --glare --adaptation local` is `map
/// --glare --adaptation local`, and the API switches both off again.
#[test]
fn glare_and_local_flags_set_the_start() {
    let dir = tempfile::tempdir().unwrap();
    let image = chart(dir.path());
    let flags = [
        "--peak",
        "0.04",
        "--glare",
        "--age",
        "70",
        "--adaptation",
        "local",
        "--adaptation-radius",
        "2",
    ];
    let server = Server::start(&image, &flags);
    let (report, png) = map(&image, &flags, dir.path());
    assert_eq!(server.json("/api/report"), report);
    assert_eq!(report["glare"]["age_years"], 70.0);
    assert_eq!(report["local"]["radius_deg"], 2.0);
    assert_eq!(server.png("/api/frame"), png);
    let (plain, plain_png) = map(&image, &["--peak", "0.04"], dir.path());
    assert_eq!(server.json("/api/report?glare=0&adaptation=global"), plain);
    assert_eq!(
        server.png("/api/frame?glare=0&adaptation=global"),
        plain_png
    );
}

/// A preview with glare and local adaptation is the library's own: the retinal image of
/// the full-resolution scene (`operator::prepare`), box-averaged to the preview
/// (`preview::downsample_into`), its local adaptation map made at the preview's pixels
/// (`preview::report_at_width`, `operator::local_map`) and mapped (`local::apply_into`).
/// Tolerance: none, the same code values.
#[test]
fn previews_with_glare_and_local_adaptation_are_the_librarys() {
    use visadapt::operator::{self, AdaptationMode, ViewingConditions};
    use visadapt::{glare::Glare, local, preview};
    let dir = tempfile::tempdir().unwrap();
    let image = chart(dir.path());
    let server = Server::start(&image, &["--fov", "6.7173"]);
    let scene = visadapt::io::read(&image, &visadapt::Limits::default()).unwrap();
    let (w, h) = (scene.width, scene.height);
    for (peak, glare, adaptation) in [
        (0.04, true, true),
        (0.04, false, true),
        (0.04, true, false),
        (20.0, true, true),
    ] {
        let conditions = ViewingConditions {
            view: Some(visadapt::View::perspective(6.7173, w, h)),
            glare: glare.then(Glare::default),
            adaptation: if adaptation {
                AdaptationMode::Local(local::LocalAdaptation::default())
            } else {
                AdaptationMode::Global
            },
            ..ViewingConditions::default()
        };
        let mut scaled = scene.clone();
        let factor = scene
            .peak_factor(peak, conditions.hot_pixel_fraction)
            .unwrap();
        scaled.scale(factor as f32);
        let (retina, report) = operator::prepare(&scaled, &conditions).unwrap();
        let mut small = visadapt::HdrImage::zeros(0, 0);
        preview::downsample_into(&retina, 200, &mut small).unwrap();
        let small_report = preview::report_at_width(&report, 200);
        let mut out = visadapt::DisplayImage::default();
        match conditions.adaptation {
            AdaptationMode::Local(options) => {
                let map =
                    operator::local_map(&small, &small_report, &conditions, &options).unwrap();
                let mapping = local::LocalMapping::steady_state(&map, &small_report, true);
                local::apply_into(&small, &map, &mapping, &mut out);
            }
            AdaptationMode::Global => {
                operator::apply_into(&small, &small_report.mapping, &mut out);
            }
        }
        let want = (
            200,
            small.height as u32,
            visadapt::io::display::to_srgb8(&out),
        );
        let query = format!(
            "/api/frame?peak={peak}&width=200&glare={}&adaptation={}",
            u8::from(glare),
            if adaptation { "local" } else { "global" }
        );
        let got = server.png(&query);
        assert_eq!(max_diff(&got, &want), 0, "{query}");
        // The preview shows the full frame's picture: its mean code value within a few
        // percent (the box average and the sRGB curve shift it a little).
        let full = server.png(&query.replace("&width=200", ""));
        let (a, b) = (mean(&full.2), mean(&got.2));
        assert!((a - b).abs() < 0.04 * a, "{query}: full {a}, preview {b}");
    }
}

/// The pixel inspector under local adaptation reads the thresholds at the pixel's own
/// adaptation (the library's map of the full scene), and under glare the luminance that
/// reaches the retina there.
#[test]
fn pixel_reads_local_thresholds_and_the_veil() {
    use visadapt::operator::{self, ViewingConditions};
    use visadapt::visibility::Sensitivity;
    use visadapt::{glare::Glare, local, preview};
    let dir = tempfile::tempdir().unwrap();
    let image = chart(dir.path());
    let server = Server::start(&image, &["--fov", "6.7173"]);
    let scene = visadapt::io::read(&image, &visadapt::Limits::default()).unwrap();
    let w = scene.width;
    let conditions = ViewingConditions {
        view: Some(visadapt::View::perspective(6.7173, w, scene.height)),
        ..ViewingConditions::default()
    };
    let mut scaled = scene.clone();
    scaled.scale(
        scene
            .peak_factor(0.04, conditions.hot_pixel_fraction)
            .unwrap() as f32,
    );
    let report = operator::plan(&scaled, &conditions).unwrap();
    let map = operator::local_map(
        &scaled,
        &report,
        &conditions,
        &local::LocalAdaptation::default(),
    )
    .unwrap();
    let mut differ = 0;
    for (x, y) in [(100usize, 700usize), (400, 300), (700, 100)] {
        let want = preview::probe(
            &scaled,
            x,
            y,
            &Sensitivity::local(&map, y * w + x, None),
            0.3,
        )
        .unwrap();
        let p = server.json(&format!(
            "/api/pixel?peak=0.04&x={x}&y={y}&change=0.3&adaptation=local"
        ));
        let t = p["threshold_cd_m2"].as_f64().unwrap();
        assert!(
            (t - want.threshold_cd_m2).abs() <= 1e-9 * t,
            "({x}, {y}): {t} vs {want:?}"
        );
        let jnd = p["change_jnd"].as_f64().unwrap();
        assert!(
            (jnd - want.change_jnd).abs() <= 1e-9 * jnd,
            "({x}, {y}): {jnd}"
        );
        assert_eq!(p["retinal_cd_m2"], p["luminance_cd_m2"]);
        let g = server.json(&format!("/api/pixel?peak=0.04&x={x}&y={y}&change=0.3"));
        let tg = g["threshold_cd_m2"].as_f64().unwrap();
        differ += usize::from((t / tg - 1.0).abs() > 0.01);
    }
    // The local thresholds are not the global one.
    assert!(differ >= 1, "{differ}");
    let global = server.json("/api/pixel?peak=0.04&x=100&y=700&change=0.3");
    // With glare the eye's scatter moves light (a bright pixel loses some to its halo, a
    // dark one gains); the scene's own luminance stays.
    let veiled = server.json("/api/pixel?peak=0.04&x=100&y=700&change=0.3&glare=1");
    assert_eq!(veiled["luminance_cd_m2"], global["luminance_cd_m2"]);
    let (l, r) = (
        veiled["luminance_cd_m2"].as_f64().unwrap(),
        veiled["retinal_cd_m2"].as_f64().unwrap(),
    );
    assert!((r - l).abs() > 0.01 * l, "retinal {r} vs scene {l}");
    let (retina, _) = operator::prepare(
        &scaled,
        &ViewingConditions {
            glare: Some(Glare::default()),
            ..conditions
        },
    )
    .unwrap();
    let want = f64::from(retina.y[700 * w + 100]);
    assert!((r - want).abs() <= 1e-6 * want, "{r} vs {want}");
}

/// A time course with glare and local adaptation: the frames are `sequence`'s with the
/// same flags, to one code value (one step of t seconds against steps of 60 and 150).
#[test]
fn time_course_with_glare_and_local_adaptation_is_the_sequence() {
    let dir = tempfile::tempdir().unwrap();
    let image = chart(dir.path());
    let server = Server::start(&image, &[]);
    let frames = dir.path().join("frames");
    visadapt()
        .arg("sequence")
        .arg(&image)
        .args(["--from", "1412", "--to", "0.1", "--times", "60,210"])
        .args(["--glare", "--adaptation", "local", "-o"])
        .arg(&frames)
        .assert()
        .success();
    let mut names = common::files_in(&frames);
    names.sort();
    assert_eq!(names.len(), 3, "{names:?}");
    for (t, name) in [(60.0, &names[1]), (210.0, &names[2])] {
        let q = format!("peak=0.1&from=1412&t={t}&glare=1&adaptation=local");
        let frame = server.png(&format!("/api/frame?{q}"));
        let expected = decode_png(&std::fs::read(frames.join(name)).unwrap());
        assert!(max_diff(&frame, &expected) <= 1, "t = {t}");
        // The tolerance tells the settings apart: the global frame without glare is not
        // within it.
        let global = server.png(&format!("/api/frame?peak=0.1&from=1412&t={t}"));
        let d = max_diff(&global, &expected);
        assert!(
            d > 1,
            "t = {t}: the global frame is within {d} of the sequence's"
        );
    }
}
