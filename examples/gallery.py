"""
Render scenes of other renderers
================================

Three openly licensed scenes, each in a format :meth:`voxgi.Scene.load`
reads (docs/design.md §12), rendered with voxgi's defaults to
``gallery/<name>.exr`` (linear radiance) and ``.png``:

- ``cbox``: Mitsuba 3's Cornell box, ``scenes/cbox/cbox.xml`` of
  https://github.com/mitsuba-renderer/mitsuba-data (the Mitsuba 3 project's
  data, distributed with Mitsuba 3 under its BSD-3-Clause licence; the box's
  geometry and spectra are the Cornell Program of Computer Graphics'
  published measurements). Mitsuba XML.
- ``cornell-obj``: the Cornell box as OBJ + MTL by Guedis Cardenas and
  Morgan McGuire (Williams College, 2011), released into the public domain,
  from https://casual-effects.com/data (``CornellBox-Original``).
- ``emissive-gltf``: Khronos' ``EmissiveStrengthTest`` (CC BY 4.0, The
  Khronos Group), https://github.com/KhronosGroup/glTF-Sample-Assets: cubes
  whose emission is set by ``KHR_materials_emissive_strength``. glTF 2.0.

The files are downloaded with urllib into ``gallery/src``; with
``--source DIR`` they are read from a local copy laid out as below instead
(``DIR/cbox/cbox.xml`` and ``DIR/cbox/meshes/*.obj``,
``DIR/CornellBox/CornellBox-Original.obj`` and ``.mtl``,
``DIR/EmissiveStrengthTest.glb``). What each loader approximated or left
out is printed from its warnings. A scene without a camera is viewed from
the front of its bounding box.

Run: ``python examples/gallery.py [--source DIR] [--size 256] [cbox cornell-obj emissive-gltf]``
(a minute or two per scene on two cores).
"""

import argparse
import math
import urllib.request
import warnings
import zipfile
from pathlib import Path

import numpy as np

import voxgi

MITSUBA = "https://raw.githubusercontent.com/mitsuba-renderer/mitsuba-data/master/scenes/cbox/"
CBOX_MESHES = [
    "back",
    "ceiling",
    "floor",
    "greenwall",
    "largebox",
    "luminaire",
    "redwall",
    "smallbox",
]
SCENES = {
    "cbox": {
        "file": "cbox/cbox.xml",
        "urls": {"cbox/cbox.xml": MITSUBA + "cbox.xml"}
        | {f"cbox/meshes/cbox_{m}.obj": MITSUBA + f"meshes/cbox_{m}.obj" for m in CBOX_MESHES},
    },
    "cornell-obj": {
        "file": "CornellBox/CornellBox-Original.obj",
        "zip": (
            "CornellBox.zip",
            "https://casual-effects.com/g3d/data10/common/model/CornellBox/CornellBox.zip",
        ),
    },
    "emissive-gltf": {
        "file": "EmissiveStrengthTest.glb",
        "urls": {
            "EmissiveStrengthTest.glb": "https://raw.githubusercontent.com/KhronosGroup/"
            "glTF-Sample-Assets/main/Models/EmissiveStrengthTest/glTF-Binary/EmissiveStrengthTest.glb"
        },
    },
}


def fetch(spec: dict, src: Path) -> None:
    """Download a scene's files into ``src`` (skipping those already there)."""
    for rel, url in spec.get("urls", {}).items():
        if not (src / rel).exists():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            urllib.request.urlretrieve(url, src / rel)
    if "zip" in spec and not (src / spec["file"]).exists():
        name, url = spec["zip"]
        urllib.request.urlretrieve(url, src / name)
        with zipfile.ZipFile(src / name) as z:
            z.extractall(src / Path(spec["file"]).parent)


def front_camera(scene: voxgi.Scene, size: int) -> voxgi.Camera:
    """A 40-degree view of the whole bounding box from its +z side."""
    lo, hi = scene.bounds
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    dist = radius / math.sin(math.radians(20))
    return voxgi.Camera(
        eye=centre + np.array([0.0, 0.0, dist]), target=centre, fov=40.0, width=size, height=size
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    ap.add_argument(
        "names", nargs="*", help=f"scenes to render (default: all): {', '.join(SCENES)}"
    )
    ap.add_argument("--source", type=Path, help="local copy of the files (no download)")
    ap.add_argument("--size", type=int, default=256, help="image height in pixels")
    ap.add_argument("--out", type=Path, default=Path("gallery"))
    args = ap.parse_args()
    unknown = sorted(set(args.names) - set(SCENES))
    if unknown:
        ap.error(f"unknown scene(s) {unknown}; known: {', '.join(SCENES)}")
    src = args.source or args.out / "src"
    for name in args.names or list(SCENES):
        spec = SCENES[name]
        if args.source is None:
            fetch(spec, src)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", voxgi.SceneWarning)
            scene = voxgi.Scene.load(src / spec["file"])
        for w in caught:
            print(f"{name}: warning: {w.message}")
        if scene.camera is None:
            scene.camera = front_camera(scene, args.size)
        else:
            c = scene.camera
            scene.camera = c.replace(width=round(c.width * args.size / c.height), height=args.size)
        out = voxgi.render(scene, progress=False)
        s = out.stats
        print(
            f"{name}: {len(scene.objects)} objects, {scene.n_triangles:,} triangles; "
            f"{out.frames} frames in {s['seconds']['total']:.1f} s, "
            f"estimated noise relMSE {s['est_rel_mse']:.1e}"
        )
        args.out.mkdir(parents=True, exist_ok=True)
        voxgi.io.write_exr(args.out / f"{name}.exr", out.image)
        voxgi.io.write_png(args.out / f"{name}.png", out.image)
        print(f"wrote {args.out / name}.exr and .png")


if __name__ == "__main__":
    main()
