"""Where the default makeup frame's time goes: each stage of the cosmetics render jitted on
its own (inputs from the stage before), wall and CPU time, beside the whole frame.

    .venv/bin/python benchmarks/profile_makeup.py [--repeat N] [-D key=value ...]

The stages follow `render._cosmetics_texture` and `shading.layered.radiance`: the bumped
normals (furrows), the per-texel light and view, the skin's reflectance, the Kelemen
highlights, the spectral KM work (`layered._colours`), the SSS blur (texel list → image,
FFT, image → list), the colour after the blur, the texel list → image scatter, the view's
pixels (`view.view_pixels`), the exposure and sRGB encoding, and the PNG (host). The
machine is shared: the CPU time (all threads of this process) says more than the wall time
when the load average is high.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxskin import maps, render, skin_texels, sss, texture
from jaxskin.scene import load_scene
from jaxskin.shading import kelemen, layered
from jaxskin.vectors import times3

HD = ["camera.size=1280", "camera.height=720", "texture.size=512"]


def measure(fn, *args, repeat=9):
    """(median wall ms, median CPU ms) of `fn(*args)`, after one warm-up call."""
    jax.block_until_ready(fn(*args))
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        jax.block_until_ready(fn(*args))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall) * 1e3, statistics.median(cpu) * 1e3


def stages(config, params, arrays):
    """`{name: (fn, args)}`: the frame's stages, each a jitted function of the outputs of
    the ones before (computed here once)."""
    p = render.prepare(config)
    sp = config.spectral
    mask, texels = arrays["mask"], arrays["texels"]
    shape = mask.shape
    out = {}

    def run(name, fn, *args):
        f = jax.jit(fn)
        out[name] = (f, args)
        return jax.block_until_ready(f(*args))

    def bump(params, arrays):
        frame = {k: arrays[k] for k in ("grad_s", "grad_t") if k in arrays}
        return texture.bumped(arrays["normals"], arrays["mask"], arrays["h0"],
                              arrays["noise"], params, frame, p.setup.tmap.wrap_x)["normals"]

    normals = run("bumped normals (furrows)", bump, params, arrays) if config.needs_furrows \
        else arrays["normals"]

    def light_view(normals, params, arrays):
        n = normals.reshape(-1, 3)[arrays["texels"]]
        L, V = render._light_and_view(arrays, params["light.direction"], n.dtype,
                                      lambda: arrays["positions"].reshape(-1, 3)[
                                          arrays["texels"]])
        return n, L, V

    N, L, V = run("normals, L, V per texel (gathers)", light_view, normals, params, arrays)
    skin_R = run("skin reflectance", lambda pr, a: skin_texels.skin_reflectance(sp, pr, a, texels),
                 params, arrays)
    light = params["light.intensity"] * arrays["lit"] if "lit" in arrays else \
        params["light.intensity"]
    rough = jnp.stack([params[f"layer.{s.name}.roughness"] for s in sp.layers])
    rho = jnp.stack([params[f"layer.{s.name}.specular"] for s in sp.layers])

    def highlights(N, L, V, light, params, rough, rho):
        h = light * kelemen.specular(N, L, V, params["skin.roughness"], params["skin.specular"])
        h_l = jnp.stack([light * kelemen.specular(N, L, V, rough[i], rho[i])
                         for i in range(rough.shape[0])])
        return h[:, None], h_l[..., None]

    h, h_l = run("Kelemen highlights (skin + layers)", highlights, N, L, V, light, params,
                 rough, rho)
    E = run("irradiance", lambda N, L, a, li: layered.irradiance(N, L, a, li)[:, None],
            N, L, params["light.ambient"], light)

    def per_layer(key):
        return jnp.stack([params[f"layer.{s.name}.{key}"] for s in sp.layers])

    S = arrays["S"] * per_layer("s_scale")[:, None]
    K = arrays["K"] * per_layer("k_scale")[:, None]
    X = arrays["cover"] * per_layer("thickness_mm")[:, None]
    colours = run("KM layers, stack, spectra → rgb/xyz (_colours)",
                  lambda X, E, h, h_l, S, K, s: layered._colours(sp.grid, True, X, E, h, h_l, S,
                                                                 K, s),
                  X, E, h, h_l, S, K, skin_R)

    def to_image(values):
        o = jnp.zeros((shape[0] * shape[1], values.shape[-1]), values.dtype)
        return o.at[texels].set(values, unique_indices=True).reshape(*shape, -1)

    grid = sp.grid
    skin_rgb = jnp.asarray(skin_R) @ jnp.asarray(grid.rgb_matrix, jnp.float32)

    def before_blur(colours, E, skin_R):
        xyz_da = colours[:, 3:6]
        return E * (skin_R @ jnp.asarray(grid.rgb_matrix, jnp.float32)
                    + times3(xyz_da, grid.xyz_to_rgb))

    skin = run("colour entering the skin", before_blur, colours, E, skin_R)
    img = run("texel list → image (scatter, 3 ch)", to_image, skin)

    def blur(img, arrays):
        return sss.blur(img, p.texel_mm, arrays["mask"], sp.sss, norm=arrays.get("sss_norm"),
                        kernels=arrays.get("sss_kernels"))

    blurred_img = run("SSS blur (FFT, 3 ch)", blur, img, arrays)
    blurred = run("image → texel list (gather, 3 ch)",
                  lambda im, a: im.reshape(-1, 3)[a["texels"]], blurred_img, arrays)
    del skin_rgb
    run("whole _cosmetics_texture", lambda pr, a, n: render._cosmetics_texture(
        config, p, pr, a, n), params, arrays, normals)
    colour_img = render._cosmetics_texture(config, p, params, arrays, normals)

    def after_blur(colours, E, skin_R, out, h):  # `layered.radiance` after `blur`
        rgb_surface, xyz_da, xyz_dta = colours[..., :3], colours[..., 3:6], colours[..., 6:]
        to_xyz = jnp.asarray(grid.xyz_matrix, jnp.float32)
        xyz_to_rgb = jnp.asarray(grid.xyz_to_rgb, jnp.float32)
        skin = E * (skin_R @ jnp.asarray(grid.rgb_matrix, jnp.float32)
                    + times3(xyz_da, xyz_to_rgb))
        xyz_a = skin_R @ to_xyz + xyz_da
        ok = xyz_a > 1e-12
        t1 = jnp.where(ok, xyz_dta / jnp.where(ok, xyz_a, 1.0), -1.0)
        rgb_to_xyz = jnp.asarray(np.linalg.inv(grid.xyz_to_rgb), jnp.float32)
        x = out + times3(t1 * times3(out, rgb_to_xyz), xyz_to_rgb)
        own = skin + E * times3(xyz_dta, xyz_to_rgb)
        return (rgb_surface + layered._in_gamut(x, (1.0 + t1[..., 1:2]) * out,
                                                jnp.minimum(own, 0.0))) + h

    run("colour after the blur (t, in gamut, highlights)", after_blur, colours, E, skin_R,
        blurred, h)
    run("texel list → image (scatter, final colour)", to_image, colour_img.reshape(-1, 3)[
        texels])
    mean = run("view pixels (view_pixels)", lambda im, a: render.texture_to_view(config, a, im),
               colour_img, arrays)
    run("exposure + sRGB encode", lambda m, s: render.encode_srgb(render.expose(m, s)),
        mean, params["camera.exposure"])
    return out


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=9)
    ap.add_argument("--scene", default="makeup")
    ap.add_argument("-D", action="append", default=[])
    args = ap.parse_args(argv)
    sc = load_scene(args.scene, HD + args.D)
    config, params = sc.config, sc.params
    arrays = render.prepare(config).arrays
    print(f"load average before: {os.getloadavg()}")
    whole = jax.jit(lambda pr, a: render.render_prepared(config, pr, a))
    rows = [("whole frame (render_prepared)", *measure(whole, params, arrays,
                                                         repeat=args.repeat))]
    image = np.asarray(whole(params, arrays))
    rows.append(("PNG encode (host, maps.image_bytes)",
                 *measure(lambda: maps.image_bytes(image), repeat=3)))
    for name, (fn, a) in stages(config, params, arrays).items():
        rows.append((name, *measure(fn, *a, repeat=args.repeat)))
    rows.append(("whole frame again", *measure(whole, params, arrays, repeat=args.repeat)))
    print(f"{'stage':55s} {'wall ms':>8s} {'CPU ms':>8s}")
    for name, w, c in rows:
        print(f"{name:55s} {w:8.1f} {c:8.1f}")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main(sys.argv[1:])
