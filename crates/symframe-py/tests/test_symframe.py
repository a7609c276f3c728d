"""The Python package against the command line: same maps bit for bit, same figures, same
error messages; argument checks; interruption and resumption."""

import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import symframe

MAPS = ["normals", "tangents", "confidence", "anisotropy", "tangent_confidence", "source"]


def bits(a):
    """The array's bytes, so NaNs compare equal only where their bits are equal."""
    return np.ascontiguousarray(a).view(np.uint8)


def assert_same_maps(got, want):
    for name in MAPS:
        assert got[name].dtype == want[name].dtype, name
        assert got[name].shape == want[name].shape, name
        assert np.array_equal(bits(got[name]), bits(want[name])), name


def cli_maps(folder):
    return {name: np.load(Path(folder) / f"{name}.npy") for name in MAPS}


def test_load_reads_lights_mask_and_images(capture):
    ds = symframe.load(capture)
    n, h, w = ds.shape
    assert (n, h, w) == (150, 40, 40) and len(ds) == 150
    assert ds.lights.shape == (150, 3) and ds.lights.dtype == np.float64
    assert np.allclose(np.linalg.norm(ds.lights, axis=1), 1.0)
    assert ds.mask.shape == (40, 40) and ds.mask.dtype == np.bool_
    assert 0 < ds.mask.sum() < 40 * 40
    images = ds.images()
    assert images.shape == (150, 40, 40, 3) and images.dtype == np.float32
    assert np.all(images[:, ~ds.mask] == 0) and images[:, ds.mask].max() > 0
    assert "150 lights" in repr(ds)


def test_estimate_path_equals_the_command_line(capture, cli, tmp_path):
    cli("estimate", capture, "-o", tmp_path / "cli", "--tile-size", "8")
    got = symframe.estimate_path(capture, tmp_path / "py", tile_size=8)
    assert_same_maps(got, cli_maps(tmp_path / "cli"))
    # The files written are the command line's too, and the report is report.json's content.
    assert_same_maps(cli_maps(tmp_path / "py"), cli_maps(tmp_path / "cli"))
    on_disk = json.loads((tmp_path / "py" / "report.json").read_text())
    assert got["report"] == on_disk
    cli_report = json.loads((tmp_path / "cli" / "report.json").read_text())
    for key in ["method", "parameters", "lights", "pixels", "sources", "width", "height"]:
        assert got["report"][key] == cli_report[key], key
    assert got["report"]["pixels"]["estimated"] > 800


def test_options_reach_the_job_as_the_flags_do(capture, cli, tmp_path):
    flags = ["--theta-d-max", "55", "--min-anisotropy", "0.3", "--cosine", "compensated",
             "--cosine-power", "0.25", "--fallback", "none", "--no-tangents"]
    cli("estimate", capture, "-o", tmp_path / "cli", *flags)
    got = symframe.estimate_path(capture, tmp_path / "py", theta_d_max=55, min_anisotropy=0.3,
                                 cosine="compensated", cosine_power=0.25, fallback="none",
                                 no_tangents=True)
    assert_same_maps(got, cli_maps(tmp_path / "cli"))
    assert np.isnan(got["tangents"]).all()
    assert got["report"]["parameters"]["theta_d_max_deg"] == 55


def test_light_error_reaches_the_job_and_lowers_the_confidence(capture, cli, tmp_path):
    cli("estimate", capture, "-o", tmp_path / "cli", "--light-error", "2")
    got = symframe.estimate_path(capture, tmp_path / "py", light_error=2)
    assert_same_maps(got, cli_maps(tmp_path / "cli"))
    assert got["report"]["parameters"]["noise"]["light_error_deg"] == 2
    exact = symframe.estimate_path(capture, tmp_path / "exact")
    sure = np.isfinite(exact["confidence"])
    # Lower on the whole (a pixel where a lobe now answers because the lights' error explains
    # what it leaves may be surer than its search answer was).
    assert (np.isfinite(got["confidence"]) == sure).all()
    assert got["confidence"][sure].mean() < exact["confidence"][sure].mean()
    with pytest.raises(ValueError, match=r"light_error must be in \[0, 10\] degrees, got -1"):
        symframe.estimate(symframe.load(capture).images(), symframe.load(capture).lights,
                          light_error=-1)


def test_in_memory_estimate_equals_the_tiled_job(capture, tmp_path):
    ds = symframe.load(capture)
    calls = []
    got = symframe.estimate(ds.images(), ds.lights, ds.mask, noise=ds.noise,
                            progress=lambda stage, done, total: calls.append((stage, done, total)))
    want = symframe.estimate_path(capture, tmp_path / "out")
    assert_same_maps(got, want)
    assert ds.noise == want["report"]["parameters"]["noise"]
    with pytest.raises(ValueError, match="noise"):
        symframe.estimate(ds.images(), ds.lights, ds.mask, noise={"shot": "much"})
    assert got["report"]["pixels"] == want["report"]["pixels"]
    assert got["report"]["sources"] == want["report"]["sources"]
    assert calls and calls[-1][1] == calls[-1][2]


def test_baseline_equals_the_command_line(capture, cli, tmp_path):
    cli("estimate", capture, "-o", tmp_path / "cli", "--method", "woodham")
    ds = symframe.load(capture)
    got = symframe.estimate(ds.images(), ds.lights, ds.mask, method="woodham")
    assert_same_maps(got, cli_maps(tmp_path / "cli"))
    assert got["report"]["method"] == "woodham"


def test_evaluate_gives_the_figures_of_eval(capture, cli, tmp_path):
    out = tmp_path / "out"
    maps = symframe.estimate_path(capture, out)
    cli("eval", capture.parent, out)
    figures = json.loads((out / "eval.json").read_text())
    ds = symframe.load(capture)
    gt_n = np.load(capture.parent / "gt_normals.npy")
    gt_t = np.load(capture.parent / "gt_tangents.npy")
    got = symframe.evaluate(maps["normals"], gt_n, maps["tangents"], gt_t, mask=ds.mask)
    for key, value in got.items():
        assert figures[key] == value, key
    assert got["normal_error"]["median"] < 3.0


def test_job_errors_carry_the_command_line_message(cli, tmp_path):
    missing = tmp_path / "nothing.lp"
    with pytest.raises(symframe.SymframeError) as err:
        symframe.estimate_path(missing, tmp_path / "out")
    proc = cli("estimate", missing, "-o", tmp_path / "out2", check=False)
    assert proc.returncode == 1
    assert proc.stderr.strip() == f"symframe: error: {err.value}"
    assert "\n" not in str(err.value)
    with pytest.raises(symframe.SymframeError, match="no such file"):
        symframe.load(missing)


def test_array_type_and_shape_errors(capture):
    ds = symframe.load(capture)
    images, lights, mask = ds.images(), ds.lights, ds.mask
    with pytest.raises(TypeError, match="images must be a numpy array, got list"):
        symframe.estimate(images.tolist(), lights)
    with pytest.raises(TypeError, match="images must be a float array, got dtype uint8"):
        symframe.estimate(images.astype(np.uint8), lights)
    with pytest.raises(ValueError, match=r"images must be N x H x W x 3, got shape \(150, 40, 40\)"):
        symframe.estimate(images[..., 0], lights)
    with pytest.raises(ValueError, match="150 images but 149 lights"):
        symframe.estimate(images, lights[:-1])
    with pytest.raises(ValueError, match=r"lights must be N x 3"):
        symframe.estimate(images, lights[:, :2])
    with pytest.raises(TypeError, match="mask must be a bool array, got dtype uint8"):
        symframe.estimate(images, lights, mask.astype(np.uint8))
    with pytest.raises(ValueError, match="mask must be H x W = 40 x 40"):
        symframe.estimate(images, lights, mask[:20])
    with pytest.raises(symframe.SymframeError, match="mask is empty"):
        symframe.estimate(images, lights, np.zeros_like(mask))
    with pytest.raises(ValueError, match=r"max_angle must be in \(0, 90\] degrees, got 0"):
        symframe.evaluate(np.zeros((4, 4, 3), np.float32), np.zeros((4, 4, 3), np.float32), max_angle=0)
    with pytest.raises(ValueError, match="gt_normals has shape"):
        symframe.evaluate(np.zeros((4, 4, 3), np.float32), np.zeros((4, 5, 3), np.float32))
    # float64 images and Fortran-ordered arrays are accepted (converted).
    small = np.asfortranarray(images[:, :8, :8].astype(np.float64))
    assert symframe.estimate(small, lights)["normals"].shape == (8, 8, 3)


def test_option_errors(capture, tmp_path):
    ds = symframe.load(capture)
    images = ds.images()
    with pytest.raises(ValueError, match=r"theta_d_max must be in \(0, 90\] degrees, got 95"):
        symframe.estimate(images, ds.lights, theta_d_max=95)
    with pytest.raises(ValueError, match="cosine must be one of auto, cross, raw, compensated"):
        symframe.estimate(images, ds.lights, cosine="sine")
    with pytest.raises(ValueError, match="method must be one of"):
        symframe.estimate(images, ds.lights, method="magic")
    with pytest.raises(TypeError, match="unexpected keyword argument 'theta'"):
        symframe.estimate(images, ds.lights, theta=40)
    with pytest.raises(TypeError, match="min_confidence must be a number, got str"):
        symframe.estimate(images, ds.lights, min_confidence="high")
    with pytest.raises(ValueError, match="tile_size must be in"):
        symframe.estimate_path(capture, tmp_path / "o", tile_size=0)
    with pytest.raises(ValueError, match="tiles: expected K/N"):
        symframe.estimate_path(capture, tmp_path / "o", tiles="3/2")
    with pytest.raises(ValueError, match="threads=0"):
        symframe.estimate(images, ds.lights, threads=0)
    # No output folder is left by a refused call.
    assert not (tmp_path / "o").exists()


def test_interrupted_job_resumes_to_the_same_maps(tmp_path):
    lp = symframe.synth(tmp_path / "ds", size=48, lights=120)
    out = tmp_path / "out"

    def stop_at_first_tile(stage, done, total):
        if stage == "tiles" and done >= 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        symframe.estimate_path(lp, out, tile_size=8, progress=stop_at_first_tile)
    assert not (out / "normals.npy").exists()
    finished = list((out / ".symframe-tiles").iterdir())
    assert 1 <= len(finished) < 36

    resumed = symframe.estimate_path(lp, out, tile_size=8)
    tiles = resumed["report"]["tiles"]
    assert tiles["reused"] >= 1 and tiles["computed"] >= 1
    assert tiles["reused"] + tiles["computed"] == tiles["count"] == 36
    assert resumed["report"]["cache"]["hit"] is True
    assert_same_maps(resumed, symframe.estimate_path(lp, tmp_path / "fresh", tile_size=8))


def test_progress_callback_errors_propagate(capture):
    ds = symframe.load(capture)

    def broken(stage, done, total):
        raise RuntimeError("callback failed")

    with pytest.raises(RuntimeError, match="callback failed"):
        symframe.estimate(ds.images(), ds.lights, ds.mask, progress=broken)


def test_ctrl_c_raises_keyboard_interrupt(tmp_path):
    """A real SIGINT during a job: KeyboardInterrupt, and the rerun resumes."""
    script = f"""
import os, signal, sys
import symframe
# Python keeps SIGINT ignored when it started ignored (a job started with `&` by a shell):
# Ctrl-C's own handler, whatever this process inherited.
signal.signal(signal.SIGINT, signal.default_int_handler)
lp = symframe.synth({str(tmp_path / 'ds')!r}, size=128, lights=120)
sent = []
def ctrl_c(stage, done, total):
    # Progress is told at most every 100 ms (the first and last reports always), so the job
    # must outlast that: 256 tiles. The first report with a tile done sends the signal.
    if stage == "tiles" and 1 <= done < total and not sent:
        sent.append(done)
        os.kill(os.getpid(), signal.SIGINT)
try:
    symframe.estimate_path(lp, {str(tmp_path / 'out')!r}, tile_size=8, progress=ctrl_c)
except KeyboardInterrupt:
    r = symframe.estimate_path(lp, {str(tmp_path / 'out')!r}, tile_size=8)
    print("resumed", r["report"]["tiles"]["reused"])
    sys.exit(130)
print("not interrupted")
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 130, proc.stdout + proc.stderr
    assert proc.stdout.startswith("resumed ")
    assert int(proc.stdout.split()[1]) >= 1


def test_the_gil_is_released_while_computing(capture):
    ds = symframe.load(capture)
    images, lights = ds.images(), ds.lights
    result = {}
    worker = threading.Thread(target=lambda: result.update(symframe.estimate(images, lights, reference=True)))
    worker.start()
    spins = 0
    while worker.is_alive():
        spins += 1
    worker.join()
    assert "normals" in result
    assert spins > 1000


def test_shard_returns_its_report_only(capture, tmp_path):
    got = symframe.estimate_path(capture, tmp_path / "s1", tiles="1/2", tile_size=8)
    assert set(got) == {"report"}
    assert got["report"]["tiles"]["shard"] == "1/2"
    assert (tmp_path / "s1" / "shard.json").is_file()


def test_synth_refuses_a_foreign_folder(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(symframe.SymframeError):
        symframe.synth(tmp_path / "mine", size=16, lights=20)
    with pytest.raises(ValueError, match="shape must be sphere or cylinder"):
        symframe.synth(tmp_path / "x", shape="torus")


def stub_options(function):
    """The keyword-only options and defaults that the type stub declares for `function`."""
    import ast

    stub = Path(symframe.__file__).with_suffix(".pyi")
    tree = ast.parse(stub.read_text())
    (fn,) = [n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == function]
    options = {}
    for arg, default in zip(fn.args.kwonlyargs, fn.args.kw_defaults):
        if arg.arg in ("progress", "threads") or isinstance(default.value, type(Ellipsis)):
            continue
        options[arg.arg] = ast.literal_eval(default)
    return options


def test_the_stub_declares_the_options_and_defaults_in_force(capture, tmp_path):
    ds = symframe.load(capture)
    images = ds.images()[:, :12, :12]
    options = stub_options("estimate")
    assert {"theta_d_max", "min_anisotropy", "cosine", "method"} <= set(options)
    assert_same_maps(symframe.estimate(images, ds.lights, **options),
                     symframe.estimate(images, ds.lights))
    options = stub_options("estimate_path")
    assert {"tile_size", "decode_memory", "cache", "tiles"} <= set(options)
    assert_same_maps(symframe.estimate_path(capture, **options), symframe.estimate_path(capture))


def test_fit_and_relight_equal_the_command_line(capture, cli, tmp_path):
    frames = tmp_path / "est"
    symframe.estimate_path(capture, frames)
    cli("fit", capture, "--frames", frames, "-o", tmp_path / "fit_cli", "--holdout", "10")
    got = symframe.fit(capture, frames, tmp_path / "fit_py", holdout=10)
    for name in ["base_color", "metallic", "roughness", "anisotropy_strength", "kd", "ks",
                 "alpha_t", "alpha_b", "model", "normals", "tangents"]:
        want = np.load(tmp_path / "fit_cli" / f"{name}.npy")
        assert np.array_equal(bits(got[name]), bits(want)), name
    # The default is the automatic choice: each fitted pixel Ward (1), glTF (2), clear coat (3)
    # or woven (4).
    assert got["report"]["model"] == "auto" and got["report"]["exposure"] > 0
    codes = got["model"][np.isfinite(got["residual"])]
    assert codes.size > 0 and np.isin(codes, [1, 2, 3, 4]).all()
    cli("fit", capture, "--frames", frames, "-o", tmp_path / "ward_cli", "--model", "ward",
        "--exposure", "2")
    ward = symframe.fit(capture, frames, tmp_path / "ward_py", model="ward", exposure=2.0)
    for name in ["kd", "ks", "alpha_t", "alpha_b"]:
        want = np.load(tmp_path / "ward_cli" / f"{name}.npy")
        assert np.array_equal(bits(ward[name]), bits(want)), name
    with pytest.raises(ValueError, match="unknown fit model"):
        symframe.fit(capture, frames, tmp_path / "bad", model="phong")
    with pytest.raises(ValueError, match="exposure must be positive"):
        symframe.fit(capture, frames, tmp_path / "bad", model="gltf", exposure=0.0)
    assert np.isfinite(got["residual"]).any()
    light = [0.3, 0.2, 0.9]
    cli("relight", tmp_path / "fit_cli", "-o", tmp_path / "relit_cli", "--light", "0.3,0.2,0.9",
        "--roughness-scale", "0.5")
    images = symframe.relight(tmp_path / "fit_py", tmp_path / "relit_py", light, roughness_scale=0.5)
    assert images.shape == (1, 40, 40, 3) and images.dtype == np.float32
    assert images.max() > 0
    cli_png = (tmp_path / "relit_cli" / "relit_000.png").read_bytes()
    assert (tmp_path / "relit_py" / "relit_000.png").read_bytes() == cli_png
    with pytest.raises(ValueError, match="roughness_scale must be finite and > 0"):
        symframe.relight(tmp_path / "fit_py", tmp_path / "r2", light, roughness_scale=0)
    # From the photographs themselves, as the command line's --from-samples.
    cli("relight", tmp_path / "fit_cli", "-o", tmp_path / "samples_cli", "--light",
        "0.3,0.2,0.9", "--from-samples", capture)
    images = symframe.relight(tmp_path / "fit_py", tmp_path / "samples_py", light,
                              from_samples=capture)
    assert images.shape == (1, 40, 40, 3) and images.max() > 0
    cli_png = (tmp_path / "samples_cli" / "relit_000.png").read_bytes()
    assert (tmp_path / "samples_py" / "relit_000.png").read_bytes() == cli_png
    with pytest.raises(symframe.SymframeError, match="--from-samples"):
        symframe.relight(tmp_path / "fit_py", tmp_path / "r3", light, from_samples=capture,
                         roughness_scale=0.5)


def test_merge_of_shards_equals_an_unsharded_run(capture, cli, tmp_path):
    whole = symframe.estimate_path(capture, tmp_path / "whole", tile_size=8)
    shards = [tmp_path / "s1", tmp_path / "s2"]
    for k, folder in enumerate(shards, 1):
        symframe.estimate_path(capture, folder, tiles=f"{k}/2", tile_size=8)
    with pytest.raises(symframe.SymframeError, match="shard"):
        symframe.merge(shards[:1], tmp_path / "half")
    calls = []
    got = symframe.merge(shards, tmp_path / "merged", progress=lambda *a: calls.append(a))
    assert_same_maps(got, whole)
    assert got["report"]["pixels"]["estimated"] == whole["report"]["pixels"]["estimated"] > 800
    assert calls and calls[-1][0] == "merging" and calls[-1][1] == calls[-1][2]
    # The command line's merge of the same shards writes the same maps.
    cli("merge", *shards, "-o", tmp_path / "merged_cli")
    assert_same_maps(cli_maps(tmp_path / "merged"), cli_maps(tmp_path / "merged_cli"))
    with pytest.raises(TypeError, match="list of shard folders"):
        symframe.merge(str(shards[0]), tmp_path / "x")
    with pytest.raises(ValueError, match="empty"):
        symframe.merge([], tmp_path / "x")


def test_view_writes_the_command_lines_page(capture, cli, tmp_path):
    frames = tmp_path / "est"
    symframe.estimate_path(capture, frames)
    fit_dir = tmp_path / "fit"
    symframe.fit(capture, frames, fit_dir)
    page = symframe.view(fit_dir)
    assert page == str(fit_dir / "viewer.html")
    cli("view", fit_dir, "-o", tmp_path / "cli.html")
    text = Path(page).read_text()
    assert text == (tmp_path / "cli.html").read_text()
    # The view `samples`: the capture's own relighting, as the command line's page.
    samples = symframe.view(fit_dir, tmp_path / "samples.html", from_samples=capture)
    cli("view", fit_dir, "-o", tmp_path / "samples_cli.html", "--from-samples", capture)
    assert Path(samples).read_text() == (tmp_path / "samples_cli.html").read_text()
    assert '"source","samples"]' in Path(samples).read_text()
    # The default (automatic) fit holds both models' maps.
    assert "#version 300 es" in text and '"views":["relit","normal","tangent","kd","ks",' \
        '"base_color","confidence","anisotropy","source"]' in text
    # Without the estimate's folder: a warning, and a page of the fit's views only.
    frames.rename(tmp_path / "moved")
    with pytest.warns(UserWarning, match="--frames"):
        page = symframe.view(fit_dir, tmp_path / "no_est.html")
    assert '"views":["relit","normal","tangent","kd","ks","base_color"]' in Path(page).read_text()
    assert symframe.view(fit_dir, tmp_path / "v.html", frames=tmp_path / "moved").endswith("v.html")
    # An estimate folder opens on its own maps.
    page = symframe.view(tmp_path / "moved", tmp_path / "est.html")
    assert '"views":["relit","normal","tangent","confidence","anisotropy","source"' in \
        Path(page).read_text()
    # A folder of neither says what it expected.
    (tmp_path / "empty").mkdir()
    with pytest.raises(symframe.SymframeError, match="normals.npy"):
        symframe.view(tmp_path / "empty", tmp_path / "bad.html")
    assert not (tmp_path / "bad.html").exists()


def test_integrate_equals_the_command_line(capture, cli, tmp_path):
    frames = tmp_path / "est"
    symframe.estimate_path(capture, frames)
    cli("integrate", frames, "-o", tmp_path / "int_cli", "--solver", "poisson")
    got = symframe.integrate(frames, tmp_path / "int_py", solver="poisson")
    want = np.load(tmp_path / "int_cli" / "depth.npy")
    assert got["depth"].shape == (40, 40) and got["depth"].dtype == np.float32
    assert np.array_equal(bits(got["depth"]), bits(want))
    assert got["report"]["solver"] == "poisson" and got["report"]["pixels"] > 800
    assert (tmp_path / "int_py" / "mesh.ply").read_bytes() == (tmp_path / "int_cli" / "mesh.ply").read_bytes()
    with pytest.raises(ValueError, match="solver must be poisson or bilateral"):
        symframe.integrate(frames, tmp_path / "bad", solver="multigrid")


def test_near_lights_are_honoured_as_the_command_line_honours_them(cli, tmp_path):
    data = tmp_path / "near"
    cli("synth", "--near", "--size", "48", "--dome-lights", "60", "-o", data)
    cli("estimate", data, "-o", tmp_path / "cli", "--rounds", "3", "--rig-tile", "2")
    got = symframe.estimate_path(data, tmp_path / "py", rounds=3, rig_tile=2)
    assert_same_maps(got, cli_maps(tmp_path / "cli"))
    near = got["report"]["near"]
    assert near["rig_tile"] == 2 and 2 <= near["iterations"] <= 3
    want = np.load(tmp_path / "cli" / "depth.npy")
    assert got["depth"].shape == want.shape == (24, 48)
    assert np.array_equal(bits(got["depth"]), bits(want))
    # The depths are about the object's distance (the dome's centre, 3 widths of 4.2 away).
    assert abs(np.nanmedian(got["depth"]) / 12.6 - 1) < 0.1
    # The distant model reads the same folder with the light file's directions: no depth.
    far = symframe.estimate_path(data, tmp_path / "far", light_model="distant")
    assert "near" not in far["report"] and "depth" not in far
    truth = np.load(data / "gt_normals.npy")

    def error(normals):
        dot = np.clip(np.sum(normals * truth, axis=2), -1, 1)
        keep = np.isfinite(dot) & (truth[..., 2] > 0.5)
        return np.degrees(np.arccos(dot[keep])).mean()

    assert error(got["normals"]) < error(far["normals"]) / 3
    with pytest.raises(ValueError, match="light_model must be"):
        symframe.estimate_path(data, tmp_path / "bad", light_model="far")
