"""Surface materials: a Lambertian albedo (or a texture of it) and emission, an
optional glossy layer."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _validate
from .textures import Texture

__all__ = ["AshikhminShirley", "Material"]


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
    texture : voxgi.Texture or None
        A bitmap of the albedo, looked up by the mesh's UVs (``Scene.add``'s
        ``uv``). With one, ``albedo`` is set to the texture's mean over the
        whole image (kept below 1); the display reads the texture at every
        hit and each voxel record its mean over the record's own surface.
    """

    albedo: tuple[float, float, float] = (0.8, 0.8, 0.8)
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    specular: AshikhminShirley | None = None
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
        if self.specular is not None and not isinstance(self.specular, AshikhminShirley):
            raise TypeError(
                "Material.specular: expected voxgi.AshikhminShirley or None, got "
                f"{type(self.specular).__name__}"
            )

    @property
    def is_emitter(self) -> bool:
        return max(self.emission) > 0.0
