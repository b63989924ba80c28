"""The session's renders: the view as `jaxskin render` makes it, a preview while dragging.

Rendering calls the renderer the CLI calls (`render.render_prepared` with the arrays of
`render.prepare`), with three things that only change arrays, never the traced program:

- a field edit changes the furrows: `texture.furrows` of the new configuration replaces
  `h0` (the view and every other array are the configuration's without the edit);
- a painted layer's thickness map replaces its row of `cover`, exactly as `prepare` would
  read it back from the 16-bit PNG that Save writes;
- the jit cache key (the static configuration) is the first configuration seen that
  differs only in those (edits, layer materials and maps, the shadow's direction), so none
  of them retraces; `render` of the saved scene compiles the same program and gives the
  same bytes (tests/test_editor.py).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .. import maps, render, samples, texture
from ..scene import LayerSpec, SceneConfig

__all__ = ["Rendering"]

# The spectral grid of a preview (nm) where the scene's is finer: the KM layers' work is
# per band, so 20 nm halves it against the makeup scene's 10 nm, for 0.3-0.5 ΔE2000 at the
# 99th percentile (benchmarks/RESULTS.md, makeup; 1 is a just-noticeable difference). The
# final render (release, Save) keeps the scene's grid.
PREVIEW_STEP = 20


class Rendering:
    """The `Session`'s renders (its `render`, `png`, `image_file` and `arrays`)."""

    def _key(self, config: SceneConfig) -> SceneConfig:
        """The configuration to compile `config` as: the first seen that differs only in
        what `arrays` passes in (edits, layer materials and maps, the shadow's direction,
        the camera's turn, zoom, centre and field of view): a turn or a zoom renders in the
        program compiled already (0.5 s a new one on the 64² hand, and a few memory
        mappings each, which a long session would run out of)."""
        sig = dataclasses.replace(
            config, texture=dataclasses.replace(config.texture, edits=()),
            shadow=None if config.shadow is None else (0.0, 0.0, 1.0),
            rotate=(0.0, 0.0, 0.0), zoom=1.0, center=(0.0, 0.0), fov=0.0)
        if config.spectral is not None:
            sig = dataclasses.replace(sig, spectral=dataclasses.replace(
                config.spectral, layers=tuple(LayerSpec(s.name, "", None)
                                              for s in config.spectral.layers)))
        return self._keys.setdefault(sig, config)

    def arrays(self, config: SceneConfig) -> dict:
        """`render.prepare(config).arrays`, computed for the configuration without its
        field edits where one with them is at hand, the edits' furrows and painted maps put
        in."""
        prepared = render.prepare(self._prepared_config(config))
        # Without the view's transpose table (reverse mode only; the editor takes no
        # gradients): its row count changes with every turn or zoom, and so would the
        # arrays' shapes and the compiled program.
        arrays = {k: v for k, v in prepared.arrays.items()
                  if k not in render.VIEWS and k not in render.CORNERS}
        if "list_tex" in arrays:  # Blinn, Lafortune: every sample listed, so that a turn
            arrays.update(self._full_list(prepared, config.supersample))  # keeps the shapes
        if config.needs_furrows:
            arrays["h0"] = texture.furrows(config.texture)[0]
        if self.paint and config.spectral is not None:
            arrays["cover"] = self._cover(config, arrays)
        return arrays

    def _full_list(self, prepared, k: int) -> dict:
        """`samples.sample_list` of the prepared view as long as the view has samples: the
        render's list is as long as the samples on the mesh (rounded up), which a turn or
        a zoom changes, and with it the compiled program."""
        import jax.numpy as jnp

        cached = getattr(self, "_list_cache", None)
        if cached is None or cached[0] is not prepared:
            view = prepared.view
            full = samples.sample_list(view.tex, view.shaded, k, length=view.shaded.size)
            full["list_corners"] = samples.list_corners(
                full["list_tex"], full["list_on"], np.asarray(prepared.arrays["pad"]),
                prepared.arrays["mask"].shape, view.wrap_x)
            full.update(render.corner_arrays(prepared.setup, prepared.arrays,
                                             full["list_corners"]))
            self._list_cache = cached = (prepared, {n: jnp.asarray(v) for n, v in full.items()})
        return cached[1]

    def _prepared_config(self, config: SceneConfig) -> SceneConfig:
        """A configuration equal to `config` but for what `arrays` puts in (field edits,
        painted layers' maps) whose preparation is cached already (else `config`): an edit
        then costs a furrow run and a stroke nothing, not a new view, shadow map or blur."""
        def normal(c: SceneConfig) -> SceneConfig:
            c = dataclasses.replace(c, texture=dataclasses.replace(c.texture, edits=()))
            if c.spectral is None or not self.paint:
                return c
            return dataclasses.replace(c, spectral=dataclasses.replace(c.spectral, layers=tuple(
                LayerSpec(s.name, s.material, None) if s.name in self.paint else s
                for s in c.spectral.layers)))

        for other in self._prepared:
            if normal(other) == normal(config):
                return other
        self._prepared = [config, *self._prepared[:5]]
        return config

    def _cover(self, config: SceneConfig, arrays: dict):
        import jax.numpy as jnp

        names = [s.name for s in config.spectral.layers]
        key = (id(arrays["cover"]), tuple((n, id(self.paint.get(n))) for n in names))
        if self._cover_cache is not None and self._cover_cache[0] == key:
            return self._cover_cache[1]
        texels = np.asarray(arrays["texels"])
        cover = np.array(arrays["cover"])
        for i, name in enumerate(names):
            if name in self.paint:  # as maps.read_grey reads the saved 16-bit PNG
                q = self.paint[name]
                cover[i] = np.clip(q.astype(np.float64) / 65535.0, 0.0, 1.0).reshape(-1)[
                    texels].astype(np.float32)
        out = jnp.asarray(cover, jnp.float32)
        self._cover_cache = (key, out)
        return out

    def render(self, preview: bool = False) -> np.ndarray:
        """The view `(H, W, 3)` display values, as `jaxskin render` makes it (`preview`:
        one sample per pixel and the cosmetics model's spectra at `PREVIEW_STEP` nm at the
        finest, for drags)."""
        config = self.scene.config
        if preview and config.supersample > 1:
            config = dataclasses.replace(config, supersample=1)
        if preview and config.spectral is not None and config.spectral.step < PREVIEW_STEP:
            config = dataclasses.replace(config, spectral=dataclasses.replace(
                config.spectral, step=PREVIEW_STEP))
        t0 = time.perf_counter()
        arrays = self.arrays(config)
        image = render.render_prepared(self._key(config), self.scene.params, arrays)
        image = np.asarray(image)
        self.timings["render_s"] = time.perf_counter() - t0
        return image

    def png(self, preview: bool = False) -> bytes:
        """The view as the PNG `jaxskin render` writes (8-bit)."""
        return maps.image_bytes(self.render(preview))

    def image_file(self, preview: bool = False) -> tuple[bytes, str]:
        """The view as the page gets it, `(bytes, MIME type)`: the PNG `jaxskin render`
        writes; a preview as an uncompressed BMP of the same 8-bit samples (2 ms to encode
        at 512², where the PNG takes 30-60 ms on this CPU)."""
        if not preview:
            return self.png(), "image/png"
        import imageio.v3 as iio

        image = maps.quantize(self.render(preview))
        return iio.imwrite("<bytes>", image, extension=".bmp"), "image/bmp"
