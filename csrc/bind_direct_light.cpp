// Bindings of the direct-light kernels (direct_light.h).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <optional>

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

void set_incidence_response(voxgi::DirectLightQuery& q, const std::optional<F32>& response,
                            const std::optional<I32>& response_row) {
    if (response.has_value() != response_row.has_value())
        throw py::value_error("response and response_row go together");
    if (!response) return;
    const py::ssize_t rows = check_incidence_table(*response, "response");
    check_1d(*response_row, q.records, "response_row");
    const int32_t* rr = response_row->data();
    for (py::ssize_t r = 0; r < q.records; ++r)
        if (rr[r] >= rows)
            throw py::value_error("response_row: record " + std::to_string(r) + " names row " +
                                  std::to_string(rr[r]) + " of " + std::to_string(rows));
    q.response = response->data();
    q.response_row = rr;
}

py::tuple traced(const py::tuple& emit, const F64& point, const F64& normal, const F64& shift,
                 const F64& sequence, double offset, const I32& emitter_of,
                 const voxgi::RayScene& scene, const voxgi::RayScene* emitter_scene, int threads,
                 const std::optional<F64>& hemisphere_scale, bool strategies,
                 const std::optional<F32>& response, const std::optional<I32>& response_row,
                 const std::optional<F32>& response_base) {
    const Emitters held = emitters(emit);
    const voxgi::EmitterTriangles& em = held.em;
    voxgi::DirectLightQuery q = query(point, normal, shift, sequence, offset);
    if (hemisphere_scale) {
        check_1d(*hemisphere_scale, q.records, "hemisphere_scale");
        const double* hs = hemisphere_scale->data();
        for (py::ssize_t r = 0; r < q.records; ++r)
            if (!(hs[r] > 0.0) || !std::isfinite(hs[r]))
                throw py::value_error("hemisphere_scale: record " + std::to_string(r) + " has " +
                                      std::to_string(hs[r]) + ", not finite and > 0");
        q.hemisphere_scale = hs;
    }
    set_incidence_response(q, response, response_row);
    if (response_base) {
        if (!response) throw py::value_error("response_base needs response");
        if (check_incidence_table(*response_base, "response_base") != response->shape(0))
            throw py::value_error("response_base: as many rows as response");
        q.response_base = response_base->data();
    }
    check_1d(emitter_of, scene.triangle_count(), "emitter_of");
    const int32_t* eo = emitter_of.data();
    for (py::ssize_t t = 0; t < emitter_of.shape(0); ++t)
        if (eo[t] >= em.count) throw py::value_error("emitter_of: index past the emitters");
    if (emitter_scene && emitter_scene->triangle_count() != em.count)
        throw py::value_error("emitter_scene: " + std::to_string(emitter_scene->triangle_count()) +
                              " triangles for " + std::to_string(em.count) + " emitters");
    F64 out({q.records, py::ssize_t(3)}), sq({q.records});
    F64 var({strategies ? q.records : py::ssize_t(0), py::ssize_t(2)});
    double *po = out.mutable_data(), *ps = sq.mutable_data();
    double* pv = strategies ? var.mutable_data() : nullptr;
    F64 base({response_base ? q.records : py::ssize_t(0), py::ssize_t(3)});
    double* pb = response_base ? base.mutable_data() : nullptr;
    const voxgi::StopCheck stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::direct_light_traced(em, q, eo, scene, emitter_scene, po, ps, pv, pb,
                                   voxgi::resolve_threads(threads), stop);
    }
    if (response_base && strategies) return py::make_tuple(out, sq, var, base);
    if (response_base) return py::make_tuple(out, sq, py::none(), base);
    if (strategies) return py::make_tuple(out, sq, var);
    return py::make_tuple(out, sq);
}

}  // namespace

void bind_direct_light(py::module_& m) {
    m.def("direct_light_traced", &traced, "emitters"_a, "point"_a.noconvert(),
          "normal"_a.noconvert(), "shift"_a.noconvert(), "sequence"_a.noconvert(), "offset"_a,
          "emitter_of"_a.noconvert(), "scene"_a, "emitter_scene"_a = nullptr, "threads"_a = 0,
          "hemisphere_scale"_a.noconvert() = py::none(), "strategies"_a = false,
          "response"_a.noconvert() = py::none(), "response_row"_a.noconvert() = py::none(),
          "response_base"_a.noconvert() = py::none(),
          R"doc(Direct light on records from emitting triangles: light and hemisphere
samples (samples each) combined by the power heuristic, traced in scene (a
RayScene of the triangles emitter_of (F,) int32 indexes) record by record.

emitters: (corners (E,3,3), normal (E,3), two_sided (E,) uint8, radiance (E,3),
cdf (E,), density (E,)), float64 but two_sided. point, normal (N,3), shift
(N,5), sequence (S,5) float64. Returns the per-record irradiance (N,3) and
the mean square of the luminance of each light + hemisphere sample pair (N,),
float64.
emitter_scene (a RayScene of the emitters' corners alone, in their order;
None: not used): a hemisphere ray is traced against the emitters, and
against scene only up to the nearest emitter it meets.
hemisphere_scale (N,) float64, each > 0 (None: 1): the factor on the
hemisphere samples' density in each record's power heuristic (unbiased
for any). With strategies=True a third array (N,2): the variance of the
luminance of the light samples' and of the hemisphere samples' own
estimates, each alone. response (T, 33, 3) float32 and response_row (N,)
int32 (-1: none): each sample's light weighed by its record's row of R / A
at the sample's cosine (voxgi.incidence). With response_base (T, 33, 3) the
tuple's fourth item (N, 3): the same samples weighed by its rows (the
base's share; the third item is then None without strategies).)doc");
}
