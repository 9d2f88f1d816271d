//! Every `visadapt ...` command line of the README's shell blocks, run as written (through
//! `sh`, so quotes, pipes and redirections are the README's own) in a temporary folder
//! holding small stand-ins for the files it names, built from the repository's test data.
//! The README's Rust examples are doc tests of the library (`visadapt::Readme`).

mod common;
use common::*;
use std::path::Path;
use std::process::Command;

/// Commands of the README that this test does not run, with the reason.
const SKIPPED: [(&str, &str); 1] = [(
    "visadapt serve",
    "a server that runs until stopped, and opens a browser (tests/serve.rs and the browser \
     test drive it)",
)];

/// The README's shell blocks' lines that run `visadapt` (also after a pipe), in order.
fn readme_commands() -> Vec<String> {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md"))
        .expect("the README");
    let mut in_shell = false;
    let mut commands = Vec::new();
    for line in readme.lines() {
        if let Some(info) = line.strip_prefix("```") {
            in_shell = !in_shell && info.trim() == "sh";
            continue;
        }
        let line = line.trim();
        if in_shell && (line.starts_with("visadapt ") || line.contains("| visadapt ")) {
            commands.push(line.to_string());
        }
    }
    commands
}

/// The files the README's commands read, small: its sample Radiance image as `.hdr`,
/// `.exr` and `.pfm` under the README's names, a brighter copy as the rendering to
/// compare, and three numbered frames for `video`.
fn stand_ins(dir: &Path) {
    let limits = visadapt::Limits::default();
    let scene = visadapt::io::read(&data("mixtex.hdr"), &limits).unwrap();
    let exr = |name: &str, image: &visadapt::HdrImage| {
        let path = dir.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let file = std::fs::File::create(&path).unwrap();
        visadapt::io::exr::write_hdr(image, std::io::BufWriter::new(file)).unwrap();
    };
    for name in ["scene.hdr", "a.hdr", "b.hdr"] {
        std::fs::copy(data("mixtex.hdr"), dir.join(name)).unwrap();
    }
    for name in ["scene.exr", "b.exr", "reference.exr"] {
        exr(name, &scene);
    }
    let mut render = scene.clone();
    render.scale(1.1);
    exr("render.exr", &render);
    for name in ["render.pfm", "c.pfm"] {
        std::fs::write(dir.join(name), visadapt::io::pfm::encode(&scene)).unwrap();
    }
    for (i, factor) in [1.0, 0.1, 0.01].into_iter().enumerate() {
        let mut frame = scene.clone();
        frame.scale(factor);
        exr(&format!("render/f_{:04}.exr", i + 1), &frame);
    }
}

/// The outputs a command line names (`-o`, `--apng`, `>`): files, or folders (`/`).
fn outputs(line: &str) -> Vec<String> {
    let words: Vec<&str> = line.split('#').next().unwrap().split_whitespace().collect();
    words
        .windows(2)
        .filter(|w| matches!(w[0], "-o" | "--output" | "--apng" | ">"))
        .map(|w| w[1].to_string())
        .filter(|o| o != "-")
        .collect()
}

#[test]
fn every_command_line_of_the_readme_runs() {
    let commands = readme_commands();
    let dir = tempfile::tempdir().unwrap();
    stand_ins(dir.path());
    let bin = assert_cmd::cargo::cargo_bin("visadapt");
    let path = format!(
        "{}:{}",
        bin.parent().unwrap().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut ran = 0;
    for line in &commands {
        if let Some((_, why)) = SKIPPED.iter().find(|(c, _)| line.starts_with(c)) {
            eprintln!("skipped: {line} ({why})");
            continue;
        }
        let out = Command::new("sh")
            .arg("-c")
            .arg(line)
            .current_dir(dir.path())
            .env("PATH", &path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "README: {line}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        for o in outputs(line) {
            let p = dir.path().join(&o);
            if o.ends_with('/') {
                assert!(
                    std::fs::read_dir(&p).is_ok_and(|mut d| d.next().is_some()),
                    "README: {line}: nothing in {o}"
                );
            } else {
                let len = std::fs::metadata(&p).map_or(0, |m| m.len());
                assert!(len > 0, "README: {line}: no {o}");
            }
        }
        // A report asked for as JSON on standard output is JSON.
        if line.contains("--json") && !line.contains("> ") {
            json(&out.stdout);
        }
        ran += 1;
    }
    // Every shell example of the README but the skipped ones (the count guards the
    // extraction itself: a README without them would pass nothing).
    let skipped = commands.len() - ran;
    assert!(ran >= 20, "only {ran} commands found and run");
    assert_eq!(skipped, 3, "{commands:#?}");
}

#[test]
fn the_extraction_finds_pipes_comments_and_outputs() {
    assert_eq!(
        outputs("cat scene.hdr | visadapt map - -o - > scene.png"),
        ["scene.png"]
    );
    assert_eq!(
        outputs("visadapt sequence s.hdr -o dark/ --apng dark.png   # -o x"),
        ["dark/", "dark.png"]
    );
    let commands = readme_commands();
    assert!(
        commands.iter().any(|c| c.starts_with("cat ")),
        "{commands:#?}"
    );
    assert!(
        commands
            .iter()
            .all(|c| !c.starts_with("cargo ") && !c.starts_with("pip "))
    );
}
