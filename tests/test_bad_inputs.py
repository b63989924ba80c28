"""The adversarial table: bad scenes, overrides, sweeps, meshes, layer images, polygons,
materials, BRDF files, output paths and command lines.

Each case builds its inputs in a fresh folder and runs `jaxskin` (in-process through
`cli.main`; a few as real subprocesses) and asserts: exit code 2, exactly one line on stderr
starting `jaxskin: error:`, no traceback, nothing written anywhere in the folder (the
output folder included, and no file outside it), every input file byte for byte unchanged.
The CSV readers' cases are in tests/test_measurements.py and tests/test_calibrate.py.
"""

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from jaxskin.cli import main

ROOT = Path(__file__).resolve().parent.parent
SMALL = ["-D", "texture.size=64", "-D", "camera.size=32"]
LAYERED = """name = "m"
[mesh]
file = "face"
projection = "uv"
unit_mm = 10.0
[material]
model = "spectral"
[[layer]]
name = "blush"
material = "{material}"
{region}
"""


def write(tmp, name, content):
    path = tmp / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return str(path)


def _link(path, target):
    os.symlink(target, path)
    return str(path)


def _folder_at(path):
    path.mkdir(parents=True)
    return str(path.parent)


def scene(tmp, text, *extra):
    return ["render", write(tmp, "s.toml", text), "-o", str(tmp / "out"), *SMALL, *extra]


def mesh_scene(tmp, obj):
    write(tmp, "m.obj", obj)
    return scene(tmp, '[mesh]\nfile = "m.obj"\n')


def layered(tmp, material="blush_rose", region="", *extra):
    return scene(tmp, LAYERED.format(material=material, region=region), *extra)


def material(tmp, doc):
    write(tmp, "mat.json", doc if isinstance(doc, str) else json.dumps(doc))
    return layered(tmp, "mat.json")


def good_material():
    return json.loads((ROOT / "data" / "materials" / "blush_rose.json").read_text())


def image(tmp, content=None, array=None, name="map.png"):
    import imageio.v3 as iio

    if array is not None:
        iio.imwrite(tmp / name, array)
    elif content is not None:
        write(tmp, name, content)
    return layered(tmp, region='image = "map.png"')


def polygon(tmp, body):
    return layered(tmp, region=f"[[layer.polygon]]\n{body}\n")


def brdf(tmp, doc):
    write(tmp, "b.json", doc if isinstance(doc, str) else json.dumps(doc))
    return scene(tmp, '[material]\nmodel = "lafortune"\nbrdf = "b.json"\n')


LOBE = {"Cxy": [-1.0, -1.0, -1.0], "Cz": [0.8, 0.7, 0.6], "n": [20.0, 20.0, 20.0]}


def _big_box(tmp):
    import trimesh

    trimesh.creation.box(extents=(20, 20, 20)).export(tmp / "box.obj")
    return str(tmp / "box.obj")


def hand(tmp, *extra):
    return ["render", "hand", "-o", str(tmp / "out"), *SMALL, *extra]


def brdf_csv(tmp):
    return write(tmp, "samples.csv", (ROOT / "data" / "brdf" / "skin_samples.csv").read_text())


def few_brdf_samples(tmp):
    lines = (ROOT / "data" / "brdf" / "skin_samples.csv").read_text().splitlines()
    return write(tmp, "few.csv", "\n".join(lines[:4]) + "\n")


def measurement(tmp):
    return write(tmp, "blush.csv",
                 (ROOT / "data" / "measurements" / "blush_rose.csv").read_text())


def brdf_rows(tmp, rows):
    """A BRDF samples CSV of `rows` (theta_in, phi_in, theta_out, phi_out), each R = G = B =
    0.1 plus a little that differs from row to row."""
    lines = ["theta_in_deg,phi_in_deg,theta_out_deg,phi_out_deg,R,G,B"]
    lines += [f"{a},{b},{c},{d},{0.1 + 1e-3 * i},{0.1},{0.1}"
              for i, (a, b, c, d) in enumerate(rows)]
    return write(tmp, "pairs.csv", "\n".join(lines) + "\n")


def fifo(tmp, name):
    """A named pipe: opening it blocks until a writer comes (the commands hung on one)."""
    os.mkfifo(tmp / name)
    return str(tmp / name)


def lab_image(tmp):
    """A layer map saved as a CIELAB TIFF: its channels are L, a, b, not R, G, B."""
    from PIL import Image

    Image.new("LAB", (8, 8), (50, 128, 128)).save(tmp / "map.png", format="TIFF")
    return layered(tmp, region='image = "map.png"')


def read_only_folder(tmp):
    if os.geteuid() == 0:
        pytest.skip("root writes into a read-only folder; out-unwritable covers it (/proc)")
    (tmp / "ro").mkdir()
    os.chmod(tmp / "ro", 0o555)
    return ["render", "hand", "-o", str(tmp / "ro" / "out"), *SMALL]


def symlinked_output(tmp):
    """out/m.png is a link to the scene's own layer map: writing it would overwrite an input."""
    import imageio.v3 as iio

    iio.imwrite(tmp / "map.png", np.full((8, 8), 128, np.uint8))
    (tmp / "out").mkdir()
    os.symlink(tmp / "map.png", tmp / "out" / "m.png")
    return ["render", write(tmp, "s.toml", LAYERED.format(material="blush_rose",
                                                         region='image = "map.png"')),
            "-o", str(tmp / "out")]


def output_is_input(tmp):
    """A scene named like its own layer map, rendered into its own folder (the issue's case)."""
    import imageio.v3 as iio

    iio.imwrite(tmp / "m.png", np.full((8, 8), 128, np.uint8))
    return ["render", write(tmp, "s.toml", LAYERED.format(material="blush_rose",
                                                         region='image = "m.png"')),
            "-o", str(tmp)]


CASES = {
    # --- TOML scenes
    "toml-syntax": lambda t: scene(t, "name = \n"),
    # `./hand` is a path: the message must not name it `hand` beside "built-in scenes: hand"
    "scene-dot-slash-builtin": lambda t: ["render", "./hand", "-o", str(t / "out"), *SMALL],
    # the hand's own field edits on another mesh: the edit's message, and what to do
    "D-mesh-with-the-scenes-edits": lambda t: hand(t, "-D", f"mesh.file={_big_box(t)}"),
    "toml-unknown-key": lambda t: scene(t, "[wrinkles]\nk_scal = 1.0\n"),
    "toml-out-of-range": lambda t: scene(t, "[material]\nmelanin = 5.0\n"),
    "toml-wrong-type": lambda t: scene(t, '[texture]\nsize = "big"\n'),
    "toml-nan": lambda t: scene(t, "[light]\nambient = nan\n"),
    "toml-inf": lambda t: scene(t, "[light]\nintensity = inf\n"),
    "toml-huge-number": lambda t: scene(t, "[material]\nshininess = 1e308\n"),
    "toml-nested-arrays": lambda t: scene(t, "x = " + "[" * 3000 + "]" * 3000 + "\n"),
    "toml-nested-tables": lambda t: scene(t, ".".join(["a"] * 3000) + " = 1\n"),
    "toml-not-utf8": lambda t: scene(t, b"\xff\xfe\x00garbage\x80\x81"),
    "toml-utf16": lambda t: scene(t, 'name = "x"\n'.encode("utf-16")),
    "toml-binary": lambda t: scene(t, b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\xff"),
    "toml-zero-light": lambda t: scene(t, "[light]\ndirection = [0.0, 0.0, 0.0]\n"),
    # fine in float64, zero or infinite in the render's float32: exit 2, not 1
    "toml-light-subnormal": lambda t: scene(t, "[light]\ndirection = [0.0, 0.0, 1e-320]\n"),
    "toml-light-squares-underflow": lambda t: scene(t, "[light]\ndirection = [1e-30, 0, 0]\n"),
    "D-light-float32-overflow": lambda t: hand(t, "-D", "light.direction=[1e200,0,1]"),
    "toml-edit-vertex-missing": lambda t: scene(
        t, "[[fields.edit]]\nvertex = 999999\nd1 = [1.0, 0.0, 0.0]\nd2 = [0.0, 1.0, 0.0]\n"),
    "toml-edit-too-long": lambda t: scene(
        t, "[[fields.edit]]\nvertex = 1\nd1 = [3.0, 0.0, 0.0]\nd2 = [0.0, 1.0, 0.0]\n"),
    "toml-layer-without-spectral": lambda t: scene(
        t, '[[layer]]\nname = "a"\nmaterial = "blush_rose"\n'),
    "toml-uv-without-uvs": lambda t: scene(t, '[mesh]\nprojection = "uv"\n'),
    "toml-missing-file": lambda t: ["render", str(t / "nope.toml"), "-o", str(t / "out")],
    "toml-edit-single-brackets": lambda t: scene(
        t, "[fields.edit]\nvertex = 1\nd1 = [1.0, 0.0, 0.0]\nd2 = [0.0, 1.0, 0.0]\n"),
    "scene-is-a-folder": lambda t: ["render", str(t), "-o", str(t / "out")],
    "name-parent": lambda t: scene(t, 'name = "../x"\n'),
    "name-absolute": lambda t: scene(t, f'name = "{t / "abs"}"\n'),
    "name-newline": lambda t: scene(t, 'name = "a\\nb"\n'),
    "name-nul": lambda t: scene(t, 'name = "a\\u0000b"\n'),
    "name-leading-dot": lambda t: scene(t, 'name = ".hidden"\n'),
    "name-empty": lambda t: scene(t, 'name = ""\n'),
    # a blank name would write " _texture.size-64_camera.size-32.png"
    "name-blank": lambda t: scene(t, 'name = " "\n'),
    "name-trailing-space": lambda t: scene(t, 'name = "hand "\n'),
    # a right-to-left override disguises the file's name, a line separator breaks the
    # listing, U+009B (a terminal's escape) would be echoed raw
    "name-bidi-override": lambda t: scene(t, 'name = "x\\u202eyz"\n'),
    "name-line-separator": lambda t: scene(t, 'name = "x\\u2028y"\n'),
    "name-c1-escape": lambda t: ["render", "hand", "-o", str(t / "o"), "-D",
                                 "name=a\u009b31mRED"],
    # an edit pointing out of the planar projection's plane gives deep furrows in an
    # arbitrary direction; a point 173 units away must not snap to a vertex
    "edit-across-the-plane": lambda t: scene(t, '[mesh]\nfile = "hand"\n[[fields.edit]]\n'
                                            'at = [0, 0.3, 0.15]\nd1 = [0, 0, 1.5]\n'
                                            'd2 = [1, 0, 0]\n'),
    "edit-far-away": lambda t: scene(t, '[mesh]\nfile = "hand"\n[[fields.edit]]\n'
                                    'at = [100, 100, 100]\nd1 = [1, 0, 0]\nd2 = [0, 1, 0]\n'),
    # an -o with a newline would make a folder whose name holds one
    "out-newline": lambda t: ["render", "hand", "-o", str(t / "new\nline"), *SMALL],
    "out-a-file-name": lambda t: ["calibrate", str(ROOT / "data" / "measurements" /
                                                   "blush_rose.csv"), "-o", str(t / "fit.json")],
    # a link to nowhere, a link loop, a folder where the image goes: refused before the
    # render, not exit 1 after it
    "out-dangling-link": lambda t: ["render", "hand", "-o", _link(t / "dl", t / "nowhere"),
                                    *SMALL],
    "out-link-loop": lambda t: ["render", "hand", "-o", _link(t / "loop", t / "loop"), *SMALL],
    "out-under-dangling-link": lambda t: ["render", "hand", "-o",
                                          str(Path(_link(t / "dl", t / "nowhere")) / "sub"),
                                          *SMALL],
    "out-folder-in-the-way": lambda t: ["render", "hand", "-o", _folder_at(
        t / "o" / "hand_texture.size-64_camera.size-32.png"), *SMALL],
    # 120 two-byte letters: 200 characters allowed, but with the suffixes over 255 bytes
    # (the file system's limit): failed with exit 1 after the render
    "name-too-many-bytes": lambda t: hand(t, "-D", "name=" + "é" * 120, "-D",
                                          "material.melanin=0.31"),
    # --- -D and --sweep
    "D-nan": lambda t: hand(t, "-D", "material.melanin=nan"),
    "D-out-of-range": lambda t: hand(t, "-D", "material.melanin=5"),
    "D-unknown-key": lambda t: hand(t, "-D", "nosuch.key=1"),
    "D-brdf-missing": lambda t: hand(t, "-D", "material.model=lafortune", "-D",
                                     "material.brdf=nope.json"),
    "D-no-equals": lambda t: hand(t, "-D", "material.melanin"),
    "D-name-parent": lambda t: hand(t, "-D", "name=../escaped"),
    "D-name-absolute": lambda t: hand(t, "-D", f"name={t / 'abs'}"),
    "D-memory": lambda t: ["render", "hand", "-o", str(t / "out"), "-D", "texture.size=8192",
                           "-D", "camera.size=8192", "-D", "camera.supersample=4"],
    "sweep-nan": lambda t: hand(t, "--sweep", "material.melanin=0:nan:3"),
    "sweep-inf": lambda t: hand(t, "--sweep", "material.melanin=0:inf:3"),
    "sweep-out-of-range": lambda t: hand(t, "--sweep", "material.melanin=0:5:3"),
    "sweep-zero-count": lambda t: hand(t, "--sweep", "material.melanin=0:1:0"),
    "sweep-fraction-count": lambda t: hand(t, "--sweep", "material.melanin=0:1:2.5"),
    "sweep-huge-count": lambda t: hand(t, "--sweep", "material.melanin=0:1:1000000"),
    "sweep-unknown-key": lambda t: hand(t, "--sweep", "nosuch=0:1:3"),
    "sweep-static-key": lambda t: hand(t, "--sweep", "texture.size=16:64:3"),
    "sweep-malformed": lambda t: hand(t, "--sweep", "material.melanin=0:1"),
    "sweep-and-D-same-key": lambda t: hand(t, "--sweep", "material.melanin=0:1:3", "-D",
                                           "material.melanin=0.5"),
    "sweep-two": lambda t: hand(t, "--sweep", "material.melanin=0:1:2", "--sweep",
                                "material.blood=0:1:2"),
    # --- meshes
    "mesh-empty": lambda t: mesh_scene(t, ""),
    "mesh-garbage": lambda t: mesh_scene(t, b"\x00\x01\x02garbage\xff" * 50),
    "mesh-no-faces": lambda t: mesh_scene(t, "v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
    "mesh-nan-vertex": lambda t: mesh_scene(t, "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n"),
    "mesh-degenerate": lambda t: mesh_scene(t, "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"),
    "mesh-missing": lambda t: scene(t, '[mesh]\nfile = "nope.obj"\n'),
    # --- layer images
    "image-missing": lambda t: layered(t, region='image = "nope.png"'),
    "image-corrupt": lambda t: image(t, content=b"\x89PNG\r\n\x1a\n" + b"\x00" * 64),
    "image-text": lambda t: image(t, content="not an image\n"),
    "image-animated": lambda t: image(t, array=np.zeros((3, 8, 8, 4), np.uint8),
                                      name="map.png"),
    "melanin-image-text": lambda t: layered(t, "blush_rose", "", "-D",
                                            f"skin.melanin_image={write(t, 'm.png', 'text')}"),
    "melanin-image-missing": lambda t: layered(t, "blush_rose", "", "-D",
                                               f"skin.melanin_image={t / 'nope.png'}"),
    "melanin-image-dev-null": lambda t: layered(t, "blush_rose", "", "-D",
                                                "skin.melanin_image=/dev/null"),
    "material-dev-zero": lambda t: layered(t, "blush_rose", "", "-D",
                                           "layer.blush.material=/dev/zero"),
    "image-lab": lab_image,
    # --- FIFOs: refused from os.stat, never opened (open blocks until a writer comes)
    "calibrate-fifo": lambda t: ["calibrate", fifo(t, "m.csv"), "-o", str(t / "out")],
    "melanin-image-fifo": lambda t: layered(t, "blush_rose", "", "-D",
                                            f"skin.melanin_image={fifo(t, 'm.png')}"),
    "fit-skin-fifo": lambda t: ["fit-skin", fifo(t, "m.csv"), "-o", str(t / "out")],
    "fit-brdf-fifo": lambda t: ["fit-brdf", fifo(t, "s.csv"), "-o", str(t / "f.json")],
    "fit-image-target-fifo": lambda t: ["fit-image", "hand", fifo(t, "t.png"), "--fit",
                                        "light.intensity", "-o", str(t / "out")],
    "scene-fifo": lambda t: ["render", fifo(t, "s.toml"), "-o", str(t / "out"), *SMALL],
    "brdf-fifo": lambda t: hand(t, "-D", "material.model=lafortune", "-D",
                                f"material.brdf={fifo(t, 'f.json')}"),
    "layer-image-fifo": lambda t: layered(t, region=f'image = "{Path(fifo(t, "map.png")).name}"'),
    # --- a link to itself (a loop): "no such file", not "failed unexpectedly" (Path.resolve
    # raised on it)
    "layer-image-loop": lambda t: layered(t, region=f'image = "{Path(_link(t / "l.png", "l.png")).name}"'),
    "mesh-loop": lambda t: (_link(t / "l.obj", "l.obj"), scene(t, '[mesh]\nfile = "l.obj"\n'))[1],
    "brdf-loop": lambda t: hand(t, "-D", "material.model=lafortune", "-D",
                                f"material.brdf={_link(t / 'l.json', 'l.json')}"),
    "material-loop": lambda t: layered(t, Path(_link(t / "l.json", "l.json")).name),
    "material-fifo": lambda t: layered(t, fifo(t, "mat.json")),
    # --- polygons
    "polygon-vertex-missing": lambda t: polygon(t, "vertices = [1, 2, 99999]"),
    "polygon-two-points": lambda t: polygon(t, "points = [[0.1, 0.1], [0.2, 0.2]]"),
    "polygon-nan-point": lambda t: polygon(t, "points = [[0.1, 0.1], [nan, 0.2], [0.3, 0.1]]"),
    "polygon-both": lambda t: polygon(t, "points = [[0.1, 0.1], [0.2, 0.2], [0.3, 0.1]]\n"
                                         "vertices = [1, 2, 3]"),
    "polygon-negative-feather": lambda t: polygon(t, "vertices = [1, 2, 3]\nfeather = -1.0"),
    # --- material JSON
    "material-missing-key": lambda t: material(t, {k: v for k, v in good_material().items()
                                                   if k != "K_per_mm"}),
    "material-nan": lambda t: material(t, json.dumps(good_material()).replace(
        '"S_per_mm": [', '"S_per_mm": [NaN, ', 1)),
    "material-wrong-lengths": lambda t: material(t, {**good_material(), "K_per_mm": [1.0, 2.0]}),
    "material-not-json": lambda t: material(t, "{not json"),
    "material-negative": lambda t: material(t, {**good_material(), "K_per_mm": [
        -1.0] * len(good_material()["K_per_mm"])}),
    "material-nested": lambda t: material(t, "[" * 100000 + "]" * 100000),
    # a hand edit: a renamed key is named as such (not "expected a list"), a bad entry by
    # its index, a zero by its band
    "material-key-misspelt": lambda t: material(t, {
        ("S_per_mn" if k == "S_per_mm" else k): v for k, v in good_material().items()}),
    "material-entry-text": lambda t: material(t, {**good_material(), "S_per_mm": [
        1.0, "12,5", *good_material()["S_per_mm"][2:]]}),
    "material-K-zero": lambda t: material(t, {**good_material(), "K_per_mm": [
        1.0, 1.0, 0.0, *good_material()["K_per_mm"][3:]]}),
    # S of 1e300 is finite and > 0, yet renders a NaN, all-black image, exit 0: refused
    "material-S-huge": lambda t: material(t, {**good_material(), "S_per_mm": [
        1e300] * len(good_material()["S_per_mm"])}),
    # a fit-brdf output as a layer's material is named as one (not 'wavelength_nm: expected
    # a list'), and a "model" that is not Kubelka-Munk is read, not ignored
    "material-is-a-lafortune-brdf": lambda t: material(t, {
        "model": "lafortune", "diffuse": [0.43, 0.30, 0.33],
        "lobes": [{"Cxy": [-1.0, -1.0, -1.0], "Cz": [0.86, 0.70, 0.57], "n": [64, 64, 44]}]}),
    "material-model-lafortune-with-lists": lambda t: material(t, {**good_material(),
                                                                  "model": "lafortune"}),
    "material-model-unknown": lambda t: material(t, {**good_material(), "model": "gaussian"}),
    "material-missing": lambda t: layered(t, "nope.json"),
    "material-wavelength-um": lambda t: material(t, {**good_material(), "extrapolate": "hold",
                                                     "wavelength_nm": [
        w / 1000 for w in good_material()["wavelength_nm"]]}),
    "material-is-a-csv": lambda t: layered(t, Path(measurement(t)).name),
    "material-is-a-measurement-as-txt": lambda t: layered(t, Path(write(
        t, "blush.txt", (ROOT / "data" / "measurements" / "blush_rose.csv").read_text())).name),
    "material-is-a-tab-measurement-as-dat": lambda t: layered(t, Path(write(
        t, "blush.dat", (ROOT / "data" / "measurements" / "blush_rose.csv").read_text()
        .replace(",", "\t"))).name),
    "material-is-prose": lambda t: layered(t, Path(write(t, "notes.txt",
                                                         "S and K to follow\n")).name),
    # --- BRDF JSON
    "brdf-all-zero": lambda t: brdf(t, {"model": "lafortune", "diffuse": [0, 0, 0], "lobes": [
        {"Cxy": [0, 0, 0], "Cz": [0, 0, 0], "n": [1, 1, 1]}]}),
    "brdf-nan": lambda t: brdf(t, '{"model": "lafortune", "diffuse": [NaN, 0.3, 0.3], '
                                  f'"lobes": [{json.dumps(LOBE)}]}}'),
    "brdf-missing-lobes": lambda t: brdf(t, {"model": "lafortune", "diffuse": [0.4, 0.3, 0.3]}),
    "brdf-wrong-model": lambda t: brdf(t, {"model": "phong", "diffuse": [0.4, 0.3, 0.3],
                                           "lobes": [LOBE]}),
    "brdf-not-json": lambda t: brdf(t, "]"),
    "brdf-missing": lambda t: scene(t, '[material]\nmodel = "lafortune"\nbrdf = "nope.json"\n'),
    # --- a bad scene after good ones: nothing is written for the good ones either
    "later-scene-bad-image": lambda t: ["render", "hand", "foot",
                                        *image(t, content=b"\x89PNG\r\n\x1a\n")[1:]],
    "later-scene-zero-brdf": lambda t: ["render", "arm", *brdf(t, {
        "model": "lafortune", "diffuse": [0, 0, 0], "lobes": [
            {"Cxy": [0, 0, 0], "Cz": [0, 0, 0], "n": [1, 1, 1]}]})[1:]],
    # --- output paths
    "out-is-file": lambda t: ["render", "hand", "-o", write(t, "afile", "x"), *SMALL],
    "out-under-file": lambda t: ["render", "hand", "-o", str(Path(write(t, "afile", "x")) / "sub"),
                                 *SMALL],
    "out-unwritable": lambda t: ["render", "hand", "-o", "/proc/jaxskin-test-out", *SMALL],
    "out-read-only": read_only_folder,
    "out-is-input": output_is_input,
    "out-empty": lambda t: ["render", "hand", "-o", "", *SMALL],
    "fit-brdf-too-few-samples": lambda t: ["fit-brdf", few_brdf_samples(t), "-o",
                                           str(t / "f.json")],
    "out-link-to-input": symlinked_output,
    # 50 samples, one direction pair (the case: 0.00 % error, arbitrary lobes)
    "fit-brdf-one-direction-pair": lambda t: ["fit-brdf", brdf_rows(t, [(30, 0, 40, 180)] * 50),
                                              "-o", str(t / "f.json")],
    # 50 pairs turned about the normal, in and out swapped: one pair to the lobes
    "fit-brdf-pairs-turned-about-the-normal": lambda t: [
        "fit-brdf", brdf_rows(t, [(30, 5 * i, 40, 5 * i - 180) if i % 2 else
                                  (40, 5 * i - 180, 30, 5 * i) for i in range(50)]),
        "-o", str(t / "f.json")],
    "fit-brdf-memory": lambda t: ["fit-brdf", brdf_csv(t), "-o", str(t / "f.json"), "--lobes",
                                  "16", "--starts", "1024"],
    "fit-brdf-out-folder": lambda t: ["fit-brdf", brdf_csv(t), "-o", str(t)],
    "fit-brdf-out-is-input": lambda t: [  # samples named .json, -o the same file
        "fit-brdf", write(t, "samples.json", (ROOT / "data" / "brdf" / "skin_samples.csv")
                          .read_text()), "-o", str(t / "samples.json")],
    "fit-brdf-given-a-cosmetic": lambda t: ["fit-brdf", measurement(t), "-o", str(t / "f.json")],
    # a typo in the first column names the column, not "no header row"
    "fit-brdf-header-typo": lambda t: ["fit-brdf", write(t, "typo.csv", (
        ROOT / "data" / "brdf" / "skin_samples.csv").read_text().replace(
        "theta_in_deg", "theta_in", 1)), "-o", str(t / "f.json")],
    # the same in a Windows export: semicolons, a quoted cell, cp1252 (µ) in a comment
    "fit-brdf-header-typo-windows": lambda t: ["fit-brdf", write(t, "typo.csv", (
        "# probe \u00b5-goniometer\n" + (ROOT / "data" / "brdf" / "skin_samples.csv")
        .read_text().replace("theta_in_deg", "theta_in", 1).replace(",", ";")
        .replace(";R;", ';"R";', 1)).encode("cp1252")), "-o", str(t / "f.json")],
    "fit-brdf-out-not-json": lambda t: ["fit-brdf", brdf_csv(t), "-o", str(t / "r.png")],
    "fit-brdf-out-newline": lambda t: ["fit-brdf", brdf_csv(t), "-o", str(t / "a\nb.json")],
    "fit-brdf-out-under-file": lambda t: ["fit-brdf", brdf_csv(t), "-o",
                                          str(Path(write(t, "afile", "x")) / "fit.json")],
    "calibrate-name-too-many-bytes": lambda t: ["calibrate", write(
        t, "long.csv", (ROOT / "data" / "measurements" / "blush_rose.csv").read_text()
        .replace("# name: blush_rose", f"# name: {'é' * 150}")),
        "-o", str(t / "out")],
    "fit-skin-given-a-cosmetic": lambda t: ["fit-skin", measurement(t), "-o", str(t / "out")],
    "calibrate-out-is-file": lambda t: ["calibrate", measurement(t), "-o", write(t, "afile", "x")],
    # --- command lines
    "cli-unknown-option": lambda t: hand(t, "--mapz"),
    "cli-unknown-command": lambda t: ["paint", "hand"],
    "cli-missing-output": lambda t: ["render", "hand"],
    "cli-smooth-nan": lambda t: ["calibrate", measurement(t), "-o", str(t / "out"), "--smooth",
                                 "nan"],
    "cli-smooth-negative": lambda t: ["calibrate", measurement(t), "-o", str(t / "out"),
                                      "--smooth", "-1"],
    "cli-noise-inf": lambda t: ["calibrate", measurement(t), "-o", str(t / "out"), "--noise",
                                "inf"],
    "cli-noise-zero": lambda t: ["calibrate", measurement(t), "-o", str(t / "out"), "--noise",
                                 "0"],
    "cli-thickness-zero": lambda t: ["calibrate", measurement(t), "-o", str(t / "out"),
                                     "--thickness", "0"],
    "cli-lobes-zero": lambda t: ["fit-brdf", brdf_csv(t), "-o", str(t / "f.json"), "--lobes",
                                 "0"],
    "cli-lobes-inf": lambda t: ["fit-brdf", brdf_csv(t), "-o", str(t / "f.json"), "--lobes",
                                "inf"],
    "cli-starts-negative": lambda t: ["fit-brdf", brdf_csv(t), "-o", str(t / "f.json"),
                                      "--starts", "-3"],
    "cli-seed-negative": lambda t: ["fit-brdf", brdf_csv(t), "-o", str(t / "f.json"), "--seed",
                                    "-5"],
}
SUBPROCESS = {"toml-nested-tables", "D-name-parent", "cli-smooth-nan", "image-corrupt",
              # these hung before: a subprocess's timeout ends them
              "calibrate-fifo", "fit-skin-fifo", "fit-brdf-fifo", "fit-image-target-fifo"}


def snapshot(folder: Path) -> dict:
    """Every file under `folder` (links not followed) with a hash of its bytes."""
    out = {}
    for dirpath, dirs, files in os.walk(folder):
        for name in files + [d for d in dirs if os.path.islink(os.path.join(dirpath, d))]:
            p = Path(dirpath, name)
            out[str(p)] = (hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() and not
                           p.is_symlink() else os.readlink(p) if p.is_symlink() else "")
        out.update({str(Path(dirpath, d)): "dir" for d in dirs})
    return out


def run(argv, tmp, capsys, subprocess_run: bool):
    if subprocess_run:
        proc = subprocess.run([sys.executable, "-m", "jaxskin", *argv], capture_output=True,
                              text=True, cwd=tmp, timeout=120)
        return proc.returncode, proc.stderr, proc.stdout
    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as e:  # argparse
        code = e.code
    out = capsys.readouterr()
    return code, out.err, out.out


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_one_line_exit_2_and_writes_nothing(case, tmp_path, capsys, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    argv = CASES[case](work)
    before = snapshot(tmp_path)
    code, err, out = run(argv, work, capsys, case in SUBPROCESS)
    lines = err.splitlines()
    assert code == 2, (code, err)
    assert out == "", out  # checked before any work: no progress line before the error
    assert len(lines) == 1 and lines[0].startswith("jaxskin: error: "), err
    assert "Traceback" not in err
    assert snapshot(tmp_path) == before  # nothing written, nothing changed, inputs intact


def test_the_table_is_large_enough():
    assert len(CASES) >= 40


def test_an_unexpected_failure_is_one_line_exit_1_naming_what_was_finished(
        tmp_path, capsys, monkeypatch):
    """A disk that fills up after the first image: exit 1, one line naming the file that is
    complete, no partial file; `--debug` shows the traceback instead."""
    import errno

    from jaxskin import maps

    real = maps.write_image
    calls = []

    def full_disk(image, path):
        calls.append(path)
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(image, path)

    monkeypatch.setattr(maps, "write_image", full_disk)
    out = tmp_path / "out"
    argv = ["render", "hand", "foot", "-o", str(out), *SMALL]
    assert main(argv) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("jaxskin: error: render failed unexpectedly")
    assert "No space left on device" in err[0] and "hand_texture.size-64_camera.size-32.png" in \
        err[0] and "--debug" in err[0]
    assert sorted(p.name for p in out.iterdir()) == ["hand_texture.size-64_camera.size-32.png"]
    calls.clear()
    shutil.rmtree(out)
    with pytest.raises(OSError, match="No space"):
        main(["--debug", *argv])


@pytest.mark.parametrize("case, words", [
    ("toml-edit-single-brackets", "expected [[fields.edit]] tables, one per edit"),
    ("scene-is-a-folder", "is a folder; expected a TOML scene file"),
    ("scene-dot-slash-builtin", "jaxskin: error: ./hand: no such scene file; the built-in "
                                "scene is 'hand', without the folder"),
    ("D-mesh-with-the-scenes-edits", "(the scene's [[fields.edit]] were made for its own mesh, "
                                     "not the one -D mesh.file gives: write a scene file"),
    ("D-brdf-missing", "jaxskin: error: -D material.brdf=nope.json: key 'material.brdf'"),
    ("melanin-image-missing", "key 'skin.melanin_image': no such file: "),
    ("out-a-file-name", "-o: expected the folder to write into, got a file name ('fit.json'"),
    ("material-dev-zero", "key 'layer.blush.material': not a regular file: /dev/zero"),
    ("calibrate-fifo", "m.csv: not a regular file (a FIFO): expected a CSV table"),
    ("fit-brdf-one-direction-pair", "pairs.csv: 50 weighted samples but 1 distinct direction "
                                    "pair cannot determine 10 parameters per channel (3 "
                                    "lobes)"),
    ("fit-brdf-pairs-turned-about-the-normal", "50 weighted samples but 1 distinct direction "
                                               "pair cannot"),
    ("fit-image-target-fifo", "t.png: not a regular file (a FIFO): expected an image file"),
    ("scene-fifo", "s.toml: not a regular file (a FIFO or a device)"),
    ("brdf-fifo", "key 'material.brdf': expected 'skin' (the preset) or a Lafortune JSON file "
                  "(as written by jaxskin fit-brdf); not a regular file "),
    ("toml-light-subnormal", "s.toml: key 'light.direction': expected a direction whose "
                             "length float32 holds, between 1e-19 and 1e19"),
    ("D-light-float32-overflow", "-D light.direction=[1e200,0,1]: key 'light.direction': "),
    ("image-lab", "map.png: key 'layer.blush.image': a LAB image (its channels are not R, G, "
                  "B): save it as RGB or greyscale"),
    ("melanin-image-dev-null", "key 'skin.melanin_image': not a regular file: /dev/null"),  # not "expected
    # a greyscale image file, got ..."
    ("sweep-static-key", "static setting (each value compiles its own program): render each "
                         "value with -D texture.size=VALUE"),
    ("material-wavelength-um", "key 'wavelength_nm': wavelengths 0.38-0.78 must lie in "
                               "200-3000 nm"),
    ("material-is-a-csv", "blush.csv: a CSV file, expected a material JSON: run 'jaxskin "
                          "calibrate"),
    ("material-is-a-measurement-as-txt", "blush.txt: a measurement table (a wavelength "
                                         "column), expected a material JSON: run 'jaxskin "
                                         "calibrate"),
    ("material-is-a-tab-measurement-as-dat", "blush.dat: a measurement table"),
    ("material-is-prose", "notes.txt:1: not a JSON material file"),
    ("material-key-misspelt", "key 'S_per_mm': missing (is 'S_per_mn' a misspelling of it?); "
                              "a material written by jaxskin calibrate has wavelength_nm, "
                              "S_per_mm, K_per_mm"),
    ("material-entry-text", "key 'S_per_mm': entry 1 is \"12,5\": expected a finite number"),
    ("material-K-zero", "key 'K_per_mm': must be > 0 at every band; entry 2 ("),
    ("material-S-huge", "key 'S_per_mm': must be at most 1e+09 per mm at every band "
                        "(cosmetics: about 1e-3 to 1e5); entry 0 ("),
    ("fit-brdf-header-typo", "typo.csv:2: column 'theta_in': unknown column (did you mean "
                             "'theta_in_deg'?)"),
    ("fit-brdf-header-typo-windows", "typo.csv:3: column 'theta_in': unknown column (did "
                                     "you mean 'theta_in_deg'?)"),
    ("material-is-a-lafortune-brdf", "mat.json: key 'model': a Lafortune BRDF (written by "
                                     "jaxskin fit-brdf; it goes in material.brdf)"),
    ("material-model-unknown", "key 'model': expected \"kubelka-munk\" (or no model key), "
                               "got 'gaussian'"),
    # names the scene and the key, not just "nope.obj: no such mesh file"
    ("mesh-missing", "s.toml: key 'mesh.file': expected a built-in mesh (hand, "),
    ("cli-noise-zero", "argument --noise: expected a finite number > 0"),
    ("name-blank", "' ' starts or ends with a space"),
    ("name-bidi-override", "'x\\u202eyz' contains a control character"),
    ("name-line-separator", "'x\\u2028y' contains a control character"),
    ("name-c1-escape", "-D name=a\\x9b31mRED: key 'name': an output name must be one plain "
                       "file name"),
    ("edit-across-the-plane", "s.toml: key 'fields.edit[0].d1': [0, 0, 1.5] at vertex 268 is "
                              "almost perpendicular to the x-y plane the planar projection "
                              "keeps (only 0% of it lies along it)"),
    ("edit-far-away", "s.toml: key 'fields.edit[0].at': the point is 173 from the mesh (its "
                      "nearest vertex, 724, is at [0.312, 0.664, 0.116]); the mesh spans x "
                      "-0.409..0.318, y -0.00246..0.942, z -0.0853..0.188"),
    ("out-newline", "-o: a folder to create must not contain control characters"),
    ("out-dangling-link", "dl: -o: a link to "),
    ("out-link-loop", "loop: -o: cannot use this folder (Too many levels of symbolic links)"),
    ("out-under-dangling-link", "sub: -o: "),
    ("out-folder-in-the-way", "a folder is where the output 'hand_texture.size-64_camera"
                              ".size-32.png' goes; move it or choose another -o"),
])
def test_what_the_line_says(case, words, tmp_path, capsys, monkeypatch):
    """The line names the mistake: not "expected a table with at…" of a '[fields.edit]'
    that is a table; not "no such scene file" of a folder; a missing BRDF file given with
    -D is not blamed on the scene file."""
    monkeypatch.chdir(tmp_path)
    code, err, _ = run(CASES[case](tmp_path), tmp_path, capsys, False)
    assert code == 2 and words in err, err


@pytest.mark.parametrize("direction, dtype", [
    ([0.0, 0.0, 1e-30], np.float32),  # normal in float32, its squares' sum 0: a NaN light
    ([1e20, 0.0, 1.0], np.float32),  # finite in float32, its squares' sum infinite
    ([0.0, 0.0, 1e-160], np.float64),  # the same in float64
])
def test_the_api_refuses_a_light_direction_its_dtype_cannot_normalise(direction, dtype):
    """`render` (through `render_args.check_ranges`) refuses a light direction that its
    own dtype cannot normalise, as the scene loader refuses one float32 cannot: the render
    divides by `jnp.linalg.norm` in that dtype (subnormals flushed), so NaN or 0 light."""
    from jaxskin.render_args import check_ranges
    from jaxskin.scene import SCHEMA

    params = {"light.direction": np.asarray(direction, dtype)}
    with pytest.raises(ValueError, match=r"params\['light.direction'\]: expected a finite, "
                                         r"non-zero 3-vector whose length"):
        check_ranges(params, {"light.direction": SCHEMA["light.direction"]})
    check_ranges({"light.direction": np.asarray([1e-15, 0, 1e15], dtype)},
                 {"light.direction": SCHEMA["light.direction"]})
