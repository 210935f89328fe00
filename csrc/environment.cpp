// The environment's light in the display (see environment.h).
#include "environment.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "incidence_response.h"
#include "util/hemisphere.h"
#include "util/random.h"
#include "vpl_shade.h"

namespace voxgi {

namespace {

constexpr double kPi = 3.14159265358979323846;

inline float dot3(const float* a, const float* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

}  // namespace

int64_t environment_texel(const EnvironmentMap& env, const double d[3]) {
    const double* m = env.to_world;
    double loc[3];
    for (int j = 0; j < 3; ++j) loc[j] = d[0] * m[j] + d[1] * m[3 + j] + d[2] * m[6 + j];
    const double len =
        std::max(std::sqrt(loc[0] * loc[0] + loc[1] * loc[1] + loc[2] * loc[2]), 1e-300);
    for (double& c : loc) c /= len;
    double u = std::atan2(loc[0], -loc[2]) / (2.0 * kPi);
    u -= std::floor(u);
    const double v = std::acos(std::clamp(loc[1], -1.0, 1.0)) / kPi;
    const int64_t col = std::min(int64_t(u * double(env.width)), env.width - 1);
    const int64_t row = std::min(int64_t(v * double(env.height)), env.height - 1);
    return row * env.width + col;
}

int64_t guide_row(const EnvironmentMap& env, const double x[3], const float ng[3]) {
    const EnvironmentGuide* g = env.guide;
    if (!g) return -1;
    int64_t c[3];
    for (int a = 0; a < 3; ++a) {
        const double t = (x[a] - g->origin[a]) * g->inv_cell;
        // NaN and points off the grid read the nearest cell
        c[a] = t >= 0.0 ? std::min(int64_t(t), g->dims[a] - 1) : 0;
    }
    int axis = 0;
    for (int a = 1; a < 3; ++a)
        if (std::fabs(ng[a]) > std::fabs(ng[axis])) axis = a;
    const int facing = 2 * axis + (ng[axis] < 0.f ? 1 : 0);
    const int64_t key = ((c[0] * g->dims[1] + c[1]) * g->dims[2] + c[2]) * 6 + facing;
    return g->key_row[size_t(key)];
}

double environment_density(const EnvironmentMap& env, int64_t k, int64_t row) {
    double p = env.texel_pdf[k] / env.row_solid_angle[k / env.width];
    if (row >= 0) {
        const EnvironmentGuide& g = *env.guide;
        p *= g.factor[size_t(row * g.blocks() + g.block(k))];
    }
    return p;
}

namespace {

// The texel of the sample at u0 in [0, 1) for a point of guide row `row`
// (-1: the environment's own tables).
int64_t environment_texel_at(const EnvironmentMap& env, double u0, int64_t row) {
    const int64_t n = env.width * env.height;
    if (row >= 0) {
        const EnvironmentGuide& g = *env.guide;
        if (u0 >= g.alpha) {
            // a block by the row's shares, then the place of u0 inside that
            // block's share picks a texel by the block's running texel_pdf
            const double v = (u0 - g.alpha) / (1.0 - g.alpha);
            const double* cdf = g.block_cdf.data() + row * g.blocks();
            const int64_t b =
                std::min(int64_t(std::upper_bound(cdf, cdf + g.blocks(), v) - cdf), g.blocks() - 1);
            const double c0 = b ? cdf[b - 1] : 0.0, c1 = cdf[b];
            const double t = c1 > c0 ? std::clamp((v - c0) / (c1 - c0), 0.0, 1.0) : 0.5;
            const int64_t by = b / g.blocks_w, bx = b % g.blocks_w;
            const int64_t r0 = g.first_row(by), r1 = g.first_row(by + 1);
            const int64_t c_0 = g.first_col(bx), c_1 = g.first_col(bx + 1);
            // a row by the block's running mass, then the rest of the
            // target among the row's columns of the block
            const double* rc = g.row_cdf.data() + bx * env.height;
            const double target = t * rc[r1 - 1];
            const int64_t r =
                std::clamp(int64_t(std::upper_bound(rc + r0, rc + r1, target) - rc), r0, r1 - 1);
            const double within = target - (r > r0 ? rc[r - 1] : 0.0);
            const int64_t first = r * env.width + c_0, end = r * env.width + c_1;
            const double before = first ? env.texel_cdf[first - 1] : 0.0;
            return std::clamp(int64_t(std::upper_bound(env.texel_cdf + first, env.texel_cdf + end,
                                                       before + within) -
                                      env.texel_cdf),
                              first, end - 1);
        }
        u0 /= g.alpha;
    }
    return std::min(int64_t(std::upper_bound(env.texel_cdf, env.texel_cdf + n, u0) - env.texel_cdf),
                    n - 1);
}

// One environment sample from the point u of [0, 1)^3 for a point of guide
// row `guide`: its texel and unit world direction w.
int64_t environment_sample(const EnvironmentMap& env, const double u[3], int64_t guide,
                           double w[3]) {
    const int64_t k = environment_texel_at(env, u[0], guide);
    const int64_t row = k / env.width, col = k % env.width;
    const double phi = 2.0 * kPi * (double(col) + u[1]) / double(env.width);
    const double ct = env.row_cos[row] + u[2] * (env.row_cos[row + 1] - env.row_cos[row]);
    const double st = std::sqrt(std::max(0.0, 1.0 - ct * ct));
    const double loc[3] = {st * std::sin(phi), ct, -st * std::cos(phi)};
    const double* m = env.to_world;
    for (int i = 0; i < 3; ++i)
        w[i] = m[3 * i] * loc[0] + m[3 * i + 1] * loc[1] + m[3 * i + 2] * loc[2];
    return k;
}

// The n points of pixel p's environment samples (see environment_light), into u (n, 3).
void environment_points(uint64_t base, int64_t p, int n, double* u) {
    uint64_t h = splitmix64(base ^ uint64_t(p) * 0xD1B54A32D192ED03ull);
    auto next = [&h] {
        h = splitmix64(h);
        return to_unit(h);
    };
    const int s = int(std::lround(std::sqrt(double(n))));
    const bool grid = s > 1 && s * s == n;
    for (int j = 0; j < n; ++j) {
        u[3 * j] = double(j);  // the strata, shuffled below
        u[3 * j + 1] = grid ? (j % s + next()) / s : next();
        u[3 * j + 2] = grid ? (j / s + next()) / s : next();
    }
    for (int j = n - 1; j > 0; --j) {  // Fisher-Yates over the strata of the texel coordinate
        const int i = int(next() * double(j + 1));
        std::swap(u[3 * j], u[3 * std::min(i, j)]);
    }
    for (int j = 0; j < n; ++j) u[3 * j] = (u[3 * j] + next()) / n;
}

}  // namespace

void environment_light(const ShadeHits& hits, const ShadeMaterials& mats, const EnvironmentMap& env,
                       double n_gather, uint64_t seed, int64_t frame, double eps,
                       const RayScene& scene, float* out, int64_t* rays, int threads,
                       const StopCheck& stop) {
    const int n = int(env.n_samples);
    const uint64_t base = splitmix64(seed ^ splitmix64(uint64_t(frame) + 0xE4F0E4F0E4F0E4F0ull));
    *rays = sum_over_chunks(hits.count, 512, threads, stop, [&](int64_t p0, int64_t p1) {
        std::vector<double> u(size_t(3 * std::max(n, 1)));
        int64_t traced = 0;
        for (int64_t p = p0; p < p1; ++p) {
            const int32_t m = hits.material[p];
            if (m < 0 || m >= mats.count || n <= 0) continue;
            const double* x = hits.pos + 3 * p;
            const float *nf = hits.normal + 3 * p, *ng = hits.ng + 3 * p, *wo = hits.wo + 3 * p;
            const float ro[3] = {float(x[0] + eps * ng[0]), float(x[1] + eps * ng[1]),
                                 float(x[2] + eps * ng[2])};
            environment_points(base, p, n, u.data());
            const int64_t row = guide_row(env, x, ng);
            float sum[3] = {0.f, 0.f, 0.f};
            for (int j = 0; j < n; ++j) {
                double w[3];
                const int64_t k = environment_sample(env, u.data() + 3 * j, row, w);
                const float wf[3] = {float(w[0]), float(w[1]), float(w[2])};
                if (dot3(ng, wf) <= 0.f) continue;  // below the surface: no ray
                const double* L = env.radiance + 3 * k;
                const double cos = w[0] * nf[0] + w[1] * nf[1] + w[2] * nf[2];
                const double pdf = environment_density(env, k, row);
                const double pg = mats.lobe ? gather_density(mats.lobe, m, nf, wo, wf, cos)
                                            : std::max(cos, 0.0) / kPi;
                const double dens = env.n_samples * pdf + n_gather * pg;
                if (!(dens > 0.0) || !(L[0] > 0.0 || L[1] > 0.0 || L[2] > 0.0)) continue;
                ++traced;
                float T[3];
                if (scene.occluded(ro, wf, std::numeric_limits<float>::infinity(), T)) continue;
                const float cos_x = dot3(nf, wf);
                if (cos_x <= 0.f) continue;
                float f[3];
                shade_brdf(mats, m, hit_albedo(hits, mats, p, m), nf, wf, wo, f);
                for (int ch = 0; ch < 3; ++ch)
                    sum[ch] += f[ch] * cos_x * float(L[ch] / dens) * T[ch];
            }
            for (int ch = 0; ch < 3; ++ch) out[3 * p + ch] += sum[ch];
        }
        return traced;
    });
}

int64_t learn_environment_guide(const EnvironmentMap& env, const EnvironmentGuide& blocks,
                                const double* pos, const float* normal, const int64_t* row_start,
                                int64_t rows, const int32_t* row_rays, uint64_t seed, double eps,
                                const double luminance[3], const RayScene& scene, double* hist,
                                double* possible, int threads, const StopCheck& stop) {
    const int64_t B = blocks.blocks();
    std::vector<int64_t> traced(size_t(std::max<int64_t>(rows, 1)), 0);
    // one row per task: a row's sums are written by one thread alone
    parallel_for(rows, resolve_threads(threads), stop, [&](int64_t r, int) {
        double* h = hist + r * B;
        for (int64_t i = row_start[r]; i < row_start[r + 1]; ++i) {
            const double* x = pos + 3 * i;
            const float* nf = normal + 3 * i;
            const float ro[3] = {float(x[0] + eps * nf[0]), float(x[1] + eps * nf[1]),
                                 float(x[2] + eps * nf[2])};
            uint64_t state = splitmix64(seed ^ uint64_t(i) * 0xD1B54A32D192ED03ull);
            const double nd[3] = {nf[0], nf[1], nf[2]};
            for (int j = 0; j < row_rays[r]; ++j) {
                double u[3];
                for (double& c : u) {
                    state = splitmix64(state);
                    c = to_unit(state);
                }
                // every other ray drawn by the environment's own tables, the
                // rest cosine-distributed: the balance heuristic of the two
                // finds a bright patch the first would and an open window
                // of a dim sky the second would
                double w[3];
                int64_t k;
                if (j % 2 == 0) {
                    k = environment_sample(env, u, -1, w);
                } else {
                    cosine_direction(nd, u[0], u[1], w);
                    k = environment_texel(env, w);
                }
                const double cos = w[0] * nd[0] + w[1] * nd[1] + w[2] * nd[2];
                if (!(cos > 0.0)) continue;
                const double density = 0.5 * environment_density(env, k, -1) + 0.5 * cos / kPi;
                const double* L = env.radiance + 3 * k;
                const double light =
                    (luminance[0] * L[0] + luminance[1] * L[1] + luminance[2] * L[2]) * cos /
                    density;
                possible[r] += light;
                ++traced[size_t(r)];
                const float wf[3] = {float(w[0]), float(w[1]), float(w[2])};
                float T[3];
                if (scene.occluded(ro, wf, std::numeric_limits<float>::infinity(), T)) continue;
                h[blocks.block(k)] +=
                    light * (luminance[0] * T[0] + luminance[1] * T[1] + luminance[2] * T[2]);
            }
        }
    });
    int64_t total = 0;
    for (int64_t t : traced) total += t;
    return total;
}

int64_t environment_irradiance(const EnvironmentMap& env, const double* pos, const float* normal,
                               int64_t count, int n_env, int n_cos, uint64_t seed, double eps,
                               const float* response, const float* base, const int32_t* rows,
                               const RayScene& scene, double* out, double* out_base, int threads,
                               const StopCheck& stop) {
    const uint64_t hashed = splitmix64(seed ^ 0x1D1E1D1E1D1E1D1Eull);
    return sum_over_chunks(count, 256, threads, stop, [&](int64_t i0, int64_t i1) {
        std::vector<double> u(size_t(3 * std::max(n_env, 1)));
        int64_t traced = 0;
        for (int64_t i = i0; i < i1; ++i) {
            const double* x = pos + 3 * i;
            const float* nf = normal + 3 * i;
            const double nd[3] = {nf[0], nf[1], nf[2]};
            const float ro[3] = {float(x[0] + eps * nd[0]), float(x[1] + eps * nd[1]),
                                 float(x[2] + eps * nd[2])};
            const int64_t row = guide_row(env, x, nf);
            const int32_t r = rows ? rows[i] : -1;
            double e[3] = {0.0, 0.0, 0.0}, eb[3] = {0.0, 0.0, 0.0};
            // one sample in direction w at texel k, drawn by either strategy
            auto add = [&](const double w[3], int64_t k) {
                const double cos = w[0] * nd[0] + w[1] * nd[1] + w[2] * nd[2];
                if (!(cos > 0.0)) return;
                const double* L = env.radiance + 3 * k;
                if (!(L[0] > 0.0 || L[1] > 0.0 || L[2] > 0.0)) return;
                const double dens =
                    double(n_env) * environment_density(env, k, row) + double(n_cos) * cos / kPi;
                if (!(dens > 0.0)) return;
                ++traced;
                const float wf[3] = {float(w[0]), float(w[1]), float(w[2])};
                float T[3];
                if (scene.occluded(ro, wf, std::numeric_limits<float>::infinity(), T)) return;
                double resp[3] = {1.0, 1.0, 1.0}, rb[3] = {1.0, 1.0, 1.0};
                if (response && r >= 0)
                    incidence_response(response + int64_t(3) * kIncidenceNodes * r, cos, resp);
                if (base && r >= 0)
                    incidence_response(base + int64_t(3) * kIncidenceNodes * r, cos, rb);
                for (int ch = 0; ch < 3; ++ch) {
                    const double c = L[ch] * cos * double(T[ch]) / dens;
                    e[ch] += c * resp[ch];
                    eb[ch] += c * rb[ch];
                }
            };
            if (n_env > 0) {
                environment_points(hashed, i, n_env, u.data());
                for (int j = 0; j < n_env; ++j) {
                    double w[3];
                    const int64_t k = environment_sample(env, u.data() + 3 * j, row, w);
                    add(w, k);
                }
            }
            uint64_t h = splitmix64(hashed ^ uint64_t(i) * 0x9E3779B97F4A7C15ull);
            const int s = int(std::lround(std::sqrt(double(n_cos))));
            const bool grid = s > 1 && s * s == n_cos;
            for (int j = 0; j < n_cos; ++j) {
                h = splitmix64(h);
                double u1 = to_unit(h);
                h = splitmix64(h);
                double u2 = to_unit(h);
                if (grid) u1 = (j % s + u1) / s, u2 = (j / s + u2) / s;  // stratified
                double w[3];
                cosine_direction(nd, u1, u2, w);
                add(w, environment_texel(env, w));
            }
            for (int ch = 0; ch < 3; ++ch) {
                out[3 * i + ch] = e[ch];
                if (out_base) out_base[3 * i + ch] = eb[ch];
            }
        }
        return traced;
    });
}

}  // namespace voxgi
