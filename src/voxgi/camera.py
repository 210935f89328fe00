"""The perspective camera: pinhole or thin lens."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _validate

__all__ = ["Camera"]


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
        # relative to the camera's own scale: a scene in any unit has a camera
        reach = max(np.linalg.norm(eye), np.linalg.norm(target))
        if not np.linalg.norm(fwd) > 1e-12 * reach:
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
