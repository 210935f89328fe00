"""What a scene file may read: one path policy and one way to read for every format.

A scene file may read files inside its own folder and inside the folders the
user names (``search_paths``), symbolic links resolved first; ``allow_outside``
lifts the rule (docs/scene-files.md). Every file is opened without blocking,
must be a regular file (not a FIFO, a device such as ``/dev/zero`` or a
folder) and is read only up to :attr:`Limits.file_bytes`. A path outside the
allowed folders is refused before anything is asked of the file system about
it, so that the error does not tell whether it exists.
"""

from __future__ import annotations

import io
import os
import stat
from pathlib import Path

import trimesh

from ._limits import Limits, RefusedError

__all__ = ["FileAccess"]


class FileAccess:
    """The path policy, the limits and the counts of one scene being read.

    Parameters
    ----------
    scene_file : Path
        The scene file; its folder is always allowed.
    search_paths : sequence of path-like
        More folders the scene's files may lie in.
    allow_outside : bool
        Read any path the scene names.
    limits : Limits or None
        None reads :meth:`Limits.from_env`.
    """

    def __init__(self, scene_file, search_paths=(), allow_outside: bool = False, limits=None):
        self.scene_file = Path(scene_file)
        if isinstance(search_paths, (str, os.PathLike)):
            search_paths = [search_paths]
        self.roots = [Path(os.path.realpath(self.scene_file.parent))]
        self.roots += [Path(os.path.realpath(p)) for p in search_paths]
        self.allow_outside = bool(allow_outside)
        if limits is None:
            limits = Limits.from_env()
        if not isinstance(limits, Limits):
            raise TypeError(f"limits: expected voxgi.formats.Limits, got {type(limits).__name__}")
        self.limits = limits
        self.elements = 0
        self.includes = 0

    # -- the policy ---------------------------------------------------------
    def allowed(self, path) -> bool:
        """Whether ``path`` (symbolic links resolved) lies inside an allowed folder."""
        if self.allow_outside:
            return True
        real = Path(os.path.realpath(path))
        return any(real == r or real.is_relative_to(r) for r in self.roots)

    def check(self, path, what: str) -> Path:
        """``path`` if the policy allows it, else a ValueError naming it and the rule."""
        path = Path(path)
        if not self.allowed(path):
            folders = ", ".join(str(r) for r in self.roots)
            raise RefusedError(
                f"{what} {path}: outside the folders this scene may read ({folders}); "
                "name its folder with search_paths=[...] (voxgi render --search-path DIR) "
                "or pass allow_outside=True (--allow-outside)"
            )
        return path

    # -- reading --------------------------------------------------------------
    def read_bytes(self, path, what: str) -> bytes:
        """The bytes of a regular file the policy allows, at most ``limits.file_bytes``."""
        path = self.check(path, what)
        limit = self.limits.file_bytes
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            raise FileNotFoundError(f"{what} not found: {path}") from None
        except OSError as exc:
            raise ValueError(f"{what} {path}: cannot be read ({exc.strerror or exc})") from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise ValueError(f"{what} {path}: not a regular file ({_kind(st.st_mode)})")
            self.limits.check("file_bytes", st.st_size, f"{what} {path}")
        except BaseException:
            os.close(fd)
            raise
        with open(fd, "rb", closefd=True) as fh:
            try:
                data = fh.read(limit + 1)
            except OSError as exc:
                raise ValueError(f"{what} {path}: cannot be read ({exc.strerror or exc})") from None
        # (a file that grows while read, or reports no size, as in /proc)
        self.limits.check("file_bytes", len(data), f"{what} {path}")
        return data

    def check_file(self, path, what: str) -> Path:
        """``path`` if the policy allows it and it is a regular file within
        ``limits.file_bytes`` (for readers that open the file themselves)."""
        path = self.check(path, what)
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            raise FileNotFoundError(f"{what} not found: {path}") from None
        except OSError as exc:
            raise ValueError(f"{what} {path}: cannot be read ({exc.strerror or exc})") from None
        try:
            st = os.fstat(fd)
        finally:
            os.close(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"{what} {path}: not a regular file ({_kind(st.st_mode)})")
        self.limits.check("file_bytes", st.st_size, f"{what} {path}")
        return path

    def read_text(self, path, what: str) -> str:
        """The UTF-8 text of a file, as :meth:`read_bytes`; undecodable bytes replaced."""
        return self.read_bytes(path, what).decode("utf-8", errors="replace")

    def stream(self, path, what: str) -> io.BytesIO:
        """A file's bytes as a stream (for readers that want one), as :meth:`read_bytes`."""
        return io.BytesIO(self.read_bytes(path, what))

    def count(self, name: str, n: int, where: str) -> None:
        """Add ``n`` to the scene's count of ``elements`` or ``includes``; ValueError
        naming ``where`` once the count exceeds its limit."""
        total = getattr(self, name) + n
        setattr(self, name, total)
        self.limits.check(name, total, where)

    def resolver(self, folder, what: str = "file named by a mesh") -> trimesh.resolvers.Resolver:
        """A trimesh resolver that reads the files a mesh names through this policy
        (each once: what it read is kept in its ``cache``)."""
        return _PolicyResolver(self, Path(folder), what)


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a plain file"


class _PolicyResolver(trimesh.resolvers.Resolver):
    """trimesh's view of the files beside a mesh (glTF buffers and images, MTL
    libraries), read through a :class:`FileAccess`."""

    def __init__(self, access: FileAccess, folder: Path, what: str = "file named by a mesh"):
        self.access = access
        self.parent = folder
        self.what = what
        self.cache: dict[str, bytes] = {}

    def get(self, name):
        key = str(name)
        if key not in self.cache:
            self.cache[key] = self.access.read_bytes(self.parent / key, self.what)
        return self.cache[key]

    def keys(self):  # pragma: no cover - trimesh asks only for named files
        return iter(())

    def write(self, name, data):  # pragma: no cover - voxgi only reads scenes
        raise ValueError("a scene reader does not write files")

    def namespaced(self, namespace):
        return _PolicyResolver(self.access, self.parent / namespace, self.what)
