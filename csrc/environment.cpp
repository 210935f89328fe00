// The environment's light in the display (see environment.h).
#include "environment.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

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

namespace {

// One environment sample from the point u of [0, 1)^3: its texel and unit
// world direction w.
int64_t environment_sample(const EnvironmentMap& env, const double u[3], double w[3]) {
    const int64_t n = env.width * env.height;
    const int64_t k = std::min(
        int64_t(std::upper_bound(env.texel_cdf, env.texel_cdf + n, u[0]) - env.texel_cdf), n - 1);
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
            float sum[3] = {0.f, 0.f, 0.f};
            for (int j = 0; j < n; ++j) {
                double w[3];
                const int64_t k = environment_sample(env, u.data() + 3 * j, w);
                const float wf[3] = {float(w[0]), float(w[1]), float(w[2])};
                if (dot3(ng, wf) <= 0.f) continue;  // below the surface: no ray
                const double* L = env.radiance + 3 * k;
                const double cos = w[0] * nf[0] + w[1] * nf[1] + w[2] * nf[2];
                const double pdf = env.texel_pdf[k] / env.row_solid_angle[k / env.width];
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

}  // namespace voxgi
