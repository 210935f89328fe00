// VPL shading kernels (see vpl_shade.h and DESIGN-NOTES §6).
#include "vpl_shade.h"

#include <cmath>
#include <cstring>
#include <vector>

namespace voxgi {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int64_t kChunk = 512;  // pixels per task

inline float dot3(const float *a, const float *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

inline float pow5(float x) {
    float x2 = x * x;
    return x2 * x2 * x;
}

// Tangent frame (u, v) around n: u from n x (0,1,0), or n x (1,0,0) when n is
// near +-y (DESIGN-NOTES §6; meshes carry no UVs in voxgi).
inline void tangent_frame(const float n[3], float u[3], float v[3]) {
    if (std::fabs(n[1]) < 0.99f) {  // n x (0, 1, 0)
        u[0] = -n[2];
        u[1] = 0.f;
        u[2] = n[0];
    } else {  // n x (1, 0, 0)
        u[0] = 0.f;
        u[1] = n[2];
        u[2] = -n[1];
    }
    float l = std::sqrt(dot3(u, u));
    u[0] /= l, u[1] /= l, u[2] /= l;
    v[0] = n[1] * u[2] - n[2] * u[1];
    v[1] = n[2] * u[0] - n[0] * u[2];
    v[2] = n[0] * u[1] - n[1] * u[0];
}

}  // namespace

void shade_brdf(const ShadeMaterials &mats, int32_t m, const float n[3], const float k1[3],
                const float k2[3], float f[3]) {
    const float *rd = mats.albedo + 3 * int64_t(m);
    if (!mats.glossy || !mats.glossy[m]) {
        for (int c = 0; c < 3; ++c) f[c] = rd[c] * float(1.0 / kPi);
        return;
    }
    // Ashikhmin & Shirley 2000, eqs. (4) and (5): coupled diffuse + specular.
    const float *rs = mats.rs + 3 * int64_t(m);
    const float nu = mats.nu[m], nv = mats.nv[m];
    const float nk1 = std::max(dot3(n, k1), 0.f), nk2 = std::max(dot3(n, k2), 1e-6f);
    float h[3] = {k1[0] + k2[0], k1[1] + k2[1], k1[2] + k2[2]};
    float hl = std::sqrt(dot3(h, h));
    float spec_common = 0.f, hk = 1.f;
    if (hl > 1e-12f) {
        h[0] /= hl, h[1] /= hl, h[2] /= hl;
        float u[3], v[3];
        tangent_frame(n, u, v);
        const float nh = std::max(dot3(n, h), 0.f);
        const float hu = dot3(h, u), hv = dot3(h, v);
        const float s2 = 1.f - nh * nh;  // sin² of the half vector's polar angle
        // Exponent nu cos²phi + nv sin²phi; at h = n the azimuth is undefined
        // but nh^e = 1 for any e.
        const float e = s2 > 1e-12f ? (nu * hu * hu + nv * hv * hv) / s2 : 0.5f * (nu + nv);
        hk = std::max(dot3(h, k1), 1e-6f);
        spec_common = float(std::sqrt((double(nu) + 1.0) * (double(nv) + 1.0)) / (8.0 * kPi)) *
                      std::pow(nh, e) / (hk * std::max(nk1, nk2));
    }
    const float one_m = 1.f - hk;
    const float d1 = 1.f - pow5(1.f - 0.5f * nk1), d2 = 1.f - pow5(1.f - 0.5f * nk2);
    for (int c = 0; c < 3; ++c) {
        const float fres = rs[c] + (1.f - rs[c]) * pow5(one_m);
        const float diff = float(28.0 / (23.0 * kPi)) * rd[c] * (1.f - rs[c]) * d1 * d2;
        f[c] = diff + spec_common * fres;
    }
}

int64_t vpl_prepare(const ShadeHits &hits, const ShadeMaterials &mats, const ShadeVPLs &vpls,
                    double eps, int64_t *ray_count, float *ray_org, float *ray_dir,
                    float *ray_len, float *ray_contrib, int threads, const StopCheck &stop) {
    const int64_t P = hits.count, K = vpls.count;
    const int64_t n_chunks = (P + kChunk - 1) / kChunk;
    std::vector<int64_t> chunk_rays(n_chunks, 0);
    // Each chunk writes its rays compacted from slot chunk_start*K on; a
    // serial pass then moves the chunks' blocks together.
    parallel_for(n_chunks, resolve_threads(threads), stop, [&](int64_t c, int) {
        const int64_t p0 = c * kChunk, p1 = std::min(P, p0 + kChunk);
        int64_t w = p0 * K;
        for (int64_t p = p0; p < p1; ++p) {
            const int32_t m = hits.material[p];
            int64_t cnt = 0;
            if (m >= 0 && m < mats.count) {
                const double *x = hits.pos + 3 * p;
                const float *n = hits.normal + 3 * p, *ng = hits.ng + 3 * p, *wo = hits.wo + 3 * p;
                const double ox = x[0] + eps * ng[0], oy = x[1] + eps * ng[1], oz = x[2] + eps * ng[2];
                for (int64_t k = 0; k < K; ++k) {
                    const double *y = vpls.pos + 3 * k;
                    const float *ny = vpls.normal + 3 * k;
                    const double dx = y[0] - x[0], dy = y[1] - x[1], dz = y[2] - x[2];
                    const double r2 = dx * dx + dy * dy + dz * dz;
                    if (!(r2 > 0.0)) continue;
                    const double r = std::sqrt(r2);
                    const float wi[3] = {float(dx / r), float(dy / r), float(dz / r)};
                    const float cos_y = -dot3(ny, wi);  // the VPL must face x
                    if (cos_y <= 0.f) continue;
                    if (dot3(ng, wi) <= 0.f) continue;  // below the geometric surface
                    const float cos_x = dot3(n, wi);
                    if (cos_x <= 0.f) continue;
                    // The VPL is a disc of area dA: on the axis of a disc the exact
                    // point-to-disc term is cos cos / (r² + dA/pi); bounded, and
                    // the point formula far away (DESIGN-NOTES §6).
                    const double g = double(cos_x) * cos_y / (r2 + double(vpls.area[k]) / kPi);
                    float f[3];
                    shade_brdf(mats, m, n, wi, wo, f);
                    const float *wk = vpls.weight + 3 * k;
                    float cr[3];
                    bool any = false;
                    for (int ch = 0; ch < 3; ++ch) {
                        cr[ch] = float(g * f[ch] * wk[ch]);
                        any |= cr[ch] > 0.f;
                    }
                    if (!any) continue;
                    // Shadow ray from x (offset along its geometric normal) to the
                    // VPL's point offset along its normal, stopping eps short.
                    const double tx = y[0] + eps * ny[0] - ox, ty = y[1] + eps * ny[1] - oy,
                                 tz = y[2] + eps * ny[2] - oz;
                    const double len = std::sqrt(tx * tx + ty * ty + tz * tz);
                    float *ro = ray_org + 3 * w, *rd = ray_dir + 3 * w, *rc = ray_contrib + 3 * w;
                    ro[0] = float(ox), ro[1] = float(oy), ro[2] = float(oz);
                    if (len > 0.0) {
                        rd[0] = float(tx / len), rd[1] = float(ty / len), rd[2] = float(tz / len);
                    } else {
                        rd[0] = wi[0], rd[1] = wi[1], rd[2] = wi[2];
                    }
                    ray_len[w] = float(std::max(len - eps, 0.0));
                    rc[0] = cr[0], rc[1] = cr[1], rc[2] = cr[2];
                    ++w;
                    ++cnt;
                }
            }
            ray_count[p] = cnt;
        }
        chunk_rays[c] = w - p0 * K;
    });
    // Serial compaction in increasing order: a chunk's destination ends where
    // the next one's begins, never past the next chunk's source.
    int64_t total = 0;
    for (int64_t c = 0; c < n_chunks; ++c) {
        const int64_t src = c * kChunk * K, n = chunk_rays[c];
        if (src != total && n > 0) {
            std::memmove(ray_org + 3 * total, ray_org + 3 * src, sizeof(float) * 3 * n);
            std::memmove(ray_dir + 3 * total, ray_dir + 3 * src, sizeof(float) * 3 * n);
            std::memmove(ray_len + total, ray_len + src, sizeof(float) * n);
            std::memmove(ray_contrib + 3 * total, ray_contrib + 3 * src, sizeof(float) * 3 * n);
        }
        total += n;
    }
    return total;
}

void vpl_accumulate(int64_t n_pixels, const int64_t *ray_count, const float *ray_contrib,
                    const uint8_t *occluded, float *out, int threads, const StopCheck &stop) {
    std::vector<int64_t> offset(n_pixels + 1, 0);
    for (int64_t p = 0; p < n_pixels; ++p) offset[p + 1] = offset[p] + ray_count[p];
    const int64_t n_chunks = (n_pixels + kChunk - 1) / kChunk;
    parallel_for(n_chunks, resolve_threads(threads), stop, [&](int64_t c, int) {
        const int64_t p1 = std::min(n_pixels, (c + 1) * kChunk);
        for (int64_t p = c * kChunk; p < p1; ++p) {
            double s[3] = {0.0, 0.0, 0.0};  // fixed order: the pixel's rays in VPL order
            for (int64_t r = offset[p]; r < offset[p + 1]; ++r) {
                if (occluded[r]) continue;
                for (int ch = 0; ch < 3; ++ch) s[ch] += ray_contrib[3 * r + ch];
            }
            for (int ch = 0; ch < 3; ++ch) out[3 * p + ch] = float(s[ch]);
        }
    });
}

}  // namespace voxgi
