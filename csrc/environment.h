// The environment's light in the display (docs/design.md §11): its samples,
// drawn, MIS-weighted against the gather rays and traced as they are made,
// and the texel a direction reads. No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>

#include "ray_scene.h"
#include "util/parallel.h"

namespace voxgi {

struct ShadeHits;
struct ShadeMaterials;

// An environment (docs/design.md §11): a latitude-longitude radiance image, Mitsuba's convention
// (image y up; direction (sin t sin f, cos t, -sin t cos f) at u = f / 2 pi, v = t / pi), and the
// density its own samples are drawn with, for the balance heuristic between those samples and the
// gather rays.
struct EnvironmentMap {
    int64_t width = 0, height = 0;
    const double* radiance = nullptr;         // (height, width, 3) linear radiance
    const double* to_world = nullptr;         // (3, 3) row-major rotation, image -> world
    const double* texel_pdf = nullptr;        // (height * width,) probability of each texel
    const double* row_solid_angle = nullptr;  // (height,) solid angle of one texel of each row
    double n_samples = 0.0;                   // environment samples per pixel and frame
    // for drawing samples (environment_light); may be null for gather_light alone
    const double* texel_cdf = nullptr;  // (height * width,) cumulative texel_pdf, last 1
    const double* row_cos = nullptr;    // (height + 1,) cos of each row's edges, from +1 down
};

// The texel of world direction d (any length): its index row * width + col.
int64_t environment_texel(const EnvironmentMap& env, const double d[3]);

// The environment's samples: `env.n_samples` directions per shaded pixel
// (material >= 0), a texel in proportion to luminance x solid angle, then a
// direction uniform in solid angle inside it; the texel coordinate in
// n_samples strata shuffled per pixel (Latin-hypercube pairing), the two
// inside the texel in a sqrt(n) x sqrt(n) grid when n_samples is a square;
// jittered with a hash of (seed, frame, pixel, sample), the same for any
// thread count. Each sample weighs the radiance L(w) by the balance
// heuristic against n_gather cosine-distributed gather rays, L / (n_e p_e(w)
// + n_g cos / pi) (docs/design.md §11), and, where it lies above the
// geometric surface, its ray (offset `eps` along ng) is traced to infinity
// in `scene`; a free one adds f(w, wo) max(0, n.w) times that weight into
// out (P, 3). Writes the number of rays traced into *rays.
void environment_light(const ShadeHits& hits, const ShadeMaterials& mats, const EnvironmentMap& env,
                       double n_gather, uint64_t seed, int64_t frame, double eps,
                       const RayScene& scene, float* out, int64_t* rays, int threads,
                       const StopCheck& stop);

}  // namespace voxgi
