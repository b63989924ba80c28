"""A mutation score for the physics (issue 20, item 5): does a wrong number fail a test?

    python benchmarks/mutation.py             # every mutant, ~10–20 min on 2 busy cores
    python benchmarks/mutation.py km-         # only the mutants whose id starts so
    python benchmarks/mutation.py --check     # only check that every pattern applies

Each mutant is a one-line change to the library (a wrong exponent, a dropped factor, a
misprinted formula) that a user would see. The script copies the project (the files git
tracks or would track) to a temporary folder, gives it the layout of the installed package
(`jaxskin.fitting`, `jaxskin.data` as links), and puts it first on PYTHONPATH. For each
mutant it replaces the pattern (which must occur exactly once), runs the mutant's own small
test selection with pytest, and restores the file; a mutant is killed when the selection
fails. Before the mutants, every selection must pass on the unchanged copy. The kill rate
and the survivors are printed and written to the `mutation` section of RESULTS.md.

Since the merge of the rewritten look (Blinn's skin colour in optical density, bump
normals in the surface frame, one radiometric scale, exposure, shadows, texture padding)
the list covers that code too: ids starting `blinn-`, `bump-`, `scale-`, `shadow-`, `pad-`.
Not in the list yet: the shipped materials' and cosmetics' colour targets (data/materials),
whose numbers are data rather than one line of code.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parent.parent


class Mutant(NamedTuple):
    id: str
    file: str  # relative to the project root
    old: str  # must occur exactly once in the file
    new: str
    tests: tuple[str, ...]  # pytest arguments: node ids, -k expressions


REF = "tests/test_references.py"
GRAD = "tests/test_gradients.py"
RAD = "tests/test_radiometry.py"
BUMP = "tests/test_bump_frames.py"
SHADOW = "tests/test_shadow.py"
VIEW = "tests/test_view.py"
WRINKLES = "tests/test_wrinkles.py"


def _k(path, expr):
    return (path, "-k", expr)


MUTANTS = [
    # ---- Kelemen specular (Huang eq. 5, d'Eon & Luebke)
    Mutant("kelemen-schlick-exponent-5-to-3", "jaxskin/shading/kelemen.py",
           "0.0, 1.0)) ** 5", "0.0, 1.0)) ** 3", _k(REF, "kelemen")),
    Mutant("kelemen-beckmann-cos4-to-cos2", "jaxskin/shading/kelemen.py",
           "/ (m2 * c2 * c2)", "/ (m2 * c2)", _k(REF, "kelemen")),
    Mutant("kelemen-beckmann-m2-to-m", "jaxskin/shading/kelemen.py",
           "/ (c2 * m2))", "/ (c2 * roughness))", _k(REF, "kelemen")),
    Mutant("kelemen-F0-0.028-to-0.04", "jaxskin/shading/kelemen.py",
           "F0_SKIN = 0.028", "F0_SKIN = 0.04", _k(REF, "kelemen")),
    Mutant("kelemen-no-L+V-denominator", "jaxskin/shading/kelemen.py",
           "P_H * F / jnp.where(has_h, hh, 1.0)", "P_H * F / 4.0", _k(REF, "kelemen")),
    # ---- the skin profile (d'Eon & Luebke 2007)
    Mutant("sss-widest-variance-7.41-to-3.0", "jaxskin/sss.py",
           "1.99, 7.41)", "1.99, 3.0)", _k(REF, "point_light or edge")),
    Mutant("sss-weights-green-blue-swapped-in-gaussian-5", "jaxskin/sss.py",
           "(0.358, 0.004, 0.000),", "(0.358, 0.000, 0.004),", _k(REF, "point_light or edge")),
    Mutant("sss-gaussian-2v-to-v", "jaxskin/sss.py",
           "np.exp(-rr / (2 * v))", "np.exp(-rr / v)", _k(REF, "point_light or edge")),
    Mutant("sss-kernel-cut-4-to-2-sigma", "jaxskin/sss.py",
           "texel_mm, cut=4.0)\n    ry, rx", "texel_mm, cut=2.0)\n    ry, rx",
           _k(REF, "point_light or edge")),
    Mutant("sss-no-edge-renormalisation", "jaxskin/sss.py",
           "jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0), 0, -1)",
           "jnp.where(ok, num, 0.0), 0, -1)",
           _k("tests/test_cosmetics.py", "conserve_energy")),
    # ---- melanin (Jacques 1998)
    Mutant("melanin-slope-3.33-to-2", "jaxskin/skin.py",
           "MELANIN_EXPONENT = -3.33", "MELANIN_EXPONENT = -2.0", _k(REF, "melanin")),
    Mutant("melanin-reference-500-to-550nm", "jaxskin/skin.py",
           "MELANIN_REFERENCE_NM = 500.0", "MELANIN_REFERENCE_NM = 550.0", _k(REF, "melanin")),
    # ---- sRGB encoding (IEC 61966-2-1)
    Mutant("srgb-exponent-2.4-to-2.2", "jaxskin/render.py",
           "** (1 / 2.4)", "** (1 / 2.2)", _k(REF, "srgb or colorchecker")),
    Mutant("srgb-threshold-0.0031308-to-0.04045", "jaxskin/render.py",
           "curved = x > 0.0031308", "curved = x > 0.04045", _k(REF, "srgb")),
    Mutant("srgb-linear-slope-12.92-to-12", "jaxskin/render.py",
           "12.92 * x)", "12.0 * x)", _k(REF, "srgb")),
    # ---- view sampling and supersampling
    Mutant("view-half-texel-offset-removed-x", "jaxskin/view.py",
           "x = jnp.asarray(tex)[..., 0] - 0.5", "x = jnp.asarray(tex)[..., 0]",
           _k(REF, "checkerboard")),
    Mutant("view-half-texel-offset-removed-y", "jaxskin/view.py",
           "y = jnp.asarray(tex)[..., 1] - 0.5", "y = jnp.asarray(tex)[..., 1]",
           _k(REF, "checkerboard")),
    Mutant("view-wrap-ignored", "jaxskin/view.py",
           "xi = jnp.mod(xi, Wt) if wrap_x else jnp.clip(xi, 0, Wt - 1)",
           "xi = jnp.clip(xi, 0, Wt - 1)", _k(REF, "checkerboard")),
    Mutant("view-perspective-barycentrics-not-corrected", "jaxskin/view.py",
           "bary = bary / w[mesh.faces[safe]]", "bary = bary / 1.0", _k(REF, "ray_casting")),
    Mutant("view-downsample-max-not-mean", "jaxskin/view.py",
           ".mean(axis=(1, 3))", ".max(axis=(1, 3))", _k(REF, "downsample")),
    # ---- the view's samples on the mesh, shaded as a list (Blinn, Lafortune)
    Mutant("samples-pixel-mean-not-divided", "jaxskin/samples.py",
           "        / rows.shape[1]\n", "\n", ("tests/test_samples.py",)),
    Mutant("samples-wrong-pixel-of-sample", "jaxskin/samples.py",
           "pixel = (row // k) * W + col // k", "pixel = (row // k) * W + col % k",
           ("tests/test_samples.py",)),
    Mutant("view-known-corners-reversed", "jaxskin/view.py",
           "blend_corners([flat[corners[i]] for i in range(4)], tex, mask)",
           "blend_corners([flat[corners[3 - i]] for i in range(4)], tex, mask)",
           ("tests/test_samples.py",)),
    Mutant("samples-transpose-not-divided", "jaxskin/samples.py",
           "return (padded[inverse] / rows.shape[1],)",
           "return (padded[inverse],)", ("tests/test_samples.py",)),
    Mutant("bump-corner-t-neighbour-below", "jaxskin/bump.py",
           "t = np.where(row > 0, texels - W, texels)",
           "t = np.where(row < H - 1, texels + W, texels)", ("tests/test_samples.py",)),
    Mutant("bump-corner-seam-not-wrapped", "jaxskin/bump.py",
           "s = row * W + (col + 1) % W", "s = np.where(col < W - 1, texels + 1, texels)",
           ("tests/test_samples.py",)),
    Mutant("render-covered-rows-not-exposed", "jaxskin/render.py",
           "    mean = expose(mean, stops)\n    if output == \"display\":\n        return place_",
           "    if output == \"display\":\n        return place_",
           _k("tests/test_radiometry.py", "exposure")),
    # ---- spectral → colour
    Mutant("spectral-no-chromatic-adaptation", "jaxskin/spectral.py",
           "A = adapt.T @ np.asarray(srgb.matrix_XYZ_to_RGB).T",
           "A = np.asarray(srgb.matrix_XYZ_to_RGB).T", _k(REF, "colorchecker")),
    Mutant("spectral-cat02-to-bradford", "jaxskin/spectral.py",
           'transform="CAT02")', 'transform="Bradford")', _k(REF, "colorchecker")),
    Mutant("spectral-no-white-scaling", "jaxskin/spectral.py",
           "A = A / (white @ A)", "A = A", _k(REF, "colorchecker")),
    Mutant("spectral-Y-scale-100-to-99", "jaxskin/spectral.py",
           "dtype=np.float64) / 100.0", "dtype=np.float64) / 99.0",
           ("tests/test_spectral.py::test_xyz_agrees_with_colour_sd_to_xyz",)),
    # ---- Kubelka–Munk
    Mutant("km-r-inf-root-K+2S-to-K+S", "jaxskin/km.py",
           "jnp.sqrt(K) * jnp.sqrt(K + 2 * S))", "jnp.sqrt(K) * jnp.sqrt(K + S))",
           _k("tests/test_km.py", "r_inf_and_inverse")),
    Mutant("km-ks-from-r-inf-2R-to-R", "jaxskin/km.py",
           "(1.0 - R) ** 2 / (2.0 * R)", "(1.0 - R) ** 2 / R",
           _k("tests/test_km.py", "r_inf_and_inverse")),
    Mutant("km-compose-T-without-interreflection", "jaxskin/km.py",
           "T1 * T2 * inv, R2b", "T1 * T2, R2b", _k("tests/test_km.py", "stack or compose")),
    Mutant("km-compose-huang-misprint-T1-R1-T1", "jaxskin/km.py",
           "Slab(R1 + T1 * T1 * R2 * inv,", "Slab(R1 + T1 * R1 * T1 * inv,",
           _k("tests/test_km.py", "compose")),
    Mutant("km-layer-denominator-S+K-to-S", "jaxskin/km.py",
           "inv_den = 1.0 / (SK * tau + 1.0)", "inv_den = 1.0 / (S * tau + 1.0)",
           _k("tests/test_km.py", "high_precision")),
    # ---- the cosmetics model (Huang et al. 2013 §3)
    Mutant("layered-cosmetic-surface-depth-x10", "jaxskin/shading/layered.py",
           "COVER_MM = 0.001", "COVER_MM = 0.01", _k(REF, "highlight_coverage")),
    Mutant("layered-no-skin-interreflection", "jaxskin/shading/layered.py",
           "g = 1.0 / (1.0 - top.R_back * skin_R)", "g = 1.0",
           _k("tests/test_makeup.py", "exact_spectral_over")),
    # the same line in the CPU's chunked form (`_spectra_skipping`), which a CPU run renders
    Mutant("layered-no-skin-interreflection-cpu", "jaxskin/shading/layered.py",
           "g = 1.0 / (1.0 - Rb * skin_R)", "g = 1.0",
           _k("tests/test_makeup.py", "exact_spectral_over")),
    Mutant("layered-highlight-dimmed-once-not-twice", "jaxskin/shading/layered.py",
           "T2 = T_l[i] * T_l[i]", "T2 = T_l[i]", _k("tests/test_makeup.py", "highlights")),
    Mutant("layered-no-ambient", "jaxskin/shading/layered.py",
           "return ambient + light * jnp.maximum(", "return light * jnp.maximum(",
           _k("tests/test_makeup.py", "exact_spectral_over")),
    Mutant("layered-chunked-jvp-misaligned", "jaxskin/shading/layered.py",
           "out_dot.shape[-1])[:P]", "out_dot.shape[-1])[-P:]",
           _k(GRAD, "chunked_jvp and unblurred")),
    # ---- Lafortune (eq. 4.15–4.16)
    Mutant("lafortune-diffuse-not-over-pi", "jaxskin/shading/lafortune.py",
           "return p.diffuse / math.pi + jnp.sum(", "return p.diffuse + jnp.sum(",
           _k(REF, "lafortune")),
    Mutant("lafortune-shade-xy-includes-zz", "jaxskin/shading/lafortune.py",
           "dot(L, V) - zz, zz)", "dot(L, V), zz)",
           _k(REF, "lafortune")),
    Mutant("lafortune-uz-uz-not-uz-vz", "jaxskin/shading/lafortune.py",
           "u[..., 2] * v[..., 2])", "u[..., 2] * u[..., 2])", _k(REF, "lafortune")),
    Mutant("lafortune-skin-lobe-3-exponent-typo", "jaxskin/shading/lafortune.py",
           "[64.208486, 63.919687, 43.809866]", "[46.208486, 63.919687, 43.809866]",
           _k(REF, "lafortune")),
    # ---- direction fields (eq. 3.1)
    Mutant("fields-inverse-square-distance", "jaxskin/fields.py",
           "w = lam[None] / np.where(at_edit, 1.0, dist)",
           "w = lam[None] / np.where(at_edit, 1.0, dist) ** 2", _k(REF, "eq_3_1")),
    Mutant("fields-weight-lambda-ignored", "jaxskin/fields.py",
           "lam = np.array([e.weight for e in edits], np.float64)",
           "lam = np.ones(len(edits))", _k(REF, "eq_3_1")),
    Mutant("fields-initial-d1-along-x", "jaxskin/fields.py",
           "np.broadcast_to([0.0, 1.0, 0.0],", "np.broadcast_to([1.0, 0.0, 0.0],",
           _k(REF, "initial_fields")),
    Mutant("fields-d2-is-n-cross-d1", "jaxskin/fields.py",
           "return d1, np.cross(d1, mesh.normals)", "return d1, np.cross(mesh.normals, d1)",
           _k(REF, "initial_fields")),
    # ---- furrows (§3.3, §5.2)
    Mutant("wrinkles-f-angle-0.4-to-0.2", "jaxskin/wrinkles.py",
           "return (1.0 - 0.4 * x,", "return (1.0 - 0.2 * x,", _k(REF, "furrow_functions")),
    Mutant("wrinkles-f-length-4+x-to-4+2x", "jaxskin/wrinkles.py",
           "k_scale * (4.0 + x),", "k_scale * (4.0 + 2 * x),", _k(REF, "furrow_functions")),
    Mutant("wrinkles-f-depth-0.25-to-0.5", "jaxskin/wrinkles.py",
           "0.25 * x * x,", "0.5 * x * x,", _k(REF, "furrow_functions")),
    Mutant("wrinkles-f-limit-10x-to-5x", "jaxskin/wrinkles.py",
           "jnp.floor(30.0 - 10.0 * x)", "jnp.floor(30.0 - 5.0 * x)",
           _k(REF, "furrow_functions")),
    Mutant("wrinkles-noise-raises-not-lowers", "jaxskin/wrinkles.py",
           "h - k_noise * r, h)", "h + k_noise * r, h)",
           _k("tests/test_wrinkles.py", "step_nine")),
    # ---- texture space
    Mutant("projection-texel-size-area-not-length", "jaxskin/projection.py",
           "return math.sqrt(surface / max(texels, 1e-300))",
           "return surface / max(texels, 1e-300)",
           _k("tests/test_makeup.py", "texel_size")),
    Mutant("skin-melanin-one-pass-not-two", "jaxskin/skin.py",
           "return base * jnp.exp(-melanin * jnp.asarray(shape, base.dtype))",
           "return base * jnp.exp(-0.5 * melanin * jnp.asarray(shape, base.dtype))",
           _k(REF, "melanin or flat_skin")),
    # ---- rasterizer and interpolation
    Mutant("raster-pixel-corner-not-centre", "jaxskin/raster.py",
           "cx, cy = px + 0.5, py + 0.5", "cx, cy = px + 0.0, py + 0.0",
           _k("tests/test_geometry.py", "linear_attribute or pixel_aligned")),
    Mutant("raster-farthest-wins", "jaxskin/raster.py",
           "order = np.lexsort((f, z, pixel))", "order = np.lexsort((f, -z, pixel))",
           _k("tests/test_geometry.py", "nearest")),
    Mutant("raster-interpolate-barycentrics-reversed", "jaxskin/raster.py",
           'einsum("hwk,hwkc->hwc", bary.astype(values.dtype), values)',
           'einsum("hwk,hwkc->hwc", bary.astype(values.dtype)[..., ::-1], values)',
           _k("tests/test_geometry.py", "linear_attribute")),
    # ---- Blinn's skin colour in optical density (shading/blinn.py, data/make_skin_colour.py)
    Mutant("blinn-melanin-red-density-1.56-to-1.0", "jaxskin/shading/blinn.py",
           "A_MELANIN = (1.5581,", "A_MELANIN = (1.0,", _k(RAD, "published_data")),
    Mutant("blinn-blood-green-density-dropped", "jaxskin/shading/blinn.py",
           "A_BLOOD = (0.0000, 0.2759,", "A_BLOOD = (0.0000, 0.0,", _k(RAD, "published_data")),
    Mutant("blinn-blood-brightens", "jaxskin/shading/blinn.py",
           "a_m - blood[..., None] * a_b)", "a_m + blood[..., None] * a_b)",
           _k(RAD, "published_data")),
    # ---- bump normals in the surface frame (bump.py, projection.py, texture.py) and eq. 4.10
    Mutant("bump-general-form-tilts-toward-gradient", "jaxskin/bump.py",
           "n[..., i] - k_bump * (hs", "n[..., i] + k_bump * (hs", _k(BUMP, "cylindrical_bump")),
    Mutant("bump-t-down-not-up", "jaxskin/bump.py",
           "ht = jnp.pad(h[:-1, :] - h[1:, :],", "ht = jnp.pad(h[1:, :] - h[:-1, :],",
           _k(BUMP, "cylindrical_bump")),
    Mutant("bump-eq-4.10-second-cross-reversed", "jaxskin/bump.py",
           "b = (0.0 * nz - -nx * ny, -nx * nx - nz * nz, nz * ny - 0.0 * nx)",
           "b = (-nx * ny - 0.0 * nz, nz * nz - -nx * nx, 0.0 * nx - nz * ny)",
           _k(BUMP, "planar_gradients")),
    Mutant("bump-seam-not-wrapped-in-height-gradient", "jaxskin/bump.py",
           "    if wrap_s:\n        hs = jnp.roll", "    if False:\n        hs = jnp.roll",
           _k(BUMP, "cylindrical_bump")),
    Mutant("bump-gradients-t-sign-not-flipped", "jaxskin/projection.py",
           "return J * np.array([1.0, -1.0])[None, :, None]",
           "return J * np.array([1.0, 1.0])[None, :, None]", _k(BUMP, "cylindrical_bump")),
    Mutant("bump-cylindrical-ds-dz-sign", "jaxskin/projection.py",
           "M[:, 0, 0], M[:, 0, 2], M[:, 1, 1] = c, -n, -1.0",
           "M[:, 0, 0], M[:, 0, 2], M[:, 1, 1] = c, n, -1.0", _k(BUMP, "cylindrical_bump")),
    Mutant("bump-render-seam-wrap-off", "jaxskin/texture.py",
           "frame[\"grad_t\"], wrap_s=wrap_s)}", "frame[\"grad_t\"], wrap_s=False)}",
           _k(BUMP, "all_round")),
    Mutant("bump-furrows-read-not-wrapped-at-seam", "jaxskin/wrinkles.py",
           "px = (pi[:, 0] - pad) % W + pad if wrap else pi[:, 0]", "px = pi[:, 0]",
           _k(BUMP, "cross_the_cylinder_seam")),
    Mutant("bump-furrows-seam-copy-shifted-wrong-way", "jaxskin/wrinkles.py",
           "shift = jnp.where(c0 < 0, W, jnp.where(c0 + 2 * R + 1 > W, -W, 0))",
           "shift = jnp.where(c0 < 0, -W, jnp.where(c0 + 2 * R + 1 > W, W, 0))",
           _k(BUMP, "cross_the_cylinder_seam")),
    # ---- the one radiometric scale (shading/lafortune.py shade, render.py expose)
    Mutant("scale-lafortune-pi-dropped", "jaxskin/shading/lafortune.py",
           "(math.pi * light) * f", "light * f", _k(RAD, "without_lobes")),
    Mutant("scale-lafortune-ambient-over-pi", "jaxskin/shading/lafortune.py",
           "return ambient * p.diffuse + (math.pi",
           "return ambient * p.diffuse / math.pi + (math.pi",
           _k(RAD, "without_lobes")),
    Mutant("scale-exposure-e-not-2", "jaxskin/render.py",
           "return linear * jnp.exp2(", "return linear * jnp.exp(",
           _k(RAD, "exposure_in_the_cosmetics")),
    Mutant("scale-exposure-sign", "jaxskin/render.py",
           "jnp.exp2(jnp.asarray(stops,", "jnp.exp2(-jnp.asarray(stops,",
           _k(RAD, "exposure_in_the_cosmetics")),
    # ---- shadows (shadow.py)
    Mutant("shadow-bias-x10", "jaxskin/shadow.py", "BIAS = 1.5", "BIAS = 15.0",
           _k(SHADOW, "floating_square or convex or close_occluder")),
    Mutant("shadow-lit-comparison-flipped", "jaxskin/shadow.py",
           "(depth <= nearest + bias)", "(depth >= nearest + bias)",
           _k(SHADOW, "floating_square or convex or close_occluder")),
    Mutant("shadow-bias-subtracted", "jaxskin/shadow.py",
           "(depth <= nearest + bias)", "(depth <= nearest - bias)",
           _k(SHADOW, "floating_square or convex or close_occluder")),
    Mutant("shadow-light-direction-reversed", "jaxskin/shadow.py",
           "w = w / np.linalg.norm(w)", "w = -w / np.linalg.norm(w)",
           _k(SHADOW, "floating_square or convex or close_occluder")),
    Mutant("shadow-slope-bias-cos-not-sin", "jaxskin/shadow.py",
           "slope = np.sqrt(np.maximum(1 - cos * cos, 0.0)) / np.maximum(",
           "slope = cos / np.maximum(", _k(SHADOW, "floating_square or convex or close_occluder")),
    # ---- texture padding beyond the mesh (view.pad_index)
    Mutant("pad-corners-before-edges", "jaxskin/view.py",
           "steps.sort(key=lambda s: abs(s[0]) + abs(s[1]))",
           "steps.sort(key=lambda s: -abs(s[0]) - abs(s[1]))", _k(VIEW, "pad_index")),
    Mutant("pad-one-texel-short", "jaxskin/view.py",
           "for _ in range(width):", "for _ in range(width - 1):", _k(VIEW, "pad_index")),
    Mutant("pad-seam-not-wrapped", "jaxskin/view.py",
           "src_filled = _shift(filled, dy, dx, wrap_x, False)",
           "src_filled = _shift(filled, dy, dx, False, False)", _k(VIEW, "pad_index")),
    # ---- small formulas that were checked only against their own gradient or bounds
    # (issue 37, item 11): each now has a value computed by hand
    Mutant("small-noise-amplitude-halved", "jaxskin/wrinkles.py",
           "h - k_noise * r, h)", "h - 0.5 * k_noise * r, h)", _k(WRINKLES, "noise")),
    Mutant("small-noise-field-halved", "jaxskin/wrinkles.py",
           "return jax.random.uniform(jax.random.fold_in(key, 3), shape, dtype)",
           "return 0.5 * jax.random.uniform(jax.random.fold_in(key, 3), shape, dtype)",
           _k(WRINKLES, "noise")),
    # the same search found these already killed by a value test; kept so that stays so
    Mutant("small-blinn-ambient-not-times-albedo", "jaxskin/shading/blinn.py",
           "return (ambient * r + light * r", "return (ambient + light * r",
           (f"{REF}::test_blinn_geometry_by_hand", "tests/test_render.py", "-k", "by_hand")),
    Mutant("small-blinn-highlight-not-times-light", "jaxskin/shading/blinn.py",
           "+ light * specular * spec[..., None])", "+ specular * spec[..., None])",
           (f"{REF}::test_blinn_geometry_by_hand", "tests/test_render.py", "-k", "by_hand")),
    Mutant("small-feather-ramp-not-centred-on-the-edge", "jaxskin/cosmetics.py",
           "np.clip(0.5 + inside_distance / feather", "np.clip(inside_distance / feather",
           _k("tests/test_cosmetics.py", "region_and_image_maps")),
    Mutant("small-image-map-scale-dropped", "jaxskin/cosmetics.py",
           "return scale_mm * img[rows", "return img[rows",
           _k("tests/test_cosmetics.py", "region_and_image_maps")),
    Mutant("small-ellipse-turned-the-other-way", "jaxskin/cosmetics.py",
           "x = (math.cos(t) * du + math.sin(t) * dv)",
           "x = (math.cos(t) * du - math.sin(t) * dv)",
           _k("tests/test_cosmetics.py", "region_and_image_maps")),
    Mutant("small-biophysical-mie-exponent-1.5-to-1", "jaxskin/biophysical.py",
           "2e5 * wl ** -1.5", "2e5 * wl ** -1.0", ("tests/test_biophysical.py",)),
    Mutant("small-biophysical-saunderson-k2-dropped-below", "jaxskin/biophysical.py",
           "R / (1.0 - K2 * R)", "R / (1.0 - K2)", ("tests/test_biophysical.py",)),
    Mutant("small-biophysical-S-three-quarters-to-one", "jaxskin/biophysical.py",
           "S = 0.75 * _band(skin.scattering", "S = 1.0 * _band(skin.scattering",
           ("tests/test_biophysical.py",)),
]


def project_files(root: Path) -> list[str]:
    """The files git tracks or would track (untracked, not ignored)."""
    out = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=root,
                         capture_output=True, text=True, check=True).stdout
    return [f for f in out.splitlines() if (root / f).is_file()]


def check(root: Path = ROOT, mutants=MUTANTS) -> list[str]:
    """Problems with the list: a pattern that does not occur exactly once, a mutant that
    changes nothing, a duplicate id, a test file that does not exist."""
    problems, seen = [], set()
    for m in mutants:
        if m.id in seen:
            problems.append(f"{m.id}: duplicate id")
        seen.add(m.id)
        text = (root / m.file).read_text()
        if text.count(m.old) != 1:
            problems.append(f"{m.id}: pattern occurs {text.count(m.old)} times in {m.file}")
        if m.old == m.new:
            problems.append(f"{m.id}: the mutant changes nothing")
        for t in m.tests:
            if t.startswith("tests/") and not (root / t.split("::")[0]).is_file():
                problems.append(f"{m.id}: no test file {t}")
    return problems


def make_copy(root: Path, dest: Path) -> None:
    """The project's files under `dest`, with `jaxskin/fitting` and `jaxskin/data` linked
    to `fitting/` and `data/` as the installed package maps them."""
    for f in project_files(root):
        target = dest / f
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / f, target)
    for sub in ("fitting", "data"):
        os.symlink(dest / sub, dest / "jaxskin" / sub)


def run_tests(copy: Path, tests, timeout: float) -> tuple[int, float, str]:
    env = {**os.environ, "PYTHONPATH": str(copy), "PYTHONDONTWRITEBYTECODE": "1"}
    t0 = time.perf_counter()
    try:
        p = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                            *tests], cwd=copy, env=env, capture_output=True, text=True,
                           timeout=timeout)
        rc, tail = p.returncode, (p.stdout + p.stderr).strip().splitlines()[-1:]
    except subprocess.TimeoutExpired:
        rc, tail = -1, ["timeout"]
    return rc, time.perf_counter() - t0, " ".join(tail)


def main(argv: list[str]) -> int:
    problems = check()
    if problems:
        print("\n".join(problems))
        return 2
    if "--check" in argv:
        print(f"{len(MUTANTS)} mutants, every pattern applies once")
        return 0
    prefixes = [a for a in argv if not a.startswith("-")]
    chosen = [m for m in MUTANTS if not prefixes or any(m.id.startswith(p) for p in prefixes)]
    with tempfile.TemporaryDirectory(prefix="jaxskin-mutants-") as tmp:
        copy = Path(tmp)
        make_copy(ROOT, copy)
        probe = subprocess.run([sys.executable, "-c", "import jaxskin.data, jaxskin; "
                                "print(jaxskin.__file__)"], cwd=copy, capture_output=True,
                               text=True, env={**os.environ, "PYTHONPATH": str(copy)})
        if not probe.stdout.strip().startswith(str(copy)):
            print(f"the copy is not what Python imports: {probe.stdout}{probe.stderr}")
            return 2
        # Every selection collects tests and passes on the unchanged copy.
        for tests in dict.fromkeys(m.tests for m in chosen):
            rc, secs, tail = run_tests(copy, tests, 1800)
            print(f"baseline {secs:5.1f} s  {' '.join(tests)}  ({tail})", flush=True)
            if rc != 0:
                print("a selection fails (or selects nothing) on the unchanged project")
                return 2
        rows, t_all = [], time.perf_counter()
        for m in chosen:
            path = copy / m.file
            original = path.read_text()
            path.write_text(original.replace(m.old, m.new, 1))
            try:
                rc, secs, tail = run_tests(copy, m.tests, 600)
            finally:
                path.write_text(original)
            if rc in (3, 4, 5):  # pytest's internal error, usage error, nothing collected
                print(f"{m.id}: pytest could not run the selection (rc {rc}): {tail}")
                return 2
            killed = rc != 0  # 1: a test failed; 2: collection failed; -1: timeout
            rows.append((m, killed, secs, tail))
            print(f"{'killed ' if killed else 'SURVIVED'} {secs:5.1f} s  {m.id}  ({tail})",
                  flush=True)
    killed = sum(r[1] for r in rows)
    total = time.perf_counter() - t_all
    print(f"\nkill rate {killed}/{len(rows)} = {killed / len(rows):.0%} in {total:.0f} s")
    if len(chosen) == len(MUTANTS):
        _write_results(rows, total)
    return 0 if killed == len(rows) else 1


def _write_results(rows, total) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from common import machine, write_section

    killed = sum(r[1] for r in rows)
    lines = [
        "## Mutation score (issue 20)",
        "",
        f"Command: `python benchmarks/mutation.py`. Machine: {machine()}.",
        "",
        "Each mutant is a one-line change to the library's physics, applied to a copy of "
        "the project; it is killed when its own test selection fails. The list and the "
        "selections are in benchmarks/mutation.py.",
        "",
        f"**Kill rate: {killed}/{len(rows)} ({killed / len(rows):.0%})**, "
        f"{total:.0f} s in all.",
        "",
        "| mutant | file | killed | s |",
        "|---|---|---|---|",
    ]
    lines += [f"| {m.id} | {m.file} | {'yes' if k else '**no**'} | {s:.0f} |"
              for m, k, s, _ in rows]
    survivors = [m.id for m, k, _, _ in rows if not k]
    lines += ["", "Survivors: " + (", ".join(survivors) if survivors else "none") + ".", "",
              "Not in the list yet: the shipped materials' and cosmetics' colour targets "
              "(data/materials), data rather than one line of code."]
    write_section("mutation", "\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
