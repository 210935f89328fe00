"""Where a render's frames are computed: the spec of a frame shader and the
executor protocol (``docs/design.md`` §8)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from ..scene import Camera, Scene
from .shader import _FrameShader, _Tracer
from .vpls import VPLSampler

__all__ = ["FrameExecutor", "FrameShaderSpec", "LocalFrames"]


@dataclass(frozen=True, eq=False)
class FrameShaderSpec:
    """What a frame shader is built from; picklable, so an executor can ship it.

    Frames are independent (each has its own VPLs, sub-pixel offset and
    gather-ray seed), so a shader built from the same spec anywhere returns
    the same frame ``f``.

    Attributes
    ----------
    scene : Scene
    camera : Camera
    sampler : VPLSampler
    eps : float
        Shadow-ray offset (scene units).
    gather : int
        Gather rays per pixel and frame for the non-emitter light (0: VPLs only).
    seed : int
    indirect_filter : int
        Radius in pixels of the geometry-aware filter of the non-emitting
        records' light (0: none; :attr:`RenderTuning.indirect_filter`).
    control_emission : bool
        Replace, at pixels that see emission over part of their footprint,
        each frame's seen emission by its mean over the pixel
        (:mod:`voxgi.display.seen_emission`).
    guide_environment : bool
        Draw the environment's samples where its light reaches each pixel's
        place (:mod:`voxgi.display.environment_guide`).
    near_reach : float
        Gather rays that land nearer than this many voxel pitches on a
        diffuse surface that does not emit continue one bounce (0: never).
    mirror_alpha : float
        Camera rays go on through conductors whose lobe's alpha is at most
        this (0: through none; :attr:`RenderTuning.mirror_alpha`).
    """

    scene: Scene
    camera: Camera
    sampler: VPLSampler
    eps: float
    gather: int
    seed: int
    indirect_filter: int = 0
    control_emission: bool = True
    guide_environment: bool = True
    near_reach: float = 0.0
    mirror_alpha: float = 0.0

    @property
    def gather_per_frame(self) -> int:
        """Gather rays per pixel and frame the shader will trace."""
        return int(self.gather) if self.sampler.mis else 0

    @property
    def glossy(self) -> bool:
        """Whether any material has a specular layer."""
        return any(o.material.specular is not None for o in self.scene.objects)

    def build(self, threads: int = 1) -> _FrameShader:
        """The shader (Embree scene, material tables, buffers) on ``threads`` threads.

        It has ``frame(f, seed)`` -> (H*W, 3) float32, the counters
        ``primary_rays``, ``shadow_rays``, ``gather_rays``, ``seconds``, and
        ``close()``."""
        tracer = _Tracer(self.scene, threads)
        return _FrameShader(
            self.scene,
            self.camera,
            tracer,
            self.sampler,
            self.eps,
            threads,
            self.gather,
            self.seed,
            self.indirect_filter,
            self.control_emission,
            self.guide_environment,
            self.near_reach,
            self.mirror_alpha,
        )


class FrameExecutor(Protocol):
    """Where a render's frames are computed (``docs/design.md`` §8).

    ``frames(spec, max_frames, threads=...)`` returns a frame source with
    the interface of :meth:`FrameShaderSpec.build`'s shader: ``frame(f,
    seed)`` must return frame ``f`` as the local shader would, whatever
    the order of computation; the render loop asks for frames 0, 1, ... and
    stops after at most ``max_frames``. After each frame, the source's
    ``surface`` attribute, where it has one, is that frame's
    :func:`frame_surface`; without it the relMSE estimate rests on the
    blocks of frames alone (``docs/design.md`` §6).
    """

    def frames(self, spec: FrameShaderSpec, max_frames: int, *, threads: int = 1): ...


class LocalFrames:
    """The default frame executor: every frame in this process."""

    def frames(self, spec: FrameShaderSpec, max_frames: int, *, threads: int = 1):
        """The shader built here."""
        return spec.build(threads)
