#include "camera.h"

#include <cmath>

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

void camera_hits(const PixelCamera& cam, const double offset[2], const double lens[2],
                 const RayScene& scene, const PrimaryScene& triangles, double* pos, float* normal,
                 float* ng, float* wo, int32_t* material, float* emission, int32_t* prim,
                 float* through, int threads, const StopCheck& stop,
                 const SurfaceTextures* textures, const float* obj_albedo, float* albedo) {
    auto one_pixel = [&](int64_t p) {
        double o[3], d[3];
        camera_ray(cam, offset, lens, p, o, d);
        const float of[3] = {float(o[0]), float(o[1]), float(o[2])};
        const float df[3] = {float(d[0]), float(d[1]), float(d[2])};
        const int32_t t =
            scene.intersect(of, df, nullptr, nullptr, nullptr, through ? through + 3 * p : nullptr);
        prim[p] = t;
        primary_hit(o, d, t, triangles, pos + 3 * p, normal + 3 * p, ng + 3 * p, material + p,
                    emission + 3 * p);
        for (int c = 0; c < 3; ++c) wo[3 * p + c] = float(-d[c]);
        if (albedo)
            primary_albedo(triangles, textures, obj_albedo, t, pos + 3 * p, material[p],
                           albedo + 3 * p);
    };
    // 512 pixels a task: neighbouring, coherent rays
    for_each_chunked(cam.width * cam.height, 512, threads, stop, one_pixel);
}

void camera_emission(const PixelCamera& cam, const int64_t* pixels, int64_t count,
                     const double* samples, int64_t K, const RayScene& scene,
                     const PrimaryScene& triangles, float* emission, float* wo, int32_t* prim,
                     float* through, int threads, const StopCheck& stop) {
    auto one_sample = [&](int64_t i) {
        const double* s = samples + 4 * (i % K);
        double o[3], d[3], x[3];
        camera_ray(cam, s, s + 2, pixels[i / K], o, d);
        const float of[3] = {float(o[0]), float(o[1]), float(o[2])};
        const float df[3] = {float(d[0]), float(d[1]), float(d[2])};
        const int32_t t =
            scene.intersect(of, df, nullptr, nullptr, nullptr, through ? through + 3 * i : nullptr);
        prim[i] = t;
        float ns[3], ng[3];
        int32_t material;
        primary_hit(o, d, t, triangles, x, ns, ng, &material, emission + 3 * i);
        for (int c = 0; c < 3; ++c) wo[3 * i + c] = float(-d[c]);
    };
    // a pixel's samples are consecutive: coherent rays in a task
    for_each_chunked(count * K, 512, threads, stop, one_sample);
}

}  // namespace voxgi
