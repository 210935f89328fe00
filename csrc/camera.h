// Camera rays of the display (docs/design.md §6), made, traced and turned
// into hit points pixel by pixel, without ray arrays.
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>

#include "microfacet.h"
#include "ray_scene.h"
#include "texture.h"
#include "util/parallel.h"
#include "vpl_shade.h"

namespace voxgi {

// A pinhole or thin-lens camera over a width x height image, in the frame
// of the ray scene (eye already moved by the scene's centre).
struct PixelCamera {
    double eye[3] = {0.0, 0.0, 0.0};
    double right[3] = {1.0, 0.0, 0.0};
    double up[3] = {0.0, 1.0, 0.0};
    double forward[3] = {0.0, 0.0, 1.0};
    double tan_half_fov = 1.0;  // tan(fov / 2), fov vertical
    int64_t width = 1;
    int64_t height = 1;
    double aperture = 0.0;  // lens radius; 0: pinhole
    double focus = 1.0;     // distance of the plane in focus along forward
};

// Origin and unit direction of pixel p's ray (row-major from the top-left
// pixel) through sub-pixel position `offset` in [0, 1)^2 (x right, y down)
// and lens point `lens` on the unit disc.
void camera_ray(const PixelCamera& cam, const double offset[2], const double lens[2], int64_t p,
                double org[3], double dir[3]);

// camera_ray for every pixel: org, dir (P, 3), P = width * height.
void camera_rays(const PixelCamera& cam, const double offset[2], const double lens[2], double* org,
                 double* dir, int threads, const StopCheck& stop);

// The smooth mirrors a camera ray continues through (docs/design.md §6):
// per object, whether it is one and its lobe (a conductor's). A pixel's hit
// on a mirror becomes the surface seen in it: one direction drawn from the
// lobe about the way back (microfacet_sample: the first from `point`
// rotated by a hash of `seed` and the ray's index, the next from a stream
// of that hash), traced `eps` off the mirror, and `through`
// multiplied by the lobe's f cos / pdf there; up to `max_links` mirrors in
// turn. A direction below the mirror's geometric plane ends the ray dark.
struct CameraMirrors {
    const uint8_t* is_mirror = nullptr;    // (O,)
    const MicrofacetLobe* lobe = nullptr;  // (O,) rows; read only where is_mirror
    uint64_t seed = 0;
    double point[2] = {0.5, 0.5};  // the frame's numbers of the first link (camera_hits)
    double eps = 0.0;
    int max_links = 4;
};

// Every pixel's camera ray, its first hit in `scene` and primary_hit on it:
// pos (P, 3), normal, ng, wo (the unit direction back to the eye) (P, 3),
// material (P,), emission (P, 3) and the hit triangle prim (P,) (-1: none),
// P = width * height; `through` (P, 3) or null: the product of the sheets'
// transmittances before the hit (RayScene::intersect). With `albedo` (P, 3)
// (nullable), also each hit's diffuse albedo: its object's `obj_albedo`
// (O, 3), or its texture at the hit point where `textures` (nullable) gives
// the object one; 0 where nothing is shaded. With `mirrors` (nullable;
// `through` must then be given), the ray goes on through mirrors and every
// output is that of the hit it ends on (wo: the way back along the last
// link), `through` including the mirrors' reflectance.
void camera_hits(const PixelCamera& cam, const double offset[2], const double lens[2],
                 const RayScene& scene, const PrimaryScene& triangles, double* pos, float* normal,
                 float* ng, float* wo, int32_t* material, float* emission, int32_t* prim,
                 float* through, int threads, const StopCheck& stop,
                 const SurfaceTextures* textures = nullptr, const float* obj_albedo = nullptr,
                 float* albedo = nullptr, const CameraMirrors* mirrors = nullptr);

// The emission seen by camera samples (offset, lens) through chosen pixels,
// for the display's control variate on emitters seen directly (docs/design.md
// §6): for pixel pixels[m] and sample k (samples (K, 4): sub-pixel offset in
// [0, 1)^2, then the lens point on the unit disc; `width` 6: then the first
// mirror link's numbers in [0, 1)^2, else 4), at index m * K + k, the
// emission of the first hit (primary_hit's; 0 on a miss or a one-sided
// back), wo (the unit direction back to the eye, which finds the
// environment on a miss), the hit triangle prim (-1: none) and, where
// `through` is not null, what the sheets before the hit let through. With
// `mirrors` (nullable; `through` must then be given), as camera_hits.
void camera_emission(const PixelCamera& cam, const int64_t* pixels, int64_t count,
                     const double* samples, int64_t K, int width, const RayScene& scene,
                     const PrimaryScene& triangles, float* emission, float* wo, int32_t* prim,
                     float* through, int threads, const StopCheck& stop,
                     const CameraMirrors* mirrors = nullptr);

}  // namespace voxgi
