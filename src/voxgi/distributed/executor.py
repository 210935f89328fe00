"""The executor the stages accept for ``client=``."""

from __future__ import annotations

from ..display import FrameShaderSpec
from ..radiosity import LineRecords
from .client import check_client
from .frames import DistributedFrames
from .lines import DistributedLineSystem


def executor(client):
    """The executor for ``client=``: None for None, an executor as it is
    (an object with a ``line_system`` or a ``frames`` method, see
    :class:`voxgi.radiosity.LineExecutor` and :class:`voxgi.display.FrameExecutor`),
    a ``dask.distributed.Client`` wrapped in a :class:`DaskExecutor`.

    >>> executor(None) is None
    True

    Raises
    ------
    ImportError
        A Client-like argument while dask.distributed is not installed.
    TypeError
        Neither an executor nor a Client.
    """
    if client is None:
        return None
    if any(callable(getattr(client, m, None)) for m in ("line_system", "frames")):
        return client
    return DaskExecutor(check_client(client))


class DaskExecutor:
    """Solve passes and render frames on the workers of a Dask cluster.

    Parameters
    ----------
    client : dask.distributed.Client
    """

    def __init__(self, client):
        self.client = check_client(client)

    def line_system(self, records: LineRecords, *, progress: bool = False):
        """A :class:`DistributedLineSystem` of ``records`` (see
        :class:`voxgi.radiosity.LineExecutor`)."""
        return DistributedLineSystem(self.client, records, progress=progress)

    def frames(self, spec: FrameShaderSpec, max_frames: int, *, threads: int = 1):
        """A :class:`DistributedFrames` of ``spec`` (see
        :class:`voxgi.display.FrameExecutor`; each task uses its worker's threads)."""
        return DistributedFrames(self.client, spec, max_frames)
