#include "direct_light.h"

#include <algorithm>
#include <cmath>

namespace voxgi {
namespace {

constexpr double kLuminance[3] = {0.2126, 0.7152, 0.0722};
constexpr int64_t kRecordsPerTask = 256;

inline double dot(const double *a, const double *b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// Draw triangle and point for one sample u of [0, 1)^3: u[0] by the
// cumulative table, (u[1], u[2]) uniform in area (square-root warp).
inline int64_t draw(const EmitterTriangles &em, const double u[3], double y[3]) {
    const double *end = em.cdf + em.count;
    int64_t k = std::upper_bound(em.cdf, end, u[0]) - em.cdf;
    k = std::min<int64_t>(k, em.count - 1);
    const double s = std::sqrt(u[1]);
    const double b0 = 1.0 - s, b1 = u[2] * s, b2 = 1.0 - b0 - b1;
    const double *c = em.corners + 9 * k;
    for (int i = 0; i < 3; ++i) y[i] = b0 * c[i] + b1 * c[3 + i] + b2 * c[6 + i];
    return k;
}

}  // namespace

void direct_light_rays(const EmitterTriangles &em, const DirectLightQuery &q, float *origin,
                       float *direction, float *length, float *contribution, int threads,
                       const StopCheck &stop) {
    const int64_t tasks = (q.records + kRecordsPerTask - 1) / kRecordsPerTask;
    parallel_for(tasks, threads, stop, [&](int64_t task, int) {
        const int64_t r0 = task * kRecordsPerTask;
        const int64_t r1 = std::min(q.records, r0 + kRecordsPerTask);
        for (int64_t r = r0; r < r1; ++r) {
            const double *x = q.point + 3 * r, *nx = q.normal + 3 * r, *sh = q.shift + 3 * r;
            for (int64_t s = 0; s < q.samples; ++s) {
                const int64_t ray = r * q.samples + s;
                double u[3], y[3], d[3];
                for (int i = 0; i < 3; ++i) {
                    u[i] = q.sequence[3 * s + i] + sh[i];
                    if (u[i] >= 1.0) u[i] -= 1.0;
                }
                const int64_t k = draw(em, u, y);
                for (int i = 0; i < 3; ++i) d[i] = y[i] - x[i];
                const double r2 = dot(d, d), dist = std::sqrt(r2);
                double cos_x = 0.0, cos_y = 0.0;
                if (dist > 2.0 * q.offset) {
                    cos_x = dot(d, nx) / dist;
                    cos_y = -dot(d, em.normal + 3 * k) / dist;
                    if (em.two_sided[k]) cos_y = std::fabs(cos_y);
                }
                float *o = origin + 3 * ray, *w = direction + 3 * ray, *c = contribution + 3 * ray;
                if (cos_x <= 0.0 || cos_y <= 0.0) {
                    for (int i = 0; i < 3; ++i) o[i] = float(x[i]), w[i] = float(nx[i]), c[i] = 0.f;
                    length[ray] = 0.f;
                    continue;
                }
                // start off the surface on the lit side; the segment ends an
                // offset short of the emitter so the emitter does not occlude
                double org[3], seg[3];
                for (int i = 0; i < 3; ++i) org[i] = x[i] + q.offset * nx[i], seg[i] = y[i] - org[i];
                const double len = std::sqrt(dot(seg, seg));
                for (int i = 0; i < 3; ++i) o[i] = float(org[i]), w[i] = float(seg[i] / len);
                length[ray] = float(std::max(0.0, len - q.offset));
                const double g = cos_x * cos_y / (r2 * em.density[k]);
                for (int i = 0; i < 3; ++i) c[i] = float(g * em.radiance[3 * k + i]);
            }
        }
    });
}

void direct_light_sum(int64_t records, int64_t samples, const float *contribution,
                      const int32_t *hit, double *irradiance, double *mean_square, int threads,
                      const StopCheck &stop) {
    const int64_t tasks = (records + kRecordsPerTask - 1) / kRecordsPerTask;
    parallel_for(tasks, threads, stop, [&](int64_t task, int) {
        const int64_t r0 = task * kRecordsPerTask;
        const int64_t r1 = std::min(records, r0 + kRecordsPerTask);
        for (int64_t r = r0; r < r1; ++r) {
            double sum[3] = {0.0, 0.0, 0.0}, sq = 0.0;
            for (int64_t s = 0; s < samples; ++s) {
                const int64_t ray = r * samples + s;
                if (hit[ray] != -1) continue;
                const float *c = contribution + 3 * ray;
                double lum = 0.0;
                for (int i = 0; i < 3; ++i) sum[i] += c[i], lum += kLuminance[i] * c[i];
                sq += lum * lum;
            }
            for (int i = 0; i < 3; ++i) irradiance[3 * r + i] = sum[i] / double(samples);
            mean_square[r] = sq / double(samples);
        }
    });
}

}  // namespace voxgi
