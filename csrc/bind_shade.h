// pybind11 checks shared by the bindings of the display's shading kernels:
// materials, primary hits, the MIS weights and per-pixel ray counts.
#pragma once

#include <cmath>
#include <limits>
#include <string>

#include "bind_common.h"
#include "ray_scene.h"
#include "vpl_shade.h"

namespace voxgi::py_helpers {

inline voxgi::ShadeMaterials materials(const F32& albedo, const F32& rs, const F32& nu,
                                       const F32& nv, const U8& glossy) {
    check_2d(albedo, -1, 3, "mat_albedo");
    const py::ssize_t m = albedo.shape(0);
    check_2d(rs, m, 3, "mat_rs");
    check_1d(nu, m, "mat_nu");
    check_1d(nv, m, "mat_nv");
    check_1d(glossy, m, "mat_glossy");
    voxgi::ShadeMaterials s;
    s.count = m;
    s.albedo = albedo.data();
    s.rs = rs.data();
    s.nu = nu.data();
    s.nv = nv.data();
    s.glossy = glossy.data();
    return s;
}

inline voxgi::ShadeMIS make_mis(double n_gather) {
    if (!(n_gather >= 0.0) || !std::isfinite(n_gather))
        throw py::value_error("n_gather must be finite and >= 0");
    voxgi::ShadeMIS mis;
    mis.n_gather = n_gather;
    return mis;
}

inline voxgi::ShadeHits make_hits(const F64& hit_pos, const F32& hit_normal, const F32& hit_ng,
                                  const F32& hit_wo, const I32& hit_material, py::ssize_t n_mat) {
    check_2d(hit_pos, -1, 3, "hit_pos");
    const py::ssize_t P = hit_pos.shape(0);
    check_2d(hit_normal, P, 3, "hit_normal");
    check_2d(hit_ng, P, 3, "hit_ng");
    check_2d(hit_wo, P, 3, "hit_wo");
    check_1d(hit_material, P, "hit_material");
    const int32_t* mi = hit_material.data();
    for (py::ssize_t p = 0; p < P; ++p)
        if (mi[p] >= n_mat)
            throw py::value_error("hit_material: index " + std::to_string(mi[p]) +
                                  " out of range (" + std::to_string(n_mat) + " materials)");
    voxgi::ShadeHits hits;
    hits.count = P;
    hits.pos = hit_pos.data();
    hits.normal = hit_normal.data();
    hits.ng = hit_ng.data();
    hits.wo = hit_wo.data();
    hits.material = hit_material.data();
    return hits;
}

// ray_count (P,): each pixel's rays, non-negative and summing to all `rays`.
inline void check_ray_counts(const I64& ray_count, py::ssize_t rays) {
    const int64_t* pc = ray_count.data();
    int64_t total = 0;
    for (py::ssize_t p = 0; p < ray_count.shape(0); ++p) {
        if (pc[p] < 0) throw py::value_error("ray_count: negative count");
        total += pc[p];
    }
    if (total != rays)
        throw py::value_error("ray_count sums to " + std::to_string(total) + ", expected " +
                              std::to_string(rays) + " rays");
}

// The triangles must be those `scene` was built from, for prim to index them.
inline void check_scene(const voxgi::RayScene& scene, int64_t triangles) {
    if (scene.triangle_count() != triangles)
        throw py::value_error("scene holds " + std::to_string(scene.triangle_count()) +
                              " triangles, tri_v " + std::to_string(triangles));
}

}  // namespace voxgi::py_helpers
