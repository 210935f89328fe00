#include "direct_light.h"

#include <algorithm>
#include <cmath>

#include "incidence_response.h"
#include "util/hemisphere.h"

namespace voxgi {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kLuminance[3] = {0.2126, 0.7152, 0.0722};
constexpr int64_t kRecordsPerTask = 256;

inline double dot(const double* a, const double* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// The record's k-th sample point of [0, 1)^5, shifted by the record's shift.
inline void sample_point(const DirectLightQuery& q, int64_t r, int64_t s, double u[5]) {
    for (int i = 0; i < 5; ++i) {
        u[i] = q.sequence[5 * s + i] + q.shift[5 * r + i];
        if (u[i] >= 1.0) u[i] -= 1.0;
    }
}

// A light sample: triangle by the cumulative table, point uniform in area
// (square-root warp of the barycentrics).
inline int64_t draw_light(const EmitterTriangles& em, const double u[3], double y[3]) {
    int64_t k = std::upper_bound(em.cdf, em.cdf + em.count, u[0]) - em.cdf;
    k = std::min<int64_t>(k, em.count - 1);
    const double s = std::sqrt(u[1]);
    const double b0 = 1.0 - s, b1 = u[2] * s, b2 = 1.0 - b0 - b1;
    const double* c = em.corners + 9 * k;
    for (int i = 0; i < 3; ++i) y[i] = b0 * c[i] + b1 * c[3 + i] + b2 * c[6 + i];
    return k;
}

// Cosine of the emitter's normal with the direction back to the receiver
// (w points from the receiver to the emitter); 0 on a one-sided back.
inline double emitter_cosine(const EmitterTriangles& em, int64_t k, const double w[3]) {
    const double c = -dot(w, em.normal + 3 * k);
    return em.two_sided[k] ? std::fabs(c) : std::max(c, 0.0);
}

// The light sample's ray and its contribution c, weighted by the power
// heuristic with the hemisphere density scaled by sqrt(s2); raw: its own
// estimate f / p, unweighted.
void light_ray(const EmitterTriangles& em, const DirectLightQuery& q, int64_t r, const double u[5],
               double s2, float* o, float* w, float* len, float* c, float* raw, float* cb) {
    const double *x = q.point + 3 * r, *nx = q.normal + 3 * r;
    double y[3], d[3];
    const int64_t k = draw_light(em, u, y);
    for (int i = 0; i < 3; ++i) d[i] = y[i] - x[i];
    const double r2 = dot(d, d), dist = std::sqrt(r2);
    double cos_x = 0.0, cos_y = 0.0;
    if (dist > 2.0 * q.offset) {
        const double wd[3] = {d[0] / dist, d[1] / dist, d[2] / dist};
        cos_x = dot(wd, nx);
        cos_y = emitter_cosine(em, k, wd);
    }
    if (cos_x <= 0.0 || cos_y <= 0.0) {
        for (int i = 0; i < 3; ++i)
            o[i] = float(x[i]), w[i] = float(nx[i]), c[i] = 0.f, raw[i] = 0.f, cb[i] = 0.f;
        *len = 0.f;
        return;
    }
    // off the surface on the lit side; the segment stops an offset short of
    // the emitter so the emitter does not occlude its own point
    double org[3], seg[3];
    for (int i = 0; i < 3; ++i) org[i] = x[i] + q.offset * nx[i], seg[i] = y[i] - org[i];
    const double sl = std::sqrt(dot(seg, seg));
    for (int i = 0; i < 3; ++i) o[i] = float(org[i]), w[i] = float(seg[i] / sl);
    *len = float(std::max(0.0, sl - q.offset));
    // power heuristic, area measure: f p_light / (p_light^2 + s2 p_hemisphere^2)
    const double g = cos_x * cos_y / r2, pl = em.density[k], ph = g / kPi;
    const double weight = g * pl / (pl * pl + s2 * ph * ph);
    double resp[3], base[3];
    incidence_response(incidence_row(q.response, q.response_row, r), cos_x, resp);
    incidence_response(incidence_row(q.response_base, q.response_row, r), cos_x, base);
    for (int i = 0; i < 3; ++i) {
        c[i] = float(weight * em.radiance[3 * k + i] * resp[i]);
        raw[i] = float(g / pl * em.radiance[3 * k + i] * resp[i]);
        cb[i] = float(weight * em.radiance[3 * k + i] * base[i]);
    }
}

// What sample `ray` of record r brings, light and hemisphere sample together:
// the light sample's contribution times what passes its ray (0: blocked, the
// sheets' transmittance), and the power-heuristic share of emitter k, which
// its hemisphere ray met first at barycentrics u, v (-1: no emitter first),
// times what passes that ray (its density scaled by sqrt(s2) in the
// heuristic); hemi: the hemisphere sample's own estimate, pi L_e through it;
// pair_base: the pair weighed by the base response (contribution_base the
// light sample's).
inline void sample_pair(const EmitterTriangles& em, const DirectLightQuery& q, int64_t r, double s2,
                        const float* contribution, const float* contribution_base,
                        const float* light_through, const float* hemi_direction, int32_t k,
                        float hu, float hv, const float* hemi_through, double pair[3],
                        double hemi[3], double pair_base[3]) {
    const double *x = q.point + 3 * r, *nx = q.normal + 3 * r;
    for (int i = 0; i < 3; ++i) {
        pair[i] = double(contribution[i]) * double(light_through[i]), hemi[i] = 0.0;
        pair_base[i] = double(contribution_base[i]) * double(light_through[i]);
    }
    if (k < 0) return;
    // the hit point from its barycentrics, in double
    const double* c = em.corners + 9 * k;
    const double bu = hu, bv = hv, b0 = 1.0 - bu - bv;
    double d[3];
    for (int i = 0; i < 3; ++i) d[i] = b0 * c[i] + bu * c[3 + i] + bv * c[6 + i] - x[i];
    const double r2 = dot(d, d);
    const double w[3] = {hemi_direction[0], hemi_direction[1], hemi_direction[2]};
    const double cos_x = std::max(0.0, dot(w, nx)), cos_y = emitter_cosine(em, k, w);
    if (cos_y > 0.0 && r2 > 0.0) {
        // power heuristic, solid-angle measure
        const double pl = em.density[k] * r2 / cos_y, ph = cos_x / kPi;
        const double weight = cos_x * s2 * ph / (pl * pl + s2 * ph * ph);
        double resp[3], base[3];
        incidence_response(incidence_row(q.response, q.response_row, r), cos_x, resp);
        incidence_response(incidence_row(q.response_base, q.response_row, r), cos_x, base);
        for (int i = 0; i < 3; ++i) {
            const double seen = em.radiance[3 * k + i] * hemi_through[i];
            pair[i] += weight * seen * resp[i];
            pair_base[i] += weight * seen * base[i];
            if (cos_x > 0.0) hemi[i] = kPi * seen * resp[i];
        }
    }
}

// Record r's light and hemisphere rays of sample s.
inline void sample_rays(const EmitterTriangles& em, const DirectLightQuery& q, int64_t r, int64_t s,
                        double s2, float* lo, float* ld, float* ll, float* con, float* raw,
                        float* cb, float* ho, float* hd) {
    const double *x = q.point + 3 * r, *nx = q.normal + 3 * r;
    double u[5], w[3];
    sample_point(q, r, s, u);
    light_ray(em, q, r, u, s2, lo, ld, ll, con, raw, cb);
    cosine_direction(nx, u[3], u[4], w);
    for (int i = 0; i < 3; ++i) {
        ho[i] = float(x[i] + q.offset * nx[i]);
        hd[i] = float(w[i]);
    }
}

}  // namespace

void direct_light_traced(const EmitterTriangles& em, const DirectLightQuery& q,
                         const int32_t* emitter_of, const RayScene& scene,
                         const RayScene* emitter_scene, double* irradiance, double* mean_square,
                         double* strategy_variance, double* base_irradiance, int threads,
                         const StopCheck& stop) {
    const int64_t tasks = (q.records + kRecordsPerTask - 1) / kRecordsPerTask;
    const int64_t nt = scene.triangle_count();
    parallel_for(tasks, threads, stop, [&](int64_t task, int) {
        const int64_t r1 = std::min(q.records, (task + 1) * kRecordsPerTask);
        for (int64_t r = task * kRecordsPerTask; r < r1; ++r) {
            const double scale = q.hemisphere_scale ? q.hemisphere_scale[r] : 1.0;
            const double s2 = scale * scale;
            double sum[3] = {0.0, 0.0, 0.0}, sum_base[3] = {0.0, 0.0, 0.0}, sq = 0.0;
            // the luminance of each strategy's own estimates: sums, squares
            double own[2] = {0.0, 0.0}, own_sq[2] = {0.0, 0.0};
            for (int64_t s = 0; s < q.samples; ++s) {
                float lo[3], ld[3], ll, con[3], raw[3], cb[3], ho[3], hd[3], hu, hv, te;
                float light_through[3] = {0.f, 0.f, 0.f}, hemi_through[3] = {1.f, 1.f, 1.f};
                sample_rays(em, q, r, s, s2, lo, ld, &ll, con, raw, cb, ho, hd);
                // light rays that cannot contribute have length 0 (and no
                // contribution) and are not traced
                if (ll > 0.f) scene.occluded(lo, ld, ll, light_through);
                // The hemisphere ray brings light only where an emitter is
                // the first thing it meets. With the emitters' own scene: its
                // nearest emitter, unless the whole scene blocks the way
                // there (stopping an offset short, as light rays do), so that
                // the many rays that meet no emitter cost only that.
                int32_t k = -1;
                if (emitter_scene) {
                    k = emitter_scene->intersect(ho, hd, &hu, &hv, &te);
                    if (k >= 0 && scene.occluded(ho, hd, te - float(q.offset), hemi_through))
                        k = -1;
                } else {
                    const int32_t t = scene.intersect(ho, hd, &hu, &hv, nullptr, hemi_through);
                    k = (t >= 0 && t < nt) ? emitter_of[t] : -1;
                }
                double pair[3], hemi[3], pair_base[3];
                sample_pair(em, q, r, s2, con, cb, light_through, hd, k, hu, hv, hemi_through, pair,
                            hemi, pair_base);
                double lum = 0.0, lum_light = 0.0, lum_hemi = 0.0;
                for (int i = 0; i < 3; ++i) {
                    sum[i] += pair[i];
                    sum_base[i] += pair_base[i];
                    lum += kLuminance[i] * pair[i];
                    lum_light += kLuminance[i] * double(raw[i]) * double(light_through[i]);
                    lum_hemi += kLuminance[i] * hemi[i];
                }
                sq += lum * lum;
                own[0] += lum_light, own_sq[0] += lum_light * lum_light;
                own[1] += lum_hemi, own_sq[1] += lum_hemi * lum_hemi;
            }
            const double n = double(q.samples);
            for (int i = 0; i < 3; ++i) {
                irradiance[3 * r + i] = sum[i] / n;
                if (base_irradiance) base_irradiance[3 * r + i] = sum_base[i] / n;
            }
            mean_square[r] = sq / n;
            if (strategy_variance)
                for (int j = 0; j < 2; ++j) {
                    const double m = own[j] / n;
                    strategy_variance[2 * r + j] = std::max(0.0, own_sq[j] / n - m * m);
                }
        }
    });
}

}  // namespace voxgi
