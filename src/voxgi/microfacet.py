"""Microfacet lobes: Mitsuba 3's ``roughplastic`` and ``roughconductor``
(isotropic GGX or Beckmann), which the display evaluates at each camera hit
and samples with a share of its gather rays (``docs/design.md`` §14)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from . import _validate

__all__ = ["CONDUCTORS", "Microfacet"]

#: Mitsuba 3's named conductors as its RGB variants read them: (eta, k) per
#: channel (its spectral data reduced to RGB as Mitsuba reduces it).
CONDUCTORS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "none": ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
    "a-C": ((2.94405, 2.22714, 1.96816), (0.88746, 0.7993, 0.81529)),
    "Ag": ((0.15528, 0.11673, 0.13839), (4.82835, 3.12222, 2.1469)),
    "Al": ((1.6575, 0.8804, 0.52124), (9.22381, 6.2695, 4.837)),
    "AlAs": ((3.6053, 3.23294, 2.21632), (0.00068, 0.0, 0.00751)),
    "AlAs_palik": ((3.6053, 3.23294, 2.21632), (0.00068, 0.0, 0.00751)),
    "AlSb": ((0.0, 4.13937, 4.66925), (0.0, 0.09401, 1.30057)),
    "Au": ((0.14304, 0.37531, 1.44205), (3.983, 2.38556, 1.60336)),
    "Be": ((4.18501, 3.18503, 2.78406), (3.83547, 3.01012, 2.86899)),
    "Cr": ((4.36967, 2.91651, 1.6549), (5.20655, 4.23131, 3.7547)),
    "CsI": ((2.1449, 1.70232, 1.66243), (0.0, 0.0, 0.0)),
    "Cu": ((0.20101, 0.92375, 1.10222), (3.91326, 2.45305, 2.14209)),
    "Cu2O": ((3.55177, 2.94987, 2.75188), (0.11421, 0.1939, 0.60613)),
    "CuO": ((3.24754, 2.44781, 2.21022), (0.52109, 0.57003, 0.72218)),
    "d-C": ((2.70872, 2.31883, 2.2289), (0.0, 0.0, 0.0)),
    "Hg": ((2.39894, 1.44003, 0.90957), (6.32759, 4.37192, 3.42176)),
    "HgTe": ((4.77904, 3.2312, 2.6599), (1.63161, 1.58081, 1.72929)),
    "Ir": ((3.0863, 2.08219, 1.61791), (5.59215, 4.06709, 3.26731)),
    "K": ((0.06404, 0.04641, 0.03818), (2.1042, 1.34894, 0.91313)),
    "Li": ((0.26579, 0.19562, 0.22095), (3.54015, 2.31112, 1.66861)),
    "MgO": ((2.08958, 1.65072, 1.59488), (0.0, 0.0, 0.0)),
    "Mo": ((4.48397, 3.52513, 2.77631), (4.11144, 3.42083, 3.15061)),
    "Na_palik": ((0.06027, 0.05614, 0.06199), (3.17927, 2.11249, 1.57904)),
    "Nb": ((3.42007, 2.79009, 2.39563), (3.44139, 2.73767, 2.57975)),
    "Ni_palik": ((2.3673, 1.66337, 1.46708), (4.49881, 3.05015, 2.34544)),
    "Rh": ((2.58579, 1.86022, 1.55426), (6.78226, 4.70299, 3.97607)),
    "Se": ((4.05831, 2.84294, 2.82085), (0.75405, 0.63844, 0.52181)),
    "SiC": ((3.17234, 2.52597, 2.47937), (0.0, 0.0, 1e-05)),
    "SnTe": ((4.52425, 1.98164, 1.28159), (0.0, 0.0, 0.0)),
    "Ta": ((2.06272, 2.39294, 2.62793), (2.40836, 1.74149, 1.94703)),
    "Te": ((7.39023, 4.4821, 2.63711), (3.25602, 3.52706, 3.29205)),
    "ThF4": ((1.83071, 1.44223, 1.38765), (0.0, 0.0, 0.0)),
    "TiC": ((3.70053, 2.83742, 2.58229), (3.26564, 2.35159, 2.17279)),
    "TiN": ((1.64845, 1.15052, 1.37982), (3.36833, 1.9435, 1.10207)),
    "TiO2": ((3.45661, 2.80174, 2.90517), (0.00011, 0.0, 0.00065)),
    "VC": ((3.65757, 2.75274, 2.53267), (3.0683, 2.19869, 1.96319)),
    "V_palik": ((4.27758, 3.51295, 2.76107), (3.4913, 2.88945, 3.11152)),
    "VN": ((2.8656, 2.11919, 1.94009), (3.03224, 2.05612, 1.61631)),
    "W": ((4.37082, 3.30025, 2.99841), (3.50064, 2.60487, 2.27323)),
}

#: Samples of the coat's transmittance table over cos θ (Mitsuba's resolution).
_COAT_SAMPLES = 64
#: Width of one packed row (csrc/microfacet.h, MicrofacetLobe).
LOBE_WIDTH = 21 + _COAT_SAMPLES
#: Share of a pixel's gather rays drawn from the lobe (the rest cosine-
#: distributed): a plastic's base is lit mostly by the diffuse rays, a
#: conductor has no base (docs/design.md §14).
_LOBE_SHARE = {"plastic": 0.5, "conductor": 0.9}


@dataclass(frozen=True)
class Microfacet:
    """A microfacet lobe as Mitsuba 3's ``roughplastic`` / ``roughconductor``.

    For ``kind="plastic"`` the material's ``albedo`` (or texture) is the
    diffuse base under a rough dielectric coat (Mitsuba's
    ``diffuse_reflectance``); for ``kind="conductor"`` there is no base, and
    the material's ``albedo`` is the lobe's hemispherical reflectance (what
    the diffuse solve bounces; :meth:`albedo`). The display evaluates the
    whole BSDF at each camera hit; the solve stays diffuse.

    Parameters
    ----------
    kind : {"plastic", "conductor"}
    alpha : float
        Roughness in [1e-4, 4] (Mitsuba clamps below 1e-4).
    distribution : {"ggx", "beckmann"}
    specular_reflectance : float or (3,) float
        Scale of the specular term per channel, in [0, 1].
    ior : float
        Plastic: interior over exterior index of refraction (Mitsuba's
        ``int_ior / ext_ior``; default polypropylene in air).
    eta, k : float or (3,) float
        Conductor: the complex index of refraction per channel (default a
        perfect mirror, ``eta`` 0 and ``k`` 1, Mitsuba's ``material="none"``).
        See :data:`CONDUCTORS`.
    nonlinear : bool
        Plastic: Mitsuba's ``nonlinear`` (the base's inner bounces tint it).

    Examples
    --------
    >>> import voxgi
    >>> lobe = voxgi.Microfacet("conductor", alpha=0.2, eta=voxgi.CONDUCTORS["Au"][0],
    ...                         k=voxgi.CONDUCTORS["Au"][1])
    >>> [round(x, 2) for x in lobe.albedo()]
    [0.88, 0.74, 0.32]
    """

    kind: str = "plastic"
    alpha: float = 0.1
    distribution: str = "ggx"
    specular_reflectance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ior: float = 1.49 / 1.000277
    eta: tuple[float, float, float] = (0.0, 0.0, 0.0)
    k: tuple[float, float, float] = (1.0, 1.0, 1.0)
    nonlinear: bool = False

    def __post_init__(self):
        if self.kind not in ("plastic", "conductor"):
            raise ValueError(f"Microfacet.kind: 'plastic' or 'conductor', got {self.kind!r}")
        if self.distribution not in ("ggx", "beckmann"):
            raise ValueError(
                f"Microfacet.distribution: 'ggx' or 'beckmann', got {self.distribution!r}"
            )
        a = _validate.real(self.alpha, "Microfacet.alpha", low=1e-4, high=4.0)
        object.__setattr__(self, "alpha", a)
        object.__setattr__(
            self,
            "specular_reflectance",
            _validate.rgb(self.specular_reflectance, "Microfacet.specular_reflectance", high=1.0),
        )
        ior = _validate.real(self.ior, "Microfacet.ior", low=0.1, high=10.0)
        if self.kind == "plastic" and ior == 1.0:
            raise ValueError("Microfacet.ior: a plastic's coat needs an index other than 1")
        object.__setattr__(self, "ior", ior)
        object.__setattr__(self, "eta", _validate.rgb(self.eta, "Microfacet.eta", high=100.0))
        object.__setattr__(self, "k", _validate.rgb(self.k, "Microfacet.k", high=100.0))
        object.__setattr__(self, "nonlinear", bool(self.nonlinear))

    def lobe_row(self) -> np.ndarray:
        """(85,) float32: the lobe as the display's kernels read it
        (csrc/microfacet.h)."""
        return _lobe_row(self).copy()

    def _row(self) -> np.ndarray:
        row = np.zeros(LOBE_WIDTH, np.float32)
        row[0] = 1.0 if self.kind == "plastic" else 2.0
        row[1] = 1.0 if self.distribution == "beckmann" else 0.0
        row[2] = self.alpha
        row[7] = _LOBE_SHARE[self.kind]
        row[8:11] = self.specular_reflectance
        row[11:14] = self.eta
        row[14:17] = self.k
        if self.kind == "plastic":
            row[3] = self.ior
            row[4] = 1.0 / self.ior**2
            row[5] = self.internal_reflectance()
            row[6] = 1.0 if self.nonlinear else 0.0
            s, c = self._plastic_albedo_terms()
            row[17:20] = s
            row[20] = c
            row[21:] = self.coat_transmittance()
        else:
            row[3] = 1.0
        return row

    def coat_transmittance(self) -> np.ndarray:
        """(64,) the rough coat's transmittance at cos θ = i / 63: the light
        refracted into it that its facets do not mask (the table Mitsuba's
        roughplastic interpolates)."""
        return _coat_transmittance(self).copy()

    def internal_reflectance(self) -> float:
        """The coat's reflectance of the base's light from inside, as
        Mitsuba's roughplastic computes it (twice the mean over the table's
        cosines of the reflectance times the cosine)."""
        return _internal_reflectance(self)

    def _plastic_albedo_terms(self) -> tuple[np.ndarray, float]:
        """(S, c): a plastic's hemispherical reflectance under uniform light
        is S + c g(rd), S (3,) its coat's and c g(rd) its base's, with
        g(rd) = rd / (1 - Fdr) (or rd / (1 - Fdr rd), nonlinear)."""
        s, c = _plastic_albedo_terms(self)
        return s.copy(), c

    def solve_albedo(self, base) -> np.ndarray:
        """The hemispherical reflectance under uniform light of a plastic of
        diffuse base ``base`` ((..., 3)): what the diffuse solve reflects
        (``docs/design.md`` §14). A conductor's is :meth:`albedo`."""
        base = np.asarray(base, np.float64)
        if self.kind == "conductor":
            return np.broadcast_to(np.asarray(self.albedo()), base.shape).copy()
        s, c = self._plastic_albedo_terms()
        f = self.internal_reflectance()
        g = base / (1.0 - f * base) if self.nonlinear else base / (1.0 - f)
        return s + c * g

    def directional_albedo(self, base, mu) -> np.ndarray:
        """(len(mu), 3) the share of light arriving at cos θ = ``mu`` that the
        material reflects, its coat's and (a plastic of diffuse base ``base``
        (3,)) its base's through the coat, R(μ) = r(μ) + g(base) t(μ) τ̄ / η²:
        the directional albedo, whose mean 2 ∫ R(μ) μ dμ under uniform light
        is :meth:`solve_albedo` (``docs/design.md`` §14)."""
        mu = np.clip(np.atleast_1d(np.asarray(mu, np.float64)), 1e-6, 1.0)
        if self.kind == "conductor":
            out = np.empty((len(mu), 3))
            for c in range(3):
                fres = ("conductor", self.eta[c], self.k[c])
                r = _reflectance(self.distribution, self.alpha, mu, fres)
                out[:, c] = r * self.specular_reflectance[c]
            return out
        spec = _reflectance(self.distribution, self.alpha, mu, ("dielectric", self.ior))
        return spec[:, None] * np.asarray(self.specular_reflectance) + self.base_albedo(base, mu)

    def base_albedo(self, base, mu) -> np.ndarray:
        """(len(mu), 3) the share of light arriving at cos θ = ``mu`` that a
        plastic's diffuse base ``base`` (3,) sends back out through the coat,
        g(base) t(μ) τ̄ / η² (:meth:`directional_albedo` less the coat's own
        reflection); 0 for a conductor."""
        mu = np.clip(np.atleast_1d(np.asarray(mu, np.float64)), 1e-6, 1.0)
        if self.kind == "conductor":
            return np.zeros((len(mu), 3))
        t = np.interp(mu, np.linspace(0.0, 1.0, _COAT_SAMPLES), _coat_transmittance(self))
        base = np.asarray(base, np.float64)
        f = self.internal_reflectance()
        g = base / (1.0 - f * base) if self.nonlinear else base / (1.0 - f)
        _, c = self._plastic_albedo_terms()
        tau = np.sqrt(c) * self.ior  # c = τ̄² / η²
        return g * (t * tau / self.ior**2)[:, None]

    def albedo(self) -> tuple[float, float, float]:
        """The specular term's hemispherical reflectance under uniform
        light, per channel (the albedo a conductor's records carry in the
        diffuse solve)."""
        return _conductor_albedo(self)


# The lobe's tables are integrals over thousands of facet samples (a
# plastic's, about 0.4 s); a loaded interior gives hundreds of objects a
# few distinct lobes, so each lobe's are computed once. Cached arrays are
# read-only and handed out as copies.


@functools.lru_cache(maxsize=1024)
def _lobe_row(lobe: Microfacet) -> np.ndarray:
    return lobe._row()


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@functools.lru_cache(maxsize=1024)
def _coat_transmittance(lobe: Microfacet) -> np.ndarray:
    mu = np.maximum(1e-6, np.linspace(0.0, 1.0, _COAT_SAMPLES))
    return _frozen(_reflectance(lobe.distribution, lobe.alpha, mu, ("dielectric", lobe.ior), True))


@functools.lru_cache(maxsize=1024)
def _internal_reflectance(lobe: Microfacet) -> float:
    mu = np.maximum(1e-6, np.linspace(0.0, 1.0, _COAT_SAMPLES))
    r = _reflectance(lobe.distribution, lobe.alpha, mu, ("dielectric", 1.0 / lobe.ior))
    return float(2.0 * np.mean(r * mu))


@functools.lru_cache(maxsize=1024)
def _plastic_albedo_terms(lobe: Microfacet) -> tuple[np.ndarray, float]:
    x, w = np.polynomial.legendre.leggauss(48)
    mu, w = 0.5 * (x + 1.0), 0.5 * w
    r = _reflectance(lobe.distribution, lobe.alpha, mu, ("dielectric", lobe.ior))
    s = float(np.sum(2.0 * w * mu * r)) * np.asarray(lobe.specular_reflectance, np.float64)
    # the base's light: (2 ∫ t(μ) μ dμ)² / eta², t interpolated as Mitsuba does
    t = np.interp(mu, np.linspace(0.0, 1.0, _COAT_SAMPLES), _coat_transmittance(lobe))
    c = float(np.sum(2.0 * w * mu * t)) ** 2 / lobe.ior**2
    return _frozen(s), c


@functools.lru_cache(maxsize=1024)
def _conductor_albedo(lobe: Microfacet) -> tuple[float, float, float]:
    x, w = np.polynomial.legendre.leggauss(48)
    mu, w = 0.5 * (x + 1.0), 0.5 * w
    out = []
    for c in range(3):
        fres = ("conductor", lobe.eta[c], lobe.k[c])
        r = _reflectance(lobe.distribution, lobe.alpha, mu, fres)
        out.append(float(np.sum(2.0 * w * mu * r)) * lobe.specular_reflectance[c])
    return tuple(out)


def _smith_g1(dist: str, alpha: float, cv: np.ndarray, vm: np.ndarray) -> np.ndarray:
    t2 = alpha * alpha * np.maximum(0.0, 1.0 - cv * cv) / np.maximum(cv * cv, 1e-300)
    with np.errstate(divide="ignore"):
        if dist == "beckmann":
            a = 1.0 / np.sqrt(t2)
            g = np.where(
                a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1 + 2.276 * a + 2.577 * a * a)
            )
        else:
            g = 2.0 / (1.0 + np.sqrt(1.0 + t2))
    g = np.where(t2 == 0, 1.0, g)
    return np.where(vm * cv > 0, g, 0.0)


def _fresnel(c: np.ndarray, fres: tuple) -> np.ndarray:
    if fres[0] == "dielectric":
        eta = fres[1]
        c = np.maximum(c, 1e-12)
        st2 = (1.0 - c * c) / (eta * eta)
        ct = np.sqrt(np.maximum(0.0, 1.0 - st2))
        a_s = (c - eta * ct) / (c + eta * ct)
        a_p = (ct - eta * c) / (ct + eta * c)
        return np.where(st2 >= 1.0, 1.0, 0.5 * (a_s * a_s + a_p * a_p))
    eta, k = fres[1], fres[2]
    c2 = c * c
    s2 = 1.0 - c2
    t1 = eta * eta - k * k - s2
    a2b2 = np.sqrt(np.maximum(0.0, t1 * t1 + 4 * k * k * eta * eta))
    a = np.sqrt(np.maximum(0.0, 0.5 * (a2b2 + t1)))
    term1, term2 = a2b2 + c2, 2 * c * a
    rs = (term1 - term2) / (term1 + term2)
    term3, term4 = a2b2 * c2 + s2 * s2, term2 * s2
    return 0.5 * (rs + rs * (term3 - term4) / (term3 + term4))


def _visible_slopes(dist: str, cos_i: float, u: np.ndarray, v: np.ndarray):
    """Slopes of the visible normals of the unit-roughness lobe seen at
    cos θ_i from samples (u, v) in the unit square, as Mitsuba draws them."""
    if dist == "beckmann":
        from scipy.special import erf, erfinv

        tan_i = np.sqrt(max(0.0, 1.0 - cos_i * cos_i)) / cos_i
        cot_i = 1.0 / tan_i if tan_i > 0 else np.inf
        maxval = erf(cot_i)
        u = np.clip(u, 1e-6, 1.0 - 1e-6)
        v = np.clip(v, 1e-6, 1.0 - 1e-6)
        x = maxval - (maxval + 1.0) * erf(np.sqrt(-np.log(u)))
        tail = tan_i * np.exp(-cot_i * cot_i) / np.sqrt(np.pi) if tan_i > 0 else 0.0
        u = u * (1.0 + maxval + tail)
        for _ in range(3):
            slope = erfinv(x)
            value = 1.0 + x + tan_i * np.exp(-slope * slope) / np.sqrt(np.pi) - u
            x = x - value / (1.0 - slope * tan_i)
        return erfinv(x), erfinv(2.0 * v - 1.0)
    # the concentric disk, half of it stretched by the view (GGX)
    a, b = 2.0 * u - 1.0, 2.0 * v - 1.0
    q13 = np.abs(a) < np.abs(b)
    r = np.where(q13, b, a)
    rp = np.where(q13, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = 0.25 * np.pi * rp / r
    phi = np.where(q13, 0.5 * np.pi - phi, phi)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    px, py = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + cos_i)
    py = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - px * px)) + s * py
    pz = np.sqrt(np.maximum(0.0, 1.0 - px * px - py * py))
    sin_i = np.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    norm = 1.0 / (sin_i * py + cos_i * pz)
    return (cos_i * py - sin_i * pz) * norm, px * norm


def _reflectance(
    dist: str, alpha: float, mu: np.ndarray, fres: tuple, transmitted: bool = False
) -> np.ndarray:
    """Directional reflectance of the specular term, ∫ f cos_o dω_o, at
    cos θ_i = mu: the mean over the visible normals of F G1(wo); or with
    ``transmitted`` (a dielectric) of (1 - F) G1(wt) along the refracted wt; by the
    Gauss-Legendre rule over Mitsuba's sampling of them that its
    roughplastic tabulates (32² nodes, 128² for a relative index below 1),
    so that the table is Mitsuba's."""
    res = 128 if fres[0] == "dielectric" and fres[1] < 1.0 else 32
    x, w = np.polynomial.legendre.leggauss(res)
    U, V = np.meshgrid(0.5 * (x + 1.0), 0.5 * (x + 1.0), indexing="xy")
    W = np.outer(w, w).T.ravel() * 0.25
    U, V = U.ravel(), V.ravel()
    out = np.empty(len(mu))
    for i, c in enumerate(np.asarray(mu, np.float64)):
        s_i = np.sqrt(max(0.0, 1.0 - c * c))
        # the view stretched to unit roughness: (α s_i, 0, c) normalised
        wl = np.hypot(alpha * s_i, c)
        sx, sy = _visible_slopes(dist, c / wl, U, V)
        m = np.stack([-alpha * sx, -alpha * sy, np.ones_like(sx)], axis=1)
        m /= np.linalg.norm(m, axis=1, keepdims=True)
        im = m[:, 0] * s_i + m[:, 2] * c
        F = _fresnel(np.clip(im, 0.0, 1.0), fres)
        if transmitted:
            inv = 1.0 / fres[1]
            ct = -np.sqrt(np.maximum(0.0, 1.0 - (1.0 - im * im) * inv * inv))
            # the refracted direction m (wi·m / eta + cos θ_t) - wi / eta
            wt = m * (im * inv + ct)[:, None] - np.array([s_i, 0.0, c]) * inv
            wt_m = np.einsum("ij,ij->i", wt, m)
            g = _smith_g1(dist, alpha, wt[:, 2], wt_m) * (1.0 - F)
            out[i] = np.sum(np.where(wt[:, 2] * c < 0, g, 0.0) * W)
            continue
        wo_z = 2.0 * im * m[:, 2] - c
        g = _smith_g1(dist, alpha, wo_z, im) * F
        out[i] = np.sum(np.where(wo_z > 0, g, 0.0) * W)
    return out
