"""The scene a command reads and the files it writes, checked before any work."""

from __future__ import annotations

import tempfile
from pathlib import Path

from ._args import UsageError


def output_paths(output: str | Path) -> tuple[Path, Path]:
    """The ``(EXR, PNG)`` pair that ``-o output`` names.

    ``out.exr`` gives ``out.exr`` and the preview ``out.png``; ``out.png``
    gives ``out.png`` and the data ``out.exr``. Any other extension is a
    :class:`UsageError` naming the supported ones.
    """
    out = Path(output)
    ext = out.suffix.lower()
    if ext == ".exr":
        return out, out.with_suffix(".png")
    if ext == ".png":
        return out.with_suffix(".exr"), out
    raise UsageError(
        f"-o {out}: unsupported extension {ext or '(none)'!r}; use .exr or .png "
        "(voxgi writes both: the linear EXR and a tone-mapped PNG beside it)"
    )


def check_writable(paths) -> None:
    """Fail now, before any work, if a file cannot be written at each of ``paths``.

    Creates missing folders, then a temporary file in each folder (removed
    at once): the same steps the final writes take. A read-only file
    (:func:`voxgi.io.is_read_only`) is refused, as the final write would.
    """
    from ..io import is_read_only

    for path in paths:
        path = Path(path)
        if path.is_dir():
            raise UsageError(f"cannot write {path}: it is a folder")
        if is_read_only(path):
            raise UsageError(f"cannot write {path}: the file is read-only")
        blocker = next((p for p in path.parents if p.exists() and not p.is_dir()), None)
        if blocker is not None:
            raise UsageError(f"cannot write {path}: {blocker} is a file, not a folder")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(
                dir=path.parent, prefix=f".{path.stem}.", suffix=".probe"
            ):
                pass
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None


def _scene_source(spec: str) -> tuple[Path | None, str]:
    """``(scene file or None for a built-in scene, name)``, checked without loading."""
    from .. import formats, scenes

    src = Path(spec)
    if src.suffix.lower() in {".toml", *formats.LOADERS} or src.exists():
        if not src.is_file():
            raise UsageError(f"scene file not found: {src}")
        return src, src.stem
    if spec.replace("_", "-").lower() not in scenes.names():
        raise UsageError(
            f"unknown built-in scene {spec!r}; known: {', '.join(scenes.names())} "
            "(or give a scene file: .toml, .xml, .obj, .gltf, .glb)"
        )
    return None, spec


def _load_scene(args, src: Path | None, name: str):
    """The scene of a file (through the path policy the options widen) or a
    built-in name; a scene without a camera is a ValueError (exit 1)."""
    from .. import scenes
    from ..scene import Scene

    if src is None:
        return scenes.get(name)
    scene = Scene.load(src, search_paths=args.search_path or (), allow_outside=args.allow_outside)
    if scene.camera is None:
        raise ValueError(
            f"scene file {src}: has no camera to render from (an OBJ holds none); "
            "name the file in a TOML scene with a [camera] table (docs/scene-files.md)"
        )
    return scene
