// pybind11 bindings for the VPL shading kernels (vpl_shade.h).
#include <pybind11/stl.h>

#include <memory>
#include <optional>

#include "bind_shade.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

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

py::tuple vpl_light_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                       F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy,
                       F64 vpl_pos, F32 vpl_normal, F32 vpl_weight, F32 vpl_area, F32 vpl_pa,
                       double n_gather, double eps, const voxgi::RayScene& scene,
                       std::optional<I32> pixel_set, std::optional<I64> set_start, int threads,
                       const std::optional<F32>& hit_albedo, const std::optional<F32>& mat_lobe,
                       const std::optional<U8>& mat_continue, const std::optional<F32>& vpl_share,
                       const std::optional<F32>& mat_base_out,
                       const std::optional<I32>& vpl_object) {
    voxgi::ShadeMaterials mats =
        materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy, mat_lobe);
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    set_hit_albedo(hits, hit_albedo);
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    voxgi::ShadeMIS mis = make_mis(n_gather);
    voxgi::ShadeVPLs vpls = make_vpls(vpl_pos, vpl_normal, vpl_weight, vpl_area, vpl_pa, n_gather);
    if (mat_continue.has_value() != vpl_share.has_value())
        throw py::value_error("mat_continue and vpl_share go together");
    if (mat_continue) {
        check_1d(*mat_continue, mats.count, "mat_continue");
        check_2d(*vpl_share, vpls.count, 3, "vpl_share");
        mats.continue_lobe = mat_continue->data();
        vpls.share = vpl_share->data();
    }
    if (mat_base_out.has_value() != vpl_object.has_value())
        throw py::value_error("mat_base_out and vpl_object go together");
    if (mat_base_out) {
        if (!mat_continue) throw py::value_error("mat_base_out needs mat_continue");
        if (check_incidence_table(*mat_base_out, "mat_base_out") != mats.count)
            throw py::value_error("mat_base_out: one row per material");
        check_1d(*vpl_object, vpls.count, "vpl_object");
        for (int64_t k = 0; k < vpls.count; ++k)
            if (vpl_object->data()[k] < 0 || vpl_object->data()[k] >= mats.count)
                throw py::value_error("vpl_object: VPL " + std::to_string(k) +
                                      " names no material");
        mats.base_out = mat_base_out->data();
        vpls.object = vpl_object->data();
    }
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

auto shade_brdf_py(F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy, I32 material,
                   F32 n, F32 k1, F32 k2, const std::optional<F32>& mat_lobe) {
    voxgi::ShadeMaterials mats =
        materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy, mat_lobe);
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
                         int threads, const std::optional<F32>& hit_albedo,
                         const std::optional<F32>& mat_lobe) {
    voxgi::ShadeMaterials mats =
        materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy, mat_lobe);
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    set_hit_albedo(hits, hit_albedo);
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

// A validated copy of the guide's tables (voxgi.display.environment_guide).
std::unique_ptr<voxgi::EnvironmentGuide> make_guide(F64 origin, double cell, I64 dims,
                                                    int64_t width, int64_t height, int64_t blocks_w,
                                                    int64_t blocks_h, double alpha, I32 key_row,
                                                    F64 factor, F64 block_cdf, F64 row_cdf) {
    auto g = std::make_unique<voxgi::EnvironmentGuide>();
    check_1d(origin, 3, "origin");
    check_1d(dims, 3, "dims");
    if (!(cell > 0.0) || !std::isfinite(cell)) throw py::value_error("cell must be finite and > 0");
    if (!(alpha > 0.0 && alpha <= 1.0)) throw py::value_error("alpha must be in (0, 1]");
    if (width < 1 || height < 1 || blocks_w < 1 || blocks_h < 1 || blocks_w > width ||
        blocks_h > height)
        throw py::value_error("blocks must be within 1 and the environment's width and height");
    int64_t keys = 6;
    for (int a = 0; a < 3; ++a) {
        g->origin[a] = origin.data()[a];
        if (!std::isfinite(g->origin[a])) throw py::value_error("origin must be finite");
        g->dims[a] = dims.data()[a];
        if (g->dims[a] < 1 || g->dims[a] > 4096) throw py::value_error("dims must be in [1, 4096]");
        keys *= g->dims[a];
    }
    g->inv_cell = 1.0 / cell;
    g->width = width;
    g->height = height;
    g->blocks_w = blocks_w;
    g->blocks_h = blocks_h;
    g->alpha = alpha;
    const int64_t B = g->blocks();
    if (factor.ndim() != 2 || factor.shape(1) != B)
        throw py::value_error("factor must have shape (rows, blocks_w * blocks_h)");
    const int64_t rows = factor.shape(0);
    check_2d(block_cdf, rows, B, "block_cdf");
    check_1d(key_row, keys, "key_row");
    check_2d(row_cdf, blocks_w, height, "row_cdf");
    g->key_row.assign(key_row.data(), key_row.data() + keys);
    for (int32_t r : g->key_row)
        if (r < -1 || r >= rows) throw py::value_error("key_row: a row out of range");
    g->factor.assign(factor.data(), factor.data() + rows * B);
    for (double f : g->factor)
        if (!(f >= 0.0) || !std::isfinite(f))
            throw py::value_error("factor must be finite and >= 0");
    g->block_cdf.assign(block_cdf.data(), block_cdf.data() + rows * B);
    for (int64_t r = 0; r < rows; ++r) {
        const double* c = g->block_cdf.data() + r * B;
        for (int64_t b = 0; b < B; ++b)
            if (!(c[b] >= (b ? c[b - 1] : 0.0)) || !(c[b] <= 1.0))
                throw py::value_error("block_cdf: each row must ascend within [0, 1]");
        if (!(c[B - 1] == 1.0)) throw py::value_error("block_cdf: each row must end at 1");
    }
    g->row_cdf.assign(row_cdf.data(), row_cdf.data() + blocks_w * height);
    for (int64_t bx = 0; bx < blocks_w; ++bx)
        for (int64_t by = 0; by < blocks_h; ++by) {
            const double* rc = g->row_cdf.data() + bx * height;
            const int64_t r0 = g->first_row(by), r1 = g->first_row(by + 1);
            if (!(r0 < r1)) throw py::value_error("blocks must each hold a row");
            for (int64_t r = r0; r < r1; ++r)
                if (!std::isfinite(rc[r]) || !(rc[r] >= (r > r0 ? rc[r - 1] : 0.0)))
                    throw py::value_error("row_cdf: block (" + std::to_string(by) + ", " +
                                          std::to_string(bx) + ") must ascend from 0 at row " +
                                          std::to_string(r));
        }
    return g;
}

py::tuple learn_environment_guide_py(const F64& env_radiance, const F64& env_to_world,
                                     const F64& env_texel_pdf, const F64& env_row_solid_angle,
                                     const F64& env_texel_cdf, const F64& env_row_cos,
                                     int64_t blocks_w, int64_t blocks_h, F64 pos, F32 normal,
                                     I64 row_start, I32 row_rays, uint64_t seed, double eps,
                                     F64 luminance, const voxgi::RayScene& scene, int threads) {
    const voxgi::EnvironmentMap env =
        *make_environment(env_radiance, env_to_world, env_texel_pdf, env_row_solid_angle, 0.0,
                          &env_texel_cdf, &env_row_cos);
    voxgi::EnvironmentGuide blocks;
    blocks.width = env.width;
    blocks.height = env.height;
    if (blocks_w < 1 || blocks_h < 1 || blocks_w > env.width || blocks_h > env.height)
        throw py::value_error("blocks must be within 1 and the environment's width and height");
    blocks.blocks_w = blocks_w;
    blocks.blocks_h = blocks_h;
    check_2d(pos, -1, 3, "pos");
    const int64_t n = pos.shape(0);
    check_2d(normal, n, 3, "normal");
    if (row_start.ndim() != 1 || row_start.shape(0) < 1)
        throw py::value_error("row_start must have shape (rows + 1,)");
    const int64_t rows = row_start.shape(0) - 1;
    const int64_t* rs = row_start.data();
    if (rs[0] != 0 || rs[rows] != n) throw py::value_error("row_start must run from 0 to N");
    for (int64_t r = 0; r < rows; ++r)
        if (rs[r + 1] < rs[r]) throw py::value_error("row_start must ascend");
    for (int64_t i = 0; i < 3 * n; ++i)
        if (!std::isfinite(pos.data()[i]) || !std::isfinite(normal.data()[i]))
            throw py::value_error("pos and normal must be finite");
    check_1d(row_rays, rows, "row_rays");
    for (int64_t r = 0; r < rows; ++r)
        if (row_rays.data()[r] < 0 || row_rays.data()[r] > (1 << 20))
            throw py::value_error("row_rays must be in [0, 2**20]");
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    check_1d(luminance, 3, "luminance");
    py::array_t<double> hist({rows, blocks.blocks()});
    py::array_t<double> possible(rows);
    std::fill(hist.mutable_data(), hist.mutable_data() + hist.size(), 0.0);
    std::fill(possible.mutable_data(), possible.mutable_data() + rows, 0.0);
    int64_t rays = 0;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        rays = voxgi::learn_environment_guide(
            env, blocks, pos.data(), normal.data(), rs, rows, row_rays.data(), seed, eps,
            luminance.data(), scene, hist.mutable_data(), possible.mutable_data(), threads, stop);
    }
    return py::make_tuple(hist, possible, rays);
}

py::tuple environment_irradiance_py(const F64& env_radiance, const F64& env_to_world,
                                    const F64& env_texel_pdf, const F64& env_row_solid_angle,
                                    const F64& env_texel_cdf, const F64& env_row_cos, F64 pos,
                                    F32 normal, int n_env, int n_cos, uint64_t seed, double eps,
                                    const voxgi::RayScene& scene, int threads,
                                    const std::optional<F32>& response,
                                    const std::optional<F32>& response_base,
                                    const std::optional<I32>& response_row) {
    const voxgi::EnvironmentMap env =
        *make_environment(env_radiance, env_to_world, env_texel_pdf, env_row_solid_angle, 0.0,
                          &env_texel_cdf, &env_row_cos);
    check_2d(pos, -1, 3, "pos");
    const int64_t n = pos.shape(0);
    check_2d(normal, n, 3, "normal");
    for (int64_t i = 0; i < 3 * n; ++i)
        if (!std::isfinite(pos.data()[i]) || !std::isfinite(normal.data()[i]))
            throw py::value_error("pos and normal must be finite");
    if (n_env < 0 || n_env > 4096 || n_cos < 0 || n_cos > 4096)
        throw py::value_error("n_env and n_cos must be in [0, 4096]");
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    const int given = int(response.has_value()) + int(response_row.has_value());
    if (given == 1) throw py::value_error("response and response_row go together");
    if (response_base && !response) throw py::value_error("response_base needs response");
    const float *pr = nullptr, *pb = nullptr;
    const int32_t* rows = nullptr;
    if (response) {
        const py::ssize_t T = check_incidence_table(*response, "response");
        check_1d(*response_row, n, "response_row");
        rows = response_row->data();
        for (int64_t i = 0; i < n; ++i)
            if (rows[i] < -1 || rows[i] >= T)
                throw py::value_error("response_row: point " + std::to_string(i) +
                                      " names no row of response");
        pr = response->data();
        if (response_base) {
            if (check_incidence_table(*response_base, "response_base") != T)
                throw py::value_error("response_base: as many rows as response");
            pb = response_base->data();
        }
    }
    py::array_t<double> out({n, int64_t(3)});
    std::optional<py::array_t<double>> base;
    if (pb) base.emplace(std::vector<py::ssize_t>{n, 3});
    int64_t rays = 0;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        rays = voxgi::environment_irradiance(env, pos.data(), normal.data(), n, n_env, n_cos, seed,
                                             eps, pr, pb, rows, scene, out.mutable_data(),
                                             base ? base->mutable_data() : nullptr, threads, stop);
    }
    return py::make_tuple(out, base ? py::object(*base) : py::object(py::none()), rays);
}

int64_t environment_light_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                             F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy,
                             const F64& env_radiance, const F64& env_to_world,
                             const F64& env_texel_pdf, const F64& env_row_solid_angle,
                             const F64& env_texel_cdf, const F64& env_row_cos, int env_samples,
                             double n_gather, uint64_t seed, int64_t frame, double eps,
                             const voxgi::RayScene& scene, F32Out out, int threads,
                             const std::optional<F32>& hit_albedo,
                             const std::optional<F32>& mat_lobe,
                             const voxgi::EnvironmentGuide* env_guide) {
    voxgi::ShadeMaterials mats =
        materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy, mat_lobe);
    voxgi::ShadeHits hits =
        make_hits(hit_pos, hit_normal, hit_ng, hit_wo, hit_material, mats.count);
    set_hit_albedo(hits, hit_albedo);
    if (env_samples < 0 || env_samples > 4096)
        throw py::value_error("env_samples must be in [0, 4096]");
    if (!(n_gather >= 0.0) || !std::isfinite(n_gather))
        throw py::value_error("n_gather must be finite and >= 0");
    if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
    voxgi::EnvironmentMap env =
        *make_environment(env_radiance, env_to_world, env_texel_pdf, env_row_solid_angle,
                          double(env_samples), &env_texel_cdf, &env_row_cos);
    attach_guide(env, env_guide);
    check_2d(out, hits.count, 3, "out");
    check_inplace(out, "out");
    float* po = out.mutable_data();
    int64_t rays = 0;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::environment_light(hits, mats, env, n_gather, seed, frame, eps, scene, po, &rays,
                                 threads, stop);
    }
    return rays;
}

}  // namespace

void bind_vpl_shade(py::module_& m) {
    py::class_<voxgi::EnvironmentGuide>(m, "EnvironmentGuide", R"doc(Where an environment's light
reaches a scene: per cell of a grid (origin (3,), cell edge, dims (3,)) and
facing (the geometric normal's dominant axis and sign: key = cell * 6 + 2 *
axis + (negative)), key_row (dims product * 6,) int32 picks a row (-1: none)
of factor and block_cdf (rows, blocks_w * blocks_h) float64, the density over
the environment's own per block of texels and the running shares of the
blocks. row_cdf (blocks_w, height) float64: per column of blocks, the
running texel_pdf of its texels row by row, from 0 again at each block's
first row (a row ceil(by * height / blocks_h)). Samples take
the environment's own tables with probability alpha. Checked and copied;
voxgi.display.environment_guide builds it.)doc")
        .def(py::init(&make_guide), "origin"_a.noconvert(), "cell"_a, "dims"_a.noconvert(),
             "width"_a, "height"_a, "blocks_w"_a, "blocks_h"_a, "alpha"_a, "key_row"_a.noconvert(),
             "factor"_a.noconvert(), "block_cdf"_a.noconvert(), "row_cdf"_a.noconvert());
    m.def("environment_irradiance", &environment_irradiance_py, "env_radiance"_a.noconvert(),
          "env_to_world"_a.noconvert(), "env_texel_pdf"_a.noconvert(),
          "env_row_solid_angle"_a.noconvert(), "env_texel_cdf"_a.noconvert(),
          "env_row_cos"_a.noconvert(), "pos"_a.noconvert(), "normal"_a.noconvert(), "n_env"_a,
          "n_cos"_a, "seed"_a, "eps"_a, "scene"_a, "threads"_a = 0,
          "response"_a.noconvert() = py::none(), "response_base"_a.noconvert() = py::none(),
          "response_row"_a.noconvert() = py::none(),
          R"doc(The environment's irradiance at points (pos (R, 3) float64, unit normal
(R, 3) float32, rays offset eps along it): n_env samples drawn from the
environment's tables and n_cos cosine-distributed directions, traced in scene and combined by the
balance heuristic. With response (T, 33, 3) float32 and response_row (R,)
int32 (-1: none) each sample is weighed by the point's row at its cosine,
and with response_base as well the same samples weighed by its rows are
returned too. Returns (irradiance (R, 3) float64, base irradiance (R, 3)
float64 or None, the number of rays traced).)doc");

    m.def("learn_environment_guide", &learn_environment_guide_py, "env_radiance"_a.noconvert(),
          "env_to_world"_a.noconvert(), "env_texel_pdf"_a.noconvert(),
          "env_row_solid_angle"_a.noconvert(), "env_texel_cdf"_a.noconvert(),
          "env_row_cos"_a.noconvert(), "blocks_w"_a, "blocks_h"_a, "pos"_a.noconvert(),
          "normal"_a.noconvert(), "row_start"_a.noconvert(), "row_rays"_a.noconvert(), "seed"_a,
          "eps"_a, "luminance"_a.noconvert(), "scene"_a, "threads"_a = 0,
          R"doc(The environment guide's learning rays: from each point (pos (N, 3) float64,
normal (N, 3) float32, offset eps along it) of row r (points row_start[r] to
row_start[r + 1]), row_rays[r] (rows,) int32 directions each, every other one drawn by the
environment's own tables and the rest cosine-distributed, traced in scene. Returns (hist (rows, blocks_w * blocks_h) float64: per row
and block of texels, the luminance-weighted light L cos / p that arrived
unblocked, p the balance of the two densities; possible (rows,) float64: the same for every ray above the
surface, blocked or not; the number of rays traced).)doc");

    m.def("environment_light", &environment_light_py, "hit_pos"_a.noconvert(),
          "hit_normal"_a.noconvert(), "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(),
          "hit_material"_a.noconvert(), "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(),
          "mat_nu"_a.noconvert(), "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(),
          "env_radiance"_a.noconvert(), "env_to_world"_a.noconvert(), "env_texel_pdf"_a.noconvert(),
          "env_row_solid_angle"_a.noconvert(), "env_texel_cdf"_a.noconvert(),
          "env_row_cos"_a.noconvert(), "env_samples"_a, "n_gather"_a, "seed"_a, "frame"_a, "eps"_a,
          "scene"_a, "out"_a.noconvert(), "threads"_a = 0, "hit_albedo"_a.noconvert() = py::none(),
          "mat_lobe"_a.noconvert() = py::none(), "env_guide"_a = py::none(),
          R"doc(The environment's light at the hits: env_samples directions per shaded
pixel drawn from the environment's tables (with env_guide, an
EnvironmentGuide, from its row at each pixel) (as voxgi.Environment.sample:
env_texel_cdf (H*W,), env_row_cos (H+1,)), each weighed by the balance
heuristic against n_gather cosine-distributed gather rays and traced in
scene (a RayScene) as it is made; the free ones' f cos L / density added into
out (P, 3) float32. Returns the number of rays traced.)doc");

    m.def("vpl_light", &vpl_light_py, "hit_pos"_a.noconvert(), "hit_normal"_a.noconvert(),
          "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(), "hit_material"_a.noconvert(),
          "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(), "mat_nu"_a.noconvert(),
          "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(), "vpl_pos"_a.noconvert(),
          "vpl_normal"_a.noconvert(), "vpl_weight"_a.noconvert(), "vpl_area"_a.noconvert(),
          "vpl_pa"_a.noconvert(), "n_gather"_a, "eps"_a, "scene"_a,
          "pixel_set"_a.noconvert() = py::none(), "set_start"_a.noconvert() = py::none(),
          "threads"_a = 0, "hit_albedo"_a.noconvert() = py::none(),
          "mat_lobe"_a.noconvert() = py::none(), "mat_continue"_a.noconvert() = py::none(),
          "vpl_share"_a.noconvert() = py::none(), "mat_base_out"_a.noconvert() = py::none(),
          "vpl_object"_a.noconvert() = py::none(),
          R"doc(The VPLs' light at the hits: per (pixel, VPL) pair the unoccluded term and
its shadow ray, traced in scene (a RayScene) as it is made; returns each
pixel's sum over its free rays in VPL order (P, 3) float32 and the number of
shadow rays traced.

Inputs are C-contiguous: hit_pos (P, 3) float64, hit_normal / hit_ng / hit_wo
(P, 3) float32 unit vectors on the viewer's side, hit_material (P,) int32
(-1: not shaded), per-material mat_albedo (M, 3), mat_rs (M, 3), mat_nu,
mat_nv (M,) float32, mat_glossy (M,) uint8; vpl_pos (K, 3) float64,
vpl_normal (K, 3), vpl_weight (K, 3) = (TA/n) B/pi, vpl_area (K,) float32,
vpl_pa (K,) float32: n_v times the area pdf of VPLs combined with gather rays
(their weight is B/pi; n_gather rays per pixel), 0 for the others. With pixel_set (P,) int32 and set_start (S+1,)
int64, pixel p sees only the VPLs of set pixel_set[p]. With mat_continue
(M,) uint8 and vpl_share (K, 3) float32, a pixel with a lobe (whose gather
rays follow the lobes of the materials marked 1) takes vpl_share of each
VPL's light; with mat_base_out (M, 33, 3) float32 and vpl_object (K,) int32
as well, that share times its material's row of mat_base_out at the VPL's
cosine towards the pixel (the base's outgoing radiance over its mean).)doc");

    m.def("light_accumulate", &light_accumulate_py, "hit_pos"_a.noconvert(),
          "hit_normal"_a.noconvert(), "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(),
          "hit_material"_a.noconvert(), "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(),
          "mat_nu"_a.noconvert(), "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(),
          "ray_count"_a.noconvert(), "ray_dir"_a.noconvert(), "ray_weight"_a.noconvert(),
          "occluded"_a.noconvert(), "out"_a.noconvert(), "threads"_a = 0,
          "hit_albedo"_a.noconvert() = py::none(), "mat_lobe"_a.noconvert() = py::none(),
          R"doc(Light along known directions (delta lights, environment samples, escaped
gather rays): adds f(wi, wo) max(0, n.wi) weight into out (P, 3) for each ray
(pixel-major, ray_count (P,) int64) not occluded (uint8 (R,), or empty: none).)doc");

    m.def("shade_brdf", &shade_brdf_py, "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(),
          "mat_nu"_a.noconvert(), "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(),
          "material"_a.noconvert(), "n"_a.noconvert(), "k1"_a.noconvert(), "k2"_a.noconvert(),
          "mat_lobe"_a.noconvert() = py::none(),
          R"doc(The display's BRDF f(k1, k2) (1/sr) for Q direction pairs (tests):
rho/pi, or Ashikhmin-Shirley coupled diffuse + specular where mat_glossy, or
where mat_lobe (M, 85) float32 has a row of kind 1 or 2 the microfacet lobe
(voxgi.Microfacet.lobe_row) with k1 towards the light.)doc");
}
