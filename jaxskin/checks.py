"""The checks a scene passes before any render, shared by `jaxskin render`, `jaxskin
fit-image` and the editor: memory, mesh, edits, BRDF, materials, images, polygons. Each
failure is an `InputError` naming the file or key and what was expected."""

from __future__ import annotations

import contextlib

import numpy as np

from .io import InputError

__all__ = ["BODY_MM", "check_scene", "reading", "size_warning"]


@contextlib.contextmanager
def reading(path, key=None):
    """A file nested too deeply for Python's parsers is bad input, not a crash."""
    try:
        yield
    except RecursionError:
        raise InputError("nested too deeply to read", path, key=key) from None


def check_scene(sc, count: int, overrides=()) -> list:
    """Everything a `scene.Scene` reads, checked before any render of `count` images at
    once: memory first (no allocation), then the mesh, edits, polygons, BRDF file,
    materials and images (`maps.read_grey`, the reader the render uses). Returns the
    scene's input files. An error about a key that one of the `-D` `overrides` set names
    that item, not the scene file (which may not mention the key at all)."""
    from .scene import parse_override

    try:
        return _check_scene(sc, count)
    except InputError as e:
        keys = [parse_override(o)[0] for o in overrides]
        if "mesh.file" in keys and str(e.key).startswith("fields.edit"):
            raise InputError(f"{e.message} (the scene's [[fields.edit]] were made for its own "
                             "mesh, not the one -D mesh.file gives: write a scene file with "
                             "edits for that mesh, or none)", e.path, e.line, e.column,
                             e.key) from None
        item = next((o for o, k in reversed(list(zip(overrides, keys, strict=True)))
                     if e.key is not None and k == e.key), None)  # the last: the one used
        if item is None:
            raise
        raise InputError(e.message, f"-D {item}", key=e.key) from None


# What a mesh of a body or a part of one measures across (its bounding box's longest side):
# a lip or an eyelid patch 20 mm and more, a whole body under 2.5 m. Outside, `mesh.unit_mm`
# is most likely wrong (a scan in metres read as millimetres), and the subsurface scattering,
# whose profile is in mm (0.08–2.7 mm, `jaxskin.sss`), is off by as much.
BODY_MM = (20.0, 2500.0)
UNITS = {"metres": 1000.0, "centimetres": 10.0, "millimetres": 1.0, "inches": 25.4}


def size_warning(name: str, extent: float, unit_mm: float) -> str | None:
    """A warning line when a mesh `extent` mesh units across is no body's size at
    `mesh.unit_mm = unit_mm`, naming the unit that makes it one (the closest to a head's
    250 mm); None when it is one (`BODY_MM`)."""
    across = unit_mm * float(extent)
    lo, hi = BODY_MM
    if lo <= across <= hi or not across > 0:
        return None
    fits = {unit: mm for unit, mm in UNITS.items() if lo <= mm * extent <= hi}
    line = (f"mesh.unit_mm = {unit_mm:g}: {name} is {across:.3g} mm across, no body's or "
            f"body part's size ({lo:g}-{hi:g} mm); the skin's subsurface scattering is "
            "computed in mm from it")
    if not fits:
        return line + "; set mesh.unit_mm to the millimetres one mesh unit is"
    unit = min(fits, key=lambda u: abs(np.log(fits[u] * extent / 250.0)))
    return (line + f". In {unit}? mesh.unit_mm = {fits[unit]:g} makes it "
            f"{fits[unit] * extent:.3g} mm")


def _check_scene(sc, count: int) -> list:
    from . import cosmetics, maps, resources
    from .mesh import BUILTIN as MESHES
    from .mesh import load_mesh, missing_uv
    from .scene import SKIN_MAPS

    config = sc.config
    resources.check_memory(resources.render_bytes(config, count),
                           f"scene {sc.name!r} (texture {config.texture.size}², image "
                           f"{config.image}x{config.image_height or config.image}, "
                           f"supersample {config.supersample}"
                           + (f", {count} sweep values" if count > 1 else "") + ")",
                           sc.source)
    inputs = [sc.source]
    mesh_name = config.texture.mesh
    with reading(mesh_name):
        mesh = load_mesh(mesh_name)
    if mesh_name not in MESHES:
        inputs.append(mesh_name)
    if config.texture.projection == "uv" and mesh.uv is None:
        raise InputError(missing_uv(mesh_name), sc.source, key="mesh.projection")
    sp = config.spectral
    if sp is not None and sp.sss is not None and not sp.texel_mm:  # mm from the mesh
        line = size_warning(mesh_name, np.ptp(mesh.vertices, axis=0).max(), sp.unit_mm)
        if line is not None:
            import warnings
            warnings.warn(line, stacklevel=2)
    for i, e in enumerate(config.texture.edits):
        if e.vertex is not None and e.vertex >= len(mesh.vertices):
            raise InputError(f"vertex {e.vertex} does not exist; the mesh has "
                             f"{len(mesh.vertices)} vertices", sc.source,
                             key=f"fields.edit[{i}].vertex")
    if config.texture.edits:
        _check_edits(sc, config)
    if config.material == "lafortune":
        if config.brdf != "skin":
            inputs.append(config.brdf)
        with reading(config.brdf, "material.brdf"):
            lobes = sc.params["material.lafortune"]
        arrays = [np.asarray(a) for a in (lobes.diffuse, lobes.Cxy, lobes.Cz)]
        if not any(np.any(a != 0) for a in arrays):
            raise InputError("every term is zero (diffuse and all lobes): this material "
                             "reflects no light; expected a fit from jaxskin fit-brdf",
                             config.brdf)
    for map_key, (_, image_key) in SKIN_MAPS.items():
        image = sp.image_of(map_key) if sp is not None else None
        if image is not None:
            inputs.append(image)
            _square(maps.read_grey(image, key=image_key), image, image_key)
        elif sc.values.get(image_key):  # set, but this model reads no such map (`idle_maps`)
            inputs.append(sc.values[image_key])  # still an input: never overwritten
    if sp is not None and sp.texture is not None:  # skin.texture: a colour texture
        import warnings

        from .skin_texture import read_texture

        inputs.append(sp.texture)
        for line in read_texture(sp.texture, key="skin.texture", size=config.texture.size,
                                 square=True)[2]:
            warnings.warn(line, stacklevel=2)
    for image in (sp.colour_image, sp.mask_image) if sp is not None else ():
        if image is not None:  # skin.colour_image, skin.mask_image: read by `render.prepare`
            inputs.append(image)
            with reading(image):
                maps.read_image(image)
    for layer in sp.layers if sp is not None else ():
        inputs.append(layer.material)
        with reading(layer.material):
            cosmetics.load_material(layer.material, sp.grid)
        if layer.image is not None:
            inputs.append(layer.image)
            key = f"layer.{layer.name}.image"
            _square(maps.read_grey(layer.image, key=key), layer.image, key)
        for i, (_, vertices, _) in enumerate(layer.polygons):
            if vertices is not None and max(vertices) >= len(mesh.vertices):
                raise InputError(f"vertex {max(vertices)} does not exist; the mesh has "
                                 f"{len(mesh.vertices)} vertices", sc.source,
                                 key=f"layer.{layer.name}.polygon[{i}].vertices")
    return inputs


def picture_warnings(sc, side: list[str] | None = None) -> list[str]:
    """What `jaxskin render` and the editor's footer warn about a scene's picture: maps that
    change nothing (`idle_maps`), a view from the side of a planar map (`hidden_side`, or
    `side` where the caller has it already), layers thick as masks (`thick_layers`)."""
    return idle_maps(sc) + (hidden_side(sc) if side is None else side) + thick_layers(sc)


def idle_map_keys(sc) -> set[str]:
    """The image keys `idle_maps` warns about."""
    return {key for key, _ in _idle_maps(sc)}


def idle_maps(sc) -> list[str]:
    """`_idle_maps`' warnings."""
    return [line for _, line in _idle_maps(sc)]


def _listed(names) -> str:
    """`a`, `a and b`, `a, b and c`."""
    return " and ".join([", ".join(names[:-1]), names[-1]] if len(names) > 2 else names)


def _idle_maps(sc) -> list[tuple[str, str]]:
    """`(image key, warning)` for skin maps that change nothing in scene `sc`: one its
    material model does not read (`skin.melanin_image` in a Blinn scene), or a
    `skin.*_image` that scales its scalar (`skin.melanin_image` × `skin.melanin`, ...), so
    with that scalar at 0 (the default of `skin.melanin`) the map is read and multiplied by
    0: the render is the same to the byte, and nothing said so."""
    from .scene import SKIN_MAPS, SKIN_MAPS_READ

    out = []
    sp = sc.config.spectral
    model = sc.values["material.model"]
    for map_key, (scalar, image) in SKIN_MAPS.items():
        if sc.values.get(image) and (sp is None or sp.image_of(map_key) is None):
            reads = [] if sp is None else [SKIN_MAPS[m][1] for m in SKIN_MAPS_READ[sp.skin]]
            out.append((image, f"{image} changes nothing in scene {sc.name!r}: its material model "
                       f"({model}{'' if sp is None else f', {sp.skin} skin'}) reads "
                       + (f"{_listed(reads)} instead" if reads else "no skin map")))
        elif sc.values.get(image) and scalar in sc.params and float(sc.values[scalar]) == 0.0:
            out.append((image, f"{image} scales {scalar}, which is 0 in scene {sc.name!r}: "
                        f"the map changes nothing (set {scalar} above 0, e.g. to 1)"))
    for key in ("skin.texture", "skin.colour_image", "skin.mask_image"):
        if sc.values.get(key) and (sp is None or sp.skin != "biophysical"):
            out.append((key, f"{key} changes nothing in scene {sc.name!r}: only the "
                        "biophysical skin reads it (material.model = \"biophysical\")"))
    return out


# A cosmetic layer thicker than this (mm) gets a warning: films are µm to a tenth of a mm.
THICK_LAYER_MM = 1.0


_SAID_STRETCHED: set[str] = set()


def _square(grey, path, key) -> None:
    """Warn (once a file) when a texture-space map is not square: it is stretched over the
    square texture, its aspect ratio lost, which nothing else would say."""
    h, w = grey.shape
    if abs(w - h) > 0.01 * max(w, h) and str(path) not in _SAID_STRETCHED:
        import warnings

        _SAID_STRETCHED.add(str(path))
        warnings.warn(f"{key} = {path}: {w}x{h} pixels, stretched over the square texture "
                      "(its aspect ratio is not kept): texture-space maps are square; pad or "
                      "crop it to a square", stacklevel=2)


def thick_layers(sc) -> list[str]:
    """Warnings for cosmetic layers of scene `sc` thicker than `THICK_LAYER_MM`: 10 meant as
    10 µm is accepted (the key allows up to 10 mm) and renders an opaque mask of the
    product's colour."""
    out = []
    for layer in sc.layers:
        key = f"layer.{layer.name}.thickness_mm"
        x = float(sc.values.get(key, 0.0))
        if x > THICK_LAYER_MM:
            out.append(f"{key} = {x:g} mm: cosmetic films are 0.1 µm to 1 mm thick (10 µm is "
                       "0.01 mm); at this thickness most products are opaque")
    return out


# An edit's `at` further than this share of the mesh's bounding-box diagonal from every
# vertex is refused (the built-in scenes' furthest: 0.15, the foot's instep); a direction
# whose part in texture space is under this share of it is refused (it points across the
# surface, or the planar projection's x-y plane: the texture sees almost nothing of it).
EDIT_FAR, EDIT_ALONG_NORMAL = 0.25, 0.2


def _check_edits(sc, config) -> None:
    """Field edits that cannot mean what they say: `at` far from the mesh (it snapped to
    whatever vertex was nearest), a direction along the surface normal (the furrows took
    an arbitrary direction), which would otherwise be accepted in silence."""
    import numpy as np

    from . import texture

    mesh, tmap = texture.mapped(config.texture.mesh, config.texture.projection,
                                config.texture.size)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    for i, e in enumerate(config.texture.edits):
        v = e.vertex
        if v is None:
            distance = np.linalg.norm(mesh.vertices - np.asarray(e.at), axis=1)
            v = int(np.argmin(distance))
            if distance[v] > EDIT_FAR * diagonal:
                spans = ", ".join(f"{c} {a:.3g}..{b:.3g}" for c, a, b in zip("xyz", lo, hi,
                                                                            strict=True))
                raise InputError(f"the point is {distance[v]:.3g} from the mesh (its nearest "
                                 f"vertex, {v}, is at {_vec(mesh.vertices[v])}); the mesh "
                                 f"spans {spans}", sc.source, key=f"fields.edit[{i}].at")
        n = mesh.normals[v]
        for name, d in (("d1", e.d1), ("d2", e.d2)):
            d = np.asarray(d, np.float64)
            size = float(np.linalg.norm(d))
            if tmap.keep_magnitude:  # uv: the map keeps |d|; what counts is the tangent part
                seen = float(np.linalg.norm(d - np.dot(d, n) * n))
            else:  # planar, cylindrical: what the texture keeps of it
                at_v = np.zeros_like(mesh.vertices)
                at_v[v] = d
                seen = float(np.linalg.norm(tmap.vectors(at_v)[v]))
            if size > 0 and seen < EDIT_ALONG_NORMAL * size:
                plane = {"planar": "the x-y plane the planar projection keeps",
                         "cylindrical": "the cylinder's surface"}.get(tmap.kind, "the surface")
                raise InputError(f"{_vec(d)} at vertex {v} is almost perpendicular to "
                                 f"{plane} (only {seen / size:.0%} of it lies along it): "
                                 "the furrows would take an arbitrary direction; give a "
                                 "direction along it", sc.source,
                                 key=f"fields.edit[{i}].{name}")


def _vec(a) -> str:
    return "[" + ", ".join(f"{x:.3g}" for x in a) + "]"


# A view more than this share of whose samples show the other side's texels is warned (the
# hand turned 60° about y: 18 %, streaks along the fingers; 30°: 4.5 %).
HIDDEN_SIDE_WARN = 0.1
# A view whose mesh is more than this share its inside (drawn black) gets a warning.
INSIDE_WARN = 0.5


def _small_view(sc):
    """`(texture map, view)` of scene `sc`'s camera at 64 pixels across."""
    from . import texture
    from .view import make_view

    config = sc.config
    tmap = texture.mapped(config.texture.mesh, config.texture.projection,
                          config.texture.size)[1]
    height = max(1, round(64 * config.image_height / config.image)) if config.image_height \
        else 0
    return tmap, make_view(tmap, 64, config.camera, 1, config.fov, config.rotate, height,
                           config.zoom, config.center)


def empty_picture(sc) -> str:
    """Why a picture of scene `sc` is black at every pixel: the mesh is out of view, or the
    camera sees only its inside (measured on a 64-pixel view)."""
    if _small_view(sc)[1].mask.any():
        return ("every pixel is black: the camera sees the mesh's inside only (an open mesh "
                "from behind), drawn black; turn camera.rotate toward its front")
    return ("the mesh is not in view (every pixel is background); check camera.zoom and "
            "camera.center")


def hidden_side(sc) -> list[str]:
    """Warnings about what scene `sc`'s camera sees, measured on a 64-pixel view of it:

    - much of the side of a planar map that does not own its texels
      (`view.hidden_side_share`): a view from the side (the foot turned 70°), where the
      texels the two sides share go to the side the camera faces more, and the rest shows
      them lit wrongly (a side the camera faces fully gets its own: `scene.planar_side`);
    - mostly the inside of an open mesh (the face from behind), which is drawn black: a
      black picture needs this reason, not a warning that the mesh is not in view."""
    from .view import hidden_side_share

    config = sc.config
    tmap, view = _small_view(sc)
    out = []
    seen = int(view.mask.sum())
    inside = 1.0 - int(view.shaded.sum()) / seen if seen else 0.0
    if inside > INSIDE_WARN:
        out.append(f"scene {sc.name!r}: {inside:.0%} of the mesh in view is its inside (an "
                   "open mesh seen from behind or through an opening), which is drawn black; "
                   "turn camera.rotate toward the mesh's front")
    if config.texture.projection not in ("planar", "planar-back"):
        return out
    share = hidden_side_share(tmap, view)
    if share <= HIDDEN_SIDE_WARN:
        return out
    return out + [
        f"scene {sc.name!r}: {share:.0%} of the view is a side of the mesh that the "
        "planar projection shades with the other side's texels (their normals, their "
        "light): seen from the side, the two sides' texels interleave; view it more "
        "nearly face on, or use mesh.projection = \"cylindrical\""]


def unused_overrides(sc, overrides) -> list[str]:
    """The `-D` items of `overrides` that change nothing in scene `sc` (loaded with them):
    a value the scene's material model does not use (`skin.subject` on the Blinn hand,
    `material.melanin` on the spectral face). An item is unused when the scene loaded
    without it has the same configuration and parameters although its value differs (a
    static value the configuration keeps though no stage reads it, such as
    `wrinkles.k_scale` with wrinkles off, is not found). For a warning: `-D` applies to every scene
    of a command, so a key one scene does not use may serve another."""
    import numpy as np

    from .scene import load_scene, parse_override

    def same(a, b) -> bool:
        import jax

        la, ta = jax.tree.flatten(a)
        lb, tb = jax.tree.flatten(b)
        return ta == tb and all(np.array_equal(np.asarray(x), np.asarray(y))
                                for x, y in zip(la, lb, strict=True))

    out = []
    for item in overrides:
        key, _ = parse_override(item)
        if key == "name":  # names the outputs only
            continue
        rest = [o for o in overrides if parse_override(o)[0] != key]
        try:
            without = load_scene(sc.source, rest, flag="-D")
        except InputError:
            continue
        if without.values.get(key) == sc.values.get(key):
            continue  # the scene's own value: nothing asked to change
        if without.values.get(key) == "auto":  # the choice "auto" makes here: it is used
            continue  # (wrinkles.method=sequential on a CPU is not "not used")
        if without.config == sc.config and same(without.params, sc.params):
            out.append(item)
    return out


def read_instead(sc, item: str, overrides=()) -> str | None:
    """For a `-D` item that changes nothing in scene `sc` (`unused_overrides`), a key of the
    same last name that the scene does read, or `None`: `material.melanin` for
    `skin.melanin=0.3` on the Blinn hand (the two sections are the two skin models). Found
    by trying the value under each such key, with the command's other `overrides`
    (`-D material.model=lafortune` reads neither)."""
    from .scene import load_scene, parse_override

    key, value = parse_override(item)
    leaf = key.rsplit(".", 1)[-1]
    for other in sorted(k for k in sc.values if k != key and k.rsplit(".", 1)[-1] == leaf):
        rest = [o for o in overrides if parse_override(o)[0] not in (key, other)]
        trial = f"{other}={value}"
        try:
            changed = load_scene(sc.source, [*rest, trial], flag="-D")
        except InputError:
            continue
        if trial not in unused_overrides(changed, [*rest, trial]):
            return other
    return None
