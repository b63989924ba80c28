"""fit-image on ground truth: makeup thickness maps recovered from the face, the optimiser
comparison for maps (the per-texel Gauss–Newton, Adam, L-BFGS, nonlinear CG), the speed
at 512², the ambiguity and maps figures.

    python benchmarks/bench_fit_image.py maps [--size 48] [--steps 30] [--solvers gn,adam]
        [--noise 0.01] [--smooth 1e-6] [--image 192] [-D layer.lipstick.thickness_mm=0.003]
    python benchmarks/bench_fit_image.py speed --size 512 --steps 25 --solvers gn
    python benchmarks/bench_fit_image.py ambiguity      # writes fit_image_ambiguity.png
    python benchmarks/bench_fit_image.py figure         # writes fit_image_maps.png

Targets are rendered with known values, plus Gaussian noise σ in display values; the fits
start from each layer everywhere at 1/20 of its thickness. Printed: time, steps, the final
loss and data RMS, and per map the RMS relative error over the texels whose Cramér–Rao
bound (`fitting.image.map_bounds`, at the truth, the layers together) is under 2.5 % and
under 10 %, and over all the texels the layer covers; and the fraction of each layer's
texels under those bounds; the face pixels per texel seen, and the share of each layer's
texels under 2.5 % at σ 0.002, 0.001 and 0.0005 (the bound scales with σ).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxskin import render
from jaxskin.fitting import image as fi
from jaxskin.scene import Scene, load_scene

MAPS = ("foundation", "blush", "lipstick")
START = 20


def without_regions(scene: Scene, names) -> Scene:
    """`scene` with the named layers everywhere (their regions dropped)."""
    layers = tuple(dataclasses.replace(layer, ellipses=(), polygons=(), image=None)
                   if layer.name in names else layer for layer in scene.layers)
    return dataclasses.replace(scene, layers=layers)


def recoverable(truth: Scene, w, noise, names=MAPS, bound=0.025):
    """The texels of each layer whose thickness the image pins to `bound` (relative, 1σ),
    by the Cramér–Rao bound at the truth (`fitting.image.map_bounds`, the layers fitted
    together) with noise `noise`, among the texels the layer covers. Returns name →
    mask and name → the bounds."""
    arrays = render.prepare(truth.config).arrays
    mask = np.asarray(arrays["mask"])
    texels = np.asarray(arrays["texels"])
    params = dict(truth.params)
    for i, layer in enumerate(truth.layers):
        m = np.zeros(mask.size, np.float32)
        m[texels] = np.asarray(arrays["cover"][i])
        params[f"layer.{layer.name}.map"] = jnp.asarray(m.reshape(mask.shape))
    keys = [f"layer.{n}.map" for n in names]
    b = fi.map_bounds(truth.config, params, keys, w, noise)
    tm = true_maps(truth)
    return ({n: (b[f"layer.{n}.map"] < bound) & (tm[n] > 0) for n in names},
            {n: b[f"layer.{n}.map"] for n in names})


def true_maps(scene: Scene):
    """The truth's per-texel thickness maps (mm) `(H, W)` by layer name."""
    arrays = render.prepare(scene.config).arrays
    mask = np.asarray(arrays["mask"])
    texels = np.asarray(arrays["texels"])
    out = {}
    for i, layer in enumerate(scene.layers):
        m = np.zeros(mask.size)
        m[texels] = np.asarray(arrays["cover"][i]) * scene.values[
            f"layer.{layer.name}.thickness_mm"]
        out[layer.name] = m.reshape(mask.shape)
    return out


def pixels_per_texel(config, w) -> float:
    """Image pixels on the face (the fit's weights `w`) per texel they see: Σ w over the
    number of texels that gather at least 0.1 of a weighted pixel through the view's
    sampling map (`fitting.image.view_matrix`; its rows sum to 1 per pixel). An area
    ratio: a camera at k× the texture's resolution gives about k² × (the share of the
    texture the face's view uses)."""
    rows, cols, vals = fi.view_matrix(config)
    Ht, Wt = np.asarray(render.prepare(config).arrays["mask"]).shape
    wf = np.asarray(w, np.float64).reshape(-1)
    gathered = np.bincount(cols, weights=vals * wf[rows], minlength=Ht * Wt)
    return float(wf.sum() / max(1, (gathered >= 0.1).sum()))


def maps(size, steps, solvers, smooth, rate=fi.ADAM_RATE, noise=0.01, seed=0, names=MAPS,
         image=None, extra=(), sigmas=(0.002, 0.001, 0.0005)):
    """The makeup maps fitted from a `size`² texture seen by an `image`² camera (default
    2 × size) with noise `noise`; `extra`: more scene overrides (e.g. a thinner layer,
    `layer.lipstick.thickness_mm=0.003`, or `camera.supersample=1`). Also printed: the
    pixels per texel and the share of each layer's texels whose bound is < 2.5 % at each
    of `sigmas` (the bound is proportional to σ: one computation serves them all)."""
    image = image or 2 * size
    ov = [f"texture.size={size}", f"camera.size={image}", *extra]
    truth = load_scene("makeup", ov)
    target = np.asarray(render.render(truth.config, truth.params))
    target = np.clip(target + np.random.default_rng(seed).normal(0, noise, target.shape), 0, 1)
    # The start: each layer everywhere, at 1/START of its true thickness (thin: a thick
    # layer is opaque, and what lies under it has no gradient).
    start = load_scene("makeup", ov + [f"layer.{n}.thickness_mm="
                                       f"{truth.values[f'layer.{n}.thickness_mm'] / START}"
                                       for n in names])
    start = without_regions(start, names)
    w = fi.weights(start.config, start.params)
    keys = fi.fit_keys(start, ",".join(f"layer.{n}.map" for n in names))
    truth_mm = true_maps(truth)
    seen, bounds = recoverable(truth, w, noise, names)
    ppt = pixels_per_texel(truth.config, w)
    rows = []
    for solver in solvers:
        t0 = time.perf_counter()
        r = fi.fit(start.config, start.params, target, w, keys, steps=steps, smooth=smooth,
                   solver=solver, rate=rate)
        errs = {}
        for k in keys:
            name = k.key.split(".")[1]
            fit_mm = np.asarray(r.params[k.key]) * float(r.params[k.scalar])
            c = truth_mm[name] > 0
            errs[name] = tuple(
                np.sqrt(np.mean((fit_mm[v] / truth_mm[name][v] - 1) ** 2)) if v.any()
                else np.nan for v in (seen[name], c & (bounds[name] < 0.1), c))
        rows.append((solver, time.perf_counter() - t0, r.steps, r.history[-1], r.rms, errs,
                     {n: [float(((bounds[n] < b) & (truth_mm[n] > 0)).sum()
                                / max(1, (truth_mm[n] > 0).sum())) for b in (0.025, 0.1)]
                      for n in names}))
        print(solver, "loss by step:", " ".join(f"{h:.3e}" for h in r.history[:40]))
    print(f"makeup face, texture {size}², image {image}² ({ppt:.1f} face pixels per texel), "
          f"noise σ {noise}, smooth {smooth}" + (f", {' '.join(extra)}" if extra else ""))
    print("texels per layer: " + ", ".join(f"{n} {(truth_mm[n] > 0).sum()}" for n in names)
          + "; median bound at σ: " + ", ".join(
              f"{n} {100 * np.median(bounds[n][truth_mm[n] > 0]):.3g} %" for n in names))
    print(f"{'solver':<7} {'time s':>7} {'steps':>5} {'loss':>10} {'rms':>7}  "
          + "  ".join(f"{n:>10}" for n in names))
    for solver, dt, n, loss, rms, errs, _ in rows:
        print(f"{solver:<7} {dt:>7.1f} {n:>5} {loss:>10.3e} {rms:>7.4f}  "
              + "  ".join("/".join(f"{100 * e:.1f}" for e in errs[m]) + "%" for m in names))
    print("(per layer: RMS relative error over the texels whose CRB is < 2.5 % / < 10 % / "
          "over all the layer covers)")
    print("fraction of each layer's texels with CRB < 2.5 % / < 10 %: "
          + ", ".join(f"{n} {100 * f[0]:.0f}/{100 * f[1]:.0f}%" for n, f in rows[0][6].items()))
    print("fraction with CRB < 2.5 % at σ " + ", ".join(
        f"{s}: " + "/".join(f"{100 * np.mean(bounds[n][truth_mm[n] > 0] * s / noise < 0.025):.0f}"
                            for n in names) + "%" for s in sigmas) + f" ({'/'.join(names)})")
    return rows


def ambiguity(size=48, n=21, out="benchmarks/fit_image_ambiguity.png"):
    """The loss over pairs of keys around the truth: on the hand (Blinn), albedo against
    intensity (material.melanin × light.intensity: a valley) and an exact one
    (camera.exposure × light.intensity, with ambient 0: a line of zero loss); on the
    makeup face (spectral, 32² texture and image), melanin against thickness
    (skin.melanin × layer.foundation.thickness_mm: a valley)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hand = [f"texture.size={size}", f"camera.size={size}"]
    face = ["texture.size=32", "camera.size=32", "camera.supersample=1",
            "wrinkles.enabled=false", "light.shadows=false", "skin.melanin=0.5"]
    panels = [("hand", hand, "material.melanin", (0.05, 0.6), "light.intensity", (0.3, 1.2)),
              ("hand", hand + ["light.ambient=0.0"], "camera.exposure", (-1.0, 1.0),
               "light.intensity", (0.3, 1.2)),
              ("makeup", face, "skin.melanin", (0.0, 1.5), "layer.foundation.thickness_mm",
               (0.0, 0.03))]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    for ax, (name, ov, kx, rx, ky, ry) in zip(axes, panels, strict=True):
        sc = load_scene(name, ov)
        arrays = render.prepare(sc.config).arrays
        target = render.render(sc.config, sc.params)
        w = jnp.asarray(fi.weights(sc.config, sc.params))[..., None]
        xs, ys = np.linspace(*rx, n), np.linspace(*ry, n)

        def loss(x, y, sc=sc, kx=kx, ky=ky, arrays=arrays, target=target, w=w):
            p = {**sc.params, kx: x, ky: y}
            return jnp.sum(w * (render.render_prepared(sc.config, p, arrays) - target) ** 2) \
                / jnp.sum(w)

        row = jax.jit(jax.vmap(loss, (0, None)))  # a row at a time: the face's memory
        grid = np.stack([np.asarray(row(jnp.asarray(xs, jnp.float32), jnp.float32(y)))
                         for y in ys])
        im = ax.contourf(xs, ys, np.log10(grid + 1e-8), 20, cmap="viridis")
        ax.plot(float(sc.params[kx]), float(sc.params[ky]), "r*", ms=12, label="truth")
        ax.set_xlabel(kx)
        ax.set_ylabel(ky)
        ax.legend(loc="upper right")
        fig.colorbar(im, ax=ax, label="log10 loss")
    axes[0].set_title("albedo against intensity: a valley\n(fix light.intensity)")
    axes[1].set_title("exposure against intensity (ambient 0): exact\n(fix either)")
    axes[2].set_title("melanin against foundation thickness: a valley\n"
                      "(fix skin.melanin, from bare skin)")
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


def figure(size=24, noise=0.01, smooth=1e-6, out="benchmarks/fit_image_maps.png"):
    """Gauss–Newton against Adam on the makeup face (three maps, `size`² texture): loss
    against step and against time, and for the blush the truth, both fits and the
    Cramér–Rao bound per texel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = MAPS
    ov = [f"texture.size={size}", f"camera.size={2 * size}"]
    truth = load_scene("makeup", ov)
    target = np.asarray(render.render(truth.config, truth.params))
    target = np.clip(target + np.random.default_rng(0).normal(0, noise, target.shape), 0, 1)
    start = without_regions(load_scene("makeup", ov + [
        f"layer.{n}.thickness_mm={truth.values[f'layer.{n}.thickness_mm'] / START}"
        for n in names]), names)
    w = fi.weights(start.config, start.params)
    keys = fi.fit_keys(start, ",".join(f"layer.{n}.map" for n in names))
    _, bounds = recoverable(truth, w, noise, names)
    mask = np.asarray(render.prepare(truth.config).arrays["mask"])
    runs = {}
    for solver, steps in (("gn", 30), ("adam", 150)):
        stamps = [time.perf_counter()]
        r = fi.fit(start.config, start.params, target, w, keys, steps=steps, smooth=smooth,
                   solver=solver, progress=lambda _loss, s=stamps: s.append(time.perf_counter()))
        runs[solver] = (r, np.cumsum(np.diff(stamps)))
    fig, axes = plt.subplots(1, 5, figsize=(22, 4), constrained_layout=True)
    for solver, (r, t) in runs.items():
        label = {"gn": "Gauss–Newton (tries)", "adam": "Adam"}[solver]
        axes[0].semilogy(np.arange(1, len(r.history) + 1), r.history, label=label)
        axes[1].semilogy(t, r.history, label=label)
    for ax, xl in zip(axes[:2], ("step", "seconds (first includes compiling)"), strict=True):
        ax.axhline(noise ** 2, color="grey", ls=":", label="σ²")
        ax.set_xlabel(xl)
        ax.set_ylabel("loss")
        ax.legend()
        ax.grid(alpha=0.3)
    axes[0].set_title(f"makeup face, 3 maps, {size}² texture, σ {noise}")
    tm = true_maps(truth)["blush"]
    top = tm.max()
    panels = [("blush truth (mm)", tm), *[(f"blush, {s} (mm)", np.asarray(
        r.params["layer.blush.map"]) * float(r.params["layer.blush.thickness_mm"]))
        for s, (r, _) in runs.items()]]
    for ax, (title, m) in zip(axes[2:4], panels[:2], strict=True):
        im = ax.imshow(np.where(mask, m, np.nan), vmin=0, vmax=top, cmap="viridis")
        ax.set_title(title)
        ax.set_axis_off()
        fig.colorbar(im, ax=ax, shrink=0.8)
    b = np.where(mask & (tm > 0), np.log10(bounds["blush"]), np.nan)
    im = axes[4].imshow(b, cmap="magma_r")
    axes[4].set_title("blush: log10 Cramér–Rao bound\n(relative; −1.6 = 2.5 %)")
    axes[4].set_axis_off()
    fig.colorbar(im, ax=axes[4], shrink=0.8)
    axes[3].set_title(panels[1][0])
    fig.savefig(out, dpi=80)
    print(f"wrote {out}")


def speed(size=512, steps=4, solvers=("gn", "adam"), names=MAPS):
    """Seconds per step of each solver on the makeup face at `size`² (texture and image,
    supersample 2, SSS, shadows, the three maps), from the progress callback's clock: the
    first step includes compilation, the others are printed as they are."""
    ov = [f"texture.size={size}", f"camera.size={size}"]
    truth = load_scene("makeup", ov)
    target = np.asarray(render.render(truth.config, truth.params))
    start = without_regions(load_scene("makeup", ov + [
        f"layer.{n}.thickness_mm={truth.values[f'layer.{n}.thickness_mm'] / START}"
        for n in names]), names)  # as in `maps`
    w = fi.weights(start.config, start.params)
    keys = fi.fit_keys(start, ",".join(f"layer.{n}.map" for n in names))
    t = time.perf_counter()
    jax.block_until_ready(render.render(start.config, start.params))
    t0 = time.perf_counter()
    jax.block_until_ready(render.render(start.config, start.params))
    print(f"{size}²: prepare + first render {t0 - t:.1f} s, "
          f"forward {time.perf_counter() - t0:.2f} s")
    for solver in solvers:
        stamps = [time.perf_counter()]
        r = fi.fit(start.config, start.params, target, w, keys, steps=steps, solver=solver,
                   progress=lambda _loss, s=stamps: s.append(time.perf_counter()))
        d = np.diff(stamps)
        print(f"{solver}: {r.steps} steps, first (with compile) {d[0]:.1f} s, then "
              + ", ".join(f"{x:.1f}" for x in d[1:]) + f" s, total {d.sum():.0f} s; loss "
              + " ".join(f"{h:.3e}" for h in r.history))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("what", choices=("maps", "ambiguity", "speed", "figure"))
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--solvers", default="adam")
    p.add_argument("--smooth", type=float, default=1e-5)
    p.add_argument("--rate", type=float, default=fi.ADAM_RATE)
    p.add_argument("--maps", default=",".join(MAPS))
    p.add_argument("--noise", type=float, default=0.01)
    p.add_argument("--image", type=int, default=0,
                   help="maps: the camera's size in pixels (default 2 × --size)")
    p.add_argument("-D", dest="extra", action="append", default=[],
                   help="maps: a scene override KEY=VALUE (repeatable), e.g. "
                        "-D layer.lipstick.thickness_mm=0.003")
    a = p.parse_args()
    if a.what == "ambiguity":
        ambiguity()
    if a.what == "figure":
        figure()
    if a.what == "speed":
        speed(a.size, a.steps, a.solvers.split(","))
    if a.what == "maps":
        maps(a.size, a.steps, a.solvers.split(","), a.smooth, a.rate,
             noise=a.noise, names=tuple(a.maps.split(",")), image=a.image or None,
             extra=tuple(a.extra))


if __name__ == "__main__":
    main()
