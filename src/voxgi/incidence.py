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

__all__ = ["NODES", "IncidenceResponse", "base_radiosity", "incidence_response"]

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
    base : (T, NODES, 3) float32 or None
        Row t: the share of R / A that the material's diffuse base reflects
        (a plastic's; 0 for a conductor), at the same cosines.
    """

    table: np.ndarray
    row: np.ndarray
    base: np.ndarray | None = None

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
        if self.base is not None:
            base = np.ascontiguousarray(self.base, np.float32)
            if base.shape != table.shape or not (np.isfinite(base) & (base >= 0)).all():
                raise ValueError(
                    f"IncidenceResponse.base: shape {table.shape} of finite values >= 0"
                )
            object.__setattr__(self, "base", base)

    def at(self, records: np.ndarray, mu: np.ndarray, base: bool = False) -> np.ndarray:
        """(R, 3) R / A of ``records`` (R,) at their cosines ``mu`` (R,);
        with ``base`` the base's share of it (1 for records without a lobe)."""
        out = np.ones((len(records), 3))
        row = self.row[records]
        has = row >= 0
        if not has.any():
            return out
        table = self.base if base else self.table
        x = np.clip(np.asarray(mu, np.float64)[has], 0.0, 1.0) * (NODES - 1)
        i = np.minimum(x.astype(np.int64), NODES - 2)
        t = (x - i)[:, None]
        tab = table[row[has]]
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
    base_table = np.ones((len(lobed), NODES, 3), np.float32)
    row_of_object = np.full(len(objects), -1, np.int32)
    # an interior gives hundreds of objects a few materials: each distinct
    # (lobe, base) is integrated once
    rows: dict = {}
    for t, i in enumerate(lobed):
        m = objects[i].material
        key = (m.specular, tuple(float(x) for x in m.albedo))
        if key not in rows:
            base = np.asarray(m.albedo, np.float64)
            mean = m.specular.solve_albedo(base)
            r = m.specular.directional_albedo(base, mu)
            rb = m.specular.base_albedo(base, mu)
            with np.errstate(divide="ignore", invalid="ignore"):
                rows[key] = (np.where(mean > 0, r / mean, 1.0), np.where(mean > 0, rb / mean, 1.0))
        table[t], base_table[t] = rows[key]
        row_of_object[i] = t
    object_id = np.asarray(vox.object_id)
    row = np.where(np.asarray(vox.back), -1, row_of_object[object_id]).astype(np.int32)
    if not (row >= 0).any():
        return None
    return IncidenceResponse(table=table, row=row, base=base_table)


def base_radiosity(
    scene, vox, response: IncidenceResponse | None, reflected, direct, direct_base
) -> np.ndarray | None:
    """(N, 3) float32: the part of each record's reflected radiosity its
    diffuse base reflects (all of it for a record without a lobe), or None
    without glossy records.

    ``reflected`` is the solve's reflected radiosity A (H_d + H_i), ``direct``
    the direct light H_d weighed by R / A and ``direct_base`` the same weighed
    by the base's share (:func:`voxgi.direct.direct_irradiance`). The direct
    light's split is exact; the light reflected from other records comes from
    all around, and its split is the one under uniform light, 1 - S / A (S the
    coat's hemispherical reflectance). A conductor's is 0 (``docs/design.md`` §14).
    """
    if response is None:
        return None
    A = np.asarray(vox.albedo, np.float64)
    R = np.asarray(reflected, np.float64)
    out = R.copy()
    glossy = np.flatnonzero(response.row >= 0)
    oid = np.asarray(vox.object_id)[glossy]
    a = A[glossy]
    uniform = np.zeros((len(glossy), 3))
    for i in np.unique(oid):
        lobe = scene.objects[i].material.specular
        sel = oid == i
        if lobe.kind == "plastic":
            coat = np.asarray(lobe._plastic_albedo_terms()[0])
            with np.errstate(divide="ignore", invalid="ignore"):
                uniform[sel] = np.where(a[sel] > 0, np.clip(1.0 - coat / a[sel], 0.0, 1.0), 0.0)
    indirect = np.maximum(R[glossy] - a * direct[glossy], 0.0)
    out[glossy] = np.minimum(a * direct_base[glossy] + uniform * indirect, R[glossy])
    return np.maximum(out, 0.0).astype(np.float32)
