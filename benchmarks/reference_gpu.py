"""Mitsuba 3 reference of voxgi's Cornell box on a GPU (cuda_ad_rgb).

The same export as :mod:`voxgi.mitsuba` (meshes, one-sided area light,
camera, box filter, ``path`` with ``max_depth = -1``), written standalone so
that it runs where voxgi is not built: next to it, ``cornell.json`` holds the
scene (``voxgi.scenes.cornell_box()``: objects' vertices, faces, albedo,
emission, two_sided; camera; fingerprint), and ``mitsuba``/``drjit`` are on
``/tmp/site``. Writes ``ref_256.npy`` (65536 spp) and ``ref_512.npy``
(16384 spp) to ``$OUT``. The committed ``results/cornell_ref_*.exr`` came
from it on an NVIDIA H100 (22 s each); ``reference.py`` renders the same on
the CPU (256x256 at 4096 spp agreed with it to relMSE 8.2e-5, that
render's own noise).
"""

import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, "/tmp/site")
import mitsuba as mi

variant = sys.argv[1] if len(sys.argv) > 1 else "cuda_ad_rgb"
mi.set_variant(variant)
d = json.load(open(os.path.join(os.path.dirname(__file__), "cornell.json")))
out = os.environ.get("OUT", ".")


def mesh(name, v, f, bsdf, emitter=None):
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    m = mi.Mesh(
        name, len(v), len(f), props=props, has_vertex_normals=False, has_vertex_texcoords=False
    )
    p = mi.traverse(m)
    p["vertex_positions"] = np.ascontiguousarray(v, np.float32).ravel()
    p["faces"] = np.ascontiguousarray(f, np.uint32).ravel()
    p.update()
    return m


def scene(size, spp):
    c = d["camera"]
    sd = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": -1},
        "sensor": {
            "type": "perspective",
            "fov": c["fov"],
            "fov_axis": "y",
            "near_clip": 1e-4,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=c["eye"], target=c["target"], up=c["up"]
            ),
            "sampler": {"type": "independent", "sample_count": spp},
            "film": {
                "type": "hdrfilm",
                "width": size,
                "height": size,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
                "component_format": "float32",
            },
        },
    }
    for i, o in enumerate(d["objects"]):
        b = {"type": "diffuse", "reflectance": {"type": "rgb", "value": o["albedo"]}}
        if o["two_sided"]:
            b = {"type": "twosided", "bsdf": b}
        em = None
        if max(o["emission"]) > 0:
            em = mi.load_dict({"type": "area", "radiance": {"type": "rgb", "value": o["emission"]}})
        sd[f"o{i}"] = mesh(f"o{i}", np.array(o["v"]), np.array(o["f"]), mi.load_dict(b), em)
    return mi.load_dict(sd)


plan = (
    [(256, 65536, 4096), (512, 16384, 1024)]
    if variant.startswith("cuda")
    else [(256, 2048, 512), (512, 1024, 256)]
)
for size, spp, per in plan:
    sc = scene(size, per)
    acc = np.zeros((size, size, 3))
    t0 = time.time()
    for k in range(spp // per):
        acc += np.array(mi.render(sc, spp=per, seed=7 + k), dtype=np.float64)[..., :3]
    img = (acc / (spp // per)).astype(np.float32)
    np.save(os.path.join(out, f"ref_{size}.npy"), img)
    print(size, spp, variant, round(time.time() - t0, 1), "s", img.mean(axis=(0, 1)), flush=True)
json.dump(
    {"variant": variant, "plan": plan, "fingerprint": d["fingerprint"]},
    open(os.path.join(out, "info.json"), "w"),
)
