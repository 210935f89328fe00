// VPL shading kernels (see vpl_shade.h and docs/design.md §6).
#include "vpl_shade.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "util/random.h"

namespace voxgi {

namespace {

// Where each pixel's rays start in pixel-major ray arrays (one more entry,
// the total), from the per-pixel counts.
std::vector<int64_t> ray_offsets(const int64_t* ray_count, int64_t n_pixels) {
    std::vector<int64_t> offset(n_pixels + 1, 0);
    for (int64_t p = 0; p < n_pixels; ++p) offset[p + 1] = offset[p] + ray_count[p];
    return offset;
}

constexpr double kPi = 3.14159265358979323846;
constexpr int64_t kChunk = 512;  // pixels per task

// body(p) for every pixel p < P, kChunk pixels a task.
template <class Body>
void for_each_pixel(int64_t P, int threads, const StopCheck& stop, Body&& body) {
    for_each_chunked(P, kChunk, threads, stop, std::forward<Body>(body));
}

// The sum of body(p), a pixel's rays, over every pixel p < P, kChunk pixels a task.
template <class Body>
int64_t sum_over_pixels(int64_t P, int threads, const StopCheck& stop, Body&& body) {
    return sum_chunked(P, kChunk, threads, stop, std::forward<Body>(body));
}

// The sum of body(p0, p1), the rays of pixels [p0, p1), over tasks of kChunk pixels.
template <class Body>
int64_t sum_over_pixel_chunks(int64_t P, int threads, const StopCheck& stop, Body&& body) {
    return sum_over_chunks(P, kChunk, threads, stop, std::forward<Body>(body));
}

inline float dot3(const float* a, const float* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

inline float pow5(float x) {
    float x2 = x * x;
    return x2 * x2 * x;
}

// Tangent frame (u, v) around n: u from n x (0,1,0), or n x (1,0,0) when n is
// near +-y (docs/design.md §6; not from a mesh's UVs, which only textures read).
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

void shade_brdf(const ShadeMaterials& mats, int32_t m, const float n[3], const float k1[3],
                const float k2[3], float f[3]) {
    shade_brdf(mats, m, mats.albedo + 3 * int64_t(m), n, k1, k2, f);
}

void shade_brdf(const ShadeMaterials& mats, int32_t m, const float* rd, const float n[3],
                const float k1[3], const float k2[3], float f[3]) {
    if (!mats.glossy || !mats.glossy[m]) {
        for (int c = 0; c < 3; ++c) f[c] = rd[c] * float(1.0 / kPi);
        return;
    }
    if (mats.lobe && mats.lobe[m].kind != 0.f)
        return microfacet_brdf(mats.lobe[m], rd, n, k1, k2, f);
    // Ashikhmin & Shirley 2000, eqs. (4) and (5): coupled diffuse + specular.
    const float* rs = mats.rs + 3 * int64_t(m);
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

namespace {

// The shadow rays of pixel p to the VPLs, in VPL order: emit(org, dir, len,
// contrib) for each (pixel, VPL) pair with a non-zero unoccluded term.
template <class Emit>
void vpl_pixel_rays(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeVPLs& vpls,
                    const ShadeMIS& mis, double eps, int64_t p, Emit&& emit) {
    const int32_t m = hits.material[p];
    if (m < 0 || m >= mats.count) return;
    const double* x = hits.pos + 3 * p;
    const float *n = hits.normal + 3 * p, *ng = hits.ng + 3 * p, *wo = hits.wo + 3 * p;
    const double ox = x[0] + eps * ng[0], oy = x[1] + eps * ng[1], oz = x[2] + eps * ng[2];
    const bool follows = vpls.share && follows_lobes(mats, m);
    for (int64_t k = 0; k < vpls.count; ++k) {
        const double* y = vpls.pos + 3 * k;
        const float* ny = vpls.normal + 3 * k;
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
        const double cc = double(cos_x) * cos_y;
        double g;
        if (vpls.pa && vpls.pa[k] > 0.f) {
            // Balance heuristic with the gather rays (see ShadeMIS), whose
            // density per unit area at y is n_g p_g(wi) cos_y / r².
            g = mats.lobe
                    ? cc / (r2 * vpls.pa[k] +
                            mis.n_gather * cos_y * gather_density(mats.lobe, m, n, wo, wi, cos_x))
                    : cc / (r2 * vpls.pa[k] + mis.n_gather * cc / kPi);
        } else {
            // The VPL is a disc of area dA: on the axis of a disc the exact
            // point-to-disc term is cos cos / (r² + dA/pi); bounded, and
            // the point formula far away (docs/design.md §6).
            g = cc / (r2 + double(vpls.area[k]) / kPi);
        }
        float f[3];
        shade_brdf(mats, m, hit_albedo(hits, mats, p, m), n, wi, wo, f);
        const float* wk = vpls.weight + 3 * k;
        // a pixel whose gather rays follow the lobes they land on takes only
        // the base's share of a glossy record's light from its VPLs
        const float* sk = follows ? vpls.share + 3 * k : nullptr;
        float cr[3];
        bool any = false;
        // which its base sends out towards x as the base's directional albedo
        double out_y[3] = {1.0, 1.0, 1.0};
        if (sk && mats.base_out && vpls.object)
            incidence_response(mats.base_out + int64_t(3) * kIncidenceNodes * vpls.object[k], cos_y,
                               out_y);
        for (int ch = 0; ch < 3; ++ch) {
            cr[ch] = float(g * f[ch] * wk[ch] * (sk ? sk[ch] * out_y[ch] : 1.f));
            any |= cr[ch] > 0.f;
        }
        if (!any) continue;
        // Shadow ray from x (offset along its geometric normal) to the
        // VPL's point offset along its normal, stopping eps short.
        const double tx = y[0] + eps * ny[0] - ox, ty = y[1] + eps * ny[1] - oy,
                     tz = y[2] + eps * ny[2] - oz;
        const double len = std::sqrt(tx * tx + ty * ty + tz * tz);
        const float ro[3] = {float(ox), float(oy), float(oz)};
        float rd[3] = {wi[0], wi[1], wi[2]};
        if (len > 0.0) rd[0] = float(tx / len), rd[1] = float(ty / len), rd[2] = float(tz / len);
        emit(ro, rd, float(std::max(len - eps, 0.0)), cr);
    }
}

}  // namespace

void vpl_light(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeVPLs& vpls,
               const ShadeMIS& mis, double eps, const int32_t* pixel_set, const int64_t* set_start,
               const RayScene& scene, float* out, int64_t* rays, int threads,
               const StopCheck& stop) {
    *rays = sum_over_pixels(hits.count, threads, stop, [&](int64_t p) {
        double s[3] = {0.0, 0.0, 0.0};  // in VPL order: the same for any thread count
        int64_t n = 0;
        ShadeVPLs mine = vpls;
        if (pixel_set) {
            const int64_t a = set_start[pixel_set[p]], b = set_start[pixel_set[p] + 1];
            mine.count = b - a;
            mine.pos += 3 * a, mine.normal += 3 * a, mine.weight += 3 * a;
            mine.area += a;
            if (mine.pa) mine.pa += a;
            if (mine.share) mine.share += 3 * a;
            if (mine.object) mine.object += a;
        }
        vpl_pixel_rays(hits, mats, mine, mis, eps, p,
                       [&](const float* ro, const float* rd, float len, const float* cr) {
                           ++n;
                           float T[3];
                           if (scene.occluded(ro, rd, len, T)) return;
                           for (int ch = 0; ch < 3; ++ch) s[ch] += cr[ch] * T[ch];
                       });
        for (int ch = 0; ch < 3; ++ch) out[3 * p + ch] = float(s[ch]);
        return n;
    });
}

namespace {

// The seed of a frame's gather rays; each pixel's stream is hashed from it.
uint64_t gather_base(uint64_t seed, int64_t frame) {
    return splitmix64(seed ^ splitmix64(uint64_t(frame) + 0x6A09E667F3BCC909ull));
}

// The n_gather rays of shaded pixel p: emit(k, org, dir), dir null for a
// lobe sample that falls below the surface (it brings nothing).
// Cosine-distributed, or for a material with a microfacet lobe each ray drawn
// from the lobe with probability lobe_share (from the same stratified pair).
template <class Emit>
void gather_pixel_rays(const ShadeHits& hits, const ShadeMaterials& mats, int n_gather,
                       uint64_t base, double eps, int64_t p, Emit&& emit) {
    const double* x = hits.pos + 3 * p;
    const float *n = hits.normal + 3 * p, *ng = hits.ng + 3 * p;
    float u[3], v[3];
    tangent_frame(n, u, v);
    uint64_t h = splitmix64(base ^ uint64_t(p) * 0xD1B54A32D192ED03ull);
    const MicrofacetLobe* lobe = mats.lobe ? mats.lobe + hits.material[p] : nullptr;
    if (lobe && lobe->kind == 0.f) lobe = nullptr;
    // A square count is stratified in both cos²θ and the azimuth (m x m
    // cells); any other in cos²θ alone.
    const int m = int(std::lround(std::sqrt(double(n_gather))));
    const bool grid = m > 1 && m * m == n_gather;
    for (int k = 0; k < n_gather; ++k) {
        h = splitmix64(h);
        const double j1 = to_unit(h);
        h = splitmix64(h);
        const double j2 = to_unit(h);
        const double u1 = grid ? (k / m + j1) / m : (k + j1) / n_gather;
        const double u2 = grid ? (k % m + j2) / m : j2;
        float ro[3], rd[3];
        for (int a = 0; a < 3; ++a) ro[a] = float(x[a] + eps * ng[a]);
        if (lobe) {
            h = splitmix64(h);
            if (to_unit(h) < lobe->lobe_share) {
                const bool up = microfacet_sample(*lobe, n, hits.wo + 3 * p, u1, u2, rd);
                emit(k, ro, up ? rd : nullptr);
                continue;
            }
        }
        const double phi = 2.0 * kPi * u2;
        const double r = std::sqrt(u1), z = std::sqrt(std::max(0.0, 1.0 - u1));
        const double lx = r * std::cos(phi), ly = r * std::sin(phi);
        for (int a = 0; a < 3; ++a) rd[a] = float(lx * u[a] + ly * v[a] + z * n[a]);
        emit(k, ro, rd);
    }
}

}  // namespace

namespace {

// Where a gather ray of pixel p landed, before its record is looked up.
struct GatherHit {
    double y[3];       // on the hit triangle's plane, in double
    float ns[3];       // the hit surface's normal on the side the ray came from
    float wi[3];       // unit direction; for a ray that met nothing, its direction as traced
    float cos_x;       // at the pixel
    int32_t obj;       // hit object
    int32_t tri;       // hit triangle
    bool front;        // met on the side its winding faces
    int64_t c[3];      // voxel of y
    int64_t key;       // its key on the grid (-1: outside), or -2: no light to look up
    bool escaped;      // met nothing: sees the environment
    float through[3];  // what the sheets before the hit let through
    bool textured;     // tex holds the albedo of a texture at y
    float tex[3];
};

// The point of triangle (a, b, c) nearest to p (Ericson, Real-Time Collision
// Detection, 5.1.5), into q.
void nearest_on_triangle(const double p[3], const double a[3], const double b[3], const double c[3],
                         double q[3]) {
    double ab[3], ac[3], ap[3], bp[3], cp[3];
    for (int i = 0; i < 3; ++i)
        ab[i] = b[i] - a[i], ac[i] = c[i] - a[i], ap[i] = p[i] - a[i], bp[i] = p[i] - b[i],
        cp[i] = p[i] - c[i];
    auto dot = [](const double* u, const double* v) {
        return u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    };
    auto put = [&](const double* o, double s, const double* e, double t, const double* f) {
        for (int i = 0; i < 3; ++i) q[i] = o[i] + s * e[i] + t * (f ? f[i] : 0.0);
    };
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) return put(a, 0.0, ab, 0.0, nullptr);
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) return put(b, 0.0, ab, 0.0, nullptr);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return put(a, d1 / (d1 - d3), ab, 0.0, nullptr);
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) return put(c, 0.0, ab, 0.0, nullptr);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return put(a, 0.0, ab, d2 / (d2 - d6), ac);
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        for (int i = 0; i < 3; ++i) q[i] = b[i] + w * (c[i] - b[i]);
        return;
    }
    const double den = 1.0 / (va + vb + vc);
    put(a, vb * den, ab, vc * den, ac);
}

// The hit of pixel p's gather ray from ro along df (unit up to float
// rounding) that first meets triangle t (-1: none). key -2 when it brings
// no light: a miss, a direction below the surface, a black back.
void gather_hit(const ShadeHits& hits, const ShadeTriangles& tris, const RecordGrid& grid,
                int64_t p, const float* ro, const float df[3], int32_t t, GatherHit& h) {
    h.key = -2;
    h.escaped = t < 0;
    h.textured = false;
    // The hit point on the ray as traced: the same direction from the
    // pixel's own point meets the plane up to the offset away, which near a
    // surface meeting the triangle can be on that surface's far side.
    const double o[3] = {ro[0], ro[1], ro[2]};
    const float *n = hits.normal + 3 * p, *ng = hits.ng + 3 * p;
    if (h.escaped)
        for (int a = 0; a < 3; ++a) h.wi[a] = df[a];
    if (t < 0 || t >= tris.count) return;
    const double d[3] = {df[0], df[1], df[2]};
    const double dl = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int a = 0; a < 3; ++a) h.wi[a] = float(d[a] / dl);
    h.cos_x = dot3(n, h.wi);
    if (h.cos_x <= 0.f || dot3(ng, h.wi) <= 0.f) return;
    // Hit point: the ray against the hit triangle's plane, in double.
    const double *v0 = tris.v + 9 * int64_t(t), *v1 = v0 + 3, *v2 = v0 + 6;
    const double e1[3] = {v1[0] - v0[0], v1[1] - v0[1], v1[2] - v0[2]};
    const double e2[3] = {v2[0] - v0[0], v2[1] - v0[1], v2[2] - v0[2]};
    double nt[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                    e1[0] * e2[1] - e1[1] * e2[0]};
    const double nl = std::sqrt(nt[0] * nt[0] + nt[1] * nt[1] + nt[2] * nt[2]);
    if (!(nl > 0.0)) return;
    nt[0] /= nl, nt[1] /= nl, nt[2] /= nl;
    const double dn = (d[0] * nt[0] + d[1] * nt[1] + d[2] * nt[2]) / dl;
    if (dn == 0.0) return;
    const double tt =
        ((v0[0] - o[0]) * nt[0] + (v0[1] - o[1]) * nt[1] + (v0[2] - o[2]) * nt[2]) / dn;
    // Kept on the triangle: in float the ray can meet it a little beyond its
    // edge, where another surface may meet it.
    double on_plane[3];
    for (int a = 0; a < 3; ++a) on_plane[a] = o[a] + tt * h.wi[a];
    nearest_on_triangle(on_plane, v0, v1, v2, h.y);
    const bool front = dn < 0.0;
    h.obj = tris.object[t];
    h.tri = t;
    h.front = front;
    if (!front && !tris.two_sided[h.obj]) return;  // black back of a one-sided surface
    for (int a = 0; a < 3; ++a) h.ns[a] = float(front ? nt[a] : -nt[a]);
    if (tris.textures) {
        double b1, b2;
        barycentric(v0, v1, v2, h.y, b1, b2);
        h.textured = surface_albedo(*tris.textures, t, h.obj, b1, b2, h.tex);
    }
    cell_of(grid, h.y, h.c);
    h.key = grid_key(grid, h.c[0], h.c[1], h.c[2]);
}

// The factors by which pixel p's gather ray h reads record rec (-1: none),
// short of the record's radiance: the BRDF f, the texture's ratio to the
// record's albedo (1 untextured) and the MIS denominator; false where the
// ray reads nothing.
static bool gather_hit_factors(const ShadeHits& hits, const ShadeMaterials& mats,
                               const ShadeMIS& mis, const RecordGrid& grid, int64_t p,
                               const GatherHit& h, int64_t rec, float f[3], float ratio[3],
                               double& denom) {
    if (rec < 0) return false;
    const float cos_y = -dot3(h.ns, h.wi);
    if (cos_y <= 0.f) return false;
    const double* x = hits.pos + 3 * p;
    const double r2 = (h.y[0] - x[0]) * (h.y[0] - x[0]) + (h.y[1] - x[1]) * (h.y[1] - x[1]) +
                      (h.y[2] - x[2]) * (h.y[2] - x[2]);
    const PackedRecord& R = grid.rec[rec];
    const int32_t m = hits.material[p];
    const double pg = mats.lobe ? gather_density(mats.lobe, m, hits.normal + 3 * p, hits.wo + 3 * p,
                                                 h.wi, h.cos_x)
                                : h.cos_x / kPi;
    denom = double(R.pa) * r2 / cos_y + mis.n_gather * pg;
    if (!(denom > 0.0)) return false;
    shade_brdf(mats, m, hit_albedo(hits, mats, p, m), hits.normal + 3 * p, h.wi, hits.wo + 3 * p,
               f);
    if (mats.response) {
        double resp[3];
        incidence_response(mats.response + int64_t(3) * kIncidenceNodes * m, h.cos_x, resp);
        for (int ch = 0; ch < 3; ++ch) f[ch] = float(f[ch] * resp[ch]);
    }
    ratio[0] = ratio[1] = ratio[2] = 1.f;
    if (h.textured) {
        // the record's albedo is the solve's (a plastic's: its coat's too)
        const MicrofacetLobe* hit_lobe = mats.hit_lobe ? mats.hit_lobe + h.obj : nullptr;
        for (int ch = 0; ch < 3; ++ch)
            if (R.albedo[ch] > 0.f)
                ratio[ch] = solve_albedo(hit_lobe, h.tex[ch], ch) / R.albedo[ch];
    }
    return true;
}

// Whether a gather ray of a pixel of material m that lands at h follows the lobe there.
inline bool continues(const ShadeMaterials& mats, int32_t m, const GatherHit& h) {
    return follows_lobes(mats, m) && h.obj >= 0 && h.obj < mats.hit_count &&
           mats.continue_lobe[h.obj] && mats.hit_lobe[h.obj].kind != 0.f;
}

// The hit of a ray leaving gather hit h along wi, from h's point offset
// along its normal by eps (into ro), with the sheets' transmittance before
// it (T): h stands as a "pixel" of one for gather_hit's facing tests.
void trace_on(const ShadeTriangles& tris, const RecordGrid& grid, const RayScene& scene, double eps,
              const GatherHit& h, const float wi[3], float ro[3], float T[3], GatherHit& out) {
    for (int a = 0; a < 3; ++a) ro[a] = float(h.y[a] + eps * h.ns[a]);
    const int32_t t = scene.intersect(ro, wi, nullptr, nullptr, nullptr, T);
    ShadeHits at_y;
    at_y.count = 1;
    at_y.normal = h.ns;
    at_y.ng = h.ns;
    gather_hit(at_y, tris, grid, 0, ro, wi, t, out);
}

// One sample of the specular reflection of the lobe at the glossy hit h
// (docs/design.md §14): a direction drawn from the lobe about the way back
// and traced. Returns the record where it lands (-1: none), with `factor`
// the lobe's f cos / pdf times the sheets' transmittance on the way, by which
// that record's radiance (or, where the ray escaped, the environment's,
// written into env_L) is read.
int64_t follow_lobe(const ShadeMaterials& mats, const ShadeTriangles& tris, const RecordGrid& grid,
                    const EnvironmentMap* env, const RayScene& scene, double eps,
                    const GatherHit& h, uint64_t& rng, LookupScratch& scratch, double factor[3],
                    float env_L[3]) {
    const MicrofacetLobe& lobe = mats.hit_lobe[h.obj];
    for (int ch = 0; ch < 3; ++ch) factor[ch] = 0.0, env_L[ch] = 0.f;
    const float wo[3] = {-h.wi[0], -h.wi[1], -h.wi[2]};
    rng = splitmix64(rng);
    const double u1 = to_unit(rng);
    rng = splitmix64(rng);
    const double u2 = to_unit(rng);
    float wi[3];
    if (!microfacet_sample(lobe, h.ns, wo, u1, u2, wi)) return -1;
    const double pdf = microfacet_pdf(lobe, h.ns, wo, wi);
    const float cos_y = dot3(h.ns, wi);
    if (!(pdf > 0.0) || !(cos_y > 0.f)) return -1;
    const float zero[3] = {0.f, 0.f, 0.f};
    float f[3];
    microfacet_brdf(lobe, zero, h.ns, wi, wo, f);
    float ro[3], T[3];
    GatherHit z;
    trace_on(tris, grid, scene, eps, h, wi, ro, T, z);
    const double w = double(cos_y) / pdf;
    for (int ch = 0; ch < 3; ++ch) factor[ch] = f[ch] * w * T[ch];
    if (z.escaped) {
        if (env) {
            const double d[3] = {wi[0], wi[1], wi[2]};
            const double* Le = env->radiance + 3 * environment_texel(*env, d);
            for (int ch = 0; ch < 3; ++ch) env_L[ch] = float(Le[ch]);
        }
        return -1;
    }
    if (z.key < 0) return -1;
    return lookup_in_cell(grid, z.y, z.ns, z.obj, z.c, z.tri, z.front, scratch);
}

// The light leaving the glossy hit h towards the ray's origin
// (docs/design.md §14): the base's share of record rec's light (ratio: the
// texture's over the record's albedo), read as the record's mean as VPLs
// read it, plus one sample of the lobe's specular reflection (follow_lobe),
// the record where it lands (or the environment) read by its factor.
// Returns the record the lobe's ray read (-1: none) and its factor.
int64_t glossy_hit_radiance(const ShadeMaterials& mats, const ShadeTriangles& tris,
                            const RecordGrid& grid, const EnvironmentMap* env,
                            const RayScene& scene, double eps, const GatherHit& h, int64_t rec,
                            const float ratio[3], uint64_t& rng, LookupScratch& scratch, float L[3],
                            float coat[3], double factor[3]) {
    const PackedRecord& R = grid.rec[rec];
    // the base sends its share out towards the ray's origin as its
    // directional albedo at that cosine (a plastic's base, behind its
    // coat's Fresnel, sends little at grazing angles)
    double out_y[3] = {1.0, 1.0, 1.0};
    if (mats.base_out)
        incidence_response(mats.base_out + int64_t(3) * kIncidenceNodes * h.obj, -dot3(h.ns, h.wi),
                           out_y);
    for (int ch = 0; ch < 3; ++ch)
        // (grid.share is given wherever continue_lobe is: the binding checks)
        L[ch] = float(R.radiance[ch] * ratio[ch] * grid.share[3 * rec + ch] * out_y[ch]);
    float Lz[3];
    const int64_t q = follow_lobe(mats, tris, grid, env, scene, eps, h, rng, scratch, factor, Lz);
    if (q >= 0)
        for (int ch = 0; ch < 3; ++ch) Lz[ch] = grid.rec[q].radiance[ch];
    for (int ch = 0; ch < 3; ++ch) coat[ch] = float(factor[ch] * Lz[ch]);
    return q;
}

// Whether pixel p's gather ray h, landing on a diffuse object that does not
// emit within tris.reach of the pixel's point, continues there (see
// ShadeTriangles::reach).
inline bool continues_near(const ShadeHits& hits, const ShadeMaterials& mats,
                           const ShadeTriangles& tris, int64_t p, const GatherHit& h) {
    if (!(tris.reach > 0.0) || h.obj < 0 || h.obj >= mats.count) return false;
    if (tris.emits && tris.emits[h.obj]) return false;
    if (mats.continue_lobe && mats.continue_lobe[h.obj]) return false;
    const double* x = hits.pos + 3 * p;
    double r2 = 0.0;
    for (int a = 0; a < 3; ++a) r2 += (h.y[a] - x[a]) * (h.y[a] - x[a]);
    return r2 < tris.reach * tris.reach;
}

// A cosine-distributed direction wi about the unit normal n, from the next
// two numbers of rng; returns its cosine.
inline double cosine_direction(const float n[3], uint64_t& rng, float wi[3]) {
    float u[3], v[3];
    tangent_frame(n, u, v);
    rng = splitmix64(rng);
    const double u1 = to_unit(rng);
    rng = splitmix64(rng);
    const double phi = 2.0 * kPi * to_unit(rng);
    const double r = std::sqrt(u1), z = std::sqrt(std::max(0.0, 1.0 - u1));
    const double lx = r * std::cos(phi), ly = r * std::sin(phi);
    for (int a = 0; a < 3; ++a) wi[a] = float(lx * u[a] + ly * v[a] + z * n[a]);
    return z;
}

// The emitters' light at the hit h (unit normal h.ns) from one of the
// frame's emitter VPLs, drawn uniformly (ShadeTriangles::emitter_pos), its
// shadow ray from ro (the offset origin of the bounce ray from h), weighed
// by the balance heuristic against a cosine-distributed ray from h, whose
// density per unit area at the VPL's point is cos_y cos_e / (pi r²): the
// bounce ray then reads the emitters it meets by emitter_hit_weight. Ld is
// the irradiance over pi that the sample brings. Returns the rays traced.
int emitter_vpl_light(const ShadeTriangles& tris, const RayScene& scene, double eps,
                      const GatherHit& h, const float ro[3], uint64_t& rng, float Ld[3]) {
    Ld[0] = Ld[1] = Ld[2] = 0.f;
    if (tris.emitter_count <= 0) return 0;
    rng = splitmix64(rng);
    const int64_t k =
        std::min(tris.emitter_count - 1, int64_t(to_unit(rng) * double(tris.emitter_count)));
    const double* e = tris.emitter_pos + 3 * k;
    const float* ne = tris.emitter_normal + 3 * k;
    const double dx = e[0] - h.y[0], dy = e[1] - h.y[1], dz = e[2] - h.y[2];
    const double r2 = dx * dx + dy * dy + dz * dz;
    if (!(r2 > 0.0) || !(tris.emitter_density[k] > 0.f)) return 0;
    const double r = std::sqrt(r2);
    const float we[3] = {float(dx / r), float(dy / r), float(dz / r)};
    const float cos_y = dot3(h.ns, we), cos_e = -dot3(ne, we);
    if (!(cos_y > 0.f) || !(cos_e > 0.f)) return 0;
    const double cc = double(cos_y) * cos_e;
    const double gb = cc / (r2 * double(tris.emitter_density[k]) + cc / kPi) / kPi;
    const double tx = e[0] + eps * ne[0] - ro[0], ty = e[1] + eps * ne[1] - ro[1],
                 tz = e[2] + eps * ne[2] - ro[2];
    const double len = std::sqrt(tx * tx + ty * ty + tz * tz);
    float sd[3] = {we[0], we[1], we[2]}, Ts[3];
    if (len > 0.0) sd[0] = float(tx / len), sd[1] = float(ty / len), sd[2] = float(tz / len);
    if (!scene.occluded(ro, sd, float(std::max(len - eps, 0.0)), Ts))
        for (int ch = 0; ch < 3; ++ch)
            Ld[ch] = float(gb * tris.emitter_radiance[3 * k + ch] * Ts[ch]);
    return 1;
}

// The balance heuristic's weight of a cosine-distributed ray from h (cosine
// z there) that landed at g on the emitter record q, against the emitter
// VPL sample of emitter_vpl_light at the same point: 1 where no emitter VPLs
// are sampled, or the object g lies on does not emit.
double emitter_hit_weight(const ShadeTriangles& tris, const RecordGrid& grid, const GatherHit& h,
                          double z, const GatherHit& g, int64_t q) {
    if (tris.emitter_count <= 0 || !tris.emits || g.obj < 0 || !tris.emits[g.obj]) return 1.0;
    const float cos_z = -dot3(g.ns, g.wi);
    const double pa = double(grid.rec[q].pa) / tris.emitter_per_set;
    double dz2 = 0.0;
    for (int a = 0; a < 3; ++a) dz2 += (g.y[a] - h.y[a]) * (g.y[a] - h.y[a]);
    const double pc = z * std::max(cos_z, 0.f) / kPi;
    return pc > 0.0 ? pc / (pc + dz2 * pa) : 0.0;
}

// The light leaving the diffuse hit h towards the ray's origin, from one
// more bounce: its albedo (the solve's, its texture's where it has one)
// times the radiance along one cosine-distributed ray from it, read from
// the record where that lands (or the environment), and with the frame's
// emitter VPLs the emitters' light from one of them, the two combined by the
// balance heuristic. Returns the rays traced.
int near_hit_radiance(const ShadeMaterials& mats, const ShadeTriangles& tris,
                      const RecordGrid& grid, const EnvironmentMap* env, const RayScene& scene,
                      double eps, const GatherHit& h, uint64_t& rng, LookupScratch& scratch,
                      float L[3]) {
    L[0] = L[1] = L[2] = 0.f;
    int rays = 1;
    const MicrofacetLobe* lobe = mats.hit_lobe ? mats.hit_lobe + h.obj : nullptr;
    float rho[3];
    for (int ch = 0; ch < 3; ++ch)
        rho[ch] = solve_albedo(lobe, h.textured ? h.tex[ch] : mats.albedo[3 * h.obj + ch], ch);
    float wi[3], ro[3], T[3];
    const double z = cosine_direction(h.ns, rng, wi);
    GatherHit g;
    trace_on(tris, grid, scene, eps, h, wi, ro, T, g);
    // The emitters' light at y from one of the frame's emitter VPLs; the
    // ray above then reads only the light of surfaces that do not emit.
    float Ld[3];
    rays += emitter_vpl_light(tris, scene, eps, h, ro, rng, Ld);
    for (int ch = 0; ch < 3; ++ch) L[ch] = rho[ch] * Ld[ch];
    float Lz[3] = {0.f, 0.f, 0.f};
    if (g.escaped) {
        if (!env) return rays;
        const double d[3] = {wi[0], wi[1], wi[2]};
        const double* Le = env->radiance + 3 * environment_texel(*env, d);
        for (int ch = 0; ch < 3; ++ch) Lz[ch] = float(Le[ch]);
    } else {
        if (g.key < 0) return rays;
        const int64_t q = lookup_in_cell(grid, g.y, g.ns, g.obj, g.c, g.tri, g.front, scratch);
        if (q < 0) return rays;
        if (tris.emitter_count > 0 && tris.emits && tris.emits[g.obj]) {
            // an emitter's record, also sampled above: the balance heuristic
            const double w = emitter_hit_weight(tris, grid, h, z, g, q);
            for (int ch = 0; ch < 3; ++ch)
                L[ch] += float(rho[ch] * grid.rec[q].radiance[ch] * T[ch] * w);
            return rays;
        }
        const PackedRecord& R = grid.rec[q];
        for (int ch = 0; ch < 3; ++ch) {
            float ratio = 1.f;
            if (g.textured && R.albedo[ch] > 0.f) {
                const MicrofacetLobe* gl = mats.hit_lobe ? mats.hit_lobe + g.obj : nullptr;
                ratio = solve_albedo(gl, g.tex[ch], ch) / R.albedo[ch];
            }
            Lz[ch] = R.radiance[ch] * ratio;
        }
    }
    for (int ch = 0; ch < 3; ++ch) L[ch] += rho[ch] * Lz[ch] * T[ch];
    return rays;
}

// Bounces a ray takes within a stack of sheets at most (follow_sheet): at
// a sheet's albedo of 0.9, 0.9^8 = 0.43 of the light it carries is left to
// the record read at the last one.
constexpr int kSheetBounces = 8;

// The light leaving a stacked sheet's hit h (record rec, ratio: the
// texture's over the record's albedo) towards the ray's origin, from
// bounces at the hit point rather than the record's mean: a slat's record
// gives its lit edge and its shaded middle one radiosity, and what a ray
// sees of the slat is the part the slats around it leave in view. One
// cosine-distributed ray from the hit point; where it lands on another
// stacked sheet that does not emit (grid.stacked 1) it bounces there again
// (up to kSheetBounces, the last one read as its record's mean), as light
// passed on between nearly closed slats does. Returns the record read
// (-1: none) with `factor`, the albedos on the way (the records' after the
// first) times the sheets' transmittance, and in `light` the light the
// walk brings: that record's radiance by `factor` and, with the frame's
// emitter VPLs (the display), the emitters' light at every bounce from one
// of them (emitter_vpl_light): a lamp seen through the gaps of a blind is
// then found by a shadow ray from each slat, not only by the few walks
// that escape to it, whose reading the balance heuristic weighs into
// `factor`. Adds the rays traced to *rays.
int64_t follow_sheet(const ShadeTriangles& tris, const RecordGrid& grid, const RayScene& scene,
                     double eps, const GatherHit& h, int64_t rec, const float ratio[3],
                     uint64_t& rng, LookupScratch& scratch, double factor[3], double light[3],
                     int64_t* rays) {
    for (int ch = 0; ch < 3; ++ch)
        factor[ch] = double(grid.rec[rec].albedo[ch]) * ratio[ch], light[ch] = 0.0;
    if (!(factor[0] > 0.0 || factor[1] > 0.0 || factor[2] > 0.0)) return -1;  // a black sheet
    GatherHit at = h;
    int64_t q = -1;
    for (int bounce = 0; bounce < kSheetBounces; ++bounce) {
        float wi[3], ro[3], T[3], Ld[3];
        const double z = cosine_direction(at.ns, rng, wi);
        GatherHit g;
        trace_on(tris, grid, scene, eps, at, wi, ro, T, g);
        *rays += 1 + emitter_vpl_light(tris, scene, eps, at, ro, rng, Ld);
        for (int ch = 0; ch < 3; ++ch) light[ch] += factor[ch] * Ld[ch];
        for (int ch = 0; ch < 3; ++ch) factor[ch] *= T[ch];
        if (g.escaped || g.key < 0) return -1;
        q = lookup_in_cell(grid, g.y, g.ns, g.obj, g.c, g.tri, g.front, scratch);
        if (q < 0) return q;
        if (grid.stacked[q] != 1) {  // (2: an emitter, read)
            const double w = emitter_hit_weight(tris, grid, at, z, g, q);
            for (int ch = 0; ch < 3; ++ch) {
                factor[ch] *= w;
                light[ch] += factor[ch] * grid.rec[q].radiance[ch];
            }
            return q;
        }
        if (bounce + 1 == kSheetBounces) {  // the last one read as its record's mean
            for (int ch = 0; ch < 3; ++ch) light[ch] += factor[ch] * grid.rec[q].radiance[ch];
            return q;
        }
        for (int ch = 0; ch < 3; ++ch) factor[ch] *= grid.rec[q].albedo[ch];
        if (!(factor[0] > 0.0 || factor[1] > 0.0 || factor[2] > 0.0)) return -1;  // black
        at = g;
    }
    return q;
}

// The gather rays' own density for pixel p's ray h onto record rec: the MIS
// denominator `denom` less the record's VPL density. The coat's part of a
// glossy hit's light comes by the gather rays alone.
inline double own_density(const ShadeHits& hits, const RecordGrid& grid, int64_t p,
                          const GatherHit& h, int64_t rec, double denom) {
    const double* x = hits.pos + 3 * p;
    double r2 = 0.0;
    for (int a = 0; a < 3; ++a) r2 += (h.y[a] - x[a]) * (h.y[a] - x[a]);
    return denom - double(grid.rec[rec].pa) * r2 / double(-dot3(h.ns, h.wi));
}

// The factor by which pixel p's gather ray h, landing on record rec's glossy
// surface, reads the record q that the lobe's ray from there read with
// `factor` (follow_lobe): false where it reads nothing.
bool followed_weight(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeMIS& mis,
                     const RecordGrid& grid, int64_t p, const GatherHit& h, int64_t rec,
                     const double factor[3], double w[3]) {
    float f[3], ratio[3];
    double denom;
    if (!gather_hit_factors(hits, mats, mis, grid, p, h, rec, f, ratio, denom)) return false;
    const double own = own_density(hits, grid, p, h, rec, denom);
    if (!(own > 0.0)) return false;
    for (int ch = 0; ch < 3; ++ch)
        w[ch] = double(f[ch]) * h.through[ch] * h.cos_x / own * factor[ch];
    return true;
}

// The MIS-weighted light of pixel p's gather ray h from record rec (-1: none)
// into s, through the sheets before the hit. With `base` and `coat`
// (nullable): the light leaving a glossy hit towards the pixel in two parts,
// the base's share of the record's, which the record's VPLs bring too (MIS),
// and the coat's, which only the gather rays bring.
void gather_hit_light(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeMIS& mis,
                      const RecordGrid& grid, int64_t p, const GatherHit& h, int64_t rec,
                      double s[3], const float* base = nullptr, const float* coat = nullptr) {
    float f[3], ratio[3];
    double denom;
    if (!gather_hit_factors(hits, mats, mis, grid, p, h, rec, f, ratio, denom)) return;
    if (base) {
        const double own = own_density(hits, grid, p, h, rec, denom);
        for (int ch = 0; ch < 3; ++ch) {
            double L = base[ch] / denom;
            if (own > 0.0) L += coat[ch] / own;
            s[ch] += double(f[ch]) * L * h.through[ch] * h.cos_x;
        }
        return;
    }
    const float* radiance = grid.rec[rec].radiance;
    for (int ch = 0; ch < 3; ++ch) {
        const float L = radiance[ch] * ratio[ch];
        s[ch] += double(f[ch]) * L * h.through[ch] * h.cos_x / denom;
    }
}

// No record read by ray r (yet).
inline void record_transport(const GatherTransport& t, int64_t r) {
    t.record[r] = -1;
    t.weight[3 * r] = t.weight[3 * r + 1] = t.weight[3 * r + 2] = 0.f;
}

// What gather_hit_light multiplies record rec's radiance by for pixel p's
// gather ray h, as ray r of the transport: the same factors with a radiance
// of 1.
void gather_hit_weight(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeMIS& mis,
                       const RecordGrid& grid, int64_t p, const GatherHit& h, int64_t rec,
                       const GatherTransport& t, int64_t r) {
    float f[3], ratio[3];
    double denom;
    if (!gather_hit_factors(hits, mats, mis, grid, p, h, rec, f, ratio, denom)) return;
    t.record[r] = int32_t(rec);
    for (int ch = 0; ch < 3; ++ch)
        t.weight[3 * r + ch] = float(double(f[ch]) * ratio[ch] * h.through[ch] * h.cos_x / denom);
}

// The environment's light along pixel p's escaped gather ray h, MIS-weighted
// against the environment samples, added into s (the arithmetic of
// light_accumulate with the weight the display computes for such a ray).
void gather_escape_light(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeMIS& mis,
                         const EnvironmentMap& env, int64_t p, const GatherHit& h, float s[3]) {
    const float *n = hits.normal + 3 * p, *ng = hits.ng + 3 * p;
    const float cos_x = dot3(n, h.wi);
    if (cos_x <= 0.f || dot3(ng, h.wi) <= 0.f) return;
    const double d[3] = {h.wi[0], h.wi[1], h.wi[2]};
    const int64_t texel = environment_texel(env, d);
    const double cos = d[0] * double(n[0]) + d[1] * double(n[1]) + d[2] * double(n[2]);
    const double pdf = environment_density(env, texel, guide_row(env, hits.pos + 3 * p, ng));
    const int32_t m = hits.material[p];
    const double pg = mats.lobe ? gather_density(mats.lobe, m, n, hits.wo + 3 * p, h.wi, cos)
                                : std::max(cos, 0.0) / kPi;
    const double dens = env.n_samples * pdf + mis.n_gather * pg;
    const double inv = dens > 0.0 ? 1.0 / dens : 0.0;
    float f[3];
    shade_brdf(mats, m, hit_albedo(hits, mats, p, m), n, h.wi, hits.wo + 3 * p, f);
    const double* L = env.radiance + 3 * texel;
    for (int ch = 0; ch < 3; ++ch) s[ch] += f[ch] * cos_x * float(L[ch] * inv) * h.through[ch];
}

}  // namespace

void gather_light(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeMIS& mis,
                  int n_gather, uint64_t seed, int64_t frame, double eps,
                  const ShadeTriangles& tris, const RecordGrid& pieces, const EnvironmentMap* env,
                  const RayScene& scene, float* out, int64_t* rays, int threads,
                  const StopCheck& stop, const GatherTransport* transport,
                  const LobeEmission* emitted) {
    // `grid` answers every lookup but the stacked sheets' (searching, where
    // the pieces are only for those: RecordGrid::pieces_for_sheets)
    RecordGrid searching = pieces;
    if (pieces.pieces_for_sheets) searching.piece_first = nullptr;
    const RecordGrid& grid = searching;
    const uint64_t base = gather_base(seed, frame);
    const int64_t P = hits.count;
    if (n_gather <= 0) {
        *rays = 0;
        return;
    }
    // A gather ray's light waits on two dependent loads from tables larger
    // than the caches: its voxel's entry in the cell table, then the record
    // rows that entry points at. Each pixel therefore goes through three
    // stages a pixel apart: trace its rays and prefetch their voxels'
    // entries; read the entries and prefetch the rows; look up and shade. A
    // pixel's own rays are traced between one stage and the next, so the
    // loads arrive in their shadow.
    constexpr int64_t kStages = 3;
    // a voxel holds a record or two (both sides, two objects at a seam)
    constexpr int64_t kRowsAhead = 3;
    *rays = sum_over_pixel_chunks(P, threads, stop, [&](int64_t p0, int64_t p1) {
        std::vector<GatherHit> ring(size_t(kStages * n_gather));
        LookupScratch scratch;
        auto slot = [&](int64_t p) { return ring.data() + (p % kStages) * n_gather; };
        auto shaded = [&](int64_t p) { return p >= p0 && p < p1 && hits.material[p] >= 0; };
        int64_t n_traced = 0;
        for (int64_t p = p0; p < p1 + kStages - 1; ++p) {
            if (shaded(p)) {
                GatherHit* h = slot(p);
                gather_pixel_rays(hits, mats, n_gather, base, eps, p,
                                  [&](int k, const float* ro, const float* rd) {
                                      if (!rd) {  // a lobe sample below the surface
                                          h[k].key = -2;
                                          h[k].escaped = false;
                                          return;
                                      }
                                      float T[3];
                                      const int32_t t =
                                          scene.intersect(ro, rd, nullptr, nullptr, nullptr, T);
                                      gather_hit(hits, tris, grid, p, ro, rd, t, h[k]);
                                      for (int ch = 0; ch < 3; ++ch) h[k].through[ch] = T[ch];
                                      if (h[k].key >= 0 && grid.cell_start)
                                          __builtin_prefetch(grid.cell_start + h[k].key);
                                  });
                n_traced += n_gather;
            }
            if (shaded(p - 1) && grid.cell_start) {
                const GatherHit* h = slot(p - 1);
                for (int k = 0; k < n_gather; ++k) {
                    if (h[k].key < 0) continue;
                    const int64_t first = grid.cell_start[h[k].key],
                                  end = grid.cell_start[h[k].key + 1];
                    for (int64_t row = first; row < std::min(end, first + kRowsAhead); ++row)
                        __builtin_prefetch(grid.rec + row);
                }
            }
            if (shaded(p - 2)) {
                const GatherHit* h = slot(p - 2);
                double s[3] = {0.0, 0.0, 0.0};        // in ray order: the same for any thread count
                double se_lobe[3] = {0.0, 0.0, 0.0};  // emitters seen in lobes (emitted)
                for (int k = 0; k < n_gather; ++k) {
                    if (transport) record_transport(*transport, int64_t(n_gather) * (p - 2) + k);
                    if (h[k].key == -2) continue;
                    int64_t rec = lookup_in_cell(grid, h[k].y, h[k].ns, h[k].obj, h[k].c, h[k].tri,
                                                 h[k].front, scratch);
                    const bool lobe = rec >= 0 && continues(mats, hits.material[p - 2], h[k]);
                    bool sheet = false;
                    const bool may_be_sheet =
                        !pieces.pieces_for_sheets ||
                        (h[k].obj >= 0 && h[k].obj < pieces.stacked_object_count &&
                         pieces.stacked_objects[h[k].obj]);
                    if (!lobe && rec >= 0 && grid.stacked && may_be_sheet) {
                        // a stacked sheet is told by the piece the ray landed on
                        const int64_t at =
                            pieces.pieces_for_sheets
                                ? lookup_in_cell(pieces, h[k].y, h[k].ns, h[k].obj, h[k].c,
                                                 h[k].tri, h[k].front, scratch)
                                : rec;
                        sheet = at >= 0 && grid.stacked[at];
                        if (sheet) rec = at;
                    }
                    if (lobe || sheet) {
                        float ratio[3] = {1.f, 1.f, 1.f};
                        const MicrofacetLobe* hl =
                            mats.hit_lobe ? mats.hit_lobe + h[k].obj : nullptr;
                        if (h[k].textured)
                            for (int ch = 0; ch < 3; ++ch)
                                if (grid.rec[rec].albedo[ch] > 0.f)
                                    ratio[ch] = solve_albedo(hl, h[k].tex[ch], ch) /
                                                grid.rec[rec].albedo[ch];
                        uint64_t rng = splitmix64(base ^ 0x9E3779B97F4A7C15ull ^
                                                  (uint64_t(p - 2) * uint64_t(n_gather) + k));
                        float L[3] = {0.f, 0.f, 0.f}, coat[3] = {0.f, 0.f, 0.f};
                        double factor[3], w[3];
                        int64_t q;
                        if (lobe) {
                            q = glossy_hit_radiance(mats, tris, grid, env, scene, eps, h[k], rec,
                                                    ratio, rng, scratch, L, coat, factor);
                        } else {
                            // the light leaving the sheet's point, which its
                            // VPLs carry too (sheet_radiance): MIS-shared
                            double light[3];
                            q = follow_sheet(tris, pieces, scene, eps, h[k], rec, ratio, rng,
                                             scratch, factor, light, &n_traced);
                            for (int ch = 0; ch < 3; ++ch) L[ch] = float(light[ch]);
                        }
                        gather_hit_light(hits, mats, mis, grid, p - 2, h[k], rec, s, L, coat);
                        if (q >= 0 && (transport || emitted) &&
                            followed_weight(hits, mats, mis, grid, p - 2, h[k], rec, factor, w)) {
                            const int64_t r = int64_t(n_gather) * (p - 2) + k;
                            if (transport) transport->record[r] = int32_t(q);
                            for (int ch = 0; ch < 3; ++ch) {
                                if (transport) transport->weight[3 * r + ch] = float(w[ch]);
                                if (emitted) se_lobe[ch] += w[ch] * emitted->radiance[3 * q + ch];
                            }
                        }
                        continue;
                    }
                    if (rec >= 0 && !transport && continues_near(hits, mats, tris, p - 2, h[k])) {
                        uint64_t rng = splitmix64(base ^ 0xC2B2AE3D27D4EB4Full ^
                                                  (uint64_t(p - 2) * uint64_t(n_gather) + k));
                        float L[3];
                        n_traced += near_hit_radiance(mats, tris, grid, env, scene, eps, h[k], rng,
                                                      scratch, L);
                        const float none[3] = {0.f, 0.f, 0.f};
                        gather_hit_light(hits, mats, mis, grid, p - 2, h[k], rec, s, L, none);
                        continue;
                    }
                    gather_hit_light(hits, mats, mis, grid, p - 2, h[k], rec, s);
                    if (transport)
                        gather_hit_weight(hits, mats, mis, grid, p - 2, h[k], rec, *transport,
                                          int64_t(n_gather) * (p - 2) + k);
                }
                for (int ch = 0; ch < 3; ++ch) out[3 * (p - 2) + ch] += float(s[ch]);
                if (emitted)
                    for (int ch = 0; ch < 3; ++ch)
                        emitted->out[3 * (p - 2) + ch] += float(se_lobe[ch]);
                if (env) {
                    float se[3] = {0.f, 0.f, 0.f};
                    for (int k = 0; k < n_gather; ++k)
                        if (h[k].escaped)
                            gather_escape_light(hits, mats, mis, *env, p - 2, h[k], se);
                    for (int ch = 0; ch < 3; ++ch) out[3 * (p - 2) + ch] += se[ch];
                }
            }
        }
        return n_traced;
    });
}

void sheet_radiance(const ShadeTriangles& tris, const RecordGrid& grid, const RayScene& scene,
                    double eps, const SheetPoints& at, int walks, uint64_t seed, int64_t frame,
                    float* out, int64_t* rays, int threads, const StopCheck& stop) {
    const uint64_t base = gather_base(seed, frame) ^ 0x94D049BB133111EBull;
    *rays = sum_over_pixel_chunks(at.count, threads, stop, [&](int64_t i0, int64_t i1) {
        LookupScratch scratch;
        int64_t traced = 0;
        for (int64_t i = i0; i < i1; ++i) {
            GatherHit h{};
            for (int a = 0; a < 3; ++a) h.y[a] = at.pos[3 * i + a], h.ns[a] = at.normal[3 * i + a];
            const int64_t rec = at.record[i];
            h.obj = grid.rec[rec].object;
            double sum[3] = {0.0, 0.0, 0.0};
            const float ratio[3] = {1.f, 1.f, 1.f};
            for (int w = 0; w < walks; ++w) {
                uint64_t rng = splitmix64(base ^ (uint64_t(i) * uint64_t(walks) + uint64_t(w)));
                double factor[3], light[3];
                follow_sheet(tris, grid, scene, eps, h, rec, ratio, rng, scratch, factor, light,
                             &traced);
                for (int ch = 0; ch < 3; ++ch) sum[ch] += light[ch];
            }
            for (int ch = 0; ch < 3; ++ch) out[3 * i + ch] = float(sum[ch] / walks);
        }
        return traced;
    });
}

void primary_hit(const double o[3], const double d[3], int32_t t, const PrimaryScene& scene,
                 double x[3], float ns_out[3], float ng_out[3], int32_t* material, float le[3]) {
    for (int c = 0; c < 3; ++c) x[c] = 0.0, ns_out[c] = ng_out[c] = le[c] = 0.f;
    *material = -1;
    if (t < 0) return;
    {
        const double* g = scene.ng + 3 * int64_t(t);
        const double* v0 = scene.v + 9 * int64_t(t);
        // The exact point on the triangle's plane: Embree's distance is float32.
        const double dn = d[0] * g[0] + d[1] * g[1] + d[2] * g[2];
        double tt = ((v0[0] - o[0]) * g[0] + (v0[1] - o[1]) * g[1] + (v0[2] - o[2]) * g[2]) / dn;
        if (!std::isfinite(tt)) tt = 0.0;
        for (int c = 0; c < 3; ++c) x[c] = o[c] + tt * d[c];
        const bool front = dn < 0.0;
        const double sgn = front ? 1.0 : -1.0;
        double n[3] = {g[0] * sgn, g[1] * sgn, g[2] * sgn};
        for (int c = 0; c < 3; ++c) ng_out[c] = float(n[c]);
        if (scene.corner_normals) {
            // Barycentric weights of x, interpolating the corner normals.
            const double *v1 = v0 + 3, *v2 = v0 + 6;
            const double e1[3] = {v1[0] - v0[0], v1[1] - v0[1], v1[2] - v0[2]};
            const double e2[3] = {v2[0] - v0[0], v2[1] - v0[1], v2[2] - v0[2]};
            const double q[3] = {x[0] - v0[0], x[1] - v0[1], x[2] - v0[2]};
            auto cross = [](const double* a, const double* b, double* r) {
                r[0] = a[1] * b[2] - a[2] * b[1];
                r[1] = a[2] * b[0] - a[0] * b[2];
                r[2] = a[0] * b[1] - a[1] * b[0];
            };
            auto dot = [](const double* a, const double* b) {
                return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            };
            double nr[3], c1[3], c2[3];
            cross(e1, e2, nr);
            cross(q, e2, c1);
            cross(e1, q, c2);
            const double a2 = dot(nr, nr);
            const double b1 = dot(c1, nr) / a2, b2 = dot(c2, nr) / a2, b0 = 1.0 - b1 - b2;
            const double* vn = scene.corner_normals + 9 * int64_t(t);
            double s[3], len2 = 0.0;
            for (int c = 0; c < 3; ++c) {
                s[c] = (b0 * vn[c] + b1 * vn[3 + c] + b2 * vn[6 + c]) * sgn;
                len2 += s[c] * s[c];
            }
            const double len = std::max(std::sqrt(len2), 1e-300);
            for (int c = 0; c < 3; ++c) s[c] /= len;
            // an interpolated normal behind the surface falls back to the winding one
            if (dot(s, n) > 0.0)
                for (int c = 0; c < 3; ++c) n[c] = s[c];
        }
        for (int c = 0; c < 3; ++c) ns_out[c] = float(n[c]);
        const int32_t obj = scene.object[t];
        if (front || scene.two_sided[obj]) {
            *material = obj;
            for (int c = 0; c < 3; ++c) le[c] = scene.emission[3 * obj + c];
        }
    }
}

void light_accumulate(const ShadeHits& hits, const ShadeMaterials& mats, const int64_t* ray_count,
                      const float* ray_dir, const float* ray_weight, const uint8_t* occluded,
                      float* out, int threads, const StopCheck& stop) {
    const int64_t P = hits.count;
    const std::vector<int64_t> offset = ray_offsets(ray_count, P);
    for_each_pixel(P, threads, stop, [&](int64_t p) {
        const int32_t m = hits.material[p];
        if (m < 0 || m >= mats.count) return;
        const float *n = hits.normal + 3 * p, *ng = hits.ng + 3 * p, *wo = hits.wo + 3 * p;
        float sum[3] = {0.f, 0.f, 0.f};
        for (int64_t r = offset[p]; r < offset[p + 1]; ++r) {
            if (occluded && occluded[r]) continue;
            const float* wi = ray_dir + 3 * r;
            const float cos_x = dot3(n, wi);
            if (cos_x <= 0.f || dot3(ng, wi) <= 0.f) continue;
            float f[3];
            shade_brdf(mats, m, hit_albedo(hits, mats, p, m), n, wi, wo, f);
            for (int ch = 0; ch < 3; ++ch) sum[ch] += f[ch] * cos_x * ray_weight[3 * r + ch];
        }
        for (int ch = 0; ch < 3; ++ch) out[3 * p + ch] += sum[ch];
    });
}

}  // namespace voxgi
