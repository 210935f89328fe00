"""Scene description: meshes with materials, lights and a camera.

A :class:`Scene` holds triangle meshes (``trimesh.Trimesh``) with a
:class:`Material` each, and a :class:`Camera`. Meshes are copied when added,
so nothing the user passes in is modified later. Scene files are read and
written by :mod:`voxgi.formats`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from . import _validate, formats
from .camera import Camera
from .lights import DELTA_LIGHTS, DirectionalLight, Environment, PointLight, SpotLight
from .materials import AshikhminShirley, Material
from .microfacet import Microfacet

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


def _stable_repr(x) -> str:
    """``repr(x)`` with numpy arrays and scalars written as the Python numbers
    they hold: the same text whatever numpy's print options (which shorten an
    array's repr), and every digit of a float. For plain Python values and
    dataclasses of them it is ``repr(x)`` itself, so their fingerprints stay."""
    if isinstance(x, np.ndarray):
        x = x.tolist()
        if isinstance(x, list):
            return _stable_repr(tuple(x))
    if isinstance(x, np.generic):
        return repr(x.item())
    if isinstance(x, tuple):
        inner = ", ".join(_stable_repr(v) for v in x)
        return f"({inner},)" if len(x) == 1 else f"({inner})"
    if isinstance(x, list):
        return "[" + ", ".join(_stable_repr(v) for v in x) + "]"
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        fields = ", ".join(
            f"{f.name}={_stable_repr(getattr(x, f.name))}" for f in dataclasses.fields(x) if f.repr
        )
        return f"{type(x).__qualname__}({fields})"
    return repr(x)


def _used_bounds(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest corner of the vertices ``faces`` use (a mask, not a
    sort: a mesh's unused vertices do not count)."""
    used = np.zeros(len(vertices), bool)
    used[faces.ravel()] = True
    v = vertices[used]
    return v.min(axis=0), v.max(axis=0)


@dataclass
class SceneObject:
    """One mesh of a scene: float64 vertices, int64 faces, a material, and
    (V, 2) float64 texture coordinates ``uv`` when its material has a texture
    (``v = 0`` the image's top row, as Mitsuba 3 holds UVs)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    material: Material
    two_sided: bool = False
    vertex_normals: np.ndarray | None = None
    source: str | None = None  # mesh file it came from, if any
    transform: np.ndarray | None = field(default=None, repr=False)
    uv: np.ndarray | None = field(default=None, repr=False)

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
    # Degenerate faces carry no light: drop them.
    keep = _validate.nondegenerate(v, f)
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


def _mesh_uv(mesh, uv, n_vertices: int, name: str, textured: bool) -> np.ndarray | None:
    """The (V, 2) float64 UVs of a textured mesh: given, or its visual's (v
    turned to the image's top); None for an untextured one."""
    if not textured:
        return None
    if uv is None:
        vis = getattr(mesh, "visual", None)
        vuv = getattr(vis, "uv", None)
        if vuv is None:
            raise ValueError(f"mesh {name!r}: a textured material needs UVs (Scene.add's uv)")
        uv = np.array(vuv, np.float64)
        uv[:, 1] = 1.0 - uv[:, 1]
    uv = np.array(uv, np.float64, copy=True)
    if uv.shape != (n_vertices, 2):
        raise ValueError(f"mesh {name!r}: uv must have shape ({n_vertices}, 2), got {uv.shape}")
    if not np.all(np.isfinite(uv)):
        bad = int(np.argwhere(~np.isfinite(uv).all(axis=1))[0, 0])
        raise ValueError(f"mesh {name!r}: uv of vertex {bad} is not finite: {uv[bad].tolist()}")
    return uv


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
        uv=None,
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
        uv : (V, 2) float, optional
            Texture coordinates of the mesh's vertices (``v = 0`` the image's
            top row, as Mitsuba 3 holds them; an OBJ file's ``vt`` has it at
            the bottom, and its reader turns them); needed with a textured
            material, which otherwise reads ``mesh.visual.uv`` (flipped the
            same way).

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
        uv = _mesh_uv(mesh, uv, len(v), name, material.texture is not None)
        obj = SceneObject(
            name=name,
            vertices=v,
            faces=f,
            material=material,
            two_sided=bool(two_sided),
            vertex_normals=vn,
            uv=uv,
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
        lo, hi = zip(*(_used_bounds(o.vertices, o.faces) for o in self.objects), strict=True)
        return np.stack([np.min(lo, axis=0), np.max(hi, axis=0)])

    def area(self) -> float:
        """Total surface area of the scene (scene units²)."""
        return float(sum(o.area() for o in self.objects))

    def triangles(self) -> dict[str, np.ndarray]:
        """All triangles concatenated.

        Returns
        -------
        dict
            ``triangles`` (F, 3, 3) float64 corner positions, ``object`` (F,)
            int32 index into :attr:`objects`, ``albedo``/``emission``/
            ``transmittance`` (O, 3) float32 per object, ``two_sided`` (O,)
            bool per object.

        Raises
        ------
        ValueError
            If the scene is empty, or its radiosity cannot fit float32
            (:meth:`check_ranges`).
        """
        self.check_nonempty()
        self.check_ranges()
        tri = np.concatenate([o.vertices[o.faces] for o in self.objects])
        return {
            "triangles": np.ascontiguousarray(tri),
            "object": self.triangle_objects(),
            "albedo": np.array([o.material.albedo for o in self.objects], np.float32),
            "emission": np.array([o.material.emission for o in self.objects], np.float32),
            "transmittance": np.array([o.material.transmittance for o in self.objects], np.float32),
            "two_sided": np.array([o.two_sided for o in self.objects], bool),
        }

    def triangle_objects(self) -> np.ndarray:
        """(F,) int32: the index into :attr:`objects` of each triangle, in the
        order of :meth:`triangles` (without building the corners: the
        shading kernels need only this)."""
        self.check_nonempty()
        sizes = [len(o.faces) for o in self.objects]
        return np.repeat(np.arange(len(sizes), dtype=np.int32), sizes)

    @property
    def has_sheets(self) -> bool:
        """Whether an object is a transmitting sheet (:attr:`Material.is_sheet`)."""
        return any(o.material.is_sheet for o in self.objects)

    def fingerprint(self) -> str:
        """Hash of geometry, materials and lights: tells a solution which scene it belongs to.

        The camera is not part of it: a new view reuses a solution.
        """
        h = hashlib.sha1()
        for o in self.objects:
            h.update(o.vertices.tobytes())
            h.update(o.faces.tobytes())
            h.update(_stable_repr((o.material.albedo, o.material.emission, o.two_sided)).encode())
            if o.material.texture is not None:
                h.update(o.material.texture.digest().encode())
                h.update(o.uv.tobytes())
            if o.material.is_sheet:  # (an opaque scene keeps the hash it had)
                h.update(_stable_repr(("sheet", o.material.transmittance)).encode())
            if isinstance(o.material.specular, Microfacet):  # (the solve's albedo follows it)
                h.update(_stable_repr(("lobe", o.material.specular)).encode())
        for light in self.lights:
            h.update(_stable_repr(light).encode())
        if self.environment is not None:
            h.update(b"environment" + self.environment.digest().encode())
        return h.hexdigest()[:16]

    def check_ranges(self, source: str = "scene") -> None:
        """Refuse emitters and lights whose radiosity cannot be held in float32.

        The radiosity of any surface is at most ``(pi Le_max + pi L_env +
        E_sun) / (1 - rho_max)`` (each bounce returns at most ``rho_max`` of
        what arrives; docs/design.md §2), so every solve's values fit in
        float32 when that bound does; a point or spot light must keep its
        power ``4 pi I`` there. The message names the object.
        """
        f32 = float(np.finfo(np.float32).max)
        rho = max((max(o.material.albedo) for o in self.objects), default=0.0)
        gain = 1.0 / (1.0 - rho)
        terms = [
            (math.pi * max(o.material.emission), f"mesh {o.name!r}: emission {o.material.emission}")
            for o in self.objects
            if o.material.is_emitter
        ]
        if self.environment is not None:
            peak = float(self.environment.image.max()) if self.environment.image.size else 0.0
            terms.append((math.pi * peak, f"environment: radiance up to {peak:.4g}"))
        for k, light in enumerate(self.lights):
            if hasattr(light, "irradiance"):
                terms.append((max(light.irradiance), f"light #{k}: irradiance {light.irradiance}"))
            elif 4 * math.pi * max(light.intensity) > f32:
                raise ValueError(
                    f"{source}: light #{k}: intensity {light.intensity} W/sr gives a power "
                    f"4 pi I beyond float32's largest value {f32:.4g}"
                )
        total = sum(t for t, _ in terms) * gain
        if total > f32:
            worst = max(terms)[1]
            raise ValueError(
                f"{source}: {worst}: radiosity up to {total:.4g} (emitted, times "
                f"1 / (1 - {rho:.6g}) for the highest albedo), beyond float32's largest value "
                f"{f32:.4g}; scale the emission down (radiosity is linear in it)"
            )

    @property
    def has_specular(self) -> bool:
        return any(o.material.specular is not None for o in self.objects)

    # -- files --------------------------------------------------------------
    @classmethod
    def load(cls, path, *, search_paths=(), allow_outside: bool = False, limits=None) -> Scene:
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

            [materials.glass]       # a transmitting sheet (Material.transmittance)
            albedo = 0
            transmittance = [0.85, 0.85, 0.85]

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

        Parameters
        ----------
        path : str or Path
            The scene file.
        search_paths : sequence of path-like, optional
            Folders besides the scene file's own that its meshes, includes,
            textures and buffers may lie in (docs/scene-files.md).
        allow_outside : bool, optional
            Let the scene read any path it names.
        limits : voxgi.formats.Limits, optional
            Budgets of bytes, elements, includes and texture pixels (default:
            :meth:`voxgi.formats.Limits.from_env`).

        Raises
        ------
        FileNotFoundError
            If ``path`` does not exist.
        ValueError
            Malformed files (naming the file and its line, or JSON pointer),
            unknown keys, bad values (naming the object and key), missing or
            refused files (outside the allowed folders, not regular, over a
            limit), emission too strong for float32 radiosity.

        Warns
        -----
        SceneWarning
            What a format's reader approximated or left out, and meshes left
            out because every face of theirs is degenerate.
        """
        path = Path(path)
        access = formats.FileAccess(path, search_paths, allow_outside, limits)
        loader = formats.LOADERS.get(path.suffix.lower())
        if loader is not None:
            data = loader(
                path, search_paths=search_paths, allow_outside=allow_outside, limits=limits
            )
            scene = cls._from_data(data, str(path), access)
        else:
            scene = formats.toml.load_toml(cls(), path, access)
        scene.check_ranges(str(path))
        return scene

    @classmethod
    def _from_data(cls, data: formats.SceneData, source: str, access=None) -> Scene:
        """The scene of what a :mod:`voxgi.formats` loader read."""
        scene = cls()
        if data.camera is not None:
            scene.camera = formats.toml.camera_from_dict(data.camera, source)
        for m in data.meshes:
            if _validate.all_degenerate(m.vertices, m.faces):
                warnings.warn(
                    formats.SceneWarning(
                        f"{source}: mesh {m.name!r}: every face is degenerate; left out"
                    ),
                    stacklevel=3,
                )
                continue
            try:
                tex = m.texture if m.uv is not None else None
                if m.transmittance is not None and np.max(m.transmittance) > 0:
                    tex = None
                    mat = Material(albedo=0.0, transmittance=m.transmittance)
                else:
                    if m.specular is not None and m.specular.kind == "conductor":
                        tex = None  # (a conductor has no diffuse base)
                    mat = Material(
                        albedo=m.albedo, emission=m.emission, texture=tex, specular=m.specular
                    )
                obj = scene.add(
                    trimesh.Trimesh(m.vertices, m.faces, process=False),
                    mat,
                    name=m.name,
                    two_sided=m.two_sided,
                    uv=m.uv if tex is not None else None,
                )
            except (TypeError, ValueError) as exc:  # (the message names the mesh)
                raise ValueError(f"{source}: {exc}") from None
            obj.source = m.source
        for k, entry in enumerate(data.lights):
            scene.add_light(formats.toml.light_from_dict(entry, f"{source}: light #{k}"))
        if data.environment is not None:
            scene.environment = formats.toml.environment_from_dict(
                data.environment, source, Path(source).parent, access
            )
        if not scene.objects:
            raise ValueError(f"{source}: no mesh with a face that is not degenerate")
        return scene

    @classmethod
    def from_dict(
        cls,
        data: dict,
        base_dir=".",
        source: str = "<dict>",
        *,
        search_paths=(),
        allow_outside: bool = False,
        limits=None,
    ) -> Scene:
        """Build a scene from the parsed contents of a scene file (see :meth:`load`);
        mesh paths are relative to ``base_dir``, the folder the path policy roots."""
        access = formats.FileAccess(
            Path(base_dir) / "scene.toml", search_paths, allow_outside, limits
        )
        scene = formats.toml.fill_scene(cls(), data, source=source, access=access)
        scene.check_ranges(source)
        return scene

    def save(self, path) -> Path:
        """Write the scene as a TOML file with one mesh file per object beside it.

        Meshes are written already transformed as OBJ with 17 significant
        digits (PLY and GLB would round vertices to float32), so ``Scene.load``
        of the result gives bit-identical geometry, materials and camera.
        """
        return formats.toml.save_toml(self, Path(path))
