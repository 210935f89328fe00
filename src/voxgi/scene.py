"""Scene description: materials, camera, meshes, and TOML scene files.

A :class:`Scene` holds triangle meshes (``trimesh.Trimesh``) with a
:class:`Material` each, and a :class:`Camera`. Meshes are copied when added,
so nothing the user passes in is modified later.
"""

from __future__ import annotations

import hashlib
import io
import math
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from . import _validate, formats
from .io import atomic_path
from .lights import DELTA_LIGHTS, DirectionalLight, Environment, PointLight, SpotLight

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "AshikhminShirley",
    "Camera",
    "DirectionalLight",
    "Environment",
    "Material",
    "PointLight",
    "Scene",
    "SceneObject",
    "SpotLight",
]


@dataclass(frozen=True)
class AshikhminShirley:
    """Ashikhmin–Shirley anisotropic Phong specular layer (display only).

    Parameters
    ----------
    rs : float or (3,) float
        Specular reflectance at normal incidence, per RGB channel, in [0, 1].
    nu, nv : float
        Phong exponents along the tangent ``u`` and bitangent ``v`` (> 0).

    References
    ----------
    M. Ashikhmin and P. Shirley, "An anisotropic Phong BRDF model",
    Journal of Graphics Tools 5(2), 2000.
    """

    rs: tuple[float, float, float] = (0.04, 0.04, 0.04)
    nu: float = 100.0
    nv: float = 100.0

    def __post_init__(self):
        object.__setattr__(self, "rs", _validate.rgb(self.rs, "AshikhminShirley.rs", high=1.0))
        object.__setattr__(
            self,
            "nu",
            _validate.real(self.nu, "AshikhminShirley.nu", low=0.0, low_open=True, high=1e6),
        )
        object.__setattr__(
            self,
            "nv",
            _validate.real(self.nv, "AshikhminShirley.nv", low=0.0, low_open=True, high=1e6),
        )


@dataclass(frozen=True)
class Material:
    """A Lambertian material with optional emission and glossy layer.

    Parameters
    ----------
    albedo : float or (3,) float
        Diffuse reflectance ``rho`` per RGB channel, in [0, 1).
    emission : float or (3,) float
        Emitted radiance ``Le`` per RGB channel (>= 0), as for an area emitter
        in Mitsuba 3 or pbrt; the emitted radiosity is ``pi * Le``.
    specular : AshikhminShirley or None
        Optional glossy layer, used by the display only.
    """

    albedo: tuple[float, float, float] = (0.8, 0.8, 0.8)
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    specular: AshikhminShirley | None = None

    def __post_init__(self):
        # The kernels hold albedo and emission in float32: a value must stay
        # itself there (an albedo that rounds to 1 never converges).
        object.__setattr__(
            self,
            "albedo",
            _validate.rgb(
                self.albedo, "Material.albedo", high=1.0, high_inclusive=False, float32=True
            ),
        )
        object.__setattr__(
            self, "emission", _validate.rgb(self.emission, "Material.emission", float32=True)
        )
        if self.specular is not None and not isinstance(self.specular, AshikhminShirley):
            raise TypeError(
                "Material.specular: expected voxgi.AshikhminShirley or None, got "
                f"{type(self.specular).__name__}"
            )

    @property
    def is_emitter(self) -> bool:
        return max(self.emission) > 0.0


@dataclass(frozen=True)
class Camera:
    """A pinhole or thin-lens perspective camera.

    Parameters
    ----------
    eye, target, up : (3,) float
        Position, look-at point and up hint (need not be orthogonal).
    fov : float
        Vertical field of view in degrees, in (0, 180).
    width, height : int
        Image size in pixels (>= 1).
    aperture : float
        Thin-lens radius in scene units; 0 gives a pinhole.
    focus_distance : float or None
        Distance to the plane in focus; None means ``|target - eye|``.
    pixel_filter : {"box", "gaussian"}
        How samples make a pixel: averaged over the pixel (``"box"``), or
        weighted by Mitsuba 3's ``gaussian`` reconstruction filter (standard
        deviation 0.5 pixel, radius 2 pixels), which a Mitsuba scene uses
        unless its film says otherwise (``docs/design.md`` §6).

    Notes
    -----
    Image conventions: ``image[0, 0]`` is the top-left pixel; rows go down
    (``-up``) and columns go right, ``right = forward x up``.
    """

    eye: tuple = (0.0, 0.0, 1.0)
    target: tuple = (0.0, 0.0, 0.0)
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 39.3
    width: int = 512
    height: int = 512
    aperture: float = 0.0
    focus_distance: float | None = None
    pixel_filter: str = "box"

    def __post_init__(self):
        if self.pixel_filter not in ("box", "gaussian"):
            raise ValueError(
                f"Camera.pixel_filter: expected 'box' or 'gaussian', got {self.pixel_filter!r}"
            )
        eye = _validate.vec3(self.eye, "Camera.eye")
        target = _validate.vec3(self.target, "Camera.target")
        up = _validate.vec3(self.up, "Camera.up")
        object.__setattr__(self, "eye", tuple(eye.tolist()))
        object.__setattr__(self, "target", tuple(target.tolist()))
        object.__setattr__(self, "up", tuple(up.tolist()))
        fwd = target - eye
        if np.linalg.norm(fwd) <= 1e-12 * max(1.0, np.linalg.norm(eye)):
            raise ValueError(f"Camera: eye {eye.tolist()} and target {target.tolist()} coincide")
        side = np.linalg.norm(np.cross(fwd / np.linalg.norm(fwd), up))
        if side < 1e-6 * max(np.linalg.norm(up), 1e-300):
            raise ValueError(f"Camera.up {up.tolist()} is zero or parallel to the view direction")
        object.__setattr__(
            self,
            "fov",
            _validate.real(
                self.fov, "Camera.fov", low=0.0, high=180.0, low_open=True, high_open=True
            ),
        )
        object.__setattr__(
            self, "width", _validate.integer(self.width, "Camera.width", low=1, high=1 << 15)
        )
        object.__setattr__(
            self, "height", _validate.integer(self.height, "Camera.height", low=1, high=1 << 15)
        )
        object.__setattr__(
            self, "aperture", _validate.real(self.aperture, "Camera.aperture", low=0.0)
        )
        object.__setattr__(
            self,
            "focus_distance",
            _validate.real(
                self.focus_distance,
                "Camera.focus_distance",
                low=0.0,
                low_open=True,
                allow_none=True,
            ),
        )

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Orthonormal ``(right, up, forward)`` basis, float64 (3,) each."""
        eye, target = np.asarray(self.eye), np.asarray(self.target)
        fwd = (target - eye) / np.linalg.norm(target - eye)
        right = np.cross(fwd, np.asarray(self.up))
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        return right, up, fwd

    @property
    def focus(self) -> float:
        """Focus distance actually used (``|target - eye|`` when unset)."""
        if self.focus_distance is not None:
            return float(self.focus_distance)
        return float(np.linalg.norm(np.asarray(self.target) - np.asarray(self.eye)))

    def replace(self, **changes) -> Camera:
        """A copy with some fields changed (validated again)."""
        kw = {f: getattr(self, f) for f in self.__dataclass_fields__}
        kw.update(changes)
        return Camera(**kw)


@dataclass
class SceneObject:
    """One mesh of a scene: float64 vertices, int64 faces, a material."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    material: Material
    two_sided: bool = False
    vertex_normals: np.ndarray | None = None
    source: str | None = None  # mesh file it came from, if any
    transform: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_triangles(self) -> int:
        return len(self.faces)

    def area(self) -> float:
        """Total area of the non-degenerate triangles (scene units²)."""
        t = self.vertices[self.faces]
        cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        return float(0.5 * np.linalg.norm(cross, axis=1).sum())

    def to_trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)


def _mesh_arrays(mesh, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Copy and check a trimesh's vertices and faces; drop degenerate faces."""
    if isinstance(mesh, trimesh.Scene):
        mesh = mesh.to_geometry() if hasattr(mesh, "to_geometry") else mesh.dump(concatenate=True)
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"mesh {name!r}: expected trimesh.Trimesh, got {type(mesh).__name__}")
    v = np.array(mesh.vertices, dtype=np.float64, copy=True)
    f = np.array(mesh.faces, dtype=np.int64, copy=True)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"mesh {name!r}: vertices must have shape (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"mesh {name!r}: faces must have shape (F, 3), got {f.shape}")
    if len(f) == 0:
        raise ValueError(f"mesh {name!r}: has no faces")
    if not np.all(np.isfinite(v)):
        bad = int(np.argwhere(~np.isfinite(v).all(axis=1))[0, 0])
        raise ValueError(f"mesh {name!r}: vertex {bad} is not finite: {v[bad].tolist()}")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"mesh {name!r}: face indices out of range [0, {len(v)})")
    # Degenerate faces (zero area, repeated vertex, collinear corners) carry
    # no light: drop them. The test is relative to each triangle's own size,
    # so that a scene far from the origin or at any scale keeps its faces.
    t = v[f]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    dbl_area = np.linalg.norm(np.cross(e1, e2), axis=1)
    edge2 = np.max([np.einsum("ij,ij->i", e, e) for e in (e1, e2, e2 - e1)], axis=0)
    keep = dbl_area > 1e-12 * edge2
    if not keep.all():
        warnings.warn(
            f"mesh {name!r}: skipped {int((~keep).sum())} degenerate face(s) (zero area)",
            UserWarning,
            stacklevel=3,
        )
        f = f[keep]
        if len(f) == 0:
            raise ValueError(f"mesh {name!r}: all faces are degenerate")
    vn = None
    # Shading normals only when the file carried them (trimesh otherwise derives them).
    if "vertex_normals" in mesh._cache.cache:
        vn = np.array(mesh.vertex_normals, dtype=np.float64, copy=True)
        if vn.shape != v.shape or not np.all(np.isfinite(vn)):
            vn = None
    return v, f, vn


class Scene:
    """Meshes with materials, and a camera.

    Parameters
    ----------
    camera : Camera, optional
        The view used by :func:`voxgi.render`; may be set later.

    Examples
    --------
    >>> import trimesh, voxgi
    >>> scene = voxgi.Scene()
    >>> box = scene.add(trimesh.creation.box(), voxgi.Material(albedo=0.5), name="box")
    >>> len(scene.objects)
    1
    """

    def __init__(self, camera: Camera | None = None):
        self.objects: list[SceneObject] = []
        #: Point, spot and directional lights (:meth:`add_light`).
        self.lights: list[PointLight | SpotLight | DirectionalLight] = []
        self.camera = camera
        self.environment = None

    # -- lights -------------------------------------------------------------
    def add_light(self, light: PointLight | SpotLight | DirectionalLight):
        """Add a point, spot or directional light (``voxgi.lights``); returns it.

        >>> import voxgi
        >>> scene = voxgi.Scene()
        >>> scene.add_light(voxgi.PointLight((0, 1, 0), 5.0)).intensity
        (5.0, 5.0, 5.0)
        """
        if not isinstance(light, DELTA_LIGHTS):
            raise TypeError(
                "Scene.add_light: expected voxgi.PointLight, SpotLight or DirectionalLight "
                f"(an environment goes in Scene.environment), got {type(light).__name__}"
            )
        self.lights.append(light)
        return light

    @property
    def environment(self) -> Environment | None:
        """The radiance from infinitely far away (:class:`voxgi.Environment`) or None."""
        return self._environment

    @environment.setter
    def environment(self, env: Environment | None) -> None:
        if env is not None and not isinstance(env, Environment):
            raise TypeError(
                f"Scene.environment: expected voxgi.Environment or None, got {type(env).__name__}"
            )
        self._environment = env

    @property
    def has_lights(self) -> bool:
        """Whether the scene has delta lights or an environment (besides emitting meshes)."""
        return bool(self.lights) or self.environment is not None

    # -- camera -------------------------------------------------------------
    @property
    def camera(self) -> Camera | None:
        return self._camera

    @camera.setter
    def camera(self, cam: Camera | None) -> None:
        if cam is not None and not isinstance(cam, Camera):
            raise TypeError(f"Scene.camera: expected voxgi.Camera, got {type(cam).__name__}")
        self._camera = cam

    # -- building -----------------------------------------------------------
    def add(
        self,
        mesh,
        material: Material | None = None,
        name: str | None = None,
        two_sided: bool = False,
    ) -> SceneObject:
        """Add a triangle mesh with a material.

        Parameters
        ----------
        mesh : trimesh.Trimesh
            Copied; the caller's mesh is not modified. Faces of zero area are
            dropped with a warning.
        material : Material, optional
            Defaults to ``Material()`` (albedo 0.8, no emission).
        name : str, optional
            Used in messages; defaults to ``"mesh<k>"``.
        two_sided : bool
            Both sides reflect (and emit, for an emitter). A one-sided surface
            is black and opaque from behind.

        Returns
        -------
        SceneObject
        """
        if name is None:
            name = f"mesh{len(self.objects)}"
        if not isinstance(name, str):
            raise TypeError(f"Scene.add: name must be a str, got {type(name).__name__}")
        if material is None:
            material = Material()
        if not isinstance(material, Material):
            raise TypeError(
                f"mesh {name!r}: material must be voxgi.Material, got {type(material).__name__}"
            )
        if not isinstance(two_sided, (bool, np.bool_)):
            raise TypeError(f"mesh {name!r}: two_sided must be a bool, got {two_sided!r}")
        v, f, vn = _mesh_arrays(mesh, name)
        obj = SceneObject(
            name=name,
            vertices=v,
            faces=f,
            material=material,
            two_sided=bool(two_sided),
            vertex_normals=vn,
        )
        self.objects.append(obj)
        return obj

    # -- queries ------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.objects)

    def __repr__(self) -> str:
        extra = f", {len(self.lights)} lights" if self.lights else ""
        extra += ", environment" if self.environment is not None else ""
        return (
            f"Scene({len(self.objects)} objects, {self.n_triangles} triangles{extra}, "
            f"camera={'set' if self.camera else 'None'})"
        )

    @property
    def n_triangles(self) -> int:
        return int(sum(o.n_triangles for o in self.objects))

    def check_nonempty(self) -> None:
        if not self.objects:
            raise ValueError("scene is empty: add at least one mesh (Scene.add)")

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64 axis-aligned bounding box of all meshes."""
        self.check_nonempty()
        lo = np.min([o.vertices[np.unique(o.faces)].min(axis=0) for o in self.objects], axis=0)
        hi = np.max([o.vertices[np.unique(o.faces)].max(axis=0) for o in self.objects], axis=0)
        return np.stack([lo, hi])

    def area(self) -> float:
        """Total surface area of the scene (scene units²)."""
        return float(sum(o.area() for o in self.objects))

    def triangles(self) -> dict[str, np.ndarray]:
        """All triangles concatenated.

        Returns
        -------
        dict
            ``triangles`` (F, 3, 3) float64 corner positions, ``object`` (F,)
            int32 index into :attr:`objects`, ``albedo``/``emission`` (O, 3)
            float32 per object, ``two_sided`` (O,) bool per object.
        """
        self.check_nonempty()
        tri = np.concatenate([o.vertices[o.faces] for o in self.objects])
        obj = np.concatenate(
            [np.full(len(o.faces), i, np.int32) for i, o in enumerate(self.objects)]
        )
        return {
            "triangles": np.ascontiguousarray(tri),
            "object": obj,
            "albedo": np.array([o.material.albedo for o in self.objects], np.float32),
            "emission": np.array([o.material.emission for o in self.objects], np.float32),
            "two_sided": np.array([o.two_sided for o in self.objects], bool),
        }

    def fingerprint(self) -> str:
        """Hash of geometry, materials and lights: tells a solution which scene it belongs to.

        The camera is not part of it: a new view reuses a solution.
        """
        h = hashlib.sha1()
        for o in self.objects:
            h.update(o.vertices.tobytes())
            h.update(o.faces.tobytes())
            h.update(repr((o.material.albedo, o.material.emission, o.two_sided)).encode())
        for light in self.lights:
            h.update(repr(light).encode())
        if self.environment is not None:
            h.update(b"environment" + self.environment.digest().encode())
        return h.hexdigest()[:16]

    @property
    def has_specular(self) -> bool:
        return any(o.material.specular is not None for o in self.objects)

    # -- files --------------------------------------------------------------
    @classmethod
    def load(cls, path) -> Scene:
        """Load a scene file: voxgi's TOML, Mitsuba 3 XML, OBJ with MTL or glTF 2.0.

        The suffix picks the reader: ``.toml`` (below), ``.xml``, ``.obj``,
        ``.gltf`` and ``.glb`` (:mod:`voxgi.formats`, docs/design.md §12;
        what they approximate or leave out is listed in a
        :class:`voxgi.formats.SceneWarning`).

        The file has an optional ``[camera]`` table (the :class:`Camera`
        fields), optional ``[materials.NAME]`` tables and ``[[object]]``
        entries::

            [camera]
            eye = [0, 1, 3]
            target = [0, 1, 0]
            fov = 40
            width = 256
            height = 256

            [materials.white]
            albedo = [0.8, 0.8, 0.8]

            [[object]]
            mesh = "floor.ply"      # relative to the TOML file; OBJ, PLY, STL, GLB
            material = "white"      # or inline: albedo = ..., emission = ...
            name = "floor"
            two_sided = false
            translate = [0, 0, 0]   # optional transform: scale, then rotate, then translate
            rotate = [90, 1, 0, 0]  # degrees about an axis
            scale = 1.0             # or [sx, sy, sz]
            # matrix = [[...4x4...]] instead of the three above

            [[light]]               # point, spot or directional (voxgi.lights)
            type = "spot"
            position = [0, 2, 0]
            direction = [0, -1, 0]
            intensity = [5, 5, 5]   # W/sr; "irradiance" for a directional light
            cutoff_angle = 30       # degrees; beam_width optional

            [environment]
            radiance = [1, 1, 1]    # or image = "sky.exr" (lat-long, relative path)
            scale = 1.0             # optional; to_world = [[...3x3 or 4x4...]] optional

        Raises
        ------
        ValueError
            Malformed TOML (with line and column), unknown keys, bad values
            (naming the object and key), missing mesh files.
        """
        path = Path(path)
        loader = formats.LOADERS.get(path.suffix.lower())
        if loader is not None:
            return cls._from_data(loader(path), str(path))
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise FileNotFoundError(f"scene file not found: {path}") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"scene file {path}: cannot be read ({exc})") from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"scene file {path}: malformed TOML: {exc}") from None
        except RecursionError:
            raise ValueError(
                f"scene file {path}: arrays or tables nested too deeply to be a scene file"
            ) from None
        try:
            return cls.from_dict(data, base_dir=path.parent, source=str(path))
        except ValueError as exc:
            line = _error_line(text, data, str(exc))
            if line is None:
                raise
            raise ValueError(f"{exc} (line {line})") from None

    @classmethod
    def _from_data(cls, data: formats.SceneData, source: str) -> Scene:
        """The scene of what a :mod:`voxgi.formats` loader read."""
        scene = cls()
        if data.camera is not None:
            scene.camera = _camera_from_dict(data.camera, source)
        for m in data.meshes:
            try:
                mat = Material(albedo=m.albedo, emission=m.emission)
                obj = scene.add(
                    trimesh.Trimesh(m.vertices, m.faces, process=False),
                    mat,
                    name=m.name,
                    two_sided=m.two_sided,
                )
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{source}: mesh {m.name!r}: {exc}") from None
            obj.source = m.source
        for k, entry in enumerate(data.lights):
            scene.add_light(_light_from_dict(entry, f"{source}: light #{k}"))
        if data.environment is not None:
            scene.environment = _environment_from_dict(
                data.environment, source, Path(source).parent
            )
        return scene

    @classmethod
    def from_dict(cls, data: dict, base_dir=".", source: str = "<dict>") -> Scene:
        """Build a scene from the parsed contents of a scene file (see :meth:`load`)."""
        base_dir = Path(base_dir)
        _check_top_level(data, source)
        scene = cls()
        if "camera" in data:
            scene.camera = _camera_from_dict(data["camera"], source)
        materials = _materials_from_dict(data.get("materials", {}), source)
        objs = data.get("object", [])
        if not isinstance(objs, list):
            raise ValueError(f"{source}: 'object' must be an array of tables ([[object]])")
        for k, o in enumerate(objs):
            _add_object_from_dict(scene, o, f"{source}: object #{k}", materials, base_dir)
        lights = data.get("light", [])
        if not isinstance(lights, list):
            raise ValueError(f"{source}: 'light' must be an array of tables ([[light]])")
        for k, entry in enumerate(lights):
            scene.add_light(_light_from_dict(entry, f"{source}: light #{k}"))
        if "environment" in data:
            scene.environment = _environment_from_dict(data["environment"], source, base_dir)
        return scene

    def save(self, path) -> Path:
        """Write the scene as a TOML file with one mesh file per object beside it.

        Meshes are written already transformed as OBJ with 17 significant
        digits (PLY and GLB would round vertices to float32), so ``Scene.load``
        of the result gives bit-identical geometry, materials and camera.
        """
        import tomli_w  # (writes any name as valid TOML: control characters escaped)

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        doc: dict = {}
        if self.camera is not None:
            c = self.camera
            doc["camera"] = {f: [float(x) for x in getattr(c, f)] for f in ("eye", "target", "up")}
            doc["camera"].update(
                fov=float(c.fov), aperture=float(c.aperture), width=c.width, height=c.height
            )
            if c.focus_distance is not None:
                doc["camera"]["focus_distance"] = float(c.focus_distance)
            if c.pixel_filter != "box":
                doc["camera"]["pixel_filter"] = c.pixel_filter
        objects = []
        for i, o in enumerate(self.objects):
            fname = f"{path.stem}_{i:03d}.obj"
            with atomic_path(path.parent / fname) as tmp:
                tmp.write_text(_obj_text(o.vertices, o.faces))
            entry = {
                "name": o.name,
                "mesh": fname,
                "albedo": [float(x) for x in o.material.albedo],
                "emission": [float(x) for x in o.material.emission],
                "two_sided": bool(o.two_sided),
            }
            spec = o.material.specular
            if spec is not None:
                entry["specular"] = {
                    "rs": [float(x) for x in spec.rs],
                    "nu": float(spec.nu),
                    "nv": float(spec.nv),
                }
            objects.append(entry)
        if objects:
            doc["object"] = objects
        if self.lights:
            doc["light"] = [_light_to_dict(light) for light in self.lights]
        if self.environment is not None:
            doc["environment"] = _environment_to_dict(self.environment, path)
        text = tomli_w.dumps(doc)
        with atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
        return path


def _obj_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    """OBJ text of a mesh, every float with 17 significant digits.

    ``%.17g`` reads back as the same float64 at any magnitude (a fixed
    number of decimals would not, below 0.1).
    """
    buf = io.StringIO()
    np.savetxt(buf, vertices, fmt="v %.17g %.17g %.17g")
    np.savetxt(buf, faces + 1, fmt="f %d %d %d")
    return buf.getvalue()


# Mesh formats that are text only: trimesh guesses the encoding of any
# other bytes with an optional package and reports that package missing.
_TEXT_MESH_FORMATS = {".obj", ".off"}


#: Keys of an ``[[object]]`` table that give its material inline.
_OBJECT_MATERIAL_KEYS = {"albedo", "emission", "specular"}
#: Every key an ``[[object]]`` table may have.
_OBJECT_KEYS = {
    "mesh",
    "material",
    "name",
    "two_sided",
    "translate",
    "rotate",
    "scale",
    "matrix",
} | _OBJECT_MATERIAL_KEYS


def _check_top_level(data, source: str) -> None:
    """Raise unless ``data`` is a table with only the known top-level keys."""
    if not isinstance(data, dict):
        raise TypeError(f"{source}: expected a table at the top level")
    unknown = set(data) - {"camera", "materials", "object", "light", "environment"}
    if unknown:
        raise ValueError(
            f"{source}: unknown top-level key(s) {sorted(unknown)}; "
            "expected camera, materials, object, light, environment"
        )


#: The ``[[light]]`` types and the class of each.
_LIGHT_TYPES = {"point": PointLight, "spot": SpotLight, "directional": DirectionalLight}


def _light_from_dict(entry, where: str):
    """The light of one ``[[light]]`` table: ``type`` and the class's fields."""
    if not isinstance(entry, dict):
        raise ValueError(f"{where}: must be a table")
    kind = entry.get("type")
    if kind not in _LIGHT_TYPES:
        raise ValueError(f"{where}: 'type' must be one of {sorted(_LIGHT_TYPES)}, got {kind!r}")
    cls = _LIGHT_TYPES[kind]
    fields = {k: v for k, v in entry.items() if k != "type"}
    allowed = set(cls.__dataclass_fields__)
    bad = set(fields) - allowed
    if bad:
        raise ValueError(
            f"{where} ({kind}): unknown key(s) {sorted(bad)}; expected {sorted(allowed)}"
        )
    try:
        return cls(**fields)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where} ({kind}): {exc}") from None


def _light_to_dict(light) -> dict:
    kind = next(k for k, c in _LIGHT_TYPES.items() if isinstance(light, c))
    out: dict = {"type": kind}
    for name in light.__dataclass_fields__:
        v = getattr(light, name)
        out[name] = [float(x) for x in v] if isinstance(v, tuple) else float(v)
    return out


def _environment_from_dict(env, source: str, base_dir: Path) -> Environment:
    where = f"{source}: [environment]"
    if not isinstance(env, dict):
        raise ValueError(f"{where} must be a table")
    bad = set(env) - {"radiance", "image", "scale", "to_world"}
    if bad:
        raise ValueError(
            f"{where}: unknown key(s) {sorted(bad)}; expected radiance or image, scale, to_world"
        )
    if ("radiance" in env) == ("image" in env):
        raise ValueError(f"{where}: give exactly one of 'radiance' (RGB) and 'image' (a path)")
    try:
        if "image" in env:
            if not isinstance(env["image"], str):
                raise ValueError(f"'image' must be a path string, got {env['image']!r}")
            img = Path(env["image"])
            radiance = img if img.is_absolute() else base_dir / img
        else:
            radiance = env["radiance"]
        return Environment(radiance, to_world=env.get("to_world"), scale=env.get("scale", 1.0))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _environment_to_dict(env: Environment, path: Path) -> dict:
    """An ``[environment]`` table; an image is written as an EXR beside the scene file."""
    out: dict = {}
    if env.constant is not None and env.image.shape[:2] == (1, 1):
        out["radiance"] = [float(x) for x in env.image[0, 0]]
    else:
        from .io import write_exr

        fname = f"{path.stem}_environment.exr"
        write_exr(path.parent / fname, env.image.astype(np.float32))
        out["image"] = fname
    if not np.array_equal(env.to_world, np.eye(3)):
        out["to_world"] = [[float(x) for x in row] for row in env.to_world]
    return out


def _camera_from_dict(cam, source: str) -> Camera:
    """The :class:`Camera` of a ``[camera]`` table."""
    if not isinstance(cam, dict):
        raise ValueError(f"{source}: [camera] must be a table")
    try:
        return Camera(**cam)
    except TypeError as exc:
        raise ValueError(f"{source}: [camera]: {exc}") from None
    except ValueError as exc:
        raise ValueError(f"{source}: [camera]: {exc}") from None


def _materials_from_dict(mats, source: str) -> dict[str, Material]:
    """The named materials of a ``[materials]`` table."""
    if not isinstance(mats, dict):
        raise ValueError(f"{source}: [materials] must be a table of tables")
    return {
        mname: _material_from_dict(m, f"{source}: [materials.{mname}]") for mname, m in mats.items()
    }


def _check_object_keys(o, where: str) -> str:
    """Check an ``[[object]]`` table's keys and types; returns ``where`` with its name."""
    if not isinstance(o, dict):
        raise ValueError(f"{where}: must be a table")
    if "name" in o:
        where += f" ({o['name']!r})"
    bad = set(o) - _OBJECT_KEYS
    if bad:
        raise ValueError(f"{where}: unknown key(s) {sorted(bad)}")
    if "mesh" not in o:
        raise ValueError(f"{where}: missing key 'mesh'")
    for key in ("mesh", "material", "name"):
        if key in o and not isinstance(o[key], str):
            raise ValueError(
                f"{where}: '{key}' must be a string, got {type(o[key]).__name__} {o[key]!r}"
            )
    return where


def _object_material(o: dict, where: str, materials: dict[str, Material]) -> Material:
    """An object's material: a named one from ``[materials]`` or its inline keys."""
    if "material" not in o:
        return _material_from_dict({k: o[k] for k in _OBJECT_MATERIAL_KEYS if k in o}, where)
    if set(o) & _OBJECT_MATERIAL_KEYS:
        raise ValueError(f"{where}: give either 'material' or inline albedo/emission")
    if o["material"] not in materials:
        raise ValueError(
            f"{where}: unknown material {o['material']!r}; defined: {sorted(materials)}"
        )
    return materials[o["material"]]


def _add_object_from_dict(
    scene: Scene, o, where: str, materials: dict[str, Material], base_dir: Path
) -> None:
    """Load, transform and add to ``scene`` the mesh of one ``[[object]]`` table."""
    where = _check_object_keys(o, where)
    mat = _object_material(o, where, materials)
    mesh_path = Path(o["mesh"])
    if not mesh_path.is_absolute():
        mesh_path = base_dir / mesh_path
    if not mesh_path.exists():
        raise ValueError(f"{where}: mesh file not found: {mesh_path}")
    mesh = _load_mesh(mesh_path, where)
    matrix = _transform_from_dict(o, where)
    if matrix is not None:
        mesh = mesh.copy()
        mesh.apply_transform(matrix)
    name = o.get("name", mesh_path.stem)
    try:
        obj = scene.add(mesh, mat, name=name, two_sided=o.get("two_sided", False))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None
    obj.source = str(o["mesh"])
    obj.transform = matrix


def _load_mesh(mesh_path: Path, where: str) -> trimesh.Trimesh:
    """Read a mesh file through trimesh; ValueError naming the file if it cannot."""
    kind = mesh_path.suffix.lower()
    if kind in _TEXT_MESH_FORMATS:
        try:
            data = mesh_path.read_bytes()
        except OSError as exc:
            raise ValueError(f"{where}: cannot read mesh file {mesh_path}: {exc}") from None
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ValueError(
                f"{where}: mesh file {mesh_path} is not UTF-8 text (byte "
                f"{exc.start}), so not a {kind[1:].upper()} file"
            ) from None
    try:
        return trimesh.load(mesh_path, force="mesh", process=False, maintain_order=True)
    except ImportError as exc:  # an optional decoder trimesh wanted for odd content
        raise ValueError(
            f"{where}: cannot load mesh {mesh_path}: unreadable content ({exc})"
        ) from None
    except Exception as exc:
        raise ValueError(f"{where}: cannot load mesh {mesh_path}: {exc}") from None


def _error_line(text: str, data, msg: str) -> int | None:
    """1-based line of the table and key that a :meth:`Scene.from_dict` error names.

    The message names the table (``object #k``, ``[camera]``,
    ``[materials.NAME]``) and usually a key; the line is the key's ``key =``
    line within that table, else the table's header line.
    """
    import re

    m = re.search(r"(object|light) #(\d+)", msg)
    if m:
        want, table = (m.group(1), int(m.group(2))), None
        objs = data.get(m.group(1)) if isinstance(data, dict) else None
        table = objs[want[1]] if isinstance(objs, list) and want[1] < len(objs) else None
    elif m := re.search(r"\[materials\.([^\]]+)\]", msg):
        want = ("materials", m.group(1))
        mats = data.get("materials") if isinstance(data, dict) else None
        table = mats.get(want[1]) if isinstance(mats, dict) else None
    elif "[camera]" in msg:
        want, table = ("camera",), data.get("camera") if isinstance(data, dict) else None
    elif "[environment]" in msg:
        want = ("environment",)
        table = data.get("environment") if isinstance(data, dict) else None
    else:
        want, table = (None,), data
    # the key named in the message (longest first, so "focus_distance" beats "focus")
    keys = sorted(table, key=len, reverse=True) if isinstance(table, dict) else []
    key = next(
        (
            k
            for k in keys
            if re.search(rf"(?<!\w){re.escape(str(k))}(?!\w)", msg.split(": ", 1)[-1])
        ),
        None,
    )
    section: tuple = (None,)
    n_obj = {"object": -1, "light": -1}
    header = None
    for i, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if h := re.match(r"^\[\[\s*(object|light)\s*\]\]", line):
            n_obj[h.group(1)] += 1
            section = (h.group(1), n_obj[h.group(1)])
        elif h := re.match(r"^\[\s*materials\.\s*[\"']?([^\]\"']+)[\"']?\s*\]", line):
            section = ("materials", h.group(1).strip())
        elif h := re.match(r"^\[\s*(camera|environment)\s*\]", line):
            section = (h.group(1),)
        elif line.startswith("["):
            section = ("other",)
        else:
            if (
                section == want
                and key is not None
                and re.match(rf"^[\"']?{re.escape(str(key))}[\"']?\s*=", line)
            ):
                return i
            continue
        if section == want and header is None:
            header = i
    return header


def _material_from_dict(m, where: str) -> Material:
    if not isinstance(m, dict):
        raise ValueError(f"{where}: material must be a table")
    bad = set(m) - {"albedo", "emission", "specular"}
    if bad:
        raise ValueError(f"{where}: unknown material key(s) {sorted(bad)}")
    spec = m.get("specular")
    try:
        if spec is not None:
            if not isinstance(spec, dict):
                raise ValueError("specular must be a table {rs, nu, nv}")
            spec = AshikhminShirley(**spec)
        kw = {k: m[k] for k in ("albedo", "emission") if k in m}
        return Material(specular=spec, **kw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _transform_from_dict(o: dict, where: str) -> np.ndarray | None:
    keys = {"translate", "rotate", "scale", "matrix"} & set(o)
    if not keys:
        return None
    try:
        if "matrix" in o:
            if keys - {"matrix"}:
                raise ValueError("give either 'matrix' or translate/rotate/scale")
            m = np.asarray(o["matrix"], dtype=np.float64)
            if m.shape != (4, 4) or not np.all(np.isfinite(m)):
                raise ValueError(f"matrix must be 4x4 finite, got shape {m.shape}")
            return m
        m = np.eye(4)
        if "scale" in o:
            s = np.broadcast_to(np.asarray(o["scale"], dtype=np.float64), (3,))
            if not np.all(np.isfinite(s)) or np.any(s == 0):
                raise ValueError(f"scale must be finite and non-zero, got {o['scale']!r}")
            m = np.diag([*s, 1.0]) @ m
        if "rotate" in o:
            r = np.asarray(o["rotate"], dtype=np.float64)
            if r.shape != (4,) or not np.all(np.isfinite(r)) or np.linalg.norm(r[1:]) == 0:
                raise ValueError(f"rotate must be [degrees, ax, ay, az], got {o['rotate']!r}")
            m = trimesh.transformations.rotation_matrix(math.radians(r[0]), r[1:]) @ m
        if "translate" in o:
            t = _validate.vec3(o["translate"], "translate")
            m = trimesh.transformations.translation_matrix(t) @ m
        return m
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None
