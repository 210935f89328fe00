"""Export a voxgi :class:`~voxgi.Scene` to a Mitsuba 3 scene dictionary.

Used by the benchmarks to render the *same* scene with a path tracer
(docs/design.md §9, §10). Mitsuba is imported lazily and is never a runtime
dependency of voxgi (it is in the optional ``bench`` extra).

The translation keeps voxgi's conventions:

- meshes as ``mi.Mesh`` objects built from the scene's float64 vertices
  (Mitsuba stores float32), winding and hence normals unchanged;
- a Lambertian ``diffuse`` BSDF, one-sided like voxgi's surfaces (Mitsuba's
  BSDFs are black from behind), wrapped in ``twosided`` for two-sided objects;
  a textured albedo as Mitsuba's ``bitmap`` with the same filter, wrap mode
  and ``to_uv``, holding the texels as voxgi decodes them (linear float32),
  and the mesh's UVs;
- an ``area`` emitter with the material's radiance, emitting on the front
  side only (a two-sided emitter gets a second, reversed copy);
- a :class:`~voxgi.Microfacet` lobe as the same ``roughplastic`` (its
  diffuse base the albedo or texture) or ``roughconductor`` (``eta``, ``k``
  per channel), with the same distribution and ``alpha``; an
  Ashikhmin–Shirley layer as its diffuse part only (Mitsuba has none);
- a transmitting sheet (glass, ``docs/design.md`` §13) as ``thindielectric``
  with equal inner and outer indices and ``specular_transmittance`` T: no
  Fresnel reflection, a path crosses it straight scaled by T per channel,
  as voxgi's rays do (``mask`` would do it with probability, and with one
  opacity for all channels: their mean);
- the camera as ``perspective`` (or ``thinlens`` with an aperture), vertical
  field of view, ``look_at`` (Mitsuba's image x axis is ``forward x up``,
  as voxgi's);
- lights as Mitsuba's ``point``, ``spot``, ``directional``, ``constant`` and
  ``envmap`` emitters with the same parameters (voxgi's lights use Mitsuba's
  units and conventions, ``docs/design.md`` §11);
- the camera's pixel filter: ``box`` (voxgi's default; Mitsuba's default
  Gaussian blurs across pixels) or Mitsuba's ``gaussian``; and a
  ``path`` integrator with ``max_depth = -1`` (no depth limit; Russian
  roulette keeps it unbiased).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from . import _validate
from .direct import check_scene_and_records
from .lights import DirectionalLight, Environment, SpotLight
from .microfacet import Microfacet
from .scene import Camera, Scene

__all__ = [
    "denoise_oidn",
    "facing_camera",
    "mitsuba_module",
    "record_reference",
    "render_mitsuba",
    "to_mitsuba",
    "with_aovs",
]


def mitsuba_module(variant: str | None = None):
    """The ``mitsuba`` module with a variant set (it imports no scene: see
    :func:`to_mitsuba` for that).

    Parameters
    ----------
    variant : str or None
        ``None`` picks the fastest CPU variant that works here: ``llvm_ad_rgb``
        (needs libLLVM >= 16; ``DRJIT_LIBLLVM_PATH`` is pointed at a
        ``libLLVM-19.so`` when one is installed and the variable is unset),
        else ``scalar_rgb``.

    Returns
    -------
    module
        The ``mitsuba`` module with the variant set.

    Raises
    ------
    ImportError
        When the ``mitsuba`` package is not installed (``pip install voxgi[bench]``).
    """
    try:
        import mitsuba as mi
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "Mitsuba 3 is needed for reference renders: pip install "
            "'voxgi[bench]' (or pip install mitsuba)"
        ) from exc
    if variant is not None:
        mi.set_variant(variant)
        return mi
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        for cand in ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", "/usr/lib/llvm-19/lib/libLLVM.so"):
            if Path(cand).exists():
                os.environ["DRJIT_LIBLLVM_PATH"] = cand
                break
    for v in ("llvm_ad_rgb", "scalar_rgb"):
        try:
            mi.set_variant(v)
            return mi
        except (ImportError, AttributeError, RuntimeError):
            continue
    raise ImportError("no usable Mitsuba variant (tried llvm_ad_rgb, scalar_rgb)")


def _mesh(mi, name: str, vertices: np.ndarray, faces: np.ndarray, bsdf, emitter=None, uv=None):
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    mesh = mi.Mesh(
        name,
        len(vertices),
        len(faces),
        props=props,
        has_vertex_normals=False,
        has_vertex_texcoords=uv is not None,
    )
    params = mi.traverse(mesh)
    params["vertex_positions"] = np.ascontiguousarray(vertices, np.float32).ravel()
    if uv is not None:
        params["vertex_texcoords"] = np.ascontiguousarray(uv, np.float32).ravel()
    params["faces"] = np.ascontiguousarray(faces, np.uint32).ravel()
    params.update()
    return mesh


def to_mitsuba(
    scene: Scene,
    *,
    spp: int = 64,
    camera: Camera | None = None,
    max_depth: int = -1,
    sampler: str = "independent",
    seed: int = 0,
) -> dict:
    """A Mitsuba 3 scene dictionary for ``scene`` (call ``mi.load_dict`` on it).

    Parameters
    ----------
    scene : Scene
        With a camera (or pass ``camera``).
    spp : int
        Samples per pixel of the sampler.
    camera : Camera, optional
        Overrides ``scene.camera``.
    max_depth : int
        Path length limit of the ``path`` integrator (-1: none).
    sampler : str
        Mitsuba sampler plugin name.
    seed : int
        Sampler seed.

    Returns
    -------
    dict
        ``{"type": "scene", "integrator": ..., "sensor": ..., "<object>": mesh, ...}``.
        Mitsuba must already have a variant set (:func:`mitsuba_module`).
    """
    import mitsuba as mi

    cam = camera if camera is not None else scene.camera
    if cam is None:
        raise ValueError("to_mitsuba: the scene has no camera")
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(max_depth)},
        "sensor": _sensor(mi, scene, cam, spp, sampler, seed),
    }
    objects = scene.objects
    skip = set()
    for i, o in enumerate(objects):
        if i in skip:
            continue
        back = objects[i + 1] if i + 1 < len(objects) else None
        if back is not None and _is_back_of(back, o):
            d.update(_emitter_with_back(mi, i, o, back))
            skip.add(i + 1)
        else:
            d.update(_shape(mi, i, o))
    for i, light in enumerate(scene.lights):
        d[f"light{i:03d}"] = _light(mi, light)
    if scene.environment is not None:
        d["environment"] = _environment(mi, scene.environment)
    return d


def _rgb(v) -> dict:
    return {"type": "rgb", "value": [float(x) for x in v]}


def _light(mi, light) -> dict:
    """The Mitsuba emitter of a point, spot or directional light (same units)."""
    if isinstance(light, DirectionalLight):
        return {
            "type": "directional",
            "direction": list(light.direction),
            "irradiance": _rgb(light.irradiance),
        }
    if isinstance(light, SpotLight):
        pos, axis = np.asarray(light.position), np.asarray(light.direction)
        up = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        return {
            "type": "spot",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=list(pos), target=list(pos + axis), up=list(up)
            ),
            "intensity": _rgb(light.intensity),
            "cutoff_angle": float(light.cutoff_angle),
            "beam_width": float(light.beam_width),
        }
    return {"type": "point", "position": list(light.position), "intensity": _rgb(light.intensity)}


def _environment(mi, env: Environment) -> dict:
    """``constant`` for a uniform environment, else ``envmap`` with the same
    lat-long image (already scaled) and rotation."""
    if env.image.shape[:2] == (1, 1):
        return {"type": "constant", "radiance": _rgb(env.image[0, 0])}
    m = np.eye(4)
    m[:3, :3] = env.to_world
    return {
        "type": "envmap",
        "bitmap": mi.Bitmap(np.ascontiguousarray(env.image, np.float32)),
        "to_world": mi.ScalarTransform4f(m.tolist()),
    }


def _sensor(mi, scene: Scene, cam: Camera, spp: int, sampler: str, seed: int) -> dict:
    """The Mitsuba sensor of ``cam``: pinhole or thin lens, box-filtered RGB film."""
    sensor = {
        "type": "thinlens" if cam.aperture > 0 else "perspective",
        "fov": float(cam.fov),
        "fov_axis": "y",
        "near_clip": 1e-4 * float(np.linalg.norm(np.ptp(scene.bounds, axis=0))),
        "to_world": mi.ScalarTransform4f().look_at(
            origin=list(cam.eye), target=list(cam.target), up=list(cam.up)
        ),
        "sampler": {"type": sampler, "sample_count": int(spp), "seed": int(seed)},
        "film": {
            "type": "hdrfilm",
            "width": int(cam.width),
            "height": int(cam.height),
            "rfilter": {"type": "gaussian" if cam.pixel_filter == "gaussian" else "box"},
            "pixel_format": "rgb",
            "component_format": "float32",
        },
    }
    if cam.aperture > 0:
        sensor["aperture_radius"] = float(cam.aperture)
        sensor["focus_distance"] = float(cam.focus)
    return sensor


def _bitmap(mi, tex) -> dict:
    """Mitsuba's ``bitmap`` of a voxgi Texture: the same filter, wrap mode and
    to_uv, and its texels as voxgi decodes them (linear float32, times the
    factor), so that both renderers filter the same values."""
    lin = tex.linear_texels()
    m = np.eye(4)
    m[:2, :2], m[:2, 3] = tex.to_uv[:2, :2], tex.to_uv[:2, 2]
    return {
        "type": "bitmap",
        "bitmap": mi.Bitmap(np.ascontiguousarray(lin, np.float32)),
        "raw": True,
        "filter_type": tex.filter,
        "wrap_mode": tex.wrap,
        "to_uv": mi.ScalarTransform4f(m.tolist()),
    }


def _lobe(lobe: Microfacet, base: dict) -> dict:
    """Mitsuba's BSDF of a microfacet lobe over the diffuse base ``base``."""
    out = {
        "type": "roughplastic" if lobe.kind == "plastic" else "roughconductor",
        "distribution": lobe.distribution,
        "alpha": float(lobe.alpha),
        "specular_reflectance": _rgb(lobe.specular_reflectance),
    }
    if lobe.kind == "plastic":
        out.update(
            diffuse_reflectance=base,
            int_ior=float(lobe.ior),
            ext_ior=1.0,
            nonlinear=bool(lobe.nonlinear),
        )
    else:
        out.update(eta=_rgb(lobe.eta), k=_rgb(lobe.k))
    return out


def _shape(mi, i: int, o) -> dict:
    """The Mitsuba mesh (or, for a two-sided emitter, meshes) of object ``i``."""
    m = o.material
    bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(m.albedo)}}
    uv = None
    if m.texture is not None:
        bsdf["reflectance"] = _bitmap(mi, m.texture)
        uv = o.uv
    lobe = m.specular if isinstance(m.specular, Microfacet) else None
    if lobe is not None:
        bsdf = _lobe(lobe, bsdf["reflectance"])
    if m.is_sheet:
        bsdf = {
            "type": "thindielectric",
            "int_ior": 1.0,
            "ext_ior": 1.0,
            "specular_transmittance": _rgb(m.transmittance),
        }
    elif o.two_sided:
        bsdf = {"type": "twosided", "bsdf": bsdf}
    bsdf_obj = mi.load_dict(bsdf)
    key = f"obj{i:03d}_{o.name}".replace(" ", "_")
    emitter = None
    if m.is_emitter:
        emitter = mi.load_dict(
            {"type": "area", "radiance": {"type": "rgb", "value": list(m.emission)}}
        )
    out = {key: _mesh(mi, key, o.vertices, o.faces, bsdf_obj, emitter, uv)}
    if m.is_emitter and o.two_sided:
        back = mi.load_dict(
            {"type": "area", "radiance": {"type": "rgb", "value": list(m.emission)}}
        )
        out[key + "_back"] = _mesh(
            mi, key + "_back", o.vertices, o.faces[:, ::-1], mi.load_dict(bsdf), back, uv
        )
    return out


def _is_back_of(back, front) -> bool:
    """Whether ``back`` is the reflecting back of the one-sided emitter
    ``front``: the same triangles, reversed, emitting nothing (how a file's
    two-sided emitter is loaded, as Mitsuba's area emitter lights its front
    only)."""
    return (
        front.material.is_emitter
        and not back.material.is_emitter
        and not front.two_sided
        and not back.two_sided
        and np.array_equal(front.vertices, back.vertices)
        and np.array_equal(front.faces[:, ::-1], back.faces)
    )


def _emitter_with_back(mi, i: int, front, back) -> dict:
    """One Mitsuba mesh for an emitter and its reflecting back: a ``twosided``
    BSDF with the two albedos and the area emitter on the front. Two coplanar
    meshes instead would each take a share of the rays that meet them
    (Embree picks either), which turns the lamp into a grid of dark pixels."""
    bsdf = {
        "type": "twosided",
        "front": {"type": "diffuse", "reflectance": _rgb(front.material.albedo)},
        "back": {"type": "diffuse", "reflectance": _rgb(back.material.albedo)},
    }
    key = f"obj{i:03d}_{front.name}".replace(" ", "_")
    emitter = mi.load_dict({"type": "area", "radiance": _rgb(front.material.emission)})
    return {key: _mesh(mi, key, front.vertices, front.faces, mi.load_dict(bsdf), emitter)}


def render_mitsuba(
    scene: Scene,
    spp: int,
    *,
    camera: Camera | None = None,
    seed: int = 0,
    variant: str | None = None,
) -> np.ndarray:
    """Render ``scene`` with Mitsuba's path tracer; returns (H, W, 3) float32
    linear radiance, ``image[0, 0]`` top-left (as voxgi's images)."""
    mi = mitsuba_module(variant)
    sc = mi.load_dict(to_mitsuba(scene, spp=spp, camera=camera, seed=seed))
    img = mi.render(sc, spp=int(spp), seed=int(seed))
    return np.ascontiguousarray(np.array(img, dtype=np.float32)[..., :3])


def record_reference(
    scene: Scene,
    vox,
    spp: int = 64,
    *,
    seed: int = 0,
    max_depth: int = -1,
    variant: str | None = None,
    rays_per_call: int = 1 << 22,
) -> np.ndarray:
    """The irradiance Mitsuba's path tracer finds at every record's point.

    From each record that reflects and has area, ``spp`` cosine-distributed
    rays leave its ``centroid`` on the side of its ``normal`` (offset as the
    solve's rays are, 1e-4 of the scene's diagonal), and Mitsuba's ``path``
    integrator returns the radiance along each, emitted light included. The
    irradiance is π times their mean. A diffuse record's reflected radiosity
    is its albedo times it (``vox.albedo * E``): what the solve's
    ``sol.radiosity - π vox.emission`` holds (``docs/design.md`` §9), at the
    record's point rather than over its part of the surface. A glossy
    record's solve weighs light by its incidence response instead (§14).

    Parameters
    ----------
    scene : Scene
        The scene ``vox`` was voxelized from.
    vox : VoxelSet
        The records.
    spp : int
        Rays per record.
    seed : int
        Seeds the directions and Mitsuba's sampler.
    max_depth : int
        The path integrator's depth (-1: none; 1: the emitted light along
        the rays, the direct light).
    variant : str, optional
        Mitsuba variant (default: :func:`mitsuba_module`'s).
    rays_per_call : int
        Rays handed to Mitsuba at once (bounds the memory).

    Returns
    -------
    (N, 3) float64
        Irradiance per record; 0 for records that do not reflect or have
        no area.
    """
    check_scene_and_records(scene, vox)
    spp = _validate.integer(spp, "spp", low=1, high=1 << 20)
    mi = mitsuba_module(variant)
    cam = scene.camera if scene.camera is not None else Camera(width=2, height=2)
    sc = mi.load_dict(to_mitsuba(scene, spp=1, camera=cam, max_depth=max_depth))
    integrator = sc.integrator()
    c = np.asarray(vox.centroid, np.float64)
    n = np.asarray(vox.normal, np.float64)
    live = np.flatnonzero((np.asarray(vox.area) > 0) & (np.asarray(vox.albedo).max(axis=1) > 0))
    eps = 1e-4 * float(np.linalg.norm(np.ptp(scene.bounds, axis=0)))
    out = np.zeros((len(vox), 3))
    rng = np.random.default_rng(seed)
    chunk = max(1, int(rays_per_call) // spp)
    for start in range(0, len(live), chunk):
        idx = live[start : start + chunk]
        nn = np.repeat(n[idx], spp, axis=0)
        o = np.repeat(c[idx], spp, axis=0) + eps * nn
        u1, u2 = rng.random(len(nn)), rng.random(len(nn))
        r, phi = np.sqrt(u1), 2.0 * np.pi * u2
        a = np.where(np.abs(nn[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
        tx = np.cross(nn, a)
        tx /= np.linalg.norm(tx, axis=1, keepdims=True)
        ty = np.cross(nn, tx)
        d = (r * np.cos(phi))[:, None] * tx + (r * np.sin(phi))[:, None] * ty
        d += np.sqrt(1.0 - u1)[:, None] * nn
        ray = mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.T))
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(int(seed) * 1_000_003 + start, len(nn))
        L = np.array(integrator.sample(sc, sampler, ray)[0], np.float64)
        L = L.T if L.shape[0] == 3 else L
        out[idx] = np.pi * L.reshape(len(idx), spp, 3).mean(axis=1)
    return out


#: The AOVs OIDN takes, from Mitsuba's ``aov`` integrator: the first hit's
#: albedo and shading normal.
AOVS = "albedo:albedo,nn:sh_normal"


def with_aovs(scene_dict: dict) -> dict:
    """``scene_dict`` (from :func:`to_mitsuba`) with its integrator wrapped in
    Mitsuba's ``aov`` integrator: a render then has 9 channels, the path
    tracer's RGB, the albedo and the shading normal (:data:`AOVS`)."""
    out = dict(scene_dict)
    out["integrator"] = {"type": "aov", "aovs": AOVS, "integrator": scene_dict["integrator"]}
    return out


def denoise_oidn(image: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """OIDN's denoised picture of a render of :func:`with_aovs`' scene.

    Parameters
    ----------
    image : (H, W, 9) array
        RGB, albedo, shading normal.
    camera : Camera
        The render's camera: each normal is turned to face it, as OIDN
        expects of the normals of the surfaces seen (Mitsuba's ``sh_normal``
        of a one-sided surface seen from behind points away).

    Returns
    -------
    (H, W, 3) float32, (H, W, 3) float32
        The denoised picture and the plain one.

    Raises
    ------
    ImportError
        When ``mitsuba-oidn`` is not installed (``pip install 'voxgi[bench]'``).
    """
    try:
        import mitsuba_oidn
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "OIDN is needed for the denoised comparison: pip install 'voxgi[bench]' "
            "(or pip install mitsuba-oidn)"
        ) from exc
    img = np.asarray(image, np.float32)
    if img.ndim != 3 or img.shape[2] != 9:
        raise ValueError(f"denoise_oidn: expected an (H, W, 9) render, got {img.shape}")
    colour = np.ascontiguousarray(img[..., :3])
    albedo = np.ascontiguousarray(np.clip(img[..., 3:6], 0.0, 1.0))
    normal = facing_camera(img[..., 6:9], camera)
    out = mitsuba_oidn.denoise(colour, albedo, normal, hdr=True)
    return np.ascontiguousarray(np.asarray(out, np.float32)), colour


def facing_camera(normal: np.ndarray, camera: Camera) -> np.ndarray:
    """(H, W, 3) float32 normals, each turned to face ``camera`` (against its
    pixel's ray through the pixel centre)."""
    from .display import camera_rays

    n = np.asarray(normal, np.float32).reshape(-1, 3)
    _, dirs = camera_rays(camera, (0.5, 0.5))
    away = np.einsum("ij,ij->i", n, dirs.reshape(-1, 3)) > 0
    return np.ascontiguousarray(np.where(away[:, None], -n, n).reshape(np.shape(normal)))
