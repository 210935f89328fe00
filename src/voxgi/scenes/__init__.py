"""Built-in scenes: the Cornell box, analytic furnaces, the paper's look-alikes, interiors.

Every function returns a fresh :class:`voxgi.Scene` with a camera set.
"""

from __future__ import annotations

from ..scene import Scene
from .cornell import CORNELL_GREEN, CORNELL_LIGHT, CORNELL_RED, CORNELL_WHITE, cornell_box
from .furnaces import cap_sphere, furnace_box, furnace_sphere
from .interiors import door_room, window_room
from .lights import point_lit_box, sky_objects, sun_room
from .paper import bunny_room, emission, geometric, labyrinth, load_bunny, shadow, sponza_atrium
from .thin_walls import split_box

__all__ = [
    "CORNELL_GREEN",
    "CORNELL_LIGHT",
    "CORNELL_RED",
    "CORNELL_WHITE",
    "bunny_room",
    "cap_sphere",
    "cornell_box",
    "door_room",
    "emission",
    "furnace_box",
    "furnace_sphere",
    "geometric",
    "get",
    "labyrinth",
    "load_bunny",
    "names",
    "point_lit_box",
    "shadow",
    "sky_objects",
    "split_box",
    "sponza_atrium",
    "sun_room",
    "window_room",
]


_REGISTRY = {
    "cornell-box": cornell_box,
    "furnace-sphere": furnace_sphere,
    "furnace-box": furnace_box,
    "cap-sphere": cap_sphere,
    "bunny-room": bunny_room,
    "labyrinth": labyrinth,
    "emission": emission,
    "shadow": shadow,
    "geometric": geometric,
    "sponza-atrium": sponza_atrium,
    "window-room": window_room,
    "point-lit-box": point_lit_box,
    "sun-room": sun_room,
    "sky-objects": sky_objects,
    "door-room": door_room,
    "split-box": split_box,
}


def names() -> list[str]:
    """Names of the built-in scenes, as the command line spells them."""
    return sorted(_REGISTRY)


def get(name: str, **kwargs) -> Scene:
    """A built-in scene by its command-line name (``cornell-box``, ...).

    Parameters
    ----------
    name : str
        A name of :func:`names` (``cornell-box``; underscores are accepted).
    **kwargs
        Passed to the scene's function (``width=``, ``height=``, ...).

    Returns
    -------
    Scene
        A new scene with its camera set.

    Raises
    ------
    ValueError
        If ``name`` is not a built-in scene's name.
    """
    key = name.replace("_", "-").lower()
    if key not in _REGISTRY:
        raise ValueError(f"unknown built-in scene {name!r}; known: {', '.join(names())}")
    return _REGISTRY[key](**kwargs)
