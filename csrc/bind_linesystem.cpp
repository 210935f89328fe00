// pybind11 bindings of LineSystem (linesystem.h): the records prepared once,
// normalisation and line keys, and as its methods the passes over it:
// gathering walked (gather.h) or replayed (pairtable.h), shooting (shoot.h).
// Arrays are taken .noconvert() and C-contiguous; shapes are re-checked here
// so bad input is a ValueError, never a crash.
#include <memory>

#include "bind_lines.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

voxgi::LineSystem* make_system(const I32& ijk, const F32& normal, const F32& point, float epsilon,
                               int history) {
    check_2d(ijk, -1, 3, "ijk");
    const py::ssize_t n = ijk.shape(0);
    if (n < 1) throw py::value_error("ijk: no records");
    check_2d(normal, n, 3, "normal");
    check_2d(point, n, 3, "point");
    if (!std::isfinite(epsilon) || epsilon < 0)
        throw py::value_error("epsilon must be finite and >= 0");
    const int32_t* a = ijk.data();
    const float *b = normal.data(), *c = point.data();
    py::gil_scoped_release release;
    return new voxgi::LineSystem(n, a, b, c, epsilon, history);
}

py::array_t<double> normalisation(const voxgi::LineSystem& s, I32 families, F64 weights,
                                  int threads) {
    auto fams = to_families(families, weights);
    F64 out(s.size());
    double* o = out.mutable_data();
    auto stop = make_stop_check();
    py::gil_scoped_release release;
    s.normalisation(fams.data(), static_cast<int64_t>(fams.size()), o, threads, stop);
    return out;
}

py::tuple gather(const voxgi::LineSystem& s, I32 families, F64 weights, F32 values,
                 I64 family_indices, bool want_vis, int threads, std::optional<Bool> stand_in,
                 voxgi::PairTable* record) {
    auto fams = to_families(families, weights);
    const py::ssize_t n = s.size();
    check_2d(values, n, 3, "values");
    check_selection(family_indices, fams.size());
    GatherArrays out(n, want_vis);
    voxgi::GatherOptions opt;
    opt.stand_in = flags_ptr(stand_in, n, "stand_in");
    opt.record = record;
    opt.threads = threads;
    const float* v = values.data();
    const int64_t* sel = family_indices.data();
    const py::ssize_t ns = family_indices.shape(0);
    double *o = out.sums.mutable_data(), *vp = out.vis_ptr();
    auto stop = make_stop_check();
    int64_t lines;
    {
        py::gil_scoped_release release;
        lines = voxgi::gather(s, fams.data(), sel, ns, v, o, vp, opt, stop);
    }
    return py::make_tuple(out.sums, out.vis_or_none(), lines);
}

py::tuple gather_recorded(const voxgi::LineSystem& s, const voxgi::PairTable& table, F32 values,
                          I64 family_indices, bool want_vis, int threads) {
    const py::ssize_t n = s.size();
    check_2d(values, n, 3, "values");
    check_1d(family_indices, -1, "family_indices");
    GatherArrays out(n, want_vis);
    const float* v = values.data();
    const int64_t* sel = family_indices.data();
    const py::ssize_t ns = family_indices.shape(0);
    double *o = out.sums.mutable_data(), *vp = out.vis_ptr();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::gather_recorded(s, table, sel, ns, v, o, vp, threads, stop);
    }
    return py::make_tuple(out.sums, out.vis_or_none());
}

py::tuple shoot(const voxgi::LineSystem& s, I32 emitters, I32 families, F64 weights, F32 values,
                int threads, std::optional<F64> coverage, std::optional<Bool> stand_in,
                std::optional<I32> object, std::optional<F64> sil_area, std::optional<Bool> back) {
    auto fams = to_families(families, weights);
    const py::ssize_t n = s.size();
    check_1d(emitters, -1, "emitters");
    check_2d(values, n, 3, "values");
    const py::ssize_t ne = emitters.shape(0);
    voxgi::ShootOptions opt;
    opt.threads = threads;
    if (coverage) {
        check_1d(*coverage, n, "coverage");
        opt.coverage = coverage->data();
    }
    if (object.has_value() != sil_area.has_value() || object.has_value() != back.has_value())
        throw py::value_error("object, sil_area and back go together");
    if (object) {
        check_1d(*object, n, "object");
        check_1d(*sil_area, n, "sil_area");
        opt.object = object->data();
        opt.sil_area = sil_area->data();
        opt.back = flags_ptr(back, n, "back");
    }
    opt.stand_in = flags_ptr(stand_in, n, "stand_in");
    F64 hd({n, py::ssize_t(3)});
    F64 unfound(ne);
    const int32_t* e = emitters.data();
    const float* v = values.data();
    double *h = hd.mutable_data(), *u = unfound.mutable_data();
    auto stop = make_stop_check();
    voxgi::ShootCount count;
    {
        py::gil_scoped_release release;
        count = voxgi::shoot(s, e, ne, fams.data(), static_cast<int64_t>(fams.size()), v, h, u, opt,
                             stop);
    }
    return py::make_tuple(hd, unfound, count.rays, count.steps);
}

py::array_t<uint32_t> keys(const voxgi::LineSystem& s, I32 v) {
    check_1d(v, 3, "v");
    int32_t vv[3] = {v.data()[0], v.data()[1], v.data()[2]};
    int m = 0;
    for (int i = 1; i < 3; ++i)
        if (std::abs(vv[i]) > std::abs(vv[m])) m = i;
    if (vv[m] <= 0) throw py::value_error("v: the largest component must be positive");
    py::array_t<uint32_t> out(s.size());
    s.keys(vv, out.mutable_data());
    return out;
}

py::array_t<double> gather_families(I32 ijk, F32 normal, F32 point, I32 families, F64 weights,
                                    F32 values, I64 family_indices, float epsilon, int history,
                                    int threads, std::optional<Bool> stand_in) {
    std::unique_ptr<voxgi::LineSystem> s(make_system(ijk, normal, point, epsilon, history));
    py::tuple r =
        gather(*s, families, weights, values, family_indices, false, threads, stand_in, nullptr);
    return r[0].cast<py::array_t<double>>();
}

constexpr const char* kLineSystemDoc = R"doc(
Records prepared for discrete-line propagation (docs/design.md §4).

Parameters
----------
ijk : (N, 3) int32
    Voxel coordinates.
normal : (N, 3) float32
    Unit normals.
point : (N, 3) float32
    A point of each record's surface in voxel units (voxel ijk spans [ijk, ijk + 1]).
epsilon : float
    Facing-rule margin in voxel units (records of one band on opposite sides fail it).
history : int
    F records a receiver passes over in its search along a line (1..32; a
    run of them in one plane counts once).
)doc";

constexpr const char* kGatherDoc = R"doc(Jacobi gathering over a subset of direction families.

Returns (sums, vis, lines): sums (N, 3) float64, for every record the sum over
the selected families and both signs of values[partner] * cos * weight (not
divided by S); vis (N,) float64 the sum of cos * weight over the directions in
which the record found a partner (None unless want_vis); lines the number of
lines walked. Partial sums over disjoint subsets add up to the full gather;
the sums do not depend on threads. stand_in (N,) bool, optional: the back
records of closed objects (they send their front twin's value); two of them
never pair along a line, and a stand-in F is not occluded/answered by a
stand-in B. record (PairTable from make_pair_table for the same families and
stand-in flags, optional): also write the pairs found into it.)doc";

constexpr const char* kShootDoc =
    R"doc(Integer discrete rays from the emitter records along every direction they face.

Returns (hd, unfound, rays, steps): hd (N, 3) float64, per receiver the sum of
values[e] * cos_r * weight (added in emitter order: independent of threads);
unfound (E,) float64, per emitter the sum of cos_e * weight over its rays that
met no receiver; rays the number of rays (emitter x direction); steps the
voxels visited. With coverage (the records' areas in voxel units), each
deposit is scaled by the share of the line that e covers, coverage[e]
|n_e.d| / |d_m|, and records of e's own sheet do not occlude it; a negative
coverage[e] keeps the whole line for e. With stand_in (N,) bool (see gather),
a stand-in receiver takes the nearest facing F that is not a stand-in as its
sender. With object (N,) int32, sil_area (N,) float64 (every record's area in
voxel units) and back (N,) bool, a line that leaves an object through another
face of it (convex edge) within one step of its band of receivers only grazed
it: the share of the line that the band does not cover goes on, past that
object's F records, to the receivers behind (silhouettes).)doc";

}  // namespace

void bind_linesystem(py::module_& m) {
    py::class_<voxgi::LineSystem>(m, "LineSystem", kLineSystemDoc)
        .def(py::init(&make_system), "ijk"_a.noconvert(), "normal"_a.noconvert(),
             "point"_a.noconvert(), "epsilon"_a = 0.05f, "history"_a = 8)
        .def_property_readonly("size", &voxgi::LineSystem::size, "Records N.")
        .def_property_readonly(
            "lo",
            [](const voxgi::LineSystem& s) {
                return py::make_tuple(s.lo()[0], s.lo()[1], s.lo()[2]);
            },
            "Lowest voxel coordinate of the records along each axis.")
        .def_property_readonly(
            "hi",
            [](const voxgi::LineSystem& s) {
                return py::make_tuple(s.hi()[0], s.hi()[1], s.hi()[2]);
            },
            "Highest voxel coordinate of the records along each axis.")
        .def("normalisation", &normalisation, "families"_a.noconvert(), "weights"_a.noconvert(),
             "threads"_a = 0,
             "Raw S(n) = sum over both signs of every family of max(0, n.s) * weight, (N,) "
             "float64.")
        .def("gather", &gather, "families"_a.noconvert(), "weights"_a.noconvert(),
             "values"_a.noconvert(), "family_indices"_a.noconvert(), "want_vis"_a = false,
             "threads"_a = 0, "stand_in"_a.noconvert() = py::none(), "record"_a = py::none(),
             kGatherDoc)
        .def(
            "make_pair_table",
            [](const voxgi::LineSystem& s, I32 families, F64 weights, bool with_stand_in) {
                auto fams = to_families(families, weights);
                py::gil_scoped_release release;
                return voxgi::make_pair_table(s, fams.data(), static_cast<int64_t>(fams.size()),
                                              with_stand_in);
            },
            "families"_a.noconvert(), "weights"_a.noconvert(), "with_stand_in"_a = false,
            R"doc(An empty PairTable for these families (3 bytes per record and family,
allocated as zero pages: memory is used as the pairs are written).)doc")
        .def("gather_recorded", &gather_recorded, "table"_a, "values"_a.noconvert(),
             "family_indices"_a.noconvert(), "want_vis"_a = false, "threads"_a = 0,
             R"doc(The gathering pass over recorded families, replayed from the table.

Returns (sums, vis) as gather does (the same pairs and weights; sums equal to
float rounding). Every family in family_indices must have been recorded.)doc")
        .def("shoot", &shoot, "emitters"_a.noconvert(), "families"_a.noconvert(),
             "weights"_a.noconvert(), "values"_a.noconvert(), "threads"_a = 0,
             "coverage"_a.noconvert() = py::none(), "stand_in"_a.noconvert() = py::none(),
             "object"_a.noconvert() = py::none(), "sil_area"_a.noconvert() = py::none(),
             "back"_a.noconvert() = py::none(), kShootDoc)
        .def("keys", &keys, "v"_a.noconvert(),
             "Line key of every record for family v, (N,) uint32.");

    m.def("gather_families", &gather_families, "ijk"_a.noconvert(), "normal"_a.noconvert(),
          "point"_a.noconvert(), "families"_a.noconvert(), "weights"_a.noconvert(),
          "values"_a.noconvert(), "family_indices"_a.noconvert(), "epsilon"_a = 0.05f,
          "history"_a = 8, "threads"_a = 0, "stand_in"_a.noconvert() = py::none(),
          R"doc(One Jacobi gathering pass over a subset of direction families.

Builds the line system from the records, gathers values over
families[family_indices] and returns the partial sums, (N, 3) float64 (see
LineSystem.gather); sums from disjoint subsets add up to the full pass.)doc");
}
