"""Built-in scenes: the Cornell box, analytic furnaces, the bunny in a room.

Every function returns a fresh :class:`voxgi.Scene` with a camera set.
"""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import trimesh

from . import _validate
from .scene import Camera, Material, Scene

__all__ = ["bunny_room", "cap_sphere", "cornell_box", "furnace_box", "furnace_sphere", "names",
           "get"]

# Cornell box reflectances and light radiance as in Mitsuba 3's
# ``mi.cornell_box()`` (RGB fits of the measured spectra), so that the
# reference renders compare like with like.
CORNELL_WHITE = (0.885809, 0.698859, 0.666422)
CORNELL_GREEN = (0.105421, 0.37798, 0.076425)
CORNELL_RED = (0.570068, 0.0430135, 0.0443706)
CORNELL_LIGHT = (18.387, 13.9873, 6.75357)


def _oriented_quads(quads: np.ndarray, inside: np.ndarray | None = None,
                    outside: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate planar quads (Q, 4, 3), winding each so its normal points
    toward ``inside`` (a point) or away from ``outside``."""
    quads = np.asarray(quads, dtype=np.float64)
    verts, faces = [], []
    for q in quads:
        n = np.cross(q[1] - q[0], q[2] - q[0])
        c = q.mean(axis=0)
        want = (inside - c) if inside is not None else (c - outside)
        if np.dot(n, want) < 0:
            q = q[::-1]
        base = len(verts) * 4
        verts.append(q)
        faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.concatenate(verts), np.asarray(faces, dtype=np.int64)


def _mesh(quads, **kw) -> trimesh.Trimesh:
    v, f = _oriented_quads(np.asarray(quads) * 1e-3, **{k: np.asarray(p) * 1e-3 for k, p in kw.items()})
    return trimesh.Trimesh(v, f, process=False)


def cornell_box(width: int = 512, height: int = 512, light_offset: float = 0.01) -> Scene:
    """The Cornell box with its published dimensions, in metres.

    Geometry from the Cornell Program of Computer Graphics' measured data
    (floor 552.8 × 559.2 mm, height 548.8 mm, two blocks); camera at
    (278, 273, −800) mm looking down +z with a 35 mm lens on a 25 mm film
    (vertical fov 39.3°). The box is open toward the camera. Reflectances
    and light radiance are Mitsuba 3's ``cornell_box()`` RGB values.

    Parameters
    ----------
    width, height : int
        Image size of the camera.
    light_offset : float
        How far (metres) the one-sided light quad hangs under the ceiling.

    Returns
    -------
    Scene
        Objects ``floor``, ``ceiling``, ``back``, ``red`` (left), ``green``
        (right), ``short_block``, ``tall_block``, ``light``.
    """
    centre = np.array([278.0, 274.4, 279.6])
    s = Scene(Camera(eye=(0.278, 0.273, -0.800), target=(0.278, 0.273, 0.0), up=(0, 1, 0),
                     fov=39.3, width=width, height=height))
    white = Material(albedo=CORNELL_WHITE)
    walls = {
        "floor": [[552.8, 0, 0], [0, 0, 0], [0, 0, 559.2], [549.6, 0, 559.2]],
        "ceiling": [[556.0, 548.8, 0], [556.0, 548.8, 559.2], [0, 548.8, 559.2], [0, 548.8, 0]],
        "back": [[549.6, 0, 559.2], [0, 0, 559.2], [0, 548.8, 559.2], [556.0, 548.8, 559.2]],
    }
    for name, q in walls.items():
        s.add(_mesh([q], inside=centre), white, name=name)
    s.add(_mesh([[[552.8, 0, 0], [549.6, 0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0]]],
                inside=centre), Material(albedo=CORNELL_RED), name="red")
    s.add(_mesh([[[0, 0, 559.2], [0, 0, 0], [0, 548.8, 0], [0, 548.8, 559.2]]], inside=centre),
          Material(albedo=CORNELL_GREEN), name="green")
    short = [
        [[130, 165, 65], [82, 165, 225], [240, 165, 272], [290, 165, 114]],
        [[290, 0, 114], [290, 165, 114], [240, 165, 272], [240, 0, 272]],
        [[130, 0, 65], [130, 165, 65], [290, 165, 114], [290, 0, 114]],
        [[82, 0, 225], [82, 165, 225], [130, 165, 65], [130, 0, 65]],
        [[240, 0, 272], [240, 165, 272], [82, 165, 225], [82, 0, 225]],
    ]
    tall = [
        [[423, 330, 247], [265, 330, 296], [314, 330, 456], [472, 330, 406]],
        [[423, 0, 247], [423, 330, 247], [472, 330, 406], [472, 0, 406]],
        [[472, 0, 406], [472, 330, 406], [314, 330, 456], [314, 0, 456]],
        [[314, 0, 456], [314, 330, 456], [265, 330, 296], [265, 0, 296]],
        [[265, 0, 296], [265, 330, 296], [423, 330, 247], [423, 0, 247]],
    ]
    s.add(_mesh(short, outside=np.array([186.0, 82.5, 169.0])), white, name="short_block")
    s.add(_mesh(tall, outside=np.array([368.5, 165.0, 351.25])), white, name="tall_block")
    y = 548.8 - light_offset * 1e3
    light = [[[343.0, y, 227.0], [343.0, y, 332.0], [213.0, y, 332.0], [213.0, y, 227.0]]]
    s.add(_mesh(light, inside=np.array([278.0, 0.0, 279.5])),
          Material(albedo=0.0, emission=CORNELL_LIGHT), name="light")
    return s


def _inward(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    # A new mesh with reversed winding (trimesh's invert() may keep stale
    # cached face normals; DESIGN-NOTES §2).
    return trimesh.Trimesh(np.array(mesh.vertices), np.array(mesh.faces)[:, ::-1], process=False)


def _furnace_camera(width: int, height: int, eye=(0.0, 0.0, 0.0)) -> Camera:
    eye = np.asarray(eye, dtype=np.float64)
    return Camera(eye=tuple(eye), target=tuple(eye + [0.3, -0.2, -1.0]), up=(0, 1, 0), fov=90.0,
                  width=width, height=height)


def furnace_sphere(albedo=0.5, emission=1.0, radius: float = 1.0, subdivisions: int = 4,
                   inner: bool = False, width: int = 64, height: int = 64) -> Scene:
    """A closed sphere seen from inside, uniform emission and albedo.

    Every point has radiance ``Le / (1 - rho)`` (the furnace test).

    Parameters
    ----------
    albedo, emission : float or (3,) float
        Uniform albedo ``rho`` in [0, 1) and emitted radiance ``Le``.
    radius : float
        Sphere radius (scene units).
    subdivisions : int
        Icosphere subdivision level (4: 5120 triangles).
    inner : bool
        Add a closed box inside with the same material (the answer must not change).
    """
    _validate.integer(subdivisions, "subdivisions", low=0, high=7)
    radius = _validate.real(radius, "radius", low=0.0, low_open=True)
    mat = Material(albedo=albedo, emission=emission)
    s = Scene(_furnace_camera(width, height, eye=(0.0, 0.0, 0.55 * radius if inner else 0.0)))
    s.add(_inward(trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)), mat,
          name="sphere")
    if inner:
        box = trimesh.creation.box(extents=[0.5 * radius, 0.35 * radius, 0.4 * radius])
        box.apply_transform(trimesh.transformations.rotation_matrix(0.4, [1, 1, 0.3]))
        box.apply_translation([0.05 * radius, -0.1 * radius, -0.1 * radius])
        s.add(trimesh.Trimesh(box.vertices, box.faces, process=False), mat, name="inner_box")
    return s


def furnace_box(albedo=0.5, emission=1.0, size: float = 1.0, inner: bool = False,
                width: int = 64, height: int = 64) -> Scene:
    """A closed cube seen from inside, uniform emission and albedo.

    Every point has radiance ``Le / (1 - rho)``. With ``inner=True`` a closed
    sphere with the same material sits inside.
    """
    size = _validate.real(size, "size", low=0.0, low_open=True)
    mat = Material(albedo=albedo, emission=emission)
    s = Scene(_furnace_camera(width, height, eye=(0.0, 0.0, 0.3 * size if inner else 0.0)))
    s.add(_inward(trimesh.creation.box(extents=[size] * 3)), mat, name="box")
    if inner:
        ball = trimesh.creation.icosphere(subdivisions=3, radius=0.2 * size)
        ball.apply_translation([-0.1 * size, -0.15 * size, -0.1 * size])
        s.add(ball, mat, name="inner_sphere")
    return s


def cap_sphere(albedo=0.5, emission=1.0, cap_angle: float = 60.0, radius: float = 1.0,
               subdivisions: int = 5, width: int = 64, height: int = 64) -> Scene:
    """A closed sphere seen from inside whose polar cap alone emits.

    Inside a sphere every pair of points has the same form-factor kernel
    ``cos θx cos θy / (π r²) = 1 / A``, so
    ``L(x) = Le(x) + rho * Le_mean / (1 - rho)`` with ``Le_mean`` the
    area-weighted mean emission (DESIGN-NOTES §1). Triangles whose centroid
    lies within ``cap_angle`` degrees of +y form the object ``cap``.
    """
    cap_angle = _validate.real(cap_angle, "cap_angle", low=0.0, high=180.0, low_open=True,
                               high_open=True)
    sph = _inward(trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius))
    c = sph.triangles_center
    in_cap = c[:, 1] / np.linalg.norm(c, axis=1) > math.cos(math.radians(cap_angle))
    s = Scene(_furnace_camera(width, height))
    for name, sel, mat in (("cap", in_cap, Material(albedo=albedo, emission=emission)),
                           ("rest", ~in_cap, Material(albedo=albedo))):
        s.add(trimesh.Trimesh(sph.vertices, sph.faces[sel], process=False), mat, name=name)
    return s


def load_bunny() -> trimesh.Trimesh:
    """The Stanford bunny shipped with voxgi (3674 triangles, closed)."""
    ref = resources.files("voxgi") / "data" / "bunny.ply"
    with resources.as_file(ref) as p:
        return trimesh.load(p, force="mesh", process=False)


def bunny_room(width: int = 512, height: int = 512, bunny_albedo=0.75, room_albedo=0.7,
               light_radiance=(12.0, 12.0, 12.0)) -> Scene:
    """The Stanford bunny on the floor of a closed room lit by a ceiling light.

    A 4 × 3 × 4 room (scene units), normals inward; the bunny is 1.8 units
    wide; a one-sided 1 × 1 area light hangs 0.01 under the ceiling.
    """
    s = Scene(Camera(eye=(0.0, 1.5, 1.9), target=(0.0, 0.6, 0.0), up=(0, 1, 0), fov=50.0,
                     width=width, height=height))
    room = trimesh.creation.box(extents=[4.0, 3.0, 4.0])
    room.apply_translation([0.0, 1.5, 0.0])
    s.add(_inward(room), Material(albedo=room_albedo), name="room")
    bunny = load_bunny()
    lo, hi = bunny.bounds
    scale = 1.8 / (hi - lo)[0]
    v = (np.asarray(bunny.vertices) - [(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2]) * scale
    s.add(trimesh.Trimesh(v, bunny.faces, process=False), Material(albedo=bunny_albedo),
          name="bunny")
    y = 2.99
    light = trimesh.Trimesh([[-0.5, y, -0.5], [0.5, y, -0.5], [0.5, y, 0.5], [-0.5, y, 0.5]],
                            [[0, 1, 2], [0, 2, 3]], process=False)  # normal -y
    s.add(light, Material(albedo=0.0, emission=light_radiance), name="light")
    return s


_REGISTRY = {
    "cornell-box": cornell_box,
    "furnace-sphere": furnace_sphere,
    "furnace-box": furnace_box,
    "cap-sphere": cap_sphere,
    "bunny-room": bunny_room,
}


def names() -> list[str]:
    """Names of the built-in scenes, as the command line spells them."""
    return sorted(_REGISTRY)


def get(name: str, **kwargs) -> Scene:
    """A built-in scene by its command-line name (``cornell-box``, ...)."""
    key = name.replace("_", "-").lower()
    if key not in _REGISTRY:
        raise ValueError(f"unknown built-in scene {name!r}; known: {', '.join(names())}")
    return _REGISTRY[key](**kwargs)
