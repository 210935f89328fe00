// pybind11 checks shared by the bindings of the display's shading kernels:
// materials, primary hits, the MIS weights and per-pixel ray counts.
#pragma once

#include <pybind11/stl.h>

#include <cmath>
#include <limits>
#include <optional>
#include <string>

#include "bind_common.h"
#include "ray_scene.h"
#include "vpl_shade.h"

namespace voxgi::py_helpers {

// (rows, kLobeWidth) float32 rows of voxgi.materials.Microfacet.lobe_row, checked.
inline const voxgi::MicrofacetLobe* lobe_rows(const F32& lobe, py::ssize_t rows, const char* name) {
    check_2d(lobe, rows, voxgi::kLobeWidth, name);
    const auto* rows_in = reinterpret_cast<const voxgi::MicrofacetLobe*>(lobe.data());
    for (py::ssize_t i = 0; i < lobe.shape(0); ++i) {
        const voxgi::MicrofacetLobe& L = rows_in[i];
        if (L.kind == 0.f) continue;
        if (!(L.kind == 1.f || L.kind == 2.f) || !(L.alpha >= 1e-4f && L.alpha <= 4.f) ||
            !(L.lobe_share >= 0.f && L.lobe_share <= 1.f) || !(L.eta > 0.f))
            throw py::value_error(std::string(name) + ": row " + std::to_string(i) +
                                  " is not a lobe (kind 1 or 2, alpha in [1e-4, 4], "
                                  "lobe_share in [0, 1], eta > 0)");
    }
    return rows_in;
}

// The materials, one per object as the display's kernels take them: the
// lobes gather rays land on are then the same rows (ShadeMaterials::hit_lobe).
inline voxgi::ShadeMaterials materials(const F32& albedo, const F32& rs, const F32& nu,
                                       const F32& nv, const U8& glossy,
                                       const std::optional<F32>& lobe = std::nullopt) {
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
    if (lobe) {
        s.lobe = lobe_rows(*lobe, m, "mat_lobe");
        s.hit_lobe = s.lobe;
        s.hit_count = m;
    }
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

// Each hit's own diffuse albedo (a texture's), when given: (P, 3).
inline void set_hit_albedo(voxgi::ShadeHits& hits, const std::optional<F32>& hit_albedo) {
    if (!hit_albedo) return;
    check_2d(*hit_albedo, hits.count, 3, "hit_albedo");
    hits.albedo = hit_albedo->data();
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

// The environment of escaped gather rays: all four tables, or none.
// The guide on an environment of these tables (checked to be its size).
inline void attach_guide(voxgi::EnvironmentMap& env, const voxgi::EnvironmentGuide* guide) {
    if (!guide) return;
    if (guide->width != env.width || guide->height != env.height)
        throw py::value_error("env_guide was made for an environment of another size");
    env.guide = guide;
}

inline std::optional<voxgi::EnvironmentMap> make_environment(
    const std::optional<F64>& radiance, const std::optional<F64>& to_world,
    const std::optional<F64>& texel_pdf, const std::optional<F64>& row_solid_angle, double samples,
    const F64* texel_cdf = nullptr, const F64* row_cos = nullptr) {
    const int given = int(radiance.has_value()) + int(to_world.has_value()) +
                      int(texel_pdf.has_value()) + int(row_solid_angle.has_value());
    if (given == 0) return std::nullopt;
    if (given != 4)
        throw py::value_error(
            "env_radiance, env_to_world, env_texel_pdf and env_row_solid_angle go together");
    if (radiance->ndim() != 3 || radiance->shape(2) != 3 || radiance->shape(0) < 1 ||
        radiance->shape(1) < 1)
        throw py::value_error("env_radiance must have shape (H, W, 3)");
    const py::ssize_t H = radiance->shape(0), W = radiance->shape(1);
    check_2d(*to_world, 3, 3, "env_to_world");
    check_1d(*texel_pdf, H * W, "env_texel_pdf");
    check_1d(*row_solid_angle, H, "env_row_solid_angle");
    const double* omega = row_solid_angle->data();
    for (py::ssize_t r = 0; r < H; ++r)
        if (!(omega[r] > 0.0) || !std::isfinite(omega[r]))
            throw py::value_error("env_row_solid_angle must be finite and > 0");
    const double* pdf = texel_pdf->data();
    for (py::ssize_t i = 0; i < H * W; ++i)
        if (!(pdf[i] >= 0.0) || !std::isfinite(pdf[i]))
            throw py::value_error("env_texel_pdf must be finite and >= 0");
    for (int i = 0; i < 9; ++i)
        if (!std::isfinite(to_world->data()[i]))
            throw py::value_error("env_to_world must be finite");
    if (!(samples >= 0.0) || !std::isfinite(samples))
        throw py::value_error("env_samples must be finite and >= 0");
    voxgi::EnvironmentMap env;
    if (texel_cdf) {
        check_1d(*texel_cdf, H * W, "env_texel_cdf");
        const double* c = texel_cdf->data();
        for (py::ssize_t i = 0; i < H * W; ++i)
            if (!(c[i] >= (i ? c[i - 1] : 0.0)) || !(c[i] <= 1.0))
                throw py::value_error("env_texel_cdf must ascend within [0, 1]");
        env.texel_cdf = c;
    }
    if (row_cos) {
        check_1d(*row_cos, H + 1, "env_row_cos");
        const double* c = row_cos->data();
        for (py::ssize_t r = 0; r <= H; ++r)
            if (!(c[r] >= -1.0 && c[r] <= 1.0))
                throw py::value_error("env_row_cos must be in [-1, 1]");
        env.row_cos = c;
    }
    env.width = W;
    env.height = H;
    env.radiance = radiance->data();
    env.to_world = to_world->data();
    env.texel_pdf = pdf;
    env.row_solid_angle = omega;
    env.n_samples = samples;
    return env;
}

// The records' grid of the gather kernels (voxgi.traced.record_grid), checked.
voxgi::RecordGrid make_grid(const I64& rec_sorted_key, const I32& rec_cell_start,
                            const F32& rec_packed, const I64& grid_dims, const I64& grid_lo,
                            const F64& grid_origin, double pitch);

// The records of each triangle's pieces (voxgi.traced's piece table).
struct PieceArgs {
    std::optional<I64> first, key;
    std::optional<I32> record;
    std::optional<U32> side;
    std::optional<I64> plane_first;
    std::optional<F64> plane;
};

// Adds the pieces to grid, checked against it; all or none.
void attach_pieces(voxgi::RecordGrid& grid, const PieceArgs& pieces);

}  // namespace voxgi::py_helpers
