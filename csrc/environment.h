// The environment's light in the display (docs/design.md §11): its samples,
// drawn, MIS-weighted against the gather rays and traced as they are made,
// and the texel a direction reads. No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>
#include <vector>

#include "ray_scene.h"
#include "util/parallel.h"

namespace voxgi {

struct ShadeHits;
struct ShadeMaterials;

// Where the environment's light reaches the scene (docs/design.md §11): for
// the points of each cell of a grid that face one way (the geometric
// normal's dominant axis and its sign), the share of the environment's
// unblocked light that comes through each block of texels, learned by
// tracing from the solve's records (voxgi.display.environment_guide). With
// probability 1 - alpha a sample draws a block from its cell's shares, then
// a texel inside it in proportion to the environment's own texel_pdf; with
// alpha, from the environment's own tables. The density of a texel is
// texel_pdf times factor[row, block]: alpha + (1 - alpha) share / mass.
// Inside a block a row is drawn by row_cdf, then a column by the
// environment's own texel_cdf over the block's columns of that row: no
// table grows with the environment's texels.
struct EnvironmentGuide {
    double origin[3] = {0.0, 0.0, 0.0};  // the grid's minimum corner
    double inv_cell = 0.0;               // 1 / the cells' edge
    int64_t dims[3] = {0, 0, 0};
    int64_t width = 0, height = 0;       // the environment's texels across and down
    int64_t blocks_w = 0, blocks_h = 0;  // texel blocks across and down
    double alpha = 1.0;
    std::vector<int32_t> key_row;   // (dims product * 6,) row of each cell and facing, -1: none
    std::vector<double> factor;     // (rows, blocks) density over the environment's own
    std::vector<double> block_cdf;  // (rows, blocks) running shares, last 1
    // (blocks_w, H): for each column of blocks, the running texel_pdf of
    // its texels row by row, restarting at each block's first row
    std::vector<double> row_cdf;

    int64_t blocks() const { return blocks_w * blocks_h; }
    // The block of texel k.
    int64_t block(int64_t k) const {
        return ((k / width) * blocks_h / height) * blocks_w + (k % width) * blocks_w / width;
    }
    // The first row of block row `by` (by = blocks_h: height) and the first
    // column of block column `bx` (bx = blocks_w: width).
    int64_t first_row(int64_t by) const { return (by * height + blocks_h - 1) / blocks_h; }
    int64_t first_col(int64_t bx) const { return (bx * width + blocks_w - 1) / blocks_w; }
};

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
    const double* texel_cdf = nullptr;        // (height * width,) cumulative texel_pdf, last 1
    const double* row_cos = nullptr;          // (height + 1,) cos of each row's edges, from +1 down
    const EnvironmentGuide* guide = nullptr;  // where the light reaches, or null
};

// The guide's row for a point x with geometric normal ng (-1: the
// environment's own density there).
int64_t guide_row(const EnvironmentMap& env, const double x[3], const float ng[3]);

// The solid-angle density of env's samples at texel k for a point of guide row `row`.
double environment_density(const EnvironmentMap& env, int64_t k, int64_t row);

// The texel of world direction d (any length): its index row * width + col.
int64_t environment_texel(const EnvironmentMap& env, const double d[3]);

// The environment's samples: `env.n_samples` directions per shaded pixel
// (material >= 0), a texel in proportion to luminance x solid angle, then a
// direction uniform in solid angle inside it; the texel coordinate in
// n_samples strata shuffled per pixel (Latin-hypercube pairing), the two
// inside the texel in a sqrt(n) x sqrt(n) grid when n_samples is a square;
// jittered with a hash of (seed, frame, pixel, sample), the same for any
// thread count; with env.guide, a texel drawn by the pixel's row of the
// guide instead. Each sample weighs the radiance L(w) by the balance
// heuristic against n_gather cosine-distributed gather rays, L / (n_e p_e(w)
// + n_g cos / pi) (docs/design.md §11), and, where it lies above the
// geometric surface, its ray (offset `eps` along ng) is traced to infinity
// in `scene`; a free one adds f(w, wo) max(0, n.w) times that weight into
// out (P, 3). Writes the number of rays traced into *rays.
void environment_light(const ShadeHits& hits, const ShadeMaterials& mats, const EnvironmentMap& env,
                       double n_gather, uint64_t seed, int64_t frame, double eps,
                       const RayScene& scene, float* out, int64_t* rays, int threads,
                       const StopCheck& stop);

// The environment's irradiance at records (voxgi.direct.light_irradiance):
// at each point i (pos (R, 3), unit normal (R, 3), offset eps along it),
// n_env samples drawn as environment_light draws a pixel's (by env.guide's
// row of the point where one is attached) and n_cos cosine-distributed
// directions, each traced to infinity in `scene`; every free ray adds
// L cos T / (n_env p_e + n_cos cos / pi) (the balance heuristic) into
// out[i] (R, 3), times response's row (R / A, nullable: 1) of the point at
// the sample's cosine, and, with out_base, times base's row into
// out_base[i]. rows (R,) picks the rows (-1: none; nullable). Hashed from
// (seed, point, sample): the same for any thread count. Returns the rays.
int64_t environment_irradiance(const EnvironmentMap& env, const double* pos, const float* normal,
                               int64_t count, int n_env, int n_cos, uint64_t seed, double eps,
                               const float* response, const float* base, const int32_t* rows,
                               const RayScene& scene, double* out, double* out_base, int threads,
                               const StopCheck& stop);

// The guide's learning rays (voxgi.display.environment_guide): from each of
// the points of row r (points row_start[r] to row_start[r + 1], offset eps
// along their normals), row_rays[r] directions each, every other one drawn by env's
// own tables and the rest cosine-distributed (hashed from seed and the
// point), traced to infinity in `scene`. Each ray that leaves above the
// point's surface adds lum(L) cos / p into possible[r] (p: the balance of
// the two densities), and
// times the luminance of its transmittance where it is free, into hist[r,
// block of its texel] (blocks as `blocks` numbers them; hist (rows,
// blocks.blocks()) zeroed by the caller). lum weighs RGB by `luminance`.
// Returns the number of rays traced.
int64_t learn_environment_guide(const EnvironmentMap& env, const EnvironmentGuide& blocks,
                                const double* pos, const float* normal, const int64_t* row_start,
                                int64_t rows, const int32_t* row_rays, uint64_t seed, double eps,
                                const double luminance[3], const RayScene& scene, double* hist,
                                double* possible, int threads, const StopCheck& stop);

}  // namespace voxgi
