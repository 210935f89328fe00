"""Surface materials: a Lambertian albedo (or a texture of it) and emission,
an optional glossy layer, or a transmitting sheet (glass)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from . import _validate
from .microfacet import Microfacet
from .textures import Texture

__all__ = ["AshikhminShirley", "Material", "glass_transmittance"]


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
    specular : Microfacet, AshikhminShirley or None
        Optional glossy layer, used by the display only (the solve is
        diffuse). A :class:`Microfacet` plastic takes ``albedo`` (or the
        texture) as its diffuse base; a conductor has none, and its
        ``albedo`` is set to the lobe's hemispherical reflectance, which the
        diffuse solve bounces (``docs/design.md`` §14).
    texture : voxgi.Texture or None
        A bitmap of the albedo, looked up by the mesh's UVs (``Scene.add``'s
        ``uv``). With one, ``albedo`` is set to the texture's mean over the
        whole image (kept below 1); the display reads the texture at every
        hit and each voxel record its mean over the record's own surface.
    transmittance : float or (3,) float
        Per RGB channel in [0, 1]: a material with a channel above 0 is a
        transmitting sheet (glass, ``docs/design.md`` §13). Light crosses it
        straight, without refraction, scaled by ``transmittance``; the rest
        is absorbed. A sheet neither reflects nor emits (``albedo`` and
        ``emission`` 0, no ``specular``) and is not voxelized; every ray
        (shadow, gather, camera) passes it. See :func:`glass_transmittance`.

    Examples
    --------
    >>> import voxgi
    >>> pane = voxgi.Material(albedo=0.0, transmittance=voxgi.glass_transmittance(1.5))
    >>> pane.is_sheet, round(pane.transmittance[0], 3)
    (True, 0.845)
    """

    albedo: tuple[float, float, float] = (0.8, 0.8, 0.8)
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    specular: Microfacet | AshikhminShirley | None = None
    transmittance: tuple[float, float, float] = (0.0, 0.0, 0.0)
    texture: Texture | None = None

    def __post_init__(self):
        if self.texture is not None:
            if not isinstance(self.texture, Texture):
                raise TypeError(
                    "Material.texture: expected voxgi.Texture or None, got "
                    f"{type(self.texture).__name__}"
                )
            below_one = float(np.nextafter(np.float32(1.0), np.float32(0.0)))
            object.__setattr__(self, "albedo", np.minimum(self.texture.mean(), below_one))
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
        if self.specular is not None and not isinstance(
            self.specular, (Microfacet, AshikhminShirley)
        ):
            raise TypeError(
                "Material.specular: expected voxgi.Microfacet, voxgi.AshikhminShirley or None, "
                f"got {type(self.specular).__name__}"
            )
        if self.is_conductor:
            if self.texture is not None:
                raise ValueError("Material: a conductor has no diffuse base to texture")
            below_one = float(np.nextafter(np.float32(1.0), np.float32(0.0)))
            albedo = np.minimum(self.specular.albedo(), below_one)
            object.__setattr__(
                self,
                "albedo",
                _validate.rgb(albedo, "Material.albedo", high=1.0, high_inclusive=False),
            )
        object.__setattr__(
            self,
            "transmittance",
            _validate.rgb(self.transmittance, "Material.transmittance", high=1.0, float32=True),
        )
        if self.is_sheet and (
            max(self.albedo) > 0.0 or self.is_emitter or self.specular is not None
        ):
            raise ValueError(
                f"Material: a transmitting sheet (transmittance {self.transmittance}) neither "
                f"reflects nor emits: got albedo {self.albedo}, emission {self.emission}"
                + (", a specular layer" if self.specular is not None else "")
                + " (give albedo=0)"
            )

    @property
    def is_emitter(self) -> bool:
        return max(self.emission) > 0.0

    @property
    def is_conductor(self) -> bool:
        """Whether the material is a :class:`Microfacet` conductor (no diffuse base)."""
        return isinstance(self.specular, Microfacet) and self.specular.kind == "conductor"

    @property
    def is_sheet(self) -> bool:
        """Whether light passes the surface (a channel of ``transmittance`` above 0)."""
        return max(self.transmittance) > 0.0


@functools.cache
def _hemispherical_transmittance(ior: float, thin: bool) -> float:
    # Gauss-Legendre in cos θ over [0, 1]: the integrand is smooth there
    x, w = np.polynomial.legendre.leggauss(256)
    c, w = 0.5 * (x + 1.0), 0.5 * w
    s2 = (1.0 - c * c) / (ior * ior)
    ct = np.sqrt(np.maximum(0.0, 1.0 - s2))
    rs = (c - ior * ct) / (c + ior * ct)
    rp = (ior * c - ct) / (ior * c + ct)
    r = 0.5 * (rs * rs + rp * rp)  # unpolarised Fresnel reflectance
    if thin:
        r = 2.0 * r / (1.0 + r)  # both faces, every inner reflection summed
    return float(np.sum(w * 2.0 * c * (1.0 - r)))


def glass_transmittance(ior: float = 1.5, *, thin: bool = True) -> float:
    """Straight-through transmittance of glass under uniform (diffuse) light.

    The fraction of the flux of a uniform radiance field that crosses the
    glass: the Fresnel transmittance averaged over the hemisphere with
    weight ``2 cos θ``. ``thin``: a slab (both faces, with all its inner
    reflections, as Mitsuba's ``thindielectric``: ``1 - 2R/(1+R)`` at each
    angle); otherwise one interface (``1 - R``), which a closed solid crosses
    twice (``docs/design.md`` §13). At ``ior`` 1.5: 0.845 thin, 0.908 one
    interface (at normal incidence 0.923 and 0.96).

    Parameters
    ----------
    ior : float
        Relative index of refraction (inside over outside), in [1, 10]; 1
        passes everything.
    thin : bool
        A thin slab (True) or a single interface (False).

    Returns
    -------
    float
        In (0, 1].
    """
    ior = _validate.real(ior, "glass_transmittance: ior", low=1.0, high=10.0)
    if ior == 1.0:
        return 1.0
    return _hemispherical_transmittance(float(ior), bool(thin))
