"""``voxgi scenes``: the built-in scenes and what each one is."""

from __future__ import annotations

import re


def plain_text(doc: str) -> str:
    """A docstring line without its Sphinx roles: ``:func:`window_room``` becomes
    ``window-room`` when it names a built-in scene (as ``voxgi render`` takes
    it), else ``window_room``; double backquotes are dropped."""
    from .. import scenes

    names = set(scenes.names())

    def name(m: re.Match) -> str:
        target = m.group(1).lstrip("~").rsplit(".", 1)[-1]
        dashed = target.replace("_", "-")
        return dashed if dashed in names else target

    doc = re.sub(r":[a-z:]+:`([^`]+)`", name, doc)
    return doc.replace("``", "")


def run_scenes(args) -> int:
    """``voxgi scenes``: each built-in scene's name and the first line of its description."""
    from .. import scenes

    names = scenes.names()
    width = max(len(n) for n in names)
    for n in names:
        fn = getattr(scenes, n.replace("-", "_"), None)
        doc = (getattr(fn, "__doc__", None) or "").strip().splitlines()
        print(f"{n:<{width}}  {plain_text(doc[0].strip()) if doc else ''}")
    return 0
