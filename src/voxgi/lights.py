"""Lights besides emissive triangles: point, spot and directional lights, and an environment.

Their units and conventions are Mitsuba 3's, so that :func:`voxgi.mitsuba.to_mitsuba`
maps each one to a Mitsuba emitter without conversion (``docs/design.md`` §11):

- :class:`PointLight`: radiant intensity ``I`` (W/sr per RGB channel); a
  surface at distance r whose normal makes the angle θ with the direction to
  the light receives the irradiance ``I cos θ / r²``.
- :class:`SpotLight`: a point light whose intensity is scaled by Mitsuba's
  ``spot`` falloff: 1 inside ``beam_width``, falling linearly in angle to 0 at
  ``cutoff_angle``.
- :class:`DirectionalLight`: a sun, light travelling along ``direction``; a
  surface facing it receives the irradiance ``E`` (``E cos θ`` tilted).
- :class:`Environment`: radiance arriving from infinitely far away, constant
  or from a latitude-longitude image (Mitsuba's ``envmap`` convention, y up).

The first three are delta lights: one shadow ray gives their light exactly.
The environment is sampled (:meth:`Environment.sample`) in proportion to
luminance times solid angle.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import _validate

__all__ = ["DirectionalLight", "Environment", "PointLight", "SpotLight", "spot_falloff"]

#: Luminance of linear RGB (Rec. 709 primaries): the weights by which
#: voxgi ranks light for sampling.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _unit(value, what: str) -> tuple[float, float, float]:
    """A non-zero finite 3-vector, normalised."""
    v = _validate.vec3(value, what)
    n = float(np.linalg.norm(v))
    if not n > 0.0:
        raise ValueError(f"{what}: expected a non-zero vector, got {list(v)}")
    # a unit vector stays bit for bit itself (saved and loaded scenes keep
    # their fingerprint): normalising again could move its last bits
    if abs(n - 1.0) > 4 * np.finfo(np.float64).eps:
        v = v / n
    return tuple(float(x) for x in v)


def _point(value, what: str) -> tuple[float, float, float]:
    return tuple(float(x) for x in _validate.vec3(value, what))


@dataclass(frozen=True)
class PointLight:
    """An isotropic point light.

    Parameters
    ----------
    position : (3,) float
        Scene units.
    intensity : float or (3,) float
        Radiant intensity per RGB channel, W/sr (>= 0); Mitsuba's ``point``
        ``intensity``.

    Examples
    --------
    >>> PointLight((0, 2, 0), 10.0).intensity
    (10.0, 10.0, 10.0)
    """

    position: tuple[float, float, float]
    intensity: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self):
        object.__setattr__(self, "position", _point(self.position, "PointLight.position"))
        object.__setattr__(
            self, "intensity", _validate.rgb(self.intensity, "PointLight.intensity", float32=True)
        )

    def incident(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Light arriving at points ``x`` (N, 3): unit directions towards the
        light (N, 3), distances (N,) and the irradiance on a surface facing
        the light (N, 3), ``I / r²``."""
        d = np.asarray(self.position) - x
        r2 = np.einsum("ij,ij->i", d, d)
        r = np.sqrt(r2)
        with np.errstate(divide="ignore", invalid="ignore"):
            w = d / r[:, None]
            e = np.asarray(self.intensity)[None, :] / r2[:, None]
        ok = r2 > 0
        return np.where(ok[:, None], w, 0.0), r, np.where(ok[:, None], e, 0.0)


def spot_falloff(cos_theta, cutoff_angle: float, beam_width: float) -> np.ndarray:
    """Mitsuba 3's ``spot`` falloff at the angle θ from the spot's axis.

    1 for θ <= ``beam_width``, ``(cutoff − θ) / (cutoff − beam_width)`` up to
    ``cutoff_angle`` and 0 beyond (angles in degrees).

    >>> round(float(spot_falloff(np.cos(np.radians(15.0)), 20.0, 10.0)), 12)
    0.5
    """
    c = np.asarray(cos_theta, np.float64)
    cut, beam = math.radians(cutoff_angle), math.radians(beam_width)
    theta = np.arccos(np.clip(c, -1.0, 1.0))
    ramp = (cut - theta) / (cut - beam) if cut > beam else np.zeros_like(theta)
    inside = np.where(c >= math.cos(beam), 1.0, ramp)
    return np.where(c > math.cos(cut), inside, 0.0)


@dataclass(frozen=True)
class SpotLight:
    """A point light limited to a cone, with Mitsuba's ``spot`` falloff.

    Parameters
    ----------
    position : (3,) float
    direction : (3,) float
        The cone's axis (normalised here).
    intensity : float or (3,) float
        Radiant intensity on the axis, W/sr (>= 0).
    cutoff_angle : float
        Half-angle of the cone in degrees, in (0, 90].
    beam_width : float or None
        Half-angle of the fully lit core, degrees, in (0, cutoff_angle]
        (None: 3/4 of ``cutoff_angle``, Mitsuba's default).

    Examples
    --------
    >>> SpotLight((0, 2, 0), (0, -1, 0), 5.0, cutoff_angle=30).beam_width
    22.5
    """

    position: tuple[float, float, float]
    direction: tuple[float, float, float]
    intensity: tuple[float, float, float] = (1.0, 1.0, 1.0)
    cutoff_angle: float = 20.0
    beam_width: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "position", _point(self.position, "SpotLight.position"))
        object.__setattr__(self, "direction", _unit(self.direction, "SpotLight.direction"))
        object.__setattr__(
            self, "intensity", _validate.rgb(self.intensity, "SpotLight.intensity", float32=True)
        )
        cut = _validate.real(
            self.cutoff_angle, "SpotLight.cutoff_angle", low=0.0, low_open=True, high=90.0
        )
        object.__setattr__(self, "cutoff_angle", cut)
        beam = 0.75 * cut if self.beam_width is None else self.beam_width
        beam = _validate.real(beam, "SpotLight.beam_width", low=0.0, low_open=True, high=cut)
        object.__setattr__(self, "beam_width", beam)

    def incident(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`PointLight.incident`, times the falloff."""
        w, r, e = PointLight(self.position, self.intensity).incident(x)
        fall = spot_falloff(-w @ np.asarray(self.direction), self.cutoff_angle, self.beam_width)
        return w, r, e * fall[:, None]


@dataclass(frozen=True)
class DirectionalLight:
    """A sun: parallel light from infinitely far away.

    Parameters
    ----------
    direction : (3,) float
        The direction the light travels (from the sun into the scene), as
        Mitsuba's ``directional`` ``direction``; normalised here.
    irradiance : float or (3,) float
        Irradiance on a surface facing the sun, W/m² per RGB channel (>= 0).

    Examples
    --------
    >>> DirectionalLight((0, -2, 0), 3.0).direction
    (0.0, -1.0, 0.0)
    """

    direction: tuple[float, float, float]
    irradiance: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self):
        object.__setattr__(self, "direction", _unit(self.direction, "DirectionalLight.direction"))
        object.__setattr__(
            self,
            "irradiance",
            _validate.rgb(self.irradiance, "DirectionalLight.irradiance", float32=True),
        )

    def incident(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`PointLight.incident`; the distance is infinite."""
        n = len(x)
        w = np.broadcast_to(-np.asarray(self.direction), (n, 3)).copy()
        return w, np.full(n, np.inf), np.broadcast_to(np.asarray(self.irradiance), (n, 3)).copy()


#: The delta lights (one shadow ray each gives their light exactly).
DELTA_LIGHTS = (PointLight, SpotLight, DirectionalLight)


class Environment:
    """Radiance arriving from infinitely far away in every direction no surface blocks.

    Parameters
    ----------
    radiance : float, (3,) float, (H, W, 3) array or path
        A constant radiance (Mitsuba's ``constant``), or a latitude-longitude
        image (Mitsuba's ``envmap``), given as an array or a file: OpenEXR
        (``voxgi.io.read_exr``), Radiance RGBE ``.hdr``, or another format
        imageio reads. Linear radiance, >= 0.
    to_world : (3, 3) or (4, 4) array or None
        Rotation from the image's frame to the scene (its translation, if any,
        is ignored: the environment is infinitely far).
    scale : float
        Multiplies the radiance (Mitsuba's ``scale``).

    Notes
    -----
    Image convention (``docs/design.md`` §11, Mitsuba's): in the image frame
    y is up; the direction ``(sin θ sin φ, cos θ, −sin θ cos φ)`` reads the
    pixel at ``u = φ / 2π`` (column ``u W``) and ``v = θ / π`` (row ``v H``,
    row 0 the +y pole). voxgi reads the texel under a direction (piecewise
    constant, the density it samples with); Mitsuba interpolates between
    texel centres, which differs only at the scale of a texel.

    Examples
    --------
    >>> env = Environment(1.5)
    >>> env.eval(np.array([[0.0, 1.0, 0.0]]))
    array([[1.5, 1.5, 1.5]])
    """

    def __init__(self, radiance=1.0, *, to_world=None, scale: float = 1.0):
        self.source: str | None = None
        if isinstance(radiance, (str, Path)):
            self.source = str(radiance)
            image = _read_image(Path(radiance))
            self.constant = None
        else:
            arr = np.asarray(radiance, dtype=np.float64) if not np.isscalar(radiance) else None
            if arr is not None and arr.ndim == 3:
                image = _validate.as_c_array(arr, np.float64, (-1, -1, 3), "Environment.radiance")
                self.constant = None
            else:
                rgb = _validate.rgb(radiance, "Environment.radiance", float32=True)
                image = np.asarray(rgb, np.float64).reshape(1, 1, 3)
                self.constant = rgb
        if image.shape[0] < 1 or image.shape[1] < 1:
            raise ValueError(f"Environment.radiance: empty image of shape {image.shape}")
        if np.any(image < 0):
            raise ValueError("Environment.radiance: negative radiance in the image")
        self.scale = _validate.real(scale, "Environment.scale", low=0.0)
        scaled = image * self.scale
        if self.constant is None:
            # images hold float32 values (as Mitsuba's and the EXR a saved
            # scene writes), so a saved and reloaded scene is the same scene
            scaled = scaled.astype(np.float32).astype(np.float64)
        self.image = np.ascontiguousarray(scaled)
        self.image.flags.writeable = False
        self.to_world = _rotation(to_world)
        self._tables = None

    def __repr__(self) -> str:
        what = self.constant if self.constant is not None else f"image {self.image.shape[:2]}"
        return f"Environment({what})"

    def __eq__(self, other) -> bool:
        return (
            isinstance(other, Environment)
            and np.array_equal(self.image, other.image)
            and np.array_equal(self.to_world, other.to_world)
        )

    __hash__ = None  # type: ignore[assignment]

    def digest(self) -> str:
        """Hash of the radiance and orientation (for :meth:`Scene.fingerprint`)."""
        h = hashlib.sha1(self.image.tobytes())
        h.update(self.to_world.tobytes())
        return h.hexdigest()

    # -- lookups --------------------------------------------------------
    def _uv(self, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Texel column and row of world directions (N, 3)."""
        loc = np.asarray(dirs, np.float64) @ self.to_world  # world -> image frame
        loc /= np.maximum(np.linalg.norm(loc, axis=1, keepdims=True), 1e-300)
        h, w = self.image.shape[:2]
        u = np.arctan2(loc[:, 0], -loc[:, 2]) / (2.0 * np.pi)
        u -= np.floor(u)
        v = np.arccos(np.clip(loc[:, 1], -1.0, 1.0)) / np.pi
        col = np.minimum((u * w).astype(np.int64), w - 1)
        row = np.minimum((v * h).astype(np.int64), h - 1)
        return col, row

    def eval(self, dirs: np.ndarray) -> np.ndarray:
        """(N, 3) radiance arriving from world directions ``dirs`` (N, 3)
        (pointing away from the scene)."""
        col, row = self._uv(dirs)
        return self.image[row, col]

    def _build(self):
        """Per texel: its solid angle and its share of luminance × solid angle."""
        if self._tables is None:
            h, w = self.image.shape[:2]
            cos_edges = np.cos(np.linspace(0.0, np.pi, h + 1))
            omega_row = (2.0 * np.pi / w) * (cos_edges[:-1] - cos_edges[1:])  # (H,)
            lum = np.maximum(self.image @ LUMINANCE, 0.0)
            weight = (lum * omega_row[:, None]).ravel()
            total = float(weight.sum())
            p = weight / total if total > 0 else np.full(h * w, 1.0 / (h * w))
            cdf = np.cumsum(p)
            cdf[-1] = 1.0
            self._tables = (p, cdf, omega_row, cos_edges)
        return self._tables

    def tables(self) -> dict:
        """The tables :meth:`sample` and :meth:`pdf` read, as the compiled
        kernels take them (float64): ``texel_pdf`` (H*W,) each texel's
        probability, row-major, ``texel_cdf`` (H*W,) their running sum (last
        1), ``row_solid_angle`` (H,) the solid angle of one texel of each row
        and ``row_cos`` (H+1,) cos θ at the rows' edges, from +1 down. The
        density at a direction is its texel's probability over its row's
        solid angle."""
        p, cdf, omega_row, cos_edges = self._build()
        return {
            "texel_pdf": p,
            "texel_cdf": cdf,
            "row_solid_angle": omega_row,
            "row_cos": cos_edges,
        }

    def sampling_arguments(self) -> tuple:
        """``(image, to_world, texel_pdf, row_solid_angle, texel_cdf,
        row_cos)``: the environment as the compiled kernels that draw its
        samples take it (float64, C order; :meth:`tables`)."""
        t = self.tables()
        return (
            self.image,
            np.ascontiguousarray(self.to_world, np.float64),
            t["texel_pdf"],
            t["row_solid_angle"],
            t["texel_cdf"],
            t["row_cos"],
        )

    def pdf(self, dirs: np.ndarray) -> np.ndarray:
        """(N,) solid-angle density of :meth:`sample` at world directions."""
        p, _, omega_row, _ = self._build()
        col, row = self._uv(dirs)
        w = self.image.shape[1]
        return p[row * w + col] / omega_row[row]

    def sample(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map points of [0, 1)³ (N, 3) to world directions (N, 3) and their
        solid-angle densities (N,): a texel in proportion to luminance ×
        solid angle, then a direction uniform in solid angle inside it
        (uniform in φ and in cos θ between the texel's edges)."""
        p, cdf, omega_row, cos_edges = self._build()
        h, w = self.image.shape[:2]
        k = np.minimum(np.searchsorted(cdf, u[:, 0], side="right"), h * w - 1)
        row, col = k // w, k % w
        phi = 2.0 * np.pi * (col + u[:, 1]) / w
        ct = cos_edges[row] + u[:, 2] * (cos_edges[row + 1] - cos_edges[row])
        st = np.sqrt(np.maximum(0.0, 1.0 - ct * ct))
        loc = np.stack([st * np.sin(phi), ct, -st * np.cos(phi)], axis=1)
        return loc @ self.to_world.T, p[k] / omega_row[row]


def _rotation(to_world) -> np.ndarray:
    """The 3x3 rotation of a (3, 3) or (4, 4) ``to_world`` (identity for None)."""
    if to_world is None:
        return np.eye(3)
    m = np.asarray(to_world, dtype=np.float64)
    if m.shape not in ((3, 3), (4, 4)) or not np.all(np.isfinite(m)):
        raise ValueError(
            f"Environment.to_world: expected a finite 3x3 or 4x4 matrix, got {m.shape}"
        )
    r = np.ascontiguousarray(m[:3, :3])
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise ValueError("Environment.to_world: its 3x3 part must be a rotation")
    return r


def _read_image(path: Path) -> np.ndarray:
    """A lat-long radiance image from an EXR (voxgi.io) or another file imageio reads."""
    if not path.exists():
        raise ValueError(f"Environment: image file not found: {path}")
    try:
        if path.suffix.lower() == ".exr":
            from .io import read_exr

            img = read_exr(path)
        elif path.suffix.lower() in (".hdr", ".pic"):
            img = _read_radiance_hdr(path)
        else:
            import imageio.v3 as iio

            img = iio.imread(path)
    except Exception as exc:
        raise ValueError(f"Environment: cannot read image {path}: {exc}") from None
    img = np.asarray(img, np.float64)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] < 3:
        raise ValueError(f"Environment: image {path} has shape {img.shape}, expected (H, W, 3)")
    img = img[..., :3]
    if not np.all(np.isfinite(img)):
        raise ValueError(f"Environment: image {path} holds non-finite values")
    return img


def _read_radiance_hdr(path: Path) -> np.ndarray:
    """(H, W, 3) float64 radiance of a Radiance RGBE file (``-Y H +X W`` only).

    Scanlines are flat RGBE or the run-length encoding of Greg Ward's
    ``fprintf`` writer: ``2 2 W>>8 W&255``, then each of the four channels as
    runs (count > 128: the next byte ``count − 128`` times; else ``count``
    literal bytes). The loop runs once per run, not per pixel.
    """
    data = path.read_bytes()
    end = data.find(b"\n\n")
    if not data.startswith((b"#?RADIANCE", b"#?RGBE")) or end < 0:
        raise ValueError("not a Radiance HDR file (no '#?RADIANCE' header)")
    if b"FORMAT=32-bit_rle_rgbe" not in data[:end]:
        raise ValueError("only FORMAT=32-bit_rle_rgbe is supported")
    eol = data.find(b"\n", end + 2)
    dims = data[end + 2 : eol].split()
    if len(dims) != 4 or dims[0] != b"-Y" or dims[2] != b"+X":
        raise ValueError(f"unsupported resolution line {data[end + 2 : eol]!r} (want -Y H +X W)")
    h, w = int(dims[1]), int(dims[3])
    buf = np.frombuffer(data, np.uint8, offset=eol + 1)
    rgbe = np.empty((h, w, 4), np.uint8)
    pos = 0
    for row in range(h):
        head = buf[pos : pos + 4]
        rle = 8 <= w < 32768 and len(head) == 4 and head[0] == 2 and head[1] == 2
        if not rle or (int(head[2]) << 8 | int(head[3])) != w:
            rgbe[row] = buf[pos : pos + 4 * w].reshape(w, 4)
            pos += 4 * w
            continue
        pos += 4
        for ch in range(4):
            x = 0
            while x < w:
                count = int(buf[pos])
                if count > 128:
                    count -= 128
                    rgbe[row, x : x + count, ch] = buf[pos + 1]
                    pos += 2
                else:
                    rgbe[row, x : x + count, ch] = buf[pos + 1 : pos + 1 + count]
                    pos += 1 + count
                if count == 0:
                    raise ValueError(f"corrupt run-length data in scanline {row}")
                x += count
    e = rgbe[..., 3].astype(np.int32)
    scale = np.where(e > 0, np.ldexp(1.0, e - 136), 0.0)  # 2^(e - 128) / 256
    return rgbe[..., :3] * scale[..., None]
