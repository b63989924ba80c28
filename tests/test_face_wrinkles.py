"""Skin microstructure on the face (issue 14, item 7): Bando's furrows on the face's UVs
under the cosmetics model; the bumped normals reach its irradiance and its highlights."""

import numpy as np

from jaxskin import render, texture, wrinkles
from jaxskin.scene import load_scene

SMALL = ["texture.size=128", "camera.size=64"]


def image(*overrides, name="face"):
    scene = load_scene(name, [*SMALL, *overrides])
    return np.asarray(render.render(scene.config, scene.params)), scene


def test_face_wrinkles_change_shading_not_albedo():
    on, scene_on = image()
    off, scene_off = image("wrinkles.enabled=false")
    assert scene_on.config.needs_furrows and not scene_off.config.needs_furrows
    np.testing.assert_array_equal(render.albedo(scene_on.config, scene_on.params),
                                  render.albedo(scene_off.config, scene_off.params))
    mask = np.asarray(render.prepare(scene_on.config).view.mask)
    # Measured: mean |Δ| 0.0064 of the display value on the face, 0 off it; k_bump 0: 2e-7.
    assert np.abs(on - off)[mask].mean() > 0.002
    assert np.all(on[~mask] == off[~mask])
    flat, _ = image("wrinkles.k_bump=0")
    np.testing.assert_allclose(flat, off, atol=2e-6)


def test_bumped_normals_reach_irradiance_and_highlight():
    """Without a highlight the furrows still show (irradiance N·L), and the highlight's own
    change with the furrows is not zero (Kelemen's N·H). Measured: mean |Δ| 0.0034 without
    a highlight, 1.3e-4 in the highlight alone (0 if it used the unbumped normals)."""
    diffuse_on, _ = image("skin.specular=0")
    diffuse_off, _ = image("skin.specular=0", "wrinkles.enabled=false")
    assert np.abs(diffuse_on - diffuse_off).mean() > 1e-3
    on, _ = image()
    off, _ = image("wrinkles.enabled=false")
    highlight_change = (on - diffuse_on) - (off - diffuse_off)
    assert np.abs(highlight_change).mean() > 1e-5


def test_the_furrow_program_runs_only_when_enabled(monkeypatch):
    calls = []
    real = wrinkles.height_field
    monkeypatch.setattr(wrinkles, "height_field", lambda *a, **k: calls.append(1) or real(*a, **k))
    for name in ("face", "makeup"):
        texture.furrows.cache_clear()
        render.prepare.cache_clear()
        _, scene = image("wrinkles.enabled=false", name=name)
        assert calls == [] and "h0" not in render.prepare(scene.config).arrays
        texture.furrows.cache_clear()
        render.prepare.cache_clear()
        _, scene = image(name=name)
        assert calls == [1] and "h0" in render.prepare(scene.config).arrays
        assert "grad_s" in render.prepare(scene.config).arrays  # the uv frame
        calls.clear()
    texture.furrows.cache_clear()
    render.prepare.cache_clear()
