// pybind11 bindings for the Embree ray scene (ray_scene.h).
#include <pybind11/stl.h>

#include <memory>
#include <optional>

#include "bind_common.h"
#include "ray_scene.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

void check_rays(const F32& org, const F32& dir, py::ssize_t n) {
    check_2d(org, n, 3, "org");
    check_2d(dir, org.shape(0), 3, "dirs");
}

U8 occluded_py(const voxgi::RayScene& s, const F32& org, const F32& dir, const F32& length,
               int threads) {
    check_rays(org, dir, -1);
    const py::ssize_t n = org.shape(0);
    check_1d(length, n, "length");
    U8 out(n);
    const float *po = org.data(), *pd = dir.data(), *pl = length.data();
    uint8_t* pr = out.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        s.occluded(po, pd, pl, n, pr, nullptr, voxgi::resolve_threads(threads), stop);
    }
    return out;
}

F32Out transmittance_py(const voxgi::RayScene& s, const F32& org, const F32& dir, const F32& length,
                        int threads) {
    check_rays(org, dir, -1);
    const py::ssize_t n = org.shape(0);
    check_1d(length, n, "length");
    F32Out through({n, py::ssize_t(3)});
    U8 blocked(n);
    const float *po = org.data(), *pd = dir.data(), *pl = length.data();
    float* pt = through.mutable_data();
    uint8_t* pb = blocked.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        s.occluded(po, pd, pl, n, pb, pt, voxgi::resolve_threads(threads), stop);
    }
    return through;
}

py::tuple intersect_py(const voxgi::RayScene& s, const F32& org, const F32& dir, bool uv,
                       int threads, bool through) {
    check_rays(org, dir, -1);
    const py::ssize_t n = org.shape(0);
    I32 prim(n);
    F32 u(uv ? n : 0), v(uv ? n : 0);
    const float *po = org.data(), *pd = dir.data();
    int32_t* pp = prim.mutable_data();
    float* pu = uv ? u.mutable_data() : nullptr;
    float* pv = uv ? v.mutable_data() : nullptr;
    F32Out T({through ? n : py::ssize_t(0), py::ssize_t(3)});
    float* pt = through ? T.mutable_data() : nullptr;
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        s.intersect(po, pd, n, pp, pu, pv, pt, voxgi::resolve_threads(threads), stop);
    }
    if (through) return py::make_tuple(prim, u, v, T);
    return py::make_tuple(prim, u, v);
}

}  // namespace

void bind_rays(py::module_& m) {
    py::class_<voxgi::RayScene, std::shared_ptr<voxgi::RayScene>>(
        m, "RayScene",
        "Embree 4 scene of a triangle soup, queried from C++ threads (GIL released).")
        .def(py::init(
                 [](const std::string& library, const F32& tris, std::optional<F32> transmittance) {
                     if (tris.ndim() != 3 || tris.shape(1) != 3 || tris.shape(2) != 3)
                         throw py::value_error("tris must have shape (F, 3, 3)");
                     const float* pt = tris.data();
                     for (py::ssize_t i = 0; i < tris.size(); ++i)
                         if (!std::isfinite(pt[i]))
                             throw py::value_error("tris: corner coordinates must be finite");
                     const float* ptr = nullptr;
                     if (transmittance) {
                         check_2d(*transmittance, tris.shape(0), 3, "transmittance");
                         ptr = transmittance->data();
                         for (py::ssize_t i = 0; i < transmittance->size(); ++i)
                             if (!(ptr[i] >= 0.f && ptr[i] <= 1.f))
                                 throw py::value_error("transmittance: values must lie in [0, 1]");
                     }
                     return std::make_shared<voxgi::RayScene>(library, pt, tris.shape(0), ptr);
                 }),
             "library"_a, "tris"_a, "transmittance"_a = py::none(),
             "Build the scene from (F, 3, 3) float32 corners with the Embree at `library`; "
             "`transmittance` (F, 3) float32 or None: a triangle with a channel above 0 is a "
             "sheet that rays cross, scaled by it.")
        .def_property_readonly("has_sheets", &voxgi::RayScene::has_sheets)
        .def_property_readonly("triangle_count", &voxgi::RayScene::triangle_count)
        .def_property_readonly("twin_count", &voxgi::RayScene::twin_count,
                               "Triangles with a reversed twin: the same corners in reverse order "
                               "(a first hit on one returns the one whose front the ray meets).")
        .def_property_readonly(
            "embree_version",
            [](const voxgi::RayScene& s) { return voxgi::version_string(s.embree_version()); },
            "The Embree library's version, \"major.minor.patch\".")
        .def("occluded", &occluded_py, "org"_a, "dirs"_a, "length"_a, "threads"_a = 0,
             "(R,) uint8: 1 where no light passes [org, org + length * dirs) (an opaque "
             "triangle lies on it, or its sheets pass nothing).")
        .def("transmittance", &transmittance_py, "org"_a, "dirs"_a, "length"_a, "threads"_a = 0,
             "(R, 3) float32: the light that passes [org, org + length * dirs): 0 where an "
             "opaque triangle lies on it, else the product of its sheets' transmittances.")
        .def("intersect", &intersect_py, "org"_a, "dirs"_a, "uv"_a = false, "threads"_a = 0,
             "through"_a = false,
             "First opaque triangle each ray meets (int32, -1: none) and, with uv, its float32 "
             "barycentrics u, v (empty arrays otherwise); with through, a fourth array (R, 3) "
             "float32: the product of the sheets' transmittances before it.");
}
