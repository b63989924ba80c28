"""Make the shipped textured face: MediaPipe's face mesh wearing a public-domain photograph.

    python data/make_scan_face.py PATH/TO/astronaut.png
    # writes data/meshes/astronaut_face.obj, .mtl and .png

No scanned head whose licence allows shipping could be had here, so this builds the next
best thing honestly, the way a scan's texture is made: a photograph projected onto a mesh.

- The mesh is `meshes/canonical_face_model.obj` (Google, MediaPipe face geometry module,
  Apache-2.0), its vertices, UVs and faces unchanged; the OBJ only gains `mtllib`/`usemtl`.
- The photograph is scikit-image's `astronaut.png` (Eileen Collins, NASA; "no known
  copyright restrictions, released into the public domain", scikit-image's
  `skimage.data.astronaut` docstring), inside the scikit-image wheel at
  `skimage/data/astronaut.png` (`pip download scikit-image --no-deps`, unzip).
- Alignment: 22 MediaPipe landmarks (eye corners, brows, nose, the lips' outer and inner
  corners and middles, chin, forehead, the face's sides and jaw) were placed by eye on the
  photograph (`LANDMARKS`, photo pixels, x right, y down, read off a 4x enlargement with a
  pixel grid); a thin-plate spline through them maps each vertex's (x, y), seen from the
  front, to the photo. Each texel of the mesh's UV layout then takes the photo's colour
  (bilinear) at the spline's image of its point on the mesh. Texels that no triangle
  covers take their nearest covered texel's colour, so that filtering at the UV borders
  never reads black.

The photo's face is about 80 pixels wide, so the texture (512²) is soft; its lighting is
baked in (a studio portrait's soft front light), as in any scan's texture. The face is
smiling, lips parted over teeth; the mesh's mouth is closed, so the inner lip landmarks
(13, 14) take the teeth's top and bottom edges: the teeth fill the narrow band between the
mesh's inner lips (5 mm), and the lips keep the lips' colour, for lipstick to go on.
Her fringe covers the top of the forehead in the photo, and so in the texture.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image
from scipy.interpolate import RBFInterpolator
from scipy.ndimage import distance_transform_edt, map_coordinates

HERE = Path(__file__).resolve().parent / "meshes"
SOURCE = HERE / "canonical_face_model.obj"
NAME = "astronaut_face"
SIZE = 512

# MediaPipe vertex index (0-based) → photo pixel (x, y) in astronaut.png (512 x 512).
LANDMARKS = {
    33: (195.0, 101.5),   # the subject's right eye, outer corner (image left)
    133: (212.5, 102.0),  # right eye, inner corner
    362: (237.5, 103.0),  # left eye, inner corner
    263: (256.0, 104.0),  # left eye, outer corner
    105: (201.0, 90.0),   # right brow, middle
    334: (246.0, 91.0),   # left brow, middle
    1: (224.0, 124.0),    # nose tip
    2: (224.0, 130.0),    # below the nose
    61: (202.5, 139.5),   # mouth corner, right
    291: (246.0, 139.0),  # mouth corner, left
    0: (224.5, 137.5),    # upper lip, top middle
    13: (224.5, 140.5),   # upper lip, inner edge (the teeth start below it)
    14: (224.5, 148.5),   # lower lip, inner edge (the teeth end above it)
    17: (224.5, 154.0),   # lower lip, bottom middle
    78: (205.5, 140.0),   # the inner corners of the lips
    308: (243.5, 140.0),
    152: (225.0, 176.0),  # chin
    10: (224.0, 66.0),    # forehead, top middle (under the fringe)
    234: (183.5, 113.0),  # the face's right side at the eyes (the photo's outline)
    454: (270.0, 114.0),  # left side
    # the jaw's outline halfway to the chin (MediaPipe's jaw-line vertices 172, 397)
    172: (193.0, 157.0),
    397: (259.0, 158.0),
}


def read_obj(path: Path):
    """Positions `(V, 3)`, UVs `(T, 2)`, faces' position and UV indices `(F, 3)` each."""
    v, vt, fv, ft = [], [], [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            v.append([float(p) for p in parts[1:4]])
        elif parts[0] == "vt":
            vt.append([float(p) for p in parts[1:3]])
        elif parts[0] == "f":
            corners = [p.split("/") for p in parts[1:4]]
            fv.append([int(c[0]) - 1 for c in corners])
            ft.append([int(c[1]) - 1 for c in corners])
    return np.array(v), np.array(vt), np.array(fv), np.array(ft)


def photo_coordinates(vertices: np.ndarray) -> np.ndarray:
    """Each vertex's photo pixel (x, y): the thin-plate spline through `LANDMARKS`, on the
    vertices' (x, y) seen from the front (+z toward the viewer)."""
    index = np.array(list(LANDMARKS))
    target = np.array(list(LANDMARKS.values()))
    spline = RBFInterpolator(vertices[index, :2], target, kernel="thin_plate_spline",
                             smoothing=0.5)
    return spline(vertices[:, :2])


def texture(photo: np.ndarray, vertices, uv, fv, ft) -> np.ndarray:
    """The `SIZE`² RGB texture of the mesh's UV layout (row 0 = v 1) sampled from `photo`."""
    from jaxskin.raster import rasterize

    per_uv = np.zeros((len(uv), 2))
    per_uv[ft.ravel()] = photo_coordinates(vertices)[fv.ravel()]
    xy = np.stack([uv[:, 0] * SIZE, (1 - uv[:, 1]) * SIZE], axis=1)
    raster = rasterize(xy, ft, SIZE, SIZE)
    corners = per_uv[ft[np.maximum(raster.tri, 0)]]  # (H, W, 3, 2)
    where = np.einsum("hwk,hwkc->hwc", raster.bary.astype(np.float64), corners)
    out = np.stack([map_coordinates(photo[..., c].astype(np.float64),
                                    [where[..., 1] - 0.5, where[..., 0] - 0.5], order=1,
                                    mode="nearest") for c in range(3)], axis=-1)
    _, (iy, ix) = distance_transform_edt(~raster.mask, return_indices=True)
    out = out[iy, ix]
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def main(photo_path: str) -> None:
    photo = np.asarray(Image.open(photo_path).convert("RGB"))
    if photo.shape != (512, 512, 3):
        sys.exit(f"{photo_path}: expected scikit-image's astronaut.png (512 x 512 RGB)")
    vertices, uv, fv, ft = read_obj(SOURCE)
    image = texture(photo, vertices, uv, fv, ft)
    Image.fromarray(image).save(HERE / f"{NAME}.png", optimize=True)
    (HERE / f"{NAME}.mtl").write_text(
        f"# {NAME}.png on MediaPipe's canonical face: see data/make_scan_face.py\n"
        f"newmtl skin\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nmap_Kd {NAME}.png\n")
    body = SOURCE.read_text()
    (HERE / f"{NAME}.obj").write_text(
        "# MediaPipe's canonical face model (Apache-2.0, Google; see\n"
        "# canonical_face_model_LICENSE_Apache-2.0.txt), unchanged but for the material:\n"
        "# a public-domain NASA photograph projected on it by data/make_scan_face.py\n"
        f"mtllib {NAME}.mtl\nusemtl skin\n" + body)
    print(f"wrote {HERE / NAME}.obj, .mtl, .png")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "astronaut.png")
