"""Tests of the Python package: the same numbers as the CLI, numpy round trips, errors, GIL.

The CLI comparisons run the `visadapt` binary: $VISADAPT_CLI, else the workspace's
target/{debug,release}/visadapt. CI sets VISADAPT_CLI, so there they cannot be skipped.
Files from the shared data set are used when $VISADAPT_SHARED_DATA is set; the rest runs
on a clean clone (a small EXR of the repository and the built-in chart).
"""

import json
import os
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import visadapt

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "crates" / "visadapt" / "tests" / "data"
SHARED = os.environ.get("VISADAPT_SHARED_DATA")

# The CLI and this package may be built at different optimisation levels: libm results can
# differ in the last bit, which the model carries on at most a few ulps.
RTOL = 1e-6


def cli_path():
    given = os.environ.get("VISADAPT_CLI")
    if given:
        assert Path(given).is_file(), f"VISADAPT_CLI={given} does not exist"
        return given
    for profile in ("debug", "release"):
        p = ROOT / "target" / profile / "visadapt"
        if p.is_file():
            return str(p)
    pytest.skip("no visadapt binary (set VISADAPT_CLI or run cargo build -p visadapt-cli)")


def cli_json(*args):
    out = subprocess.run(
        [cli_path(), *map(str, args)], check=True, capture_output=True, text=True
    )
    return json.loads(out.stdout)


def assert_same_report(got, want, at="report"):
    """Same keys, strings, booleans and integers; floats within RTOL."""
    if isinstance(want, dict):
        assert sorted(got) == sorted(want), at
        for k in want:
            assert_same_report(got[k], want[k], f"{at}.{k}")
    elif isinstance(want, list):
        assert len(got) == len(want), at
        for i, (g, w) in enumerate(zip(got, want)):
            assert_same_report(g, w, f"{at}[{i}]")
    elif isinstance(want, float):
        assert isinstance(got, float), at
        assert got == pytest.approx(want, rel=RTOL, abs=1e-300), at
    else:
        assert type(got) is type(want) and got == want, at


def map_cases():
    cases = [
        pytest.param(DATA / "GrayRampsHorizontal.exr", [], id="GrayRamps"),
        pytest.param(
            DATA / "WideFloatRange.exr",
            ["--peak", "0.05", "--fov", "40"],
            id="WideFloatRange-moonlight",
        ),
        pytest.param(
            DATA / "GrayRampsHorizontal.exr",
            ["--scale", "0.01", "--fov", "200", "--projection", "fisheye", "--display-max", "120"],
            id="GrayRamps-fisheye-dim",
        ),
        pytest.param(
            DATA / "GrayRampsHorizontal.exr",
            ["--adaptation", "local", "--adaptation-radius", "2", "--white-point", "none"],
            id="GrayRamps-local",
        ),
        pytest.param(
            DATA / "WideFloatRange.exr",
            ["--glare", "--age", "70", "--pigmentation", "1", "--fov", "40"],
            id="WideFloatRange-glare",
        ),
    ]
    if SHARED:
        cases += [
            pytest.param(Path(SHARED) / "openexr" / "Desk.exr", ["--peak", "0.5"], id="Desk"),
            pytest.param(
                Path(SHARED) / "radiance" / "sunset-fisheye.hdr", [], id="sunset-fisheye"
            ),
        ]
    return cases


def kwargs_of(flags):
    """CLI flags to keyword arguments (--no-acuity -> acuity=False)."""
    out, it = {}, iter(flags)
    for flag in it:
        name = flag[2:].replace("-", "_")
        if name == "no_acuity":
            out["acuity"] = False
        elif name == "glare":
            out["glare"] = True
        else:
            value = next(it)
            try:
                out[name] = float(value)
            except ValueError:
                out[name] = value
    return out


@pytest.mark.parametrize("path,flags", map_cases())
def test_map_gives_the_cli_report_and_linear_exr_pixels(tmp_path, path, flags):
    out = tmp_path / "cli.exr"
    want = cli_json("map", path, "-o", out, "--json", *flags)
    display, report = visadapt.map(visadapt.read(path), **kwargs_of(flags))
    assert_same_report(report, want)
    assert display.dtype == np.float32
    assert display.shape == (report["height"], report["width"], 3)

    # The CLI's linear EXR holds display RGB times display_max (whiteLuminance), which
    # `read` returns as XYZ in cd/m²; the package's display through the same conversion.
    cli_xyz = visadapt.read(out).xyz
    ours = visadapt.from_rgb(display, scale=report["display_max_cd_m2"]).xyz
    peak = float(np.abs(cli_xyz).max())
    assert peak > 0
    np.testing.assert_allclose(ours, cli_xyz, rtol=RTOL, atol=RTOL * peak)

    # And our display image written as EXR is the CLI's file, pixel for pixel.
    mine = tmp_path / "py.exr"
    visadapt.write(mine, display, display_max=report["display_max_cd_m2"])
    np.testing.assert_allclose(visadapt.read(mine).xyz, cli_xyz, rtol=RTOL, atol=RTOL * peak)


def test_map_of_the_chart_gives_the_cli_report(tmp_path):
    chart = visadapt.chart(white=0.1, fov=30)
    scene = tmp_path / "chart.exr"
    visadapt.write(scene, chart)
    # The EXR keeps X, Y, Z and the scotopic plane, not the view: give the CLI the field.
    want = cli_json("map", scene, "-o", tmp_path / "out.exr", "--json", "--fov", 30)
    display, report = visadapt.map(visadapt.read(scene), fov=30)
    assert_same_report(report, want)
    assert report["scotopic_source"] == "from the file"
    # The in-memory chart carries its view, which the model then uses.
    _, report = visadapt.map(chart)
    assert report["view"]["source"] == "from the file"
    assert report["view"]["horizontal_fov_deg"] == pytest.approx(30, rel=1e-9)
    assert report["pixels_per_degree"] == pytest.approx(want["pixels_per_degree"], rel=1e-9)


@pytest.mark.parametrize("args", [(0.01, None), (40.0, 90.0), (1e4, None)])
def test_observer_gives_the_cli_report(args):
    luminance, scotopic = args
    flags = ["--scotopic", scotopic] if scotopic is not None else []
    want = cli_json("observer", luminance, "--json", "--display-max", 100, *flags)
    got = visadapt.observer(luminance, scotopic, display_max=100)
    assert_same_report(got, want)
    # Eq. 4 at 40 cd/m² (log L = 1.602: (0.249 log L + 0.65)^2.7 - 0.72), independently.
    if luminance == 40.0:
        x = np.log10(40.0)
        assert got["cone_threshold_cd_m2"] == pytest.approx(
            10 ** ((0.249 * x + 0.65) ** 2.7 - 0.72), rel=1e-12
        )


def test_timecourse_gives_the_cli_report():
    times = [0, 1, 60, 210, 1800]
    want = cli_json(
        "timecourse", "--from", 1412, "--to", 0.1, "--times", ",".join(map(str, times)), "--json"
    )
    got = visadapt.timecourse(1412, 0.1, times)
    assert len(got) == 5
    assert_same_report(got, want)
    # Dark adaptation: the cone threshold falls monotonically.
    cone = [m["cone_threshold_cd_m2"] for m in got]
    assert all(a > b for a, b in zip(cone, cone[1:]))


def test_visible_and_tolerance_give_the_cli_reports(tmp_path):
    a, b = DATA / "GrayRampsHorizontal.exr", tmp_path / "brighter.exr"
    ref = visadapt.read(a)
    # The test image: the reference 3 % brighter (XYZ and scotopic alike).
    brighter = visadapt.from_array(ref.xyz * 1.03)
    visadapt.write(b, brighter)
    want = cli_json("visible", a, b, "--json")
    jnd, summary = visadapt.visible(ref, visadapt.read(b))
    assert_same_report(summary, want)
    assert jnd.shape == (ref.height, ref.width) and jnd.dtype == np.float32
    assert float(jnd.max()) == pytest.approx(summary["max_jnd"], rel=1e-6)
    assert float(jnd.mean()) == pytest.approx(summary["mean_jnd"], rel=1e-4)
    assert summary["max_jnd"] > 0

    out = tmp_path / "tol.exr"
    want = cli_json("tolerance", a, "-o", out, "--json")
    tol, summary = visadapt.tolerance(ref)
    want["output"] = None  # the only key that names the CLI's file
    assert_same_report(summary, want)
    # The CLI's tolerance map, read back as a grey image: Y is the tolerance in cd/m².
    np.testing.assert_allclose(tol, visadapt.read(out).xyz[..., 1], rtol=RTOL)


@pytest.mark.parametrize(
    "flags", [["--glare"], ["--adaptation", "local"]], ids=["glare", "local"]
)
def test_visible_and_tolerance_with_glare_or_local_adaptation_give_the_cli_reports(
    tmp_path, flags
):
    a, b = DATA / "GrayRampsHorizontal.exr", tmp_path / "brighter.exr"
    ref = visadapt.read(a)
    visadapt.write(b, visadapt.from_array(ref.xyz * 1.05))
    want = cli_json("visible", a, b, "--json", "--fov", 40, *flags)
    jnd, summary = visadapt.visible(ref, visadapt.read(b), fov=40, **kwargs_of(flags))
    assert_same_report(summary, want)
    assert float(jnd.max()) == pytest.approx(summary["max_jnd"], rel=1e-6)
    out = tmp_path / "tol.exr"
    # tolerance takes no view (acuity does not enter it): the file's, or the default.
    want = cli_json("tolerance", a, "-o", out, "--json", *flags)
    want["output"] = None
    tol, summary = visadapt.tolerance(ref, **kwargs_of(flags))
    assert_same_report(summary, want)
    np.testing.assert_allclose(tol, visadapt.read(out).xyz[..., 1], rtol=RTOL)


def test_refining_keywords_need_what_they_refine():
    image = visadapt.chart(white=5)
    with pytest.raises(ValueError, match="adaptation='local'"):
        visadapt.map(image, adaptation_radius=2)
    with pytest.raises(ValueError, match="glare=True"):
        visadapt.map(image, age=70)
    with pytest.raises(ValueError, match="white_point"):
        visadapt.map(image, white_point="purple")
    with pytest.raises(ValueError, match="global or local"):
        visadapt.map(image, adaptation="regional")


def test_numpy_round_trips_keep_every_value(tmp_path):
    rng = np.random.default_rng(1)
    xyz = rng.uniform(0, 500, (7, 11, 3)).astype(np.float32)
    scotopic = rng.uniform(0, 900, (7, 11)).astype(np.float32)
    image = visadapt.from_array(xyz, scotopic, view={"horizontal_fov_deg": 50})
    assert (image.width, image.height) == (11, 7)
    np.testing.assert_array_equal(image.xyz, xyz)
    np.testing.assert_array_equal(image.scotopic, scotopic)
    assert image.view["projection"] == "perspective"
    assert image.view["horizontal_fov_deg"] == 50

    path = tmp_path / "round.exr"
    visadapt.write(path, image)
    back = visadapt.read(path)
    np.testing.assert_array_equal(back.xyz, xyz)
    np.testing.assert_array_equal(back.scotopic, scotopic)
    assert back.absolute_units


def test_float64_and_fortran_order_give_the_same_image():
    rng = np.random.default_rng(2)
    xyz = rng.uniform(0, 50, (5, 9, 3))
    ref = visadapt.from_array(xyz.astype(np.float32))
    for variant in (xyz, np.asfortranarray(xyz), np.asfortranarray(xyz.astype(np.float32))):
        np.testing.assert_array_equal(visadapt.from_array(variant).xyz, ref.xyz)
    # A strided view (every other column) is read in its logical order.
    wide = rng.uniform(0, 50, (5, 18, 3))
    np.testing.assert_array_equal(
        visadapt.from_array(wide[:, ::2]).xyz, wide[:, ::2].astype(np.float32)
    )


def test_from_rgb_uses_the_primaries_and_scale():
    rgb = np.ones((2, 3, 3))
    # RGB = (1, 1, 1) is the white: Y = 1 x scale, and D65's x, y for Rec. 709.
    xyz = visadapt.from_rgb(rgb, scale=179.0).xyz
    assert xyz[0, 0, 1] == pytest.approx(179.0, rel=1e-6)
    s = xyz[0, 0].sum()
    assert xyz[0, 0, 0] / s == pytest.approx(0.3127, abs=1e-6)
    assert xyz[0, 0, 1] / s == pytest.approx(0.3290, abs=1e-6)
    # Radiance's primaries have an equal-energy white.
    xyz = visadapt.from_rgb(rgb, primaries="radiance").xyz
    assert xyz[0, 0] == pytest.approx([1.0, 1.0, 1.0], rel=1e-6)
    # XYZ "primaries" give the identity.
    xyz_primaries = ((1, 0), (0, 1), (0, 0), (1 / 3, 1 / 3))
    m = np.arange(18, dtype=np.float64).reshape(2, 3, 3)
    np.testing.assert_allclose(
        visadapt.from_rgb(m, primaries=xyz_primaries).xyz, m, rtol=1e-6, atol=1e-6
    )


def test_wrong_shapes_and_types_are_refused():
    with pytest.raises(ValueError, match=r"xyz must have shape \(H, W, 3\), got \(4, 4\)"):
        visadapt.from_array(np.zeros((4, 4), np.float32))
    with pytest.raises(ValueError, match=r"got \(4, 4, 4\)"):
        visadapt.from_array(np.zeros((4, 4, 4), np.float32))
    with pytest.raises(ValueError, match="must not be empty"):
        visadapt.from_array(np.zeros((0, 4, 3), np.float32))
    with pytest.raises(ValueError, match=r"scotopic must have shape \(4, 5\), got \(5, 4\)"):
        visadapt.from_array(np.zeros((4, 5, 3), np.float32), np.zeros((5, 4), np.float32))
    with pytest.raises(TypeError, match="float32 or float64 numpy array, got an array of dtype int64"):
        visadapt.from_array(np.zeros((4, 4, 3), np.int64))
    with pytest.raises(TypeError, match="got a list"):
        visadapt.from_array([[[0.0, 0.0, 0.0]]])
    with pytest.raises(ValueError, match="unknown projection 'fish'"):
        visadapt.from_array(np.zeros((4, 4, 3)), view={"projection": "fish", "horizontal_fov_deg": 90})


def test_nan_and_negative_pixels_follow_the_library_policy():
    xyz = np.full((8, 8, 3), 20.0, np.float32)
    xyz[0, 0] = np.nan
    xyz[1, 1, 2] = np.inf
    xyz[2, 2, 0] = -5.0
    display, report = visadapt.map(visadapt.from_array(xyz))
    assert report["pixels_non_finite"] == 2
    assert report["pixels_negative"] == 1
    assert np.isfinite(display).all()
    np.testing.assert_array_equal(display[0, 0], 0.0)
    np.testing.assert_array_equal(display[1, 1], 0.0)
    # The highest visible luminance ignores them: 20 cd/m², adapted to half of it.
    assert report["adaptation_cd_m2"] == pytest.approx(10.0, rel=1e-6)


def test_bad_parameters_raise_value_error_with_the_library_message():
    image = visadapt.chart(white=10)
    with pytest.raises(ValueError, match=r"^invalid display-max -1: must be a positive luminance from 1e-19 to 1e19 cd/m²"):
        visadapt.map(image, display_max=-1)
    with pytest.raises(ValueError, match=r"^invalid fov NaN: must be a positive, finite number$"):
        visadapt.map(image, fov=float("nan"))
    with pytest.raises(ValueError, match="hot-pixel-fraction"):
        visadapt.map(image, hot_pixel_fraction=1.5)
    with pytest.raises(ValueError, match="either scale or peak"):
        visadapt.map(image, scale=2, peak=3)
    with pytest.raises(ValueError, match="a perspective view spans less than 180"):
        visadapt.map(image, fov=200)
    with pytest.raises(ValueError, match="invalid projection 'fish'"):
        visadapt.map(image, fov=200, projection="fish")
    with pytest.raises(ValueError, match="give the field of view"):
        visadapt.map(image, projection="fisheye")
    with pytest.raises(TypeError, match=r"map\(\) got an unexpected keyword argument 'fov_deg'"):
        visadapt.map(image, fov_deg=30)
    with pytest.raises(ValueError, match="invalid times"):
        visadapt.timecourse(1, 10, [5, 1])
    with pytest.raises(ValueError):
        visadapt.observer(-1)


def test_file_errors_are_os_and_decode_errors(tmp_path):
    missing = tmp_path / "missing.exr"
    with pytest.raises(FileNotFoundError, match=str(missing)):
        visadapt.read(missing)
    # A truncated copy of a real EXR: corrupt data, one line naming the file.
    good = (DATA / "GrayRampsHorizontal.exr").read_bytes()
    bad = tmp_path / "truncated.exr"
    bad.write_bytes(good[: len(good) // 2])
    with pytest.raises(visadapt.DecodeError) as e:
        visadapt.read(bad)
    assert str(e.value).startswith(f"{bad}: invalid OpenEXR data")
    assert "\n" not in str(e.value)
    assert isinstance(e.value, ValueError)
    unknown = tmp_path / "text.hdr"
    unknown.write_text("hello")
    with pytest.raises(visadapt.UnsupportedError, match="not a Radiance, OpenEXR or PFM file"):
        visadapt.read(unknown)
    with pytest.raises(ValueError, match="exceeds the limit of 100 pixels"):
        visadapt.read(DATA / "GrayRampsHorizontal.exr", max_pixels=100)
    with pytest.raises(ValueError) as e:
        visadapt.read(DATA / "GrayRampsHorizontal.exr", max_memory_bytes=10_000)
    assert not isinstance(e.value, visadapt.DecodeError), "a budget is not corrupt data"
    with pytest.raises(ValueError, match="cannot tell the output format"):
        visadapt.write(tmp_path / "out.bmp", np.zeros((2, 2, 3), np.float32))
    assert not (tmp_path / "out.bmp").exists()


def test_every_damaged_shared_file_gives_a_python_exception():
    if not SHARED:
        pytest.skip("VISADAPT_SHARED_DATA not set")
    damaged = sorted((Path(SHARED) / "openexr-damaged").iterdir())
    assert len(damaged) > 100
    for path in damaged:
        if path.name.lower().startswith("readme") or path.name.lower().startswith("license"):
            continue
        try:
            visadapt.read(path)
        except (visadapt.DecodeError, ValueError, OSError) as e:
            assert str(e).startswith(str(path)) or "exceeds the limit" in str(e), str(e)
            assert "\n" not in str(e)


def test_write_png_jpeg_exr(tmp_path):
    display, report = visadapt.map(visadapt.chart(white=50))
    for name, magic in (("a.png", b"\x89PNG"), ("a.jpg", b"\xff\xd8"), ("a.exr", b"\x76\x2f\x31\x01")):
        visadapt.write(tmp_path / name, display)
        assert (tmp_path / name).read_bytes().startswith(magic)
    visadapt.write(tmp_path / "b.png", display, bits=16)
    assert (tmp_path / "b.png").stat().st_size > (tmp_path / "a.png").stat().st_size
    # Every PNG level holds the same pixels; run-length coding makes another file.
    visadapt.write(tmp_path / "rle.png", display, png_compression="rle")
    assert (tmp_path / "rle.png").read_bytes() != (tmp_path / "a.png").read_bytes()
    assert (visadapt.read(tmp_path / "rle.png").xyz == visadapt.read(tmp_path / "a.png").xyz).all()
    with pytest.raises(ValueError, match="fdeflate"):
        visadapt.write(tmp_path / "c.png", display, png_compression="zip")
    with pytest.raises(ValueError, match="bit"):
        visadapt.write(tmp_path / "c.png", display, bits=12)
    with pytest.raises(ValueError, match="OpenEXR"):
        visadapt.write(tmp_path / "c.png", visadapt.chart())


def test_adaptation_follows_the_time_course_and_ends_at_the_steady_state():
    image = visadapt.chart(white=200)
    steady_display, steady = visadapt.map(image)
    # From darkness into the lit chart: dazzled at first.
    eye = visadapt.Adaptation(0.001)
    eye.step(0.0, image)
    first = eye.thresholds()
    # The cones' excess right after the change is the time course's at t = 0 (it depends
    # on the photopic luminances only).
    lwa = steady["adaptation_cd_m2"]
    course = visadapt.timecourse(0.001, lwa, [0.0])
    assert first["cone_excess_log"] > 0.1
    assert first["cone_excess_log"] == pytest.approx(course[0]["cone_excess_log"], rel=1e-12)
    assert first["world_adaptation_cd_m2"] == pytest.approx(steady["adaptation_cd_m2"])
    dazzled, report = eye.map(image)
    assert report["photopic_scale"] < steady["photopic_scale"]
    assert report["offset_cd_m2"] > 0
    # Long after, the mapping is the steady one.
    eye.step(3600.0, steady)
    assert eye.thresholds()["adapted"]
    settled, report = eye.map(image)
    np.testing.assert_allclose(settled, steady_display, rtol=1e-5, atol=1e-6)
    assert report["photopic_scale"] == pytest.approx(steady["photopic_scale"], rel=1e-9)
    # The same numbers as the time course of the CLI's model.
    course = visadapt.timecourse(1.0, 100.0, [0.0, 30.0])
    eye = visadapt.Adaptation(1.0)
    eye.step(0.0, 100.0)
    eye.step(30.0, 100.0)
    now = eye.thresholds()
    assert now["cone_threshold_cd_m2"] == pytest.approx(course[1]["cone_threshold_cd_m2"], rel=1e-12)
    assert now["seconds_since_change"] == 30.0
    with pytest.raises(ValueError, match="time-step"):
        eye.step(-1.0, 100.0)


def test_long_calls_release_the_gil():
    rng = np.random.default_rng(3)
    image = visadapt.from_array(rng.uniform(0, 1000, (2000, 2000, 3)).astype(np.float32))
    calls = []

    def work():
        for _ in range(3):
            start = time.perf_counter()
            visadapt.map(image, fov=20)
            calls.append((start, time.perf_counter()))

    ticks = []
    t = threading.Thread(target=work)
    t.start()
    while t.is_alive():
        ticks.append(time.perf_counter())
    t.join()
    # With the GIL held, the main thread would not run at all during a call: no tick
    # inside it, one gap as long as the call. Released, the main thread runs throughout,
    # but for the scheduler's pauses (three busy threads on two cores: tens of
    # milliseconds at most, under load), so each call's longest gap stays well short of
    # the call (about 70 ms each here).
    for start, end in calls:
        inside = [x for x in ticks if start <= x <= end]
        assert len(inside) > 100, f"{len(inside)} ticks during a call of {end - start:.3f} s"
        gaps = np.diff([start, *inside, end])
        assert gaps.max() < 0.8 * (end - start), f"longest stall {gaps.max():.3f} s of a {end - start:.3f} s call"


def stub_tree():
    import ast

    stub = Path(visadapt.__file__).with_name("__init__.pyi")
    assert stub.is_file(), "the package ships its type stubs"
    return ast.parse(stub.read_text())


def test_stubs_and_docstrings_cover_the_api():
    import ast

    tree = stub_tree()
    stubbed = {
        n.name
        for n in tree.body
        if isinstance(n, (ast.FunctionDef, ast.ClassDef)) and n.name not in ("Conditions", "ViewDict")
    }
    import types

    public = {
        n
        for n in dir(visadapt)
        if not n.startswith("_") and not isinstance(getattr(visadapt, n), types.ModuleType)
    }
    assert stubbed == public
    for name in public:
        doc = getattr(visadapt, name).__doc__
        assert doc and len(doc.strip()) > 20, name
    for fn in ("map", "observer", "timecourse", "tolerance", "read", "chart", "write"):
        assert "cd/m²" in getattr(visadapt, fn).__doc__, f"{fn}: no units in its docstring"


def test_every_stubbed_condition_is_accepted():
    import ast

    tree = stub_tree()
    conditions = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Conditions")
    keys = [n.target.id for n in conditions.body if isinstance(n, ast.AnnAssign)]
    assert "display_max" in keys and "fov" in keys
    image = visadapt.chart(white=5)
    for key in keys:
        visadapt.map(image, **{key: None})  # None is the default of each
    with pytest.raises(TypeError):
        visadapt.map(image, not_a_condition=1)


def test_read_takes_photographs_in_relative_units_stated_with_scale(tmp_path):
    # Issue 13: read() said nothing of LDR input or of how to state its luminance.
    doc = visadapt.read.__doc__
    for word in ("PNG", "JPEG", "TIFF", "sRGB", "scale="):
        assert word in doc, word
    display, _ = visadapt.map(visadapt.chart(white=50))
    visadapt.write(tmp_path / "photo.png", display)
    photo = visadapt.read(tmp_path / "photo.png")
    assert not photo.absolute_units
    y = photo.xyz[..., 1]
    # Code-value white is Y = 1 (the sRGB curve undone, Rec. 709 primaries).
    assert 0.5 < y.max() <= 1.0 + 1e-6
    _, report = visadapt.map(photo, scale=0.05)
    _, unscaled = visadapt.map(photo)
    ratio = report["highest_visible_cd_m2"] / unscaled["highest_visible_cd_m2"]
    assert abs(ratio - 0.05) < 1e-6 * 0.05


def test_read_with_scale_is_read_then_scaled(tmp_path):
    # The factor is applied by the decoder as it converts (one rounding to float32 where
    # reading and multiplying make two): the same values within 2**-20 of each.
    display, _ = visadapt.map(visadapt.chart(white=50))
    visadapt.write(tmp_path / "scene.exr", display)
    for path in (DATA / "mixtex.hdr", DATA / "GrayRampsHorizontal.exr", tmp_path / "scene.exr"):
        plain = visadapt.read(path)
        scaled = visadapt.read(path, scale=179.0)
        assert scaled.absolute_units == plain.absolute_units
        np.testing.assert_allclose(scaled.xyz, plain.xyz * np.float32(179), rtol=2**-20, atol=0)
    for bad in (0.0, -2.0, float("nan"), float("inf"), 1e300):
        with pytest.raises(ValueError, match=r"invalid scale .*: must be a positive, finite number"):
            visadapt.read(DATA / "mixtex.hdr", scale=bad)
