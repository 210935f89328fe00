// Bindings of the direct-light kernels (direct_light.h).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>

#include "bind_common.h"
#include "direct_light.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

// An EmitterTriangles and the arrays behind it, checked. The arrays are held
// here: an input that needs converting (another dtype, not contiguous) is a
// new array that nothing else keeps alive.
struct Emitters {
    F64 corners, normal, radiance, cdf, density;
    U8 two_sided;
    voxgi::EmitterTriangles em;
};

Emitters emitters(const py::tuple& t) {
    if (t.size() != 6) throw py::value_error("emitters: expected 6 arrays");
    Emitters e{t[0].cast<F64>(),
               t[1].cast<F64>(),
               t[3].cast<F64>(),
               t[4].cast<F64>(),
               t[5].cast<F64>(),
               t[2].cast<U8>(),
               {}};
    if (e.corners.ndim() != 3 || e.corners.shape(1) != 3 || e.corners.shape(2) != 3)
        throw py::value_error("emitters: corners must have shape (E, 3, 3)");
    const py::ssize_t n = e.corners.shape(0);
    if (n == 0) throw py::value_error("emitters: no emitting triangle");
    check_2d(e.normal, n, 3, "emitters: normal");
    check_1d(e.two_sided, n, "emitters: two_sided");
    check_2d(e.radiance, n, 3, "emitters: radiance");
    check_1d(e.cdf, n, "emitters: cdf");
    check_1d(e.density, n, "emitters: density");
    e.em.count = n;
    e.em.corners = e.corners.data();
    e.em.normal = e.normal.data();
    e.em.two_sided = e.two_sided.data();
    e.em.radiance = e.radiance.data();
    e.em.cdf = e.cdf.data();
    e.em.density = e.density.data();
    return e;
}

voxgi::DirectLightQuery query(const F64& point, const F64& normal, const F64& shift,
                              const F64& sequence, double offset) {
    check_2d(point, -1, 3, "point");
    const py::ssize_t n = point.shape(0);
    check_2d(normal, n, 3, "normal");
    check_2d(shift, n, 5, "shift");
    check_2d(sequence, -1, 5, "sequence");
    if (!(offset >= 0.0) || !std::isfinite(offset)) throw py::value_error("offset must be >= 0");
    voxgi::DirectLightQuery q;
    q.records = n;
    q.point = point.data();
    q.normal = normal.data();
    q.shift = shift.data();
    q.samples = sequence.shape(0);
    q.sequence = sequence.data();
    q.offset = offset;
    return q;
}

py::tuple rays(const py::tuple& emit, const F64& point, const F64& normal, const F64& shift,
               const F64& sequence, double offset, int threads) {
    const Emitters held = emitters(emit);
    const voxgi::EmitterTriangles& em = held.em;
    const voxgi::DirectLightQuery q = query(point, normal, shift, sequence, offset);
    const py::ssize_t m = q.records * q.samples, three = 3;
    F32 lo({m, three}), ld({m, three}), ll({m}), con({m, three}), ho({m, three}), hd({m, three});
    float *plo = lo.mutable_data(), *pld = ld.mutable_data(), *pll = ll.mutable_data(),
          *pc = con.mutable_data(), *pho = ho.mutable_data(), *phd = hd.mutable_data();
    const voxgi::StopCheck stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::direct_light_rays(em, q, plo, pld, pll, pc, pho, phd,
                                 voxgi::resolve_threads(threads), stop);
    }
    return py::make_tuple(lo, ld, ll, con, ho, hd);
}

py::tuple sum(const py::tuple& emit, const F64& point, const F64& normal, const F64& shift,
              const F64& sequence, double offset, const F32& contribution, const I32& light_hit,
              const F32& hemi_direction, const I32& hemi_hit, const F32& hemi_u, const F32& hemi_v,
              const I32& emitter_of, int threads) {
    const Emitters held = emitters(emit);
    const voxgi::EmitterTriangles& em = held.em;
    const voxgi::DirectLightQuery q = query(point, normal, shift, sequence, offset);
    const py::ssize_t m = q.records * q.samples;
    check_2d(contribution, m, 3, "contribution");
    check_1d(light_hit, m, "light_hit");
    check_2d(hemi_direction, m, 3, "hemi_direction");
    check_1d(hemi_hit, m, "hemi_hit");
    check_1d(hemi_u, m, "hemi_u");
    check_1d(hemi_v, m, "hemi_v");
    check_1d(emitter_of, -1, "emitter_of");
    const int32_t* eo = emitter_of.data();
    for (py::ssize_t t = 0; t < emitter_of.shape(0); ++t)
        if (eo[t] >= em.count) throw py::value_error("emitter_of: index past the emitters");
    F64 out({q.records, py::ssize_t(3)}), sq({q.records});
    const float *pc = contribution.data(), *phd = hemi_direction.data(), *pu = hemi_u.data(),
                *pv = hemi_v.data();
    const int32_t *plh = light_hit.data(), *phh = hemi_hit.data();
    double *po = out.mutable_data(), *ps = sq.mutable_data();
    const int64_t nt = emitter_of.shape(0);
    const voxgi::StopCheck stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::direct_light_sum(em, q, pc, plh, phd, phh, pu, pv, eo, nt, po, ps,
                                voxgi::resolve_threads(threads), stop);
    }
    return py::make_tuple(out, sq);
}

py::tuple traced(const py::tuple& emit, const F64& point, const F64& normal, const F64& shift,
                 const F64& sequence, double offset, const I32& emitter_of,
                 const voxgi::RayScene& scene, const voxgi::RayScene* emitter_scene, int threads) {
    const Emitters held = emitters(emit);
    const voxgi::EmitterTriangles& em = held.em;
    const voxgi::DirectLightQuery q = query(point, normal, shift, sequence, offset);
    check_1d(emitter_of, scene.triangle_count(), "emitter_of");
    const int32_t* eo = emitter_of.data();
    for (py::ssize_t t = 0; t < emitter_of.shape(0); ++t)
        if (eo[t] >= em.count) throw py::value_error("emitter_of: index past the emitters");
    if (emitter_scene && emitter_scene->triangle_count() != em.count)
        throw py::value_error("emitter_scene: " + std::to_string(emitter_scene->triangle_count()) +
                              " triangles for " + std::to_string(em.count) + " emitters");
    F64 out({q.records, py::ssize_t(3)}), sq({q.records});
    double *po = out.mutable_data(), *ps = sq.mutable_data();
    const voxgi::StopCheck stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::direct_light_traced(em, q, eo, scene, emitter_scene, po, ps,
                                   voxgi::resolve_threads(threads), stop);
    }
    return py::make_tuple(out, sq);
}

}  // namespace

void bind_direct_light(py::module_& m) {
    m.def("direct_light_rays", &rays, "emitters"_a, "point"_a.noconvert(), "normal"_a.noconvert(),
          "shift"_a.noconvert(), "sequence"_a.noconvert(), "offset"_a, "threads"_a = 0,
          R"doc(The light and hemisphere rays of records (samples each, record-major).

emitters: (corners (E,3,3), normal (E,3), two_sided (E,) uint8, radiance (E,3),
cdf (E,), density (E,)), float64 but two_sided. point, normal (N,3), shift
(N,5), sequence (S,5) float64. Returns float32 arrays: light origin (M,3),
direction (M,3), length (M,), contribution (M,3), hemisphere origin (M,3) and
direction (M,3), M = N x S.)doc");
    m.def("direct_light_sum", &sum, "emitters"_a, "point"_a.noconvert(), "normal"_a.noconvert(),
          "shift"_a.noconvert(), "sequence"_a.noconvert(), "offset"_a, "contribution"_a.noconvert(),
          "light_hit"_a.noconvert(), "hemi_direction"_a.noconvert(), "hemi_hit"_a.noconvert(),
          "hemi_u"_a.noconvert(), "hemi_v"_a.noconvert(), "emitter_of"_a.noconvert(),
          "threads"_a = 0,
          R"doc(Per record: direct irradiance (N,3) float64 and the mean square of
the luminance of each light + hemisphere sample pair (N,) float64.)doc");
    m.def("direct_light_traced", &traced, "emitters"_a, "point"_a.noconvert(),
          "normal"_a.noconvert(), "shift"_a.noconvert(), "sequence"_a.noconvert(), "offset"_a,
          "emitter_of"_a.noconvert(), "scene"_a, "emitter_scene"_a = nullptr, "threads"_a = 0,
          R"doc(direct_light_rays, the rays traced in scene (a RayScene of the
triangles emitter_of indexes) and direct_light_sum, record by record without
ray arrays: the same per-record irradiance (N,3) and mean square (N,).
emitter_scene (a RayScene of the emitters' corners alone, in their order;
None: not used): a hemisphere ray is traced against the emitters, and
against scene only up to the nearest emitter it meets.)doc");
}
