// pybind11 bindings for the display kernels (vpl_shade.h).
#include <pybind11/stl.h>

#include <cmath>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include "batch_error.h"
#include "bind_common.h"
#include "camera.h"
#include "pixel_filter.h"
#include "vpl_shade.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

voxgi::ShadeMaterials materials(const F32& albedo, const F32& rs, const F32& nu, const F32& nv,
                                const U8& glossy) {
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

voxgi::ShadeMIS make_mis(double n_gather) {
    if (!(n_gather >= 0.0) || !std::isfinite(n_gather))
        throw py::value_error("n_gather must be finite and >= 0");
    voxgi::ShadeMIS mis;
    mis.n_gather = n_gather;
    return mis;
}

voxgi::ShadeHits make_hits(const F64& hit_pos, const F32& hit_normal, const F32& hit_ng,
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

voxgi::ShadeVPLs make_vpls(const F64& vpl_pos, const F32& vpl_normal, const F32& vpl_weight,
                           const F32& vpl_area, const F32& vpl_pa, double n_gather) {
    check_2d(vpl_pos, -1, 3, "vpl_pos");
    const py::ssize_t K = vpl_pos.shape(0);
    check_2d(vpl_normal, K, 3, "vpl_normal");
    check_2d(vpl_weight, K, 3, "vpl_weight");
    check_1d(vpl_area, K, "vpl_area");
    check_1d(vpl_pa, K, "vpl_pa");
    const float* vp = vpl_pa.data();
    for (py::ssize_t k = 0; k < K; ++k) {
        if (!(vp[k] >= 0.f) || !std::isfinite(vp[k]))
            throw py::value_error("vpl_pa must be finite and >= 0");
        if (vp[k] > 0.f && !(n_gather > 0.0))
            throw py::value_error("vpl_pa: MIS VPLs need n_gather > 0");
    }
    voxgi::ShadeVPLs vpls;
    vpls.count = K;
    vpls.pos = vpl_pos.data();
    vpls.normal = vpl_normal.data();
    vpls.weight = vpl_weight.data();
    vpls.area = vpl_area.data();
    vpls.pa = vpl_pa.data();
    return vpls;
}

// ray_count (P,): each pixel's rays, non-negative and summing to all `rays`.
void check_ray_counts(const I64& ray_count, py::ssize_t rays) {
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

auto vpl_prepare_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                    F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy, F64 vpl_pos,
                    F32 vpl_normal, F32 vpl_weight, F32 vpl_area, F32 vpl_pa, double n_gather,
                    double eps, I64Out ray_count, F32Out ray_org, F32Out ray_dir, F32Out ray_len,
                    F32Out ray_contrib, int threads) {
    voxgi::ShadeMaterials mats = materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy);
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    const py::ssize_t P = hits.count;
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    voxgi::ShadeMIS mis = make_mis(n_gather);
    voxgi::ShadeVPLs vpls = make_vpls(vpl_pos, vpl_normal, vpl_weight, vpl_area, vpl_pa, n_gather);
    const py::ssize_t K = vpls.count;
    // Output buffers, reused across frames by the caller: room for P*K rays.
    check_1d(ray_count, P, "ray_count");
    check_2d(ray_org, -1, 3, "ray_org");
    const py::ssize_t cap = ray_org.shape(0);
    if (cap < P * K)
        throw py::value_error("ray buffers hold " + std::to_string(cap) + " rays, need " +
                              std::to_string(P * K));
    check_2d(ray_dir, cap, 3, "ray_dir");
    check_1d(ray_len, cap, "ray_len");
    check_2d(ray_contrib, cap, 3, "ray_contrib");
    check_inplace(ray_count, "ray_count");
    check_inplace(ray_org, "ray_org");
    check_inplace(ray_dir, "ray_dir");
    check_inplace(ray_len, "ray_len");
    check_inplace(ray_contrib, "ray_contrib");
    int64_t* pc = ray_count.mutable_data();
    float *po = ray_org.mutable_data(), *pd = ray_dir.mutable_data(), *pl = ray_len.mutable_data(),
          *pr = ray_contrib.mutable_data();
    auto stop = make_stop_check();
    int64_t n;
    {
        py::gil_scoped_release release;
        n = voxgi::vpl_prepare(hits, mats, vpls, mis, eps, pc, po, pd, pl, pr, threads, stop);
    }
    return n;
}

auto gather_rays_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                    int n_gather, uint64_t seed, int64_t frame, double eps, I64Out ray_count,
                    F32Out ray_org, F32Out ray_dir, int threads) {
    voxgi::ShadeHits hits = make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material,
                                      std::numeric_limits<int32_t>::max());
    const py::ssize_t P = hits.count;
    if (n_gather < 0 || n_gather > 4096) throw py::value_error("n_gather must be in [0, 4096]");
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    check_1d(ray_count, P, "ray_count");
    check_2d(ray_org, -1, 3, "ray_org");
    check_2d(ray_dir, ray_org.shape(0), 3, "ray_dir");
    if (ray_org.shape(0) < P * n_gather)
        throw py::value_error("ray buffers hold " + std::to_string(ray_org.shape(0)) +
                              " rays, need " + std::to_string(P * n_gather));
    check_inplace(ray_count, "ray_count");
    check_inplace(ray_org, "ray_org");
    check_inplace(ray_dir, "ray_dir");
    int64_t* pc = ray_count.mutable_data();
    float *po = ray_org.mutable_data(), *pd = ray_dir.mutable_data();
    auto stop = make_stop_check();
    int64_t n;
    {
        py::gil_scoped_release release;
        n = voxgi::gather_rays(hits, n_gather, seed, frame, eps, pc, po, pd, threads, stop);
    }
    return n;
}

voxgi::ShadeTriangles make_triangles(const F64& tri_v, const I32& tri_object,
                                     const U8& obj_two_sided) {
    if (tri_v.ndim() != 3 || tri_v.shape(1) != 3 || tri_v.shape(2) != 3)
        throw py::value_error("tri_v must have shape (F, 3, 3)");
    const py::ssize_t F = tri_v.shape(0);
    check_1d(tri_object, F, "tri_object");
    check_1d(obj_two_sided, -1, "obj_two_sided");
    const py::ssize_t O = obj_two_sided.shape(0);
    {
        const int32_t* to = tri_object.data();
        for (py::ssize_t f = 0; f < F; ++f)
            if (to[f] < 0 || to[f] >= O) throw py::value_error("tri_object: index out of range");
    }
    voxgi::ShadeTriangles tris;
    tris.count = F;
    tris.v = tri_v.data();
    tris.object = tri_object.data();
    tris.two_sided = obj_two_sided.data();
    return tris;
}

voxgi::RecordGrid make_grid(const I64& rec_sorted_key, const I32& rec_cell_start,
                            const F32& rec_packed, const I64& grid_dims, const I64& grid_lo,
                            const F64& grid_origin, double pitch) {
    check_1d(rec_sorted_key, -1, "rec_sorted_key");
    const py::ssize_t N = rec_sorted_key.shape(0);
    constexpr py::ssize_t kRow = sizeof(voxgi::PackedRecord) / sizeof(float);
    check_2d(rec_packed, N, kRow, "rec_packed");
    check_1d(grid_dims, 3, "grid_dims");
    check_1d(grid_lo, 3, "grid_lo");
    check_1d(grid_origin, 3, "grid_origin");
    if (!(pitch > 0.0) || !std::isfinite(pitch)) throw py::value_error("pitch must be > 0");
    {
        const int64_t* sk = rec_sorted_key.data();
        for (py::ssize_t i = 1; i < N; ++i)
            if (sk[i] < sk[i - 1]) throw py::value_error("rec_sorted_key must be ascending");
    }
    voxgi::RecordGrid grid;
    grid.count = N;
    grid.sorted_key = rec_sorted_key.data();
    // float rows of the layout of PackedRecord (its object field an int32's bits)
    grid.rec = reinterpret_cast<const voxgi::PackedRecord*>(rec_packed.data());
    for (int a = 0; a < 3; ++a) {
        grid.dims[a] = grid_dims.data()[a];
        grid.lo[a] = grid_lo.data()[a];
        grid.origin[a] = grid_origin.data()[a];
        if (grid.dims[a] < 1) throw py::value_error("grid_dims must be >= 1");
    }
    grid.pitch = pitch;
    // Optional dense table of each voxel key's first sorted record.
    check_1d(rec_cell_start, -1, "rec_cell_start");
    if (rec_cell_start.shape(0) > 0) {
        const int64_t cells = grid.dims[0] * grid.dims[1] * grid.dims[2];
        if (rec_cell_start.shape(0) != cells + 1)
            throw py::value_error("rec_cell_start must have dims product + 1 entries");
        const int32_t* cs = rec_cell_start.data();
        if (cs[0] != 0 || cs[cells] != N) throw py::value_error("rec_cell_start: bad bounds");
        for (int64_t c = 0; c < cells; ++c)
            if (cs[c + 1] < cs[c]) throw py::value_error("rec_cell_start must be ascending");
        grid.cell_start = cs;
    } else {
        const int64_t* sk = rec_sorted_key.data();
        if (N > 0 && (sk[0] < 0 || sk[N - 1] >= grid.dims[0] * grid.dims[1] * grid.dims[2]))
            throw py::value_error("rec_sorted_key: key outside the grid");
    }
    return grid;
}

auto gather_shade_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                     F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy,
                     double n_gather, F64 tri_v, I32 tri_object, U8 obj_two_sided,
                     I64 rec_sorted_key, I32 rec_cell_start, F32 rec_packed, I64 grid_dims,
                     I64 grid_lo, F64 grid_origin, double pitch, I64 ray_count, F32 ray_dir,
                     I32 prim, F32Out out, int threads) {
    voxgi::ShadeMaterials mats = materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy);
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    const py::ssize_t P = hits.count;
    voxgi::ShadeMIS mis = make_mis(n_gather);
    if (!(n_gather > 0.0)) throw py::value_error("n_gather must be > 0");
    voxgi::ShadeTriangles tris = make_triangles(tri_v, tri_object, obj_two_sided);
    voxgi::RecordGrid grid = make_grid(rec_sorted_key, rec_cell_start, rec_packed, grid_dims,
                                       grid_lo, grid_origin, pitch);
    check_1d(ray_count, P, "ray_count");
    check_2d(ray_dir, -1, 3, "ray_dir");
    const py::ssize_t R = ray_dir.shape(0);
    check_1d(prim, R, "prim");
    check_ray_counts(ray_count, R);
    check_2d(out, P, 3, "out");
    check_inplace(out, "out");
    const int64_t* pc = ray_count.data();
    const float* pd = ray_dir.data();
    const int32_t* pp = prim.data();
    float* po = out.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::gather_shade(hits, mats, mis, tris, grid, pc, pd, pp, po, threads, stop);
    }
}

// The triangles must be those `scene` was built from, for prim to index them.
void check_scene(const voxgi::RayScene& scene, int64_t triangles) {
    if (scene.triangle_count() != triangles)
        throw py::value_error("scene holds " + std::to_string(scene.triangle_count()) +
                              " triangles, tri_v " + std::to_string(triangles));
}

py::tuple vpl_light_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                       F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy,
                       F64 vpl_pos, F32 vpl_normal, F32 vpl_weight, F32 vpl_area, F32 vpl_pa,
                       double n_gather, double eps, const voxgi::RayScene& scene,
                       std::optional<I32> pixel_set, std::optional<I64> set_start, int threads) {
    voxgi::ShadeMaterials mats = materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy);
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    voxgi::ShadeMIS mis = make_mis(n_gather);
    voxgi::ShadeVPLs vpls = make_vpls(vpl_pos, vpl_normal, vpl_weight, vpl_area, vpl_pa, n_gather);
    if (pixel_set.has_value() != set_start.has_value())
        throw py::value_error("pixel_set and set_start go together");
    const int32_t* ps = nullptr;
    const int64_t* ss = nullptr;
    if (pixel_set) {
        check_1d(*set_start, -1, "set_start");
        const py::ssize_t S = set_start->shape(0) - 1;
        ss = set_start->data();
        if (S < 1 || ss[0] != 0 || ss[S] != vpls.count)
            throw py::value_error("set_start must run from 0 to the VPL count");
        for (py::ssize_t i = 0; i < S; ++i)
            if (ss[i + 1] < ss[i]) throw py::value_error("set_start must be ascending");
        check_1d(*pixel_set, hits.count, "pixel_set");
        ps = pixel_set->data();
        for (py::ssize_t p = 0; p < hits.count; ++p)
            if (ps[p] < 0 || ps[p] >= S)
                throw py::value_error("pixel_set: set " + std::to_string(ps[p]) +
                                      " out of range (" + std::to_string(S) + " sets)");
    }
    F32 out({hits.count, py::ssize_t(3)});
    float* po = out.mutable_data();
    int64_t rays = 0;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::vpl_light(hits, mats, vpls, mis, eps, ps, ss, scene, po, &rays, threads, stop);
    }
    return py::make_tuple(out, rays);
}

int64_t gather_light_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                        F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy,
                        int n_gather, uint64_t seed, int64_t frame, double eps, F64 tri_v,
                        I32 tri_object, U8 obj_two_sided, I64 rec_sorted_key, I32 rec_cell_start,
                        F32 rec_packed, I64 grid_dims, I64 grid_lo, F64 grid_origin, double pitch,
                        const voxgi::RayScene& scene, F32Out out, int threads) {
    voxgi::ShadeMaterials mats = materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy);
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    if (n_gather < 1 || n_gather > 4096) throw py::value_error("n_gather must be in [1, 4096]");
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    voxgi::ShadeMIS mis = make_mis(n_gather);
    voxgi::ShadeTriangles tris = make_triangles(tri_v, tri_object, obj_two_sided);
    check_scene(scene, tris.count);
    voxgi::RecordGrid grid = make_grid(rec_sorted_key, rec_cell_start, rec_packed, grid_dims,
                                       grid_lo, grid_origin, pitch);
    check_2d(out, hits.count, 3, "out");
    check_inplace(out, "out");
    float* po = out.mutable_data();
    int64_t rays = 0;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::gather_light(hits, mats, mis, n_gather, seed, frame, eps, tris, grid, scene, po,
                            &rays, threads, stop);
    }
    return rays;
}

void geometry_filter_py(F64 hit_pos, F32 hit_normal, I32 hit_material, U8 mat_glossy, F64 eye,
                        double pixel_angle, int64_t width, int64_t height, int radius,
                        F32 reflected, F32Out out, int threads) {
    if (width < 1 || height < 1) throw py::value_error("width and height must be >= 1");
    const py::ssize_t P = py::ssize_t(width * height);
    check_2d(hit_pos, P, 3, "hit_pos");
    check_2d(hit_normal, P, 3, "hit_normal");
    check_1d(hit_material, P, "hit_material");
    check_1d(mat_glossy, -1, "mat_glossy");
    check_1d(eye, 3, "eye");
    check_2d(reflected, P, 3, "reflected");
    check_2d(out, P, 3, "out");
    check_inplace(out, "out");
    if (radius < 0 || radius > 16) throw py::value_error("radius must be in [0, 16]");
    if (!(pixel_angle > 0.0) || !std::isfinite(pixel_angle))
        throw py::value_error("pixel_angle must be finite and > 0");
    voxgi::FilterPixels px;
    px.width = width;
    px.height = height;
    px.material = hit_material.data();
    px.normal = hit_normal.data();
    px.pos = hit_pos.data();
    px.glossy = mat_glossy.data();
    px.n_materials = int32_t(mat_glossy.shape(0));
    for (int a = 0; a < 3; ++a) px.eye[a] = eye.data()[a];
    px.pixel_angle = pixel_angle;
    const float* pin = reflected.data();
    float* po = out.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::geometry_filter(px, radius, pin, po, threads, stop);
    }
}

auto vpl_accumulate_py(I64 ray_count, F32 ray_contrib, U8 occluded, int threads) {
    check_1d(ray_count, -1, "ray_count");
    check_2d(ray_contrib, -1, 3, "ray_contrib");
    const py::ssize_t R = ray_contrib.shape(0), P = ray_count.shape(0);
    check_1d(occluded, R, "occluded");
    check_ray_counts(ray_count, R);
    const int64_t* pc = ray_count.data();
    F32 out({P, py::ssize_t(3)});
    float* po = out.mutable_data();
    const float* pr = ray_contrib.data();
    const uint8_t* po_cc = occluded.data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::vpl_accumulate(P, pc, pr, po_cc, po, threads, stop);
    }
    return out;
}

auto shade_brdf_py(F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy, I32 material,
                   F32 n, F32 k1, F32 k2) {
    voxgi::ShadeMaterials mats = materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy);
    check_1d(material, -1, "material");
    const py::ssize_t Q = material.shape(0);
    check_2d(n, Q, 3, "n");
    check_2d(k1, Q, 3, "k1");
    check_2d(k2, Q, 3, "k2");
    const int32_t* mi = material.data();
    for (py::ssize_t q = 0; q < Q; ++q)
        if (mi[q] < 0 || mi[q] >= mats.count) throw py::value_error("material: index out of range");
    F32 out({Q, py::ssize_t(3)});
    float* po = out.mutable_data();
    const float *pn = n.data(), *p1 = k1.data(), *p2 = k2.data();
    for (py::ssize_t q = 0; q < Q; ++q)
        voxgi::shade_brdf(mats, mi[q], pn + 3 * q, p1 + 3 * q, p2 + 3 * q, po + 3 * q);
    return out;
}

auto light_accumulate_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                         F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy,
                         I64 ray_count, F32 ray_dir, F32 ray_weight, U8 occluded, F32Out out,
                         int threads) {
    voxgi::ShadeMaterials mats = materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy);
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    const py::ssize_t P = hits.count;
    check_1d(ray_count, P, "ray_count");
    check_2d(ray_dir, -1, 3, "ray_dir");
    const py::ssize_t R = ray_dir.shape(0);
    check_2d(ray_weight, R, 3, "ray_weight");
    if (occluded.size() != 0) check_1d(occluded, R, "occluded");
    check_2d(out, P, 3, "out");
    check_inplace(out, "out");
    check_ray_counts(ray_count, R);
    const int64_t* pc = ray_count.data();
    const float *pd = ray_dir.data(), *pw = ray_weight.data();
    const uint8_t* po = occluded.size() != 0 ? occluded.data() : nullptr;
    float* pout = out.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::light_accumulate(hits, mats, pc, pd, pw, po, pout, threads, stop);
    }
}

voxgi::PrimaryScene make_primary_scene(const F64& tri_v, const F64& tri_ng,
                                       const std::optional<F64>& corner_normals,
                                       const I32& tri_object, const U8& obj_two_sided,
                                       const F32& obj_emission) {
    if (tri_v.ndim() != 3 || tri_v.shape(1) != 3 || tri_v.shape(2) != 3)
        throw py::value_error("tri_v must have shape (F, 3, 3)");
    const py::ssize_t F = tri_v.shape(0);
    check_2d(tri_ng, F, 3, "tri_ng");
    if (corner_normals && (corner_normals->ndim() != 3 || corner_normals->shape(0) != F ||
                           corner_normals->shape(1) != 3 || corner_normals->shape(2) != 3))
        throw py::value_error("corner_normals must have shape (F, 3, 3) like tri_v");
    check_1d(tri_object, F, "tri_object");
    check_2d(obj_emission, -1, 3, "obj_emission");
    const py::ssize_t O = obj_emission.shape(0);
    check_1d(obj_two_sided, O, "obj_two_sided");
    const int32_t* po = tri_object.data();
    for (py::ssize_t i = 0; i < F; ++i)
        if (po[i] < 0 || po[i] >= O)
            throw py::value_error("tri_object: object " + std::to_string(po[i]) +
                                  " out of range (" + std::to_string(O) + " objects)");
    voxgi::PrimaryScene sc;
    sc.v = tri_v.data();
    sc.ng = tri_ng.data();
    sc.corner_normals = corner_normals ? corner_normals->data() : nullptr;
    sc.object = po;
    sc.two_sided = obj_two_sided.data();
    sc.emission = obj_emission.data();
    return sc;
}

py::tuple primary_hits_py(const F64& org, const F64& dirs, const I32& prim, const F64& tri_v,
                          const F64& tri_ng, const std::optional<F64>& corner_normals,
                          const I32& tri_object, const U8& obj_two_sided, const F32& obj_emission,
                          int threads) {
    check_2d(org, -1, 3, "org");
    const py::ssize_t P = org.shape(0);
    check_2d(dirs, P, 3, "dirs");
    check_1d(prim, P, "prim");
    const voxgi::PrimaryScene sc =
        make_primary_scene(tri_v, tri_ng, corner_normals, tri_object, obj_two_sided, obj_emission);
    const py::ssize_t F = tri_v.shape(0);
    const int32_t* pp = prim.data();
    for (py::ssize_t i = 0; i < P; ++i)
        if (pp[i] >= F)
            throw py::value_error("prim: triangle " + std::to_string(pp[i]) + " out of range (" +
                                  std::to_string(F) + " triangles)");
    F64 pos({P, py::ssize_t(3)});
    F32 normal({P, py::ssize_t(3)}), ng({P, py::ssize_t(3)}), le({P, py::ssize_t(3)});
    I32 material(P);
    const double *o = org.data(), *d = dirs.data();
    double* ppos = pos.mutable_data();
    float *pn = normal.mutable_data(), *pg = ng.mutable_data(), *pl = le.mutable_data();
    int32_t* pm = material.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::primary_hits(P, o, d, pp, sc, ppos, pn, pg, pm, pl, threads, stop);
    }
    return py::make_tuple(pos, normal, ng, material, le);
}

// (3,) finite vector `name` into out.
void vector3(const F64& a, const char* name, double out[3]) {
    check_1d(a, 3, name);
    for (int c = 0; c < 3; ++c) {
        out[c] = a.data()[c];
        if (!std::isfinite(out[c])) throw py::value_error(std::string(name) + " must be finite");
    }
}

py::tuple camera_hits_py(const F64& eye, const F64& right, const F64& up, const F64& forward,
                         double tan_half_fov, int64_t width, int64_t height, double aperture,
                         double focus, std::pair<double, double> offset,
                         std::pair<double, double> lens, const F64& tri_v, const F64& tri_ng,
                         const std::optional<F64>& corner_normals, const I32& tri_object,
                         const U8& obj_two_sided, const F32& obj_emission,
                         const voxgi::RayScene& scene, int threads) {
    voxgi::PixelCamera cam;
    vector3(eye, "eye", cam.eye);
    vector3(right, "right", cam.right);
    vector3(up, "up", cam.up);
    vector3(forward, "forward", cam.forward);
    if (!(tan_half_fov > 0.0) || !std::isfinite(tan_half_fov))
        throw py::value_error("tan_half_fov must be finite and > 0");
    if (width < 1 || height < 1 || width > (int64_t(1) << 20) || height > (int64_t(1) << 20))
        throw py::value_error("width and height must be in [1, 2^20]");
    if (!(aperture >= 0.0) || !std::isfinite(aperture))
        throw py::value_error("aperture must be finite and >= 0");
    if (aperture > 0.0 && (!(focus > 0.0) || !std::isfinite(focus)))
        throw py::value_error("focus must be finite and > 0 with an aperture");
    const double off[2] = {offset.first, offset.second}, ln[2] = {lens.first, lens.second};
    for (double v : {off[0], off[1], ln[0], ln[1]})
        if (!std::isfinite(v)) throw py::value_error("offset and lens must be finite");
    cam.tan_half_fov = tan_half_fov;
    cam.width = width;
    cam.height = height;
    cam.aperture = aperture;
    cam.focus = focus;
    const voxgi::PrimaryScene sc =
        make_primary_scene(tri_v, tri_ng, corner_normals, tri_object, obj_two_sided, obj_emission);
    check_scene(scene, tri_v.shape(0));
    const py::ssize_t P = width * height;
    F64 pos({P, py::ssize_t(3)});
    F32 normal({P, py::ssize_t(3)}), ng({P, py::ssize_t(3)}), wo({P, py::ssize_t(3)}),
        le({P, py::ssize_t(3)});
    I32 material(P), prim(P);
    double* ppos = pos.mutable_data();
    float *pn = normal.mutable_data(), *pg = ng.mutable_data(), *pw = wo.mutable_data(),
          *pl = le.mutable_data();
    int32_t* pm = material.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::camera_hits(cam, off, ln, scene, sc, ppos, pn, pg, pw, pm, pl, prim.mutable_data(),
                           threads, stop);
    }
    return py::make_tuple(pos, normal, ng, wo, material, le, prim);
}

py::tuple batch_error_py(const F32& batches, double size, double frames, double crit, int threads) {
    if (batches.ndim() < 2) throw py::value_error("batches must have shape (k, ...)");
    const py::ssize_t k = batches.shape(0);
    if (k < 2) throw py::value_error("batch_error needs at least 2 batches");
    if (!(size > 0.0) || !(frames >= size * k) || !std::isfinite(frames))
        throw py::value_error("frames must hold the k batches of size frames each");
    if (!(crit > 0.0)) throw py::value_error("crit must be > 0 (inf: no heavy-tail test)");
    std::vector<py::ssize_t> shape(batches.shape() + 1, batches.shape() + batches.ndim());
    const py::ssize_t n = batches.size() / k;
    F64 se(shape);
    U8 flagged(shape);
    const float* pb = batches.data();
    double* ps = se.mutable_data();
    uint8_t* pf = flagged.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::batch_error(pb, k, n, size, frames, crit, ps, pf, threads, stop);
    }
    return py::make_tuple(se, flagged);
}

}  // namespace

void bind_display(py::module_& m) {
    m.def("batch_error", &batch_error_py, "batches"_a.noconvert(), "size"_a, "frames"_a, "crit"_a,
          "threads"_a = 0,
          R"doc(Per-value standard error of a running mean of `frames` frames from k
batch means (k, ...) float32 of `size` frames each, raised to the largest
single-batch jump where the farthest batch is an outlier beyond `crit`
(externally studentized; inf: no test). Returns (stderr float64, flagged
uint8), each of the batches' shape without k.)doc");

    m.def("camera_hits", &camera_hits_py, "eye"_a.noconvert(), "right"_a.noconvert(),
          "up"_a.noconvert(), "forward"_a.noconvert(), "tan_half_fov"_a, "width"_a, "height"_a,
          "aperture"_a, "focus"_a, "offset"_a, "lens"_a, "tri_v"_a.noconvert(),
          "tri_ng"_a.noconvert(), "corner_normals"_a.noconvert(), "tri_object"_a.noconvert(),
          "obj_two_sided"_a.noconvert(), "obj_emission"_a.noconvert(), "scene"_a, "threads"_a = 0,
          R"doc(Every pixel's camera ray (the rays of voxgi.display.camera_rays, with
eye in the scene's frame), its first hit in scene (a RayScene built from
tri_v) and primary_hits on it: pos (P, 3) float64, normal, ng and wo (the
unit direction back to the eye) (P, 3) float32, material (P,) int32,
emission (P, 3) float32 and the hit triangle (P,) int32 (-1: none),
P = width * height, row-major from the top-left pixel.)doc");

    m.def("primary_hits", &primary_hits_py, "org"_a.noconvert(), "dirs"_a.noconvert(),
          "prim"_a.noconvert(), "tri_v"_a.noconvert(), "tri_ng"_a.noconvert(),
          "corner_normals"_a.noconvert(), "tri_object"_a.noconvert(), "obj_two_sided"_a.noconvert(),
          "obj_emission"_a.noconvert(), "threads"_a = 0,
          R"doc(Primary hits of camera rays (prim: first triangle, -1 none): the exact
point on the hit triangle's plane (P, 3) float64, the shading and geometric
normals turned to the viewer (P, 3) float32, the material (P,) int32 (-1: a
miss or a one-sided back) and its emission (P, 3) float32.)doc");

    m.def("vpl_prepare", &vpl_prepare_py, "hit_pos"_a.noconvert(), "hit_normal"_a.noconvert(),
          "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(), "hit_material"_a.noconvert(),
          "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(), "mat_nu"_a.noconvert(),
          "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(), "vpl_pos"_a.noconvert(),
          "vpl_normal"_a.noconvert(), "vpl_weight"_a.noconvert(), "vpl_area"_a.noconvert(),
          "vpl_pa"_a.noconvert(), "n_gather"_a, "eps"_a, "ray_count"_a.noconvert(),
          "ray_org"_a.noconvert(), "ray_dir"_a.noconvert(), "ray_len"_a.noconvert(),
          "ray_contrib"_a.noconvert(), "threads"_a = 0,
          R"doc(Pass 1 of a display frame: per (pixel, VPL) pair the unoccluded contribution
and a shadow ray where it is non-zero.

Inputs are C-contiguous: hit_pos (P, 3) float64, hit_normal / hit_ng / hit_wo
(P, 3) float32 unit vectors on the viewer's side, hit_material (P,) int32
(-1: not shaded), per-material mat_albedo (M, 3), mat_rs (M, 3), mat_nu,
mat_nv (M,) float32, mat_glossy (M,) uint8; vpl_pos (K, 3) float64,
vpl_normal (K, 3), vpl_weight (K, 3) = (TA/n) B/pi, vpl_area (K,) float32,
vpl_pa (K,) float32: n_v times the area pdf of VPLs combined with gather rays
(their weight is B/pi; n_gather rays per pixel), 0 for the others.

Outputs, written in place (buffers reused across frames, room for >= P*K
rays): ray_count (P,) int64, ray_org (C, 3), ray_dir (C, 3), ray_len (C,),
ray_contrib (C, 3) float32, rays pixel-major in VPL order. Returns the
number R of rays written (the first R rows).)doc");

    m.def("gather_rays", &gather_rays_py, "hit_pos"_a.noconvert(), "hit_normal"_a.noconvert(),
          "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(), "hit_material"_a.noconvert(),
          "n_gather"_a, "seed"_a, "frame"_a, "eps"_a, "ray_count"_a.noconvert(),
          "ray_org"_a.noconvert(), "ray_dir"_a.noconvert(), "threads"_a = 0,
          R"doc(Cosine-distributed gather rays (n_gather per shaded pixel, stratified,
hashed from seed/frame/pixel), written in place into ray_count (P,) int64 and
ray_org / ray_dir (C >= P*n_gather, 3) float32. Returns the number of rays.)doc");

    m.def("gather_shade", &gather_shade_py, "hit_pos"_a.noconvert(), "hit_normal"_a.noconvert(),
          "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(), "hit_material"_a.noconvert(),
          "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(), "mat_nu"_a.noconvert(),
          "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(), "n_gather"_a, "tri_v"_a.noconvert(),
          "tri_object"_a.noconvert(), "obj_two_sided"_a.noconvert(), "rec_sorted_key"_a.noconvert(),
          "rec_cell_start"_a.noconvert(), "rec_packed"_a.noconvert(), "grid_dims"_a.noconvert(),
          "grid_lo"_a.noconvert(), "grid_origin"_a.noconvert(), "pitch"_a,
          "ray_count"_a.noconvert(), "ray_dir"_a.noconvert(), "prim"_a.noconvert(),
          "out"_a.noconvert(), "threads"_a = 0,
          R"doc(Shade the gather rays (prim: first triangle hit, -1 none) with the radiance
of the record at each hit point, MIS-weighted against the VPLs; adds into
out (P, 3) float32.)doc");

    m.def("vpl_light", &vpl_light_py, "hit_pos"_a.noconvert(), "hit_normal"_a.noconvert(),
          "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(), "hit_material"_a.noconvert(),
          "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(), "mat_nu"_a.noconvert(),
          "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(), "vpl_pos"_a.noconvert(),
          "vpl_normal"_a.noconvert(), "vpl_weight"_a.noconvert(), "vpl_area"_a.noconvert(),
          "vpl_pa"_a.noconvert(), "n_gather"_a, "eps"_a, "scene"_a,
          "pixel_set"_a.noconvert() = py::none(), "set_start"_a.noconvert() = py::none(),
          "threads"_a = 0,
          R"doc(vpl_prepare, the shadow rays against scene (a RayScene) and vpl_accumulate,
pixel by pixel without ray arrays: the same (P, 3) float32 sums, and the
number of shadow rays traced. With pixel_set (P,) int32 and set_start (S+1,)
int64, pixel p sees only the VPLs of set pixel_set[p].)doc");

    m.def("gather_light", &gather_light_py, "hit_pos"_a.noconvert(), "hit_normal"_a.noconvert(),
          "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(), "hit_material"_a.noconvert(),
          "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(), "mat_nu"_a.noconvert(),
          "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(), "n_gather"_a, "seed"_a, "frame"_a,
          "eps"_a, "tri_v"_a.noconvert(), "tri_object"_a.noconvert(), "obj_two_sided"_a.noconvert(),
          "rec_sorted_key"_a.noconvert(), "rec_cell_start"_a.noconvert(),
          "rec_packed"_a.noconvert(), "grid_dims"_a.noconvert(), "grid_lo"_a.noconvert(),
          "grid_origin"_a.noconvert(), "pitch"_a, "scene"_a, "out"_a.noconvert(), "threads"_a = 0,
          R"doc(gather_rays, their first hits in scene (a RayScene built from tri_v) and
gather_shade, pixel by pixel without ray arrays: the same sums, added into
out (P, 3) float32. Returns the number of gather rays.)doc");

    m.def("geometry_filter", &geometry_filter_py, "hit_pos"_a.noconvert(),
          "hit_normal"_a.noconvert(), "hit_material"_a.noconvert(), "mat_glossy"_a.noconvert(),
          "eye"_a.noconvert(), "pixel_angle"_a, "width"_a, "height"_a, "radius"_a,
          "reflected"_a.noconvert(), "out"_a.noconvert(), "threads"_a = 0,
          R"doc(Adds into out (P, 3) float32 the reflected light (P, 3) float32 of one
frame averaged, per pixel, over the pixels of the (2 radius + 1)^2 square
around it that see the same material, with normals within about 25 degrees,
within two pixel footprints of its tangent plane (footprint: pixel_angle
times the distance to eye) and within 3 (radius + 1) footprints of it.
Pixels of glossy materials (mat_glossy) or with no material keep their own
value.)doc");

    m.def("vpl_accumulate", &vpl_accumulate_py, "ray_count"_a.noconvert(),
          "ray_contrib"_a.noconvert(), "occluded"_a.noconvert(), "threads"_a = 0,
          R"doc(Pass 2 of a display frame: per pixel, the sum of the contributions of the
rays not occluded (uint8 (R,)), in ray order. Returns (P, 3) float32.)doc");

    m.def("light_accumulate", &light_accumulate_py, "hit_pos"_a.noconvert(),
          "hit_normal"_a.noconvert(), "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(),
          "hit_material"_a.noconvert(), "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(),
          "mat_nu"_a.noconvert(), "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(),
          "ray_count"_a.noconvert(), "ray_dir"_a.noconvert(), "ray_weight"_a.noconvert(),
          "occluded"_a.noconvert(), "out"_a.noconvert(), "threads"_a = 0,
          R"doc(Light along known directions (delta lights, environment samples, escaped
gather rays): adds f(wi, wo) max(0, n.wi) weight into out (P, 3) for each ray
(pixel-major, ray_count (P,) int64) not occluded (uint8 (R,), or empty: none).)doc");

    m.def("shade_brdf", &shade_brdf_py, "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(),
          "mat_nu"_a.noconvert(), "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(),
          "material"_a.noconvert(), "n"_a.noconvert(), "k1"_a.noconvert(), "k2"_a.noconvert(),
          R"doc(The display's BRDF f(k1, k2) (1/sr) for Q direction pairs (tests):
rho/pi, or Ashikhmin-Shirley coupled diffuse + specular where mat_glossy.)doc");
}
