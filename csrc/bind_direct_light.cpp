// Bindings of the direct-light kernels (direct_light.h).
#include <cmath>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "direct_light.h"
#include "pycommon.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

voxgi::EmitterTriangles emitters(const F64 &corners, const F64 &normal, const U8 &two_sided,
                                 const F64 &radiance, const F64 &cdf, const F64 &density) {
    if (corners.ndim() != 3 || corners.shape(1) != 3 || corners.shape(2) != 3)
        throw py::value_error("corners must have shape (E, 3, 3)");
    const py::ssize_t e = corners.shape(0);
    if (e == 0) throw py::value_error("corners: no emitting triangle");
    check_2d(normal, e, 3, "normal");
    check_1d(two_sided, e, "two_sided");
    check_2d(radiance, e, 3, "radiance");
    check_1d(cdf, e, "cdf");
    check_1d(density, e, "density");
    voxgi::EmitterTriangles em;
    em.count = e;
    em.corners = corners.data();
    em.normal = normal.data();
    em.two_sided = two_sided.data();
    em.radiance = radiance.data();
    em.cdf = cdf.data();
    em.density = density.data();
    return em;
}

py::tuple rays(const F64 &corners, const F64 &normal, const U8 &two_sided, const F64 &radiance,
               const F64 &cdf, const F64 &density, const F64 &point, const F64 &rec_normal,
               const F64 &shift, const F64 &sequence, double offset, int threads) {
    const voxgi::EmitterTriangles em = emitters(corners, normal, two_sided, radiance, cdf, density);
    check_2d(point, -1, 3, "point");
    const py::ssize_t n = point.shape(0);
    check_2d(rec_normal, n, 3, "normal of the records");
    check_2d(shift, n, 3, "shift");
    check_2d(sequence, -1, 3, "sequence");
    if (!(offset >= 0.0) || !std::isfinite(offset)) throw py::value_error("offset must be >= 0");
    voxgi::DirectLightQuery q;
    q.records = n;
    q.point = point.data();
    q.normal = rec_normal.data();
    q.shift = shift.data();
    q.samples = sequence.shape(0);
    q.sequence = sequence.data();
    q.offset = offset;
    const py::ssize_t m = n * q.samples;
    F32 org({m, py::ssize_t(3)}), dir({m, py::ssize_t(3)}), len({m}), con({m, py::ssize_t(3)});
    float *o = org.mutable_data(), *d = dir.mutable_data(), *l = len.mutable_data(),
          *c = con.mutable_data();
    const voxgi::StopCheck stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::direct_light_rays(em, q, o, d, l, c, voxgi::resolve_threads(threads), stop);
    }
    return py::make_tuple(org, dir, len, con);
}

py::tuple sum(const F32 &contribution, const I32 &hit, py::ssize_t samples, int threads) {
    check_2d(contribution, -1, 3, "contribution");
    const py::ssize_t m = contribution.shape(0);
    check_1d(hit, m, "hit");
    if (samples < 1 || m % samples != 0)
        throw py::value_error("samples must divide the number of rays");
    const py::ssize_t n = m / samples;
    F64 out({n, py::ssize_t(3)}), sq({n});
    const float *c = contribution.data();
    const int32_t *h = hit.data();
    double *o = out.mutable_data(), *s = sq.mutable_data();
    const voxgi::StopCheck stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::direct_light_sum(n, samples, c, h, o, s, voxgi::resolve_threads(threads), stop);
    }
    return py::make_tuple(out, sq);
}

}  // namespace

void bind_direct_light(py::module_ &m) {
    m.def("direct_light_rays", &rays, "corners"_a.noconvert(), "normal"_a.noconvert(),
          "two_sided"_a.noconvert(), "radiance"_a.noconvert(), "cdf"_a.noconvert(),
          "density"_a.noconvert(), "point"_a.noconvert(), "record_normal"_a.noconvert(),
          "shift"_a.noconvert(), "sequence"_a.noconvert(), "offset"_a, "threads"_a = 0,
          R"doc(Shadow rays from records to points drawn on the emitting triangles.

Returns (origin (M, 3) float32, direction (M, 3) float32, length (M,) float32,
contribution (M, 3) float32) with M = records x samples, record-major.)doc");
    m.def("direct_light_sum", &sum, "contribution"_a.noconvert(), "hit"_a.noconvert(),
          "samples"_a, "threads"_a = 0,
          R"doc(Per record: mean unoccluded contribution (N, 3) float64 and the mean
square of its luminance (N,) float64; hit != -1 marks an occluded ray.)doc");
}
