"""What other tools read: 16-bit PNG, linear OpenEXR and alpha from `jaxskin render`."""

import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from jaxskin import maps, render
from jaxskin.scene import load_scene

SMALL = ["texture.size=64", "camera.size=32"]


def _render(tmp_path, *options):
    out = tmp_path / "out"
    args = [sys.executable, "-m", "jaxskin.cli", "render", "face", "-o", str(out)]
    for o in SMALL:
        args += ["-D", o]
    proc = subprocess.run([*args, *options], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="module")
def face():
    sc = load_scene("face", SMALL)
    return sc, np.asarray(render.render(sc.config, sc.params, "rgba"))


def test_png16_is_the_8_bit_png_to_within_rounding(tmp_path, face):
    out8 = _render(tmp_path / "a", "--alpha")
    out16 = _render(tmp_path / "b", "--alpha", "--format", "png16")
    png = pytest.importorskip("png", reason="pypng (the test extra) reads 16-bit colour")
    a = iio.imread(out8 / "face.png")
    width, height, rows, info = png.Reader(filename=str(out16 / "face.png")).asDirect()
    assert info["bitdepth"] == 16 and info["alpha"] and (width, height) == (32, 32)
    b = np.vstack([np.asarray(r, np.uint16) for r in rows]).reshape(32, 32, 4)
    assert a.dtype == np.uint8 and b.dtype == np.uint16 and a.shape == b.shape == (32, 32, 4)
    # Both round the same value: |b / 257 - a| <= 0.5 + 0.5 / 257 (one rounding each).
    assert np.abs(b / 257.0 - a).max() <= 0.5 + 0.5 / 257 + 1e-9
    # And the 16-bit file holds the render to 16-bit precision.
    np.testing.assert_allclose(b / 65535.0, np.clip(face[1], 0, 1), atol=0.5 / 65535 + 1e-7)
    plain = iio.imread(_render(tmp_path / "c") / "face.png")
    assert plain.shape == (32, 32, 3)  # no --alpha: RGB as before


def test_exr_holds_the_linear_render_with_alpha(tmp_path, face):
    pytest.importorskip("OpenEXR", reason="the exr extra (pip install 'jaxskin[exr]')")
    sc, rgba = face
    out = _render(tmp_path, "--format", "exr")
    exr = maps.read_exr(out / "face.exr")
    linear = np.asarray(render.render(sc.config, sc.params, "linear_rgba"))
    np.testing.assert_array_equal(exr, linear)  # float32, lossless (ZIP)
    # The linear light is the display image before encoding (over black).
    display = np.asarray(render.render(sc.config, sc.params))
    np.testing.assert_allclose(render.encode_srgb(exr[..., :3]), display, atol=2e-6)
    alpha = exr[..., 3]
    mask = render.prepare(sc.config).view.mask
    k = sc.config.supersample
    blocks = mask.reshape(32, k, 32, k)
    assert np.all(alpha[~blocks.any(axis=(1, 3))] == 0)  # background
    assert np.all(alpha[blocks.all(axis=(1, 3))] == 1)  # inside
    edge = (alpha > 0) & (alpha < 1)
    assert edge.sum() > 10  # antialiased silhouette
    assert np.all(exr[alpha == 0, :3] == 0)


def test_exr_without_the_bindings_is_an_input_error(tmp_path, monkeypatch):
    from jaxskin import cli

    monkeypatch.setattr(maps, "exr_available", lambda: False)
    assert cli.main(["render", "face", "-o", str(tmp_path / "x"), "--format", "exr"]) == 2
    assert not (tmp_path / "x").exists()
