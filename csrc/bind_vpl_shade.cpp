// pybind11 bindings for the VPL shading kernels (vpl_shade.h).
#include <pybind11/stl.h>

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
                       const std::optional<U8>& mat_continue, const std::optional<F32>& vpl_share) {
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

int64_t environment_light_py(F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material,
                             F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy,
                             const F64& env_radiance, const F64& env_to_world,
                             const F64& env_texel_pdf, const F64& env_row_solid_angle,
                             const F64& env_texel_cdf, const F64& env_row_cos, int env_samples,
                             double n_gather, uint64_t seed, int64_t frame, double eps,
                             const voxgi::RayScene& scene, F32Out out, int threads,
                             const std::optional<F32>& hit_albedo,
                             const std::optional<F32>& mat_lobe) {
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
    const voxgi::EnvironmentMap env =
        *make_environment(env_radiance, env_to_world, env_texel_pdf, env_row_solid_angle,
                          double(env_samples), &env_texel_cdf, &env_row_cos);
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
    m.def("environment_light", &environment_light_py, "hit_pos"_a.noconvert(),
          "hit_normal"_a.noconvert(), "hit_ng"_a.noconvert(), "hit_wo"_a.noconvert(),
          "hit_material"_a.noconvert(), "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(),
          "mat_nu"_a.noconvert(), "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(),
          "env_radiance"_a.noconvert(), "env_to_world"_a.noconvert(), "env_texel_pdf"_a.noconvert(),
          "env_row_solid_angle"_a.noconvert(), "env_texel_cdf"_a.noconvert(),
          "env_row_cos"_a.noconvert(), "env_samples"_a, "n_gather"_a, "seed"_a, "frame"_a, "eps"_a,
          "scene"_a, "out"_a.noconvert(), "threads"_a = 0, "hit_albedo"_a.noconvert() = py::none(),
          "mat_lobe"_a.noconvert() = py::none(),
          R"doc(The environment's light at the hits: env_samples directions per shaded
pixel drawn from the environment's tables (as voxgi.Environment.sample:
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
          "vpl_share"_a.noconvert() = py::none(),
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
VPL's light.)doc");

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
