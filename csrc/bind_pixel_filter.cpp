// pybind11 bindings for the geometry-aware filter (pixel_filter.h).
#include "bind_common.h"
#include "pixel_filter.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

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

}  // namespace

void bind_pixel_filter(py::module_& m) {
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
}
