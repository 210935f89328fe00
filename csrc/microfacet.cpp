// Microfacet lobes of the display (see microfacet.h and docs/design.md §14).
// The formulas are those Mitsuba 3's roughplastic and roughconductor
// evaluate, so that a scene exported to Mitsuba renders the same material.
#include "microfacet.h"

#include <algorithm>
#include <cmath>

namespace voxgi {

namespace {

constexpr double kPi = 3.14159265358979323846;

inline double dot3(const float* a, const float* b) {
    return double(a[0]) * b[0] + double(a[1]) * b[1] + double(a[2]) * b[2];
}

// The microfacet density D(m) of a normal at cos θ_m = c (isotropic).
double ndf(const MicrofacetLobe& L, double c) {
    if (!(c > 0.0)) return 0.0;
    const double a2 = double(L.alpha) * L.alpha, c2 = c * c, s2 = std::max(0.0, 1.0 - c2);
    double d;
    if (L.beckmann != 0.f) {
        d = std::exp(-s2 / (a2 * c2)) / (kPi * a2 * c2 * c2);
    } else {
        const double t = s2 / a2 + c2;
        d = 1.0 / (kPi * a2 * t * t);
    }
    return d * c > 1e-20 ? d : 0.0;
}

// Smith's masking of direction v (cos θ_v = cv to the normal) by facets of
// normal m (v·m = vm); Beckmann by the rational fit Mitsuba uses.
double smith_g1(const MicrofacetLobe& L, double cv, double vm) {
    if (vm * cv <= 0.0) return 0.0;
    const double xy = double(L.alpha) * L.alpha * std::max(0.0, 1.0 - cv * cv);
    if (xy == 0.0) return 1.0;
    const double t2 = xy / (cv * cv);  // (α tan θ_v)²
    if (L.beckmann != 0.f) {
        const double a = 1.0 / std::sqrt(t2);
        if (a >= 1.6) return 1.0;
        return (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a);
    }
    return 2.0 / (1.0 + std::sqrt(1.0 + t2));
}

// Unpolarised Fresnel reflectance of a dielectric interface (relative index
// eta) for light arriving from outside at cos θ = c >= 0.
double fresnel_dielectric(double c, double eta) {
    if (eta == 1.0) return 0.0;
    if (c <= 0.0) return 1.0;
    const double st2 = (1.0 - c * c) / (eta * eta);
    if (st2 >= 1.0) return 1.0;
    const double ct = std::sqrt(1.0 - st2);
    const double as = (c - eta * ct) / (c + eta * ct), ap = (ct - eta * c) / (ct + eta * c);
    return 0.5 * (as * as + ap * ap);
}

// Fresnel reflectance of a conductor (index eta + i k) at cos θ = c
// (the unpolarised closed form after Moeller, "Optics").
double fresnel_conductor(double c, double eta, double k) {
    const double c2 = c * c, s2 = 1.0 - c2, s4 = s2 * s2;
    const double t1 = eta * eta - k * k - s2;
    const double a2b2 = std::sqrt(std::max(0.0, t1 * t1 + 4.0 * k * k * eta * eta));
    const double a = std::sqrt(std::max(0.0, 0.5 * (a2b2 + t1)));
    const double term1 = a2b2 + c2, term2 = 2.0 * c * a;
    const double rs = (term1 - term2) / (term1 + term2);
    const double term3 = a2b2 * c2 + s4, term4 = term2 * s2;
    const double rp = rs * (term3 - term4) / (term3 + term4);
    return 0.5 * (rs + rp);
}

// The coat's tabulated transmittance at cos θ = c, linearly interpolated.
double coat_transmittance(const MicrofacetLobe& L, double c) {
    const int n = kCoatTransmittanceSamples;
    const double x = std::clamp(c, 0.0, 1.0) * (n - 1);
    const int i = std::min(int(x), n - 2);
    const double t = x - i;
    return (1.0 - t) * L.coat_transmittance[i] + t * L.coat_transmittance[i + 1];
}

}  // namespace

void microfacet_brdf(const MicrofacetLobe& L, const float* rd, const float n[3], const float wi[3],
                     const float wo[3], float f[3]) {
    f[0] = f[1] = f[2] = 0.f;
    const double ci = dot3(n, wi), co = dot3(n, wo);
    if (!(ci > 0.0) || !(co > 0.0)) return;
    double h[3] = {double(wi[0]) + wo[0], double(wi[1]) + wo[1], double(wi[2]) + wo[2]};
    const double hl = std::sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
    double spec[3] = {0.0, 0.0, 0.0};
    if (hl > 0.0) {
        for (double& x : h) x /= hl;
        const double ch = n[0] * h[0] + n[1] * h[1] + n[2] * h[2];
        const double ih = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2];
        const double oh = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2];
        const double dg = ndf(L, ch) * smith_g1(L, ci, ih) * smith_g1(L, co, oh) / (4.0 * ci * co);
        for (int c = 0; c < 3; ++c) {
            const double F = L.kind == 2.f ? fresnel_conductor(ih, L.eta_c[c], L.k_c[c])
                                           : fresnel_dielectric(ih, L.eta);
            spec[c] = F * dg * L.specular[c];
        }
    }
    if (L.kind == 1.f) {
        // The base's light enters and leaves through the coat, and what the
        // coat reflects back inside returns to the base (a geometric series).
        const double t = coat_transmittance(L, ci) * coat_transmittance(L, co) * L.inv_eta2 / kPi;
        for (int c = 0; c < 3; ++c) {
            const double inner = L.nonlinear != 0.f ? rd[c] * L.fdr_int : L.fdr_int;
            spec[c] += rd[c] / (1.0 - inner) * t;
        }
    }
    for (int c = 0; c < 3; ++c) f[c] = float(spec[c]);
}

double microfacet_pdf(const MicrofacetLobe& L, const float n[3], const float wo[3],
                      const float wi[3]) {
    const double ci = dot3(n, wi), co = dot3(n, wo);
    if (!(ci > 0.0) || !(co > 0.0)) return 0.0;
    double h[3] = {double(wi[0]) + wo[0], double(wi[1]) + wo[1], double(wi[2]) + wo[2]};
    const double hl = std::sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
    if (!(hl > 0.0)) return 0.0;
    const double ch = (n[0] * h[0] + n[1] * h[1] + n[2] * h[2]) / hl;
    const double oh = (wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]) / hl;
    if (!(oh > 0.0)) return 0.0;
    // D(m) cos θ_m per unit solid angle of m; dω_m / dω_i = 1 / (4 wo·m)
    return ndf(L, ch) * ch / (4.0 * oh);
}

bool microfacet_sample(const MicrofacetLobe& L, const float n[3], const float wo[3], double u1,
                       double u2, float wi[3]) {
    const double a2 = double(L.alpha) * L.alpha;
    u1 = std::min(u1, 1.0 - 1e-12);
    const double t2 = L.beckmann != 0.f ? -a2 * std::log1p(-u1) : a2 * u1 / (1.0 - u1);
    const double cm = 1.0 / std::sqrt(1.0 + t2), sm = std::sqrt(std::max(0.0, 1.0 - cm * cm));
    const double phi = 2.0 * kPi * u2;
    // a frame around n (any: the lobe is isotropic)
    double u[3];
    if (std::fabs(n[1]) < 0.99f)
        u[0] = -n[2], u[1] = 0.0, u[2] = n[0];
    else
        u[0] = 0.0, u[1] = n[2], u[2] = -n[1];
    const double ul = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    for (double& x : u) x /= ul;
    const double v[3] = {n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2],
                         n[0] * u[1] - n[1] * u[0]};
    const double a = sm * std::cos(phi), b = sm * std::sin(phi);
    double m[3], om = 0.0;
    for (int k = 0; k < 3; ++k) {
        m[k] = a * u[k] + b * v[k] + cm * n[k];
        om += wo[k] * m[k];
    }
    if (!(om > 0.0)) return false;
    double cw = 0.0;
    for (int k = 0; k < 3; ++k) {
        wi[k] = float(2.0 * om * m[k] - wo[k]);
        cw += wi[k] * double(n[k]);
    }
    return cw > 0.0;
}

}  // namespace voxgi
