// VPL shading kernels for the anti-aliased display (DESIGN-NOTES §6).
//
// One frame shades P hit points with the same K virtual point lights (VPLs).
// It runs in two passes around the visibility queries, which Python makes
// with Embree (embreex) between them:
//   1. vpl_prepare: per (pixel, VPL) pair the unoccluded contribution
//      f(wi, wo) * W_k * G_bounded, and a shadow ray where it is non-zero;
//      rays are written compacted, pixel by pixel, VPLs in order.
//   2. vpl_accumulate: per pixel, the sum of the contributions whose shadow
//      ray was not occluded, in ray order (independent of the thread count).
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>

#include "common.h"

namespace voxgi {

// Per-material shading parameters (M materials).
struct ShadeMaterials {
    int64_t count = 0;
    const float *albedo = nullptr;  // (M, 3) diffuse reflectance rho (Rd)
    const float *rs = nullptr;      // (M, 3) Ashikhmin-Shirley specular reflectance at normal incidence
    const float *nu = nullptr;      // (M,)   AS exponent along the tangent u
    const float *nv = nullptr;      // (M,)   AS exponent along the bitangent v
    const uint8_t *glossy = nullptr;  // (M,) 1 where the material has a specular layer
};

// Hit points of one frame (P pixels).
struct ShadeHits {
    int64_t count = 0;
    const double *pos = nullptr;    // (P, 3) hit points on the surface
    const float *normal = nullptr;  // (P, 3) unit shading normal, on the viewer's side
    const float *ng = nullptr;      // (P, 3) unit geometric normal, on the viewer's side
    const float *wo = nullptr;      // (P, 3) unit direction from the hit point to the viewer
    const int32_t *material = nullptr;  // (P,) material index, or -1: not shaded (miss, black back side)
};

// VPLs of one frame (K lights).
struct ShadeVPLs {
    int64_t count = 0;
    const double *pos = nullptr;     // (K, 3) point on the surface
    const float *normal = nullptr;   // (K, 3) unit normal
    const float *weight = nullptr;   // (K, 3) (TA_set / n_set) * B / pi: radiance times the estimator weight
    const float *area = nullptr;     // (K,) area the record stands for (bounds the geometry term)
};

// Pass 1. Writes per pixel the number of shadow rays (`ray_count`, (P,)), and
// for each ray, pixel-major: its origin (x offset along its geometric normal
// by `eps`), unit direction, length (to the VPL offset by `eps` along its
// normal, shortened by `eps`) and unoccluded RGB contribution. The output
// arrays need room for P*K rays. Returns the number of rays written.
int64_t vpl_prepare(const ShadeHits &hits, const ShadeMaterials &mats, const ShadeVPLs &vpls,
                    double eps, int64_t *ray_count, float *ray_org, float *ray_dir,
                    float *ray_len, float *ray_contrib, int threads, const StopCheck &stop);

// Pass 2. `ray_count` as written by vpl_prepare, `occluded` (R,) non-zero
// where the shadow ray was blocked. Writes out (P, 3) the summed radiance.
void vpl_accumulate(int64_t n_pixels, const int64_t *ray_count, const float *ray_contrib,
                    const uint8_t *occluded, float *out, int threads, const StopCheck &stop);

// The BRDF used by the display for one pair of directions (exposed for tests):
// Lambertian rho/pi, or with a specular layer the Ashikhmin-Shirley pair
// (coupled diffuse + anisotropic Phong specular). k1 towards the light,
// k2 towards the viewer, n the normal; all unit vectors. Writes f (3,).
void shade_brdf(const ShadeMaterials &mats, int32_t m, const float n[3], const float k1[3],
                const float k2[3], float f[3]);

}  // namespace voxgi
