// Microfacet lobes of the display (docs/design.md §14): Mitsuba 3's
// `roughplastic` (a rough dielectric coat over a diffuse base) and
// `roughconductor`, isotropic GGX or Beckmann, evaluated at a camera hit,
// and sampled by a share of its gather rays.
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>

namespace voxgi {

// Samples of the coat's rough transmittance over cos θ in [0, 1].
constexpr int kCoatTransmittanceSamples = 64;

// One material's lobe: one float32 row of the (M, kLobeWidth) table the
// display packs (voxgi.materials.Microfacet.lobe_row); kind 0: no lobe.
struct MicrofacetLobe {
    float kind;         // 0: none, 1: rough plastic, 2: rough conductor
    float beckmann;     // 1: Beckmann, 0: GGX
    float alpha;        // roughness (the slopes' RMS over sqrt 2 for Beckmann)
    float eta;          // plastic: interior over exterior index of refraction
    float inv_eta2;     // plastic: 1 / eta²
    float fdr_int;      // plastic: the coat's internal diffuse reflectance
    float nonlinear;    // plastic: 1 where the base's inner bounces tint it (Mitsuba's nonlinear)
    float lobe_share;   // fraction of the gather rays drawn from the lobe
    float specular[3];  // specular_reflectance
    float eta_c[3], k_c[3];  // conductor: complex index of refraction per channel
    // plastic: the hemispherical reflectance S + c g(rd) the solve's records
    // carry, g(rd) = rd / (1 - Fdr) (or rd / (1 - Fdr rd), nonlinear)
    float solve_s[3];
    float solve_c;
    // plastic: the coat's transmittance at cos θ = i / (samples - 1), as Mitsuba tabulates it
    float coat_transmittance[kCoatTransmittanceSamples];
};
constexpr int kLobeWidth = int(sizeof(MicrofacetLobe) / sizeof(float));
static_assert(kLobeWidth == 21 + kCoatTransmittanceSamples, "a packed float32 row");

// The BRDF f(wi, wo) (3,) of the lobe's material, without the cosine: the
// specular term F D G / (4 cos_i cos_o), and for a plastic the diffuse base
// rd (3,) under the coat. n the shading normal, wi towards the light, wo
// towards the viewer; all unit vectors.
void microfacet_brdf(const MicrofacetLobe& lobe, const float* rd, const float n[3],
                     const float wi[3], const float wo[3], float f[3]);

// The albedo a solve's record of a plastic of diffuse base rd carries
// (rd itself for a material without a lobe), channel c.
inline float solve_albedo(const MicrofacetLobe* lobe, float rd, int c) {
    if (!lobe || lobe->kind != 1.f) return rd;
    const float inner = lobe->nonlinear != 0.f ? rd * lobe->fdr_int : lobe->fdr_int;
    return lobe->solve_s[c] + lobe->solve_c * rd / (1.f - inner);
}

// The solid-angle density of microfacet_sample's directions wi for viewer wo.
double microfacet_pdf(const MicrofacetLobe& lobe, const float n[3], const float wo[3],
                      const float wi[3]);

// A direction wi: a microfacet normal m drawn with density D(m) cos θ_m
// from (u1, u2) in [0, 1)², wo reflected about it. False where it falls
// below the surface (wi is then undefined).
bool microfacet_sample(const MicrofacetLobe& lobe, const float n[3], const float wo[3], double u1,
                       double u2, float wi[3]);

// The density, per ray and unit solid angle, of a pixel's gather ray along
// wi: cosine-distributed, or for a material with a lobe the mixture of
// lobe_share lobe samples and the rest cosine-distributed. cos_x = n·wi.
inline double gather_density(const MicrofacetLobe* lobes, int32_t m, const float n[3],
                             const float wo[3], const float wi[3], double cos_x) {
    constexpr double kInvPi = 0.31830988618379067154;
    const double c = cos_x > 0.0 ? cos_x * kInvPi : 0.0;
    if (!lobes || lobes[m].kind == 0.f) return c;
    const double q = lobes[m].lobe_share;
    return (1.0 - q) * c + q * microfacet_pdf(lobes[m], n, wo, wi);
}

}  // namespace voxgi
