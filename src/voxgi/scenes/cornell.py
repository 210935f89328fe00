"""The Cornell box with its published dimensions."""

from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..materials import Material
from ..scene import Scene
from ._shapes import _mesh

# Cornell box reflectances and light radiance as in Mitsuba 3's
# ``mi.cornell_box()`` (RGB fits of the measured spectra), so that the
# reference renders compare like with like.
CORNELL_WHITE = (0.885809, 0.698859, 0.666422)
CORNELL_GREEN = (0.105421, 0.37798, 0.076425)
CORNELL_RED = (0.570068, 0.0430135, 0.0443706)
CORNELL_LIGHT = (18.387, 13.9873, 6.75357)


#: The Cornell box's walls (mm): each a quad, in the order they join the scene.
_CORNELL_CENTRE = np.array([278.0, 274.4, 279.6])
_CORNELL_WALLS = {
    "floor": [[552.8, 0, 0], [0, 0, 0], [0, 0, 559.2], [549.6, 0, 559.2]],
    "ceiling": [[556.0, 548.8, 0], [556.0, 548.8, 559.2], [0, 548.8, 559.2], [0, 548.8, 0]],
    "back": [[549.6, 0, 559.2], [0, 0, 559.2], [0, 548.8, 559.2], [556.0, 548.8, 559.2]],
    "red": [[552.8, 0, 0], [549.6, 0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0]],
    "green": [[0, 0, 559.2], [0, 0, 0], [0, 548.8, 0], [0, 548.8, 559.2]],
}
_CORNELL_FRONT = [[0, 0, 0], [552.8, 0, 0], [556.0, 548.8, 0], [0, 548.8, 0]]
#: The two blocks: their quads (mm) and a point inside each.
_CORNELL_BLOCKS = {
    "short_block": (
        [
            [[130, 165, 65], [82, 165, 225], [240, 165, 272], [290, 165, 114]],
            [[290, 0, 114], [290, 165, 114], [240, 165, 272], [240, 0, 272]],
            [[130, 0, 65], [130, 165, 65], [290, 165, 114], [290, 0, 114]],
            [[82, 0, 225], [82, 165, 225], [130, 165, 65], [130, 0, 65]],
            [[240, 0, 272], [240, 165, 272], [82, 165, 225], [82, 0, 225]],
        ],
        [186.0, 82.5, 169.0],
    ),
    "tall_block": (
        [
            [[423, 330, 247], [265, 330, 296], [314, 330, 456], [472, 330, 406]],
            [[423, 0, 247], [423, 330, 247], [472, 330, 406], [472, 0, 406]],
            [[472, 0, 406], [472, 330, 406], [314, 330, 456], [314, 0, 456]],
            [[314, 0, 456], [314, 330, 456], [265, 330, 296], [265, 0, 296]],
            [[265, 0, 296], [265, 330, 296], [423, 330, 247], [423, 0, 247]],
        ],
        [368.5, 165.0, 351.25],
    ),
}


def cornell_box(
    width: int = 512,
    height: int = 512,
    light_offset: float = 0.01,
    *,
    blocks: bool = True,
    closed: bool = False,
    area_light: bool = True,
) -> Scene:
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
    blocks : bool
        Include the two blocks (default).
    closed : bool
        Close the box with a white fourth wall at z = 0 (object ``front``):
        nothing escapes, so every emitted watt must be absorbed (energy
        studies; the camera then sees the wall's black back).
    area_light : bool
        Include the emitting quad under the ceiling (default; without it the
        box is dark until lights are added, as in :func:`point_lit_box`).

    Returns
    -------
    Scene
        Objects ``floor``, ``ceiling``, ``back``, ``red`` (left), ``green``
        (right), ``short_block``, ``tall_block``, ``light``.
    """
    s = Scene(
        Camera(
            eye=(0.278, 0.273, -0.800),
            target=(0.278, 0.273, 0.0),
            up=(0, 1, 0),
            fov=39.3,
            width=width,
            height=height,
        )
    )
    white = Material(albedo=CORNELL_WHITE)
    colour = {"red": Material(albedo=CORNELL_RED), "green": Material(albedo=CORNELL_GREEN)}
    for name, q in _CORNELL_WALLS.items():
        s.add(_mesh([q], inside=_CORNELL_CENTRE), colour.get(name, white), name=name)
    if blocks:
        for name, (quads, centre) in _CORNELL_BLOCKS.items():
            s.add(_mesh(quads, outside=np.array(centre)), white, name=name)
    if closed:
        s.add(_mesh([_CORNELL_FRONT], inside=_CORNELL_CENTRE), white, name="front")
    if not area_light:
        return s
    y = 548.8 - light_offset * 1e3
    light = [[[343.0, y, 227.0], [343.0, y, 332.0], [213.0, y, 332.0], [213.0, y, 227.0]]]
    s.add(
        _mesh(light, inside=np.array([278.0, 0.0, 279.5])),
        Material(albedo=0.0, emission=CORNELL_LIGHT),
        name="light",
    )
    return s
