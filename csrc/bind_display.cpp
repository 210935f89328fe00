// pybind11 bindings for the display kernels (vpl_shade.h).
#include <pybind11/stl.h>

#include "pycommon.h"
#include "vpl_shade.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

voxgi::ShadeMaterials materials(const F32 &albedo, const F32 &rs, const F32 &nu, const F32 &nv,
                                const U8 &glossy) {
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

}  // namespace

void bind_display(py::module_ &m) {
    m.def(
        "vpl_prepare",
        [](F64 hit_pos, F32 hit_normal, F32 hit_ng, F32 hit_wo, I32 hit_material, F32 mat_albedo,
           F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy, F64 vpl_pos, F32 vpl_normal,
           F32 vpl_weight, F32 vpl_area, double eps, I64 ray_count, F32 ray_org, F32 ray_dir,
           F32 ray_len, F32 ray_contrib, int threads) {
            check_2d(hit_pos, -1, 3, "hit_pos");
            const py::ssize_t P = hit_pos.shape(0);
            check_2d(hit_normal, P, 3, "hit_normal");
            check_2d(hit_ng, P, 3, "hit_ng");
            check_2d(hit_wo, P, 3, "hit_wo");
            check_1d(hit_material, P, "hit_material");
            check_2d(vpl_pos, -1, 3, "vpl_pos");
            const py::ssize_t K = vpl_pos.shape(0);
            check_2d(vpl_normal, K, 3, "vpl_normal");
            check_2d(vpl_weight, K, 3, "vpl_weight");
            check_1d(vpl_area, K, "vpl_area");
            if (!(eps >= 0.0) || !std::isfinite(eps)) throw py::value_error("eps must be finite and >= 0");
            voxgi::ShadeMaterials mats = materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy);
            {
                const int32_t *mi = hit_material.data();
                for (py::ssize_t p = 0; p < P; ++p)
                    if (mi[p] >= mats.count)
                        throw py::value_error("hit_material: index " + std::to_string(mi[p]) +
                                              " out of range (" + std::to_string(mats.count) +
                                              " materials)");
            }
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
            if (!ray_count.writeable() || !ray_org.writeable() || !ray_dir.writeable() ||
                !ray_len.writeable() || !ray_contrib.writeable())
                throw py::value_error("ray buffers must be writeable");
            voxgi::ShadeHits hits;
            hits.count = P;
            hits.pos = hit_pos.data();
            hits.normal = hit_normal.data();
            hits.ng = hit_ng.data();
            hits.wo = hit_wo.data();
            hits.material = hit_material.data();
            voxgi::ShadeVPLs vpls;
            vpls.count = K;
            vpls.pos = vpl_pos.data();
            vpls.normal = vpl_normal.data();
            vpls.weight = vpl_weight.data();
            vpls.area = vpl_area.data();
            int64_t *pc = ray_count.mutable_data();
            float *po = ray_org.mutable_data(), *pd = ray_dir.mutable_data(),
                  *pl = ray_len.mutable_data(), *pr = ray_contrib.mutable_data();
            auto stop = make_stop_check();
            int64_t n;
            {
                py::gil_scoped_release release;
                n = voxgi::vpl_prepare(hits, mats, vpls, eps, pc, po, pd, pl, pr, threads, stop);
            }
            return n;
        },
        "hit_pos"_a.noconvert(), "hit_normal"_a.noconvert(), "hit_ng"_a.noconvert(),
        "hit_wo"_a.noconvert(), "hit_material"_a.noconvert(), "mat_albedo"_a.noconvert(),
        "mat_rs"_a.noconvert(), "mat_nu"_a.noconvert(), "mat_nv"_a.noconvert(),
        "mat_glossy"_a.noconvert(), "vpl_pos"_a.noconvert(), "vpl_normal"_a.noconvert(),
        "vpl_weight"_a.noconvert(), "vpl_area"_a.noconvert(), "eps"_a,
        "ray_count"_a.noconvert(), "ray_org"_a.noconvert(), "ray_dir"_a.noconvert(),
        "ray_len"_a.noconvert(), "ray_contrib"_a.noconvert(), "threads"_a = 0,
        R"doc(Pass 1 of a display frame: per (pixel, VPL) pair the unoccluded contribution
and a shadow ray where it is non-zero.

Inputs are C-contiguous: hit_pos (P, 3) float64, hit_normal / hit_ng / hit_wo
(P, 3) float32 unit vectors on the viewer's side, hit_material (P,) int32
(-1: not shaded), per-material mat_albedo (M, 3), mat_rs (M, 3), mat_nu,
mat_nv (M,) float32, mat_glossy (M,) uint8; vpl_pos (K, 3) float64,
vpl_normal (K, 3), vpl_weight (K, 3) = (TA/n) B/pi, vpl_area (K,) float32.

Outputs, written in place (buffers reused across frames, room for >= P*K
rays): ray_count (P,) int64, ray_org (C, 3), ray_dir (C, 3), ray_len (C,),
ray_contrib (C, 3) float32, rays pixel-major in VPL order. Returns the
number R of rays written (the first R rows).)doc");

    m.def(
        "vpl_accumulate",
        [](I64 ray_count, F32 ray_contrib, U8 occluded, int threads) {
            check_1d(ray_count, -1, "ray_count");
            check_2d(ray_contrib, -1, 3, "ray_contrib");
            const py::ssize_t R = ray_contrib.shape(0), P = ray_count.shape(0);
            check_1d(occluded, R, "occluded");
            const int64_t *pc = ray_count.data();
            int64_t total = 0;
            for (py::ssize_t p = 0; p < P; ++p) {
                if (pc[p] < 0) throw py::value_error("ray_count: negative count");
                total += pc[p];
            }
            if (total != R)
                throw py::value_error("ray_count sums to " + std::to_string(total) + ", expected " +
                                      std::to_string(R) + " rays");
            F32 out({P, py::ssize_t(3)});
            float *po = out.mutable_data();
            const float *pr = ray_contrib.data();
            const uint8_t *po_cc = occluded.data();
            auto stop = make_stop_check();
            {
                py::gil_scoped_release release;
                voxgi::vpl_accumulate(P, pc, pr, po_cc, po, threads, stop);
            }
            return out;
        },
        "ray_count"_a.noconvert(), "ray_contrib"_a.noconvert(), "occluded"_a.noconvert(),
        "threads"_a = 0,
        R"doc(Pass 2 of a display frame: per pixel, the sum of the contributions of the
rays not occluded (uint8 (R,)), in ray order. Returns (P, 3) float32.)doc");

    m.def(
        "shade_brdf",
        [](F32 mat_albedo, F32 mat_rs, F32 mat_nu, F32 mat_nv, U8 mat_glossy, I32 material,
           F32 n, F32 k1, F32 k2) {
            voxgi::ShadeMaterials mats = materials(mat_albedo, mat_rs, mat_nu, mat_nv, mat_glossy);
            check_1d(material, -1, "material");
            const py::ssize_t Q = material.shape(0);
            check_2d(n, Q, 3, "n");
            check_2d(k1, Q, 3, "k1");
            check_2d(k2, Q, 3, "k2");
            const int32_t *mi = material.data();
            for (py::ssize_t q = 0; q < Q; ++q)
                if (mi[q] < 0 || mi[q] >= mats.count)
                    throw py::value_error("material: index out of range");
            F32 out({Q, py::ssize_t(3)});
            float *po = out.mutable_data();
            const float *pn = n.data(), *p1 = k1.data(), *p2 = k2.data();
            for (py::ssize_t q = 0; q < Q; ++q)
                voxgi::shade_brdf(mats, mi[q], pn + 3 * q, p1 + 3 * q, p2 + 3 * q, po + 3 * q);
            return out;
        },
        "mat_albedo"_a.noconvert(), "mat_rs"_a.noconvert(), "mat_nu"_a.noconvert(),
        "mat_nv"_a.noconvert(), "mat_glossy"_a.noconvert(), "material"_a.noconvert(),
        "n"_a.noconvert(), "k1"_a.noconvert(), "k2"_a.noconvert(),
        R"doc(The display's BRDF f(k1, k2) (1/sr) for Q direction pairs (tests):
rho/pi, or Ashikhmin-Shirley coupled diffuse + specular where mat_glossy.)doc");
}
