// pybind11 bindings for the camera rays and their primary hits (camera.h).
#include <pybind11/stl.h>

#include <optional>
#include <utility>

#include "bind_shade.h"
#include "camera.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

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

}  // namespace

void bind_camera(py::module_& m) {
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
}
