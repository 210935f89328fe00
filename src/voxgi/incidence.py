"""How much of its light a glossy record reflects, by where the light comes from.

The solve is diffuse: a record's radiosity is its albedo times the light it
gathers. A glossy material (:class:`voxgi.Microfacet`) reflects the light
arriving at cos θ = μ with its directional albedo R(μ), which grows towards
grazing incidence (the coat's Fresnel reflection) and whose mean under
uniform light, 2 ∫ R(μ) μ dμ, is the albedo its records carry. A plastic
floor lit by lamps seen at grazing angles reflects up to twice that mean, one
lit from straight above 0.9 of it. Every estimate of the light a record
gathers (its direct light, the lights and the environment, the traced
passes) therefore weighs each sample by R(μ) / A at its own cosine, so that
the record reflects what the material reflects of that light
(``docs/design.md`` §14). Where it sends that light is still the diffuse
solve's: alike in every direction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .microfacet import Microfacet

__all__ = ["NODES", "IncidenceResponse", "incidence_response"]

#: Cosines of a table row, i / (NODES - 1) (csrc/incidence_response.h).
NODES = 33


@dataclass(frozen=True)
class IncidenceResponse:
    """Each record's R(μ) / A, as the compiled kernels read it.

    Attributes
    ----------
    table : (T, NODES, 3) float32
        Row t: R / A per channel at μ = i / (NODES - 1), interpolated linearly.
    row : (N,) int32
        Each record's row, -1 where its material has no lobe (R / A = 1).
    """

    table: np.ndarray
    row: np.ndarray

    def __post_init__(self):
        table = np.ascontiguousarray(self.table, np.float32)
        row = np.ascontiguousarray(self.row, np.int32)
        if table.ndim != 3 or table.shape[1:] != (NODES, 3):
            raise ValueError(f"IncidenceResponse.table: shape (T, {NODES}, 3), got {table.shape}")
        bad = np.flatnonzero(~(np.isfinite(table) & (table >= 0)).all(axis=(1, 2)))
        if len(bad):
            raise ValueError(
                f"IncidenceResponse.table: row {bad[0]} holds a value that is not finite and >= 0"
            )
        if row.ndim != 1:
            raise ValueError(f"IncidenceResponse.row: one row per record, got shape {row.shape}")
        past = np.flatnonzero(row >= len(table))
        if len(past):
            raise ValueError(
                f"IncidenceResponse.row: record {past[0]} names row {row[past[0]]} "
                f"of a table of {len(table)}"
            )
        object.__setattr__(self, "table", table)
        object.__setattr__(self, "row", row)

    def at(self, records: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """(R, 3) R / A of ``records`` (R,) at their cosines ``mu`` (R,)."""
        out = np.ones((len(records), 3))
        row = self.row[records]
        has = row >= 0
        if not has.any():
            return out
        x = np.clip(np.asarray(mu, np.float64)[has], 0.0, 1.0) * (NODES - 1)
        i = np.minimum(x.astype(np.int64), NODES - 2)
        t = (x - i)[:, None]
        tab = self.table[row[has]]
        k = np.arange(len(i))
        out[has] = (1.0 - t) * tab[k, i] + t * tab[k, i + 1]
        return out


def incidence_response(scene, vox) -> IncidenceResponse | None:
    """The records' :class:`IncidenceResponse`, or None where no object of
    ``scene`` has a microfacet lobe (every record reflects alike from every
    direction, and no kernel pays for the tables).

    One row per object with a lobe, made for its material's base albedo
    (a texture's mean where it has one); the records on the back of a
    two-sided object, which the solve takes as diffuse, have none.
    """
    objects = scene.objects
    lobed = [i for i, o in enumerate(objects) if isinstance(o.material.specular, Microfacet)]
    if not lobed:
        return None
    mu = np.linspace(0.0, 1.0, NODES)
    table = np.ones((len(lobed), NODES, 3), np.float32)
    row_of_object = np.full(len(objects), -1, np.int32)
    for t, i in enumerate(lobed):
        m = objects[i].material
        base = np.asarray(m.albedo, np.float64)
        mean = m.specular.solve_albedo(base)
        r = m.specular.directional_albedo(base, mu)
        with np.errstate(divide="ignore", invalid="ignore"):
            table[t] = np.where(mean > 0, r / mean, 1.0)
        row_of_object[i] = t
    object_id = np.asarray(vox.object_id)
    row = np.where(np.asarray(vox.back), -1, row_of_object[object_id]).astype(np.int32)
    if not (row >= 0).any():
        return None
    return IncidenceResponse(table=np.ascontiguousarray(table), row=row)
