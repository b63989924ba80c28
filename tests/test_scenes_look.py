"""What users see in the built-in scenes (issue 14): the foot is whole (no dark cavity at
the cut ankle), the hand's cells are diamonds, the arm's wrinkles are legible."""

import numpy as np
import pytest

from jaxskin import render
from jaxskin.scene import load_scene, scene_at_width


def dark_fraction(name, size=128):
    """The share of the part's pixels darker than half their median brightness, at a small
    size, without wrinkles (the cavity is geometry)."""
    scene = scene_at_width(name, size, ["view.mode=overview", "texture.size=128"])
    image = np.asarray(render.render(scene.config, scene.params)).mean(axis=-1)
    from jaxskin.view import coverage

    whole = np.asarray(coverage(render.prepare(scene.config).view.mask,
                                scene.config.supersample)) == 1  # pixels all on the part
    values = image[whole]
    return float(np.mean(values < 0.5 * np.median(values)))


# Measured at 128 px: foot 0.036 (0.27 with the open ankle of the old foot.obj), hand 0.010,
# arm 0.022.
@pytest.mark.parametrize(("name", "most"), [("foot", 0.05), ("hand", 0.03), ("arm", 0.04)])
def test_no_dark_cavity(name, most):
    assert dark_fraction(name) < most


def test_the_foot_mesh_is_closed_at_the_ankle():
    from jaxskin.mesh import load_mesh

    faces = load_mesh("foot").faces
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)


def test_the_arm_is_cut_square_at_the_wrist_and_the_shoulder():
    """Its open ends are two planar rings across the axis (y), so a side view sees each
    edge-on: a straight outline, not the zigzag notch of the box's whole faces (the old
    arm.obj's boundary spanned 21 mm at the wrist and 18 mm at the shoulder)."""
    from jaxskin.mesh import load_mesh

    mesh = load_mesh("arm")
    directed = mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    _, inverse, counts = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True,
                                   return_counts=True)
    assert counts.max() == 2  # manifold: no seam of duplicated vertices along the cuts
    rim = np.unique(directed[counts[inverse.ravel()] == 1])
    y = mesh.vertices[rim, 1]
    ends = mesh.vertices[:, 1].min(), mesh.vertices[:, 1].max()
    at_an_end = np.isclose(y, ends[0], atol=1e-6) | np.isclose(y, ends[1], atol=1e-6)
    assert at_an_end.all(), np.ptp(y[y < 0])


def test_hand_cells_are_diamonds():
    """On the back of the hand the two fields cross at 50–70° (fig. 6.1's diamonds), not at
    90° (bricks). Measured: median 62° within 0.1 of the texture round the two edits (81°
    before)."""
    from jaxskin import texture

    scene = load_scene("hand", ["texture.size=128"])
    s = texture.setup(scene.config.texture)
    f1, f2 = np.asarray(s.field1, np.float64), np.asarray(s.field2, np.float64)
    j, i = np.meshgrid(np.arange(128) + 0.5, np.arange(128) + 0.5)
    near = np.zeros((128, 128), bool)
    for e in s.edits[:2]:  # the back of the hand
        x, y = s.tmap.xy[e.vertex]
        near |= np.hypot(j - x, i - y) < 0.1 * 128
    near &= np.asarray(s.mask)
    cos = np.abs(np.sum(f1 * f2, -1)) / np.maximum(
        np.linalg.norm(f1, axis=-1) * np.linalg.norm(f2, axis=-1), 1e-12)
    angle = np.degrees(np.arccos(np.clip(cos[near], 0, 1)))
    assert near.sum() > 100
    assert 50 < np.median(angle) < 70


def texels_per_pixel(name):
    """Median over the part of sqrt|det ∂(texel)/∂(pixel)| in the default view."""
    scene = load_scene(name, ["view.mode=overview"])
    p = render.prepare(scene.config)
    tex, mask, width = np.asarray(p.view.tex, np.float64), np.asarray(p.view.mask), p.setup.tmap.width
    dx, dy = (tex[:-1, 1:] - tex[:-1, :-1]), (tex[1:, :-1] - tex[:-1, :-1])
    if p.view.wrap_x:  # across the seam
        dx[..., 0], dy[..., 0] = ((d[..., 0] + width / 2) % width - width / 2 for d in (dx, dy))
    ok = mask[:-1, :-1] & mask[1:, :-1] & mask[:-1, 1:]
    det = np.abs(dx[..., 0] * dy[..., 1] - dx[..., 1] * dy[..., 0])[ok]
    return float(np.median(np.sqrt(det))) * scene.config.supersample


# Measured: arm 0.94 (1.87 in the old 512² square view), hand and foot 1.02.
@pytest.mark.parametrize("name", ["arm", "hand", "foot"])
def test_texels_per_pixel_near_one(name):
    assert 0.7 < texels_per_pixel(name) < 1.3
