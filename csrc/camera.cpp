#include "camera.h"

#include <cmath>

#include "util/random.h"

namespace voxgi {

void camera_ray(const PixelCamera& cam, const double offset[2], const double lens[2], int64_t p,
                double org[3], double dir[3]) {
    const int64_t i = p / cam.width, j = p % cam.width;
    const double aspect = double(cam.width) / double(cam.height);
    const double sx =
        (2.0 * (double(j) + offset[0]) / double(cam.width) - 1.0) * cam.tan_half_fov * aspect;
    const double sy = (1.0 - 2.0 * (double(i) + offset[1]) / double(cam.height)) * cam.tan_half_fov;
    double d[3];
    for (int c = 0; c < 3; ++c) d[c] = cam.forward[c] + sx * cam.right[c] + sy * cam.up[c];
    if (cam.aperture > 0.0) {
        // d·forward = 1, so eye + focus·d lies on the plane in focus
        for (int c = 0; c < 3; ++c) {
            org[c] = cam.eye[c] + cam.aperture * (lens[0] * cam.right[c] + lens[1] * cam.up[c]);
            d[c] = cam.eye[c] + cam.focus * d[c] - org[c];
        }
    } else {
        for (int c = 0; c < 3; ++c) org[c] = cam.eye[c];
    }
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int c = 0; c < 3; ++c) dir[c] = d[c] / len;
}

void camera_rays(const PixelCamera& cam, const double offset[2], const double lens[2], double* org,
                 double* dir, int threads, const StopCheck& stop) {
    for_each_chunked(cam.width * cam.height, 512, threads, stop, [&](int64_t p) {
        camera_ray(cam, offset, lens, p, org + 3 * p, dir + 3 * p);
    });
}

// The diffuse albedo of a primary hit at x on triangle t of object m (-1:
// not shaded, 0).
static void primary_albedo(const PrimaryScene& triangles, const SurfaceTextures* textures,
                           const float* obj_albedo, int32_t t, const double x[3], int32_t m,
                           float out[3]) {
    for (int c = 0; c < 3; ++c) out[c] = 0.f;
    if (m < 0) return;
    if (textures) {
        const double* v0 = triangles.v + 9 * int64_t(t);
        double b1, b2;
        barycentric(v0, v0 + 3, v0 + 6, x, b1, b2);
        if (surface_albedo(*textures, t, m, b1, b2, out)) return;
    }
    for (int c = 0; c < 3; ++c) out[c] = obj_albedo[3 * m + c];
}

namespace {

inline double dot3d(const float* a, const float* b) {
    return double(a[0]) * b[0] + double(a[1]) * b[1] + double(a[2]) * b[2];
}

// The hit (triangle t, point x, normals ns and ng, material m, emission le)
// of a ray going along d, continued through the mirrors (CameraMirrors) it
// meets: each link a direction drawn from the mirror's lobe, T (3) times its
// f cos / pdf and the sheets' transmittance on the way. The first link's
// direction comes from u0 in [0, 1)², the others' from `stream`, the ray's
// own random stream. Returns the triangle of the hit it ends on.
int32_t follow_mirrors(const CameraMirrors& M, const RayScene& scene, const PrimaryScene& triangles,
                       const double u0[2], uint64_t stream, double d[3], int32_t t, double x[3],
                       float ns[3], float ng[3], int32_t& m, float le[3], float T[3]) {
    for (int link = 0; link < M.max_links && m >= 0 && M.is_mirror[m]; ++link) {
        const float wo[3] = {float(-d[0]), float(-d[1]), float(-d[2])};
        const MicrofacetLobe& lobe = M.lobe[m];
        const double u1 = link ? to_unit(splitmix64(stream + 2 * uint64_t(link))) : u0[0];
        const double u2 = link ? to_unit(splitmix64(stream + 2 * uint64_t(link) + 1)) : u0[1];
        float wi[3], f[3];
        double weight = 0.0;
        if (microfacet_sample(lobe, ns, wo, u1, u2, wi) && dot3d(ng, wi) > 0.0) {
            const double pdf = microfacet_pdf(lobe, ns, wo, wi);
            microfacet_brdf(lobe, nullptr, ns, wi, wo, f);
            if (pdf > 0.0 && std::isfinite(pdf)) weight = dot3d(ns, wi) / pdf;
        }
        if (!(weight > 0.0)) {
            // nothing reflected this way: the ray ends dark on the mirror
            m = -1;
            for (int c = 0; c < 3; ++c) le[c] = 0.f, T[c] = 0.f;
            return t;
        }
        for (int c = 0; c < 3; ++c) T[c] = float(T[c] * f[c] * weight);
        double o[3];
        float of[3], seg[3];
        for (int c = 0; c < 3; ++c) {
            o[c] = x[c] + M.eps * ng[c];
            of[c] = float(o[c]);
            d[c] = wi[c];
        }
        const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        for (int c = 0; c < 3; ++c) d[c] /= len;
        t = scene.intersect(of, wi, nullptr, nullptr, nullptr, seg);
        for (int c = 0; c < 3; ++c) T[c] *= seg[c];
        primary_hit(o, d, t, triangles, x, ns, ng, &m, le);
    }
    return t;
}

// The random stream of camera ray `index` through the mirrors.
inline uint64_t mirror_stream(const CameraMirrors& M, int64_t index) {
    return splitmix64(M.seed ^ splitmix64(uint64_t(index))) * 0x9E3779B97F4A7C15ull;
}

// The first link's numbers: `point` rotated by the ray's own offset
// (Cranley-Patterson), so that a pixel's links over the frames stay as
// evenly spread as the frames' points, and neighbours' errors are not tied.
inline void first_link(const double point[2], uint64_t stream, double u0[2]) {
    for (int a = 0; a < 2; ++a) {
        const double u = point[a] + to_unit(splitmix64(stream ^ (0xA5A5ull + uint64_t(a))));
        u0[a] = u - std::floor(u);
        if (u0[a] >= 1.0) u0[a] = 0.0;
    }
}

}  // namespace

void camera_hits(const PixelCamera& cam, const double offset[2], const double lens[2],
                 const RayScene& scene, const PrimaryScene& triangles, double* pos, float* normal,
                 float* ng, float* wo, int32_t* material, float* emission, int32_t* prim,
                 float* through, int threads, const StopCheck& stop,
                 const SurfaceTextures* textures, const float* obj_albedo, float* albedo,
                 const CameraMirrors* mirrors) {
    auto one_pixel = [&](int64_t p) {
        double o[3], d[3];
        camera_ray(cam, offset, lens, p, o, d);
        const float of[3] = {float(o[0]), float(o[1]), float(o[2])};
        const float df[3] = {float(d[0]), float(d[1]), float(d[2])};
        int32_t t =
            scene.intersect(of, df, nullptr, nullptr, nullptr, through ? through + 3 * p : nullptr);
        primary_hit(o, d, t, triangles, pos + 3 * p, normal + 3 * p, ng + 3 * p, material + p,
                    emission + 3 * p);
        if (mirrors) {
            const uint64_t stream = mirror_stream(*mirrors, p);
            double u0[2];
            first_link(mirrors->point, stream, u0);
            t = follow_mirrors(*mirrors, scene, triangles, u0, stream, d, t, pos + 3 * p,
                               normal + 3 * p, ng + 3 * p, material[p], emission + 3 * p,
                               through + 3 * p);
        }
        prim[p] = t;
        for (int c = 0; c < 3; ++c) wo[3 * p + c] = float(-d[c]);
        if (albedo)
            primary_albedo(triangles, textures, obj_albedo, t, pos + 3 * p, material[p],
                           albedo + 3 * p);
    };
    // 512 pixels a task: neighbouring, coherent rays
    for_each_chunked(cam.width * cam.height, 512, threads, stop, one_pixel);
}

void camera_emission(const PixelCamera& cam, const int64_t* pixels, int64_t count,
                     const double* samples, int64_t K, int width, const RayScene& scene,
                     const PrimaryScene& triangles, float* emission, float* wo, int32_t* prim,
                     float* through, int threads, const StopCheck& stop,
                     const CameraMirrors* mirrors) {
    auto one_sample = [&](int64_t i) {
        const double* s = samples + width * (i % K);
        double o[3], d[3], x[3];
        camera_ray(cam, s, s + 2, pixels[i / K], o, d);
        const float of[3] = {float(o[0]), float(o[1]), float(o[2])};
        const float df[3] = {float(d[0]), float(d[1]), float(d[2])};
        int32_t t =
            scene.intersect(of, df, nullptr, nullptr, nullptr, through ? through + 3 * i : nullptr);
        float ns[3], ng[3];
        int32_t material;
        primary_hit(o, d, t, triangles, x, ns, ng, &material, emission + 3 * i);
        if (mirrors) {
            const uint64_t stream = mirror_stream(*mirrors, i);
            double u0[2] = {to_unit(splitmix64(stream ^ 0xA5A5ull)),
                            to_unit(splitmix64(stream ^ 0xA5A6ull))};
            if (width == 6) first_link(s + 4, mirrors->seed ^ uint64_t(pixels[i / K]), u0);
            t = follow_mirrors(*mirrors, scene, triangles, u0, stream, d, t, x, ns, ng, material,
                               emission + 3 * i, through + 3 * i);
        }
        prim[i] = t;
        for (int c = 0; c < 3; ++c) wo[3 * i + c] = float(-d[c]);
    };
    // a pixel's samples are consecutive: coherent rays in a task
    for_each_chunked(count * K, 512, threads, stop, one_sample);
}

}  // namespace voxgi
