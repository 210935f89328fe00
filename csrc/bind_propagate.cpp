// pybind11 bindings for the propagate kernels (propagate.h): the only
// pybind11 code for them. Arrays are taken .noconvert() and C-contiguous;
// shapes are re-checked here so bad input is a ValueError, never a crash.
#include <cmath>
#include <memory>
#include <string>
#include <optional>
#include <pybind11/stl.h>
#include <vector>

#include "propagate.h"
#include "pycommon.h"

namespace py = pybind11;
using namespace pybind11::literals;
using voxgi::py_helpers::check_1d;
using voxgi::py_helpers::check_2d;
using voxgi::py_helpers::F32;
using voxgi::py_helpers::F64;
using voxgi::py_helpers::I32;
using voxgi::py_helpers::I64;

namespace {

std::vector<voxgi::Family> to_families(const I32 &families, const F64 &weights) {
    check_2d(families, -1, 3, "families");
    check_1d(weights, families.shape(0), "weights");
    const py::ssize_t nf = families.shape(0);
    std::vector<voxgi::Family> out(nf);
    const int32_t *v = families.data();
    const double *w = weights.data();
    for (py::ssize_t f = 0; f < nf; ++f) {
        int m = 0;
        for (int i = 1; i < 3; ++i)
            if (std::abs(v[3 * f + i]) > std::abs(v[3 * f + m])) m = i;
        if (v[3 * f + m] <= 0)
            throw py::value_error("families[" + std::to_string(f) +
                                  "]: the largest component (first on ties) must be positive");
        if (std::abs(v[3 * f + m]) > 4096) throw py::value_error("families: components too large");
        if (!std::isfinite(w[f]) || w[f] < 0) throw py::value_error("weights must be finite and >= 0");
        for (int c = 0; c < 3; ++c) out[f].v[c] = v[3 * f + c];
        out[f].weight = w[f];
    }
    return out;
}

using Bool = py::array_t<bool, py::array::c_style>;

// The optional per-record stand-in flags: (n,) bool, or nullptr.
const uint8_t *stand_in_ptr(const std::optional<Bool> &a, py::ssize_t n) {
    if (!a) return nullptr;
    check_1d(*a, n, "stand_in");
    static_assert(sizeof(bool) == 1, "bool must be one byte");
    return reinterpret_cast<const uint8_t *>(a->data());
}

voxgi::LineSystem *make_system(const I32 &ijk, const F32 &normal, const F32 &point, float epsilon,
                               int history) {
    check_2d(ijk, -1, 3, "ijk");
    const py::ssize_t n = ijk.shape(0);
    if (n < 1) throw py::value_error("ijk: no records");
    check_2d(normal, n, 3, "normal");
    check_2d(point, n, 3, "point");
    if (!std::isfinite(epsilon) || epsilon < 0) throw py::value_error("epsilon must be finite and >= 0");
    const int32_t *a = ijk.data();
    const float *b = normal.data(), *c = point.data();
    py::gil_scoped_release release;
    return new voxgi::LineSystem(n, a, b, c, epsilon, history);
}

}  // namespace

void bind_propagate(py::module_ &m) {
    auto pair_table = py::class_<voxgi::PairTable>(m, "PairTable", R"doc(
The pairs of one direction set's gathering, recorded for replay
(LineSystem.make_pair_table, LineSystem.gather(record=...),
LineSystem.gather_recorded). ENTRY_BYTES (3) bytes per record and family,
each main axis's families padded to tiles of TILE; at most MAX_RECORDS
records.)doc");
    pair_table.attr("TILE") = voxgi::PairTable::kTile;
    pair_table.attr("ENTRY_BYTES") = voxgi::PairTable::kEntry;
    pair_table.attr("MAX_RECORDS") = voxgi::PairTable::kMaxRecords;
    pair_table
        .def_property_readonly("nbytes", [](const voxgi::PairTable &t) { return t.bytes(); })
        .def_property_readonly("families", [](const voxgi::PairTable &t) { return t.nfam; })
        .def_property_readonly("recorded", [](const voxgi::PairTable &t) {
            int64_t k = 0;
            for (auto f : t.filled) k += f;
            return k;
        })
        .def_property_readonly("recorded_mask", [](const voxgi::PairTable &t) {
            py::array_t<bool> out(static_cast<py::ssize_t>(t.filled.size()));
            bool *o = out.mutable_data();
            for (size_t f = 0; f < t.filled.size(); ++f) o[f] = t.filled[f] != 0;
            return out;
        }, "(families,) bool: which families' pairs are recorded");

    py::class_<voxgi::LineSystem>(m, "LineSystem", R"doc(
Records prepared for discrete-line propagation (DESIGN-NOTES §4).

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
    F records remembered per line (1..32).
)doc")
        .def(py::init(&make_system), "ijk"_a.noconvert(), "normal"_a.noconvert(), "point"_a.noconvert(),
             "epsilon"_a = 0.05f, "history"_a = 8)
        .def_property_readonly("size", &voxgi::LineSystem::size)
        .def_property_readonly("lo", [](const voxgi::LineSystem &s) {
            return py::make_tuple(s.lo()[0], s.lo()[1], s.lo()[2]);
        })
        .def_property_readonly("hi", [](const voxgi::LineSystem &s) {
            return py::make_tuple(s.hi()[0], s.hi()[1], s.hi()[2]);
        })
        .def(
            "normalisation",
            [](const voxgi::LineSystem &s, I32 families, F64 weights, int threads) {
                auto fams = to_families(families, weights);
                F64 out(s.size());
                double *o = out.mutable_data();
                auto stop = voxgi::py_helpers::make_stop_check();
                {
                    py::gil_scoped_release release;
                    s.normalisation(fams.data(), static_cast<int64_t>(fams.size()), o, threads, stop);
                }
                return out;
            },
            "families"_a.noconvert(), "weights"_a.noconvert(), "threads"_a = 0,
            "Raw S(n) = sum over both signs of every family of max(0, n.s) * weight, (N,) float64.")
        .def(
            "gather",
            [](const voxgi::LineSystem &s, I32 families, F64 weights, F32 values, I64 family_indices,
               bool want_vis, int threads, const std::string &algorithm, std::optional<Bool> stand_in,
               bool transpose, voxgi::PairTable *record) {
                if (algorithm != "onepass" && algorithm != "sort")
                    throw py::value_error("algorithm must be 'onepass' or 'sort'");
                auto fams = to_families(families, weights);
                const py::ssize_t n = s.size();
                check_2d(values, n, 3, "values");
                check_1d(family_indices, -1, "family_indices");
                const py::ssize_t ns = family_indices.shape(0);
                const int64_t *sel = family_indices.data();
                for (py::ssize_t k = 0; k < ns; ++k)
                    if (sel[k] < 0 || sel[k] >= static_cast<int64_t>(fams.size()))
                        throw py::value_error("family_indices[" + std::to_string(k) + "] = " +
                                              std::to_string(sel[k]) + " is out of range");
                F64 out({n, py::ssize_t(3)});
                F64 vis(want_vis ? n : 0);
                const float *v = values.data();
                double *o = out.mutable_data();
                double *vp = want_vis ? vis.mutable_data() : nullptr;
                const uint8_t *sb = stand_in_ptr(stand_in, n);
                auto stop = voxgi::py_helpers::make_stop_check();
                int64_t lines;
                {
                    py::gil_scoped_release release;
                    lines = s.gather(fams.data(), sel, ns, v, o, vp, threads, stop,
                                     algorithm == "onepass", sb, transpose, record);
                }
                return py::make_tuple(out, want_vis ? py::object(vis) : py::object(py::none()), lines);
            },
            "families"_a.noconvert(), "weights"_a.noconvert(), "values"_a.noconvert(),
            "family_indices"_a.noconvert(), "want_vis"_a = false, "threads"_a = 0,
            "algorithm"_a = "onepass", "stand_in"_a.noconvert() = py::none(),
            "transpose"_a = false, "record"_a = py::none(),
            R"doc(Jacobi gathering over a subset of direction families.

Returns (sums, vis, lines): sums (N, 3) float64, for every record the sum over
the selected families and both signs of values[partner] * cos * weight (not
divided by S); vis (N,) float64 the sum of cos * weight over the directions in
which the record found a partner (None unless want_vis); lines the number of
lines walked. Partial sums over disjoint subsets add up to the full gather.
stand_in (N,) bool, optional: the back records of closed objects (they send
their front twin's value); two of them never pair along a line, and a
stand-in F is not occluded/answered by a stand-in B. transpose: the transposed
operator over the same pairs (sums[partner] += values[x] * cos_x * weight: x's
weight, the partner receives); vis is unchanged. record (PairTable from
make_pair_table for the same families and stand-in flags, optional): also
write the pairs found into it (one-pass, not transposed).)doc")
        .def(
            "make_pair_table",
            [](const voxgi::LineSystem &s, I32 families, F64 weights, bool with_stand_in) {
                auto fams = to_families(families, weights);
                py::gil_scoped_release release;
                return s.make_pair_table(fams.data(), static_cast<int64_t>(fams.size()), with_stand_in);
            },
            "families"_a.noconvert(), "weights"_a.noconvert(), "with_stand_in"_a = false,
            R"doc(An empty PairTable for these families (4 bytes per record and family,
allocated as zero pages: memory is used as the pairs are written).)doc")
        .def(
            "gather_recorded",
            [](const voxgi::LineSystem &s, const voxgi::PairTable &table, F32 values, I64 family_indices,
               bool want_vis, int threads) {
                const py::ssize_t n = s.size();
                check_2d(values, n, 3, "values");
                check_1d(family_indices, -1, "family_indices");
                const py::ssize_t ns = family_indices.shape(0);
                F64 out({n, py::ssize_t(3)});
                F64 vis(want_vis ? n : 0);
                const float *v = values.data();
                const int64_t *sel = family_indices.data();
                double *o = out.mutable_data();
                double *vp = want_vis ? vis.mutable_data() : nullptr;
                auto stop = voxgi::py_helpers::make_stop_check();
                {
                    py::gil_scoped_release release;
                    s.gather_recorded(table, sel, ns, v, o, vp, threads, stop);
                }
                return py::make_tuple(out, want_vis ? py::object(vis) : py::object(py::none()));
            },
            "table"_a, "values"_a.noconvert(), "family_indices"_a.noconvert(), "want_vis"_a = false,
            "threads"_a = 0,
            R"doc(The gathering pass over recorded families, replayed from the table.

Returns (sums, vis) as gather does (the same pairs and weights; sums equal to
float rounding). Every family in family_indices must have been recorded.)doc")
        .def(
            "shoot",
            [](const voxgi::LineSystem &s, I32 emitters, I32 families, F64 weights, F32 values,
               int threads, std::optional<F64> send_scale, std::optional<F64> recv_area,
               std::optional<F64> coverage, std::optional<Bool> stand_in,
               std::optional<I32> object, std::optional<F64> sil_area, std::optional<Bool> back) {
                auto fams = to_families(families, weights);
                const py::ssize_t n = s.size();
                check_1d(emitters, -1, "emitters");
                check_2d(values, n, 3, "values");
                const py::ssize_t ne = emitters.shape(0);
                if (send_scale.has_value() != recv_area.has_value())
                    throw py::value_error("send_scale and recv_area go together");
                const double *ss = nullptr, *ra = nullptr;
                if (send_scale) {
                    check_1d(*send_scale, n, "send_scale");
                    check_1d(*recv_area, n, "recv_area");
                    ss = send_scale->data();
                    ra = recv_area->data();
                }
                const double *cov = nullptr;
                if (coverage) {
                    if (ss) throw py::value_error("coverage: only with the receiver-side deposit");
                    check_1d(*coverage, n, "coverage");
                    cov = coverage->data();
                }
                if (object.has_value() != sil_area.has_value() || object.has_value() != back.has_value())
                    throw py::value_error("object, sil_area and back go together");
                const int32_t *ob = nullptr;
                const double *sa = nullptr;
                if (object) {
                    if (ss) throw py::value_error("object: only with the receiver-side deposit");
                    check_1d(*object, n, "object");
                    check_1d(*sil_area, n, "sil_area");
                    ob = object->data();
                    sa = sil_area->data();
                }
                const uint8_t *bk = object ? stand_in_ptr(back, n) : nullptr;
                F64 hd({n, py::ssize_t(3)});
                F64 unfound(ne);
                const int32_t *e = emitters.data();
                const float *v = values.data();
                double *h = hd.mutable_data(), *u = unfound.mutable_data();
                const uint8_t *sb = stand_in_ptr(stand_in, n);
                auto stop = voxgi::py_helpers::make_stop_check();
                int64_t rays, steps = 0;
                {
                    py::gil_scoped_release release;
                    rays = s.shoot(e, ne, fams.data(), static_cast<int64_t>(fams.size()), v, h, u,
                                   threads, stop, &steps, ss, ra, cov, sb, ob, sa, bk);
                }
                return py::make_tuple(hd, unfound, rays, steps);
            },
            "emitters"_a.noconvert(), "families"_a.noconvert(), "weights"_a.noconvert(),
            "values"_a.noconvert(), "threads"_a = 0, "send_scale"_a.noconvert() = py::none(),
            "recv_area"_a.noconvert() = py::none(), "coverage"_a.noconvert() = py::none(),
            "stand_in"_a.noconvert() = py::none(), "object"_a.noconvert() = py::none(),
            "sil_area"_a.noconvert() = py::none(), "back"_a.noconvert() = py::none(),
            R"doc(Integer discrete rays from the emitter records along every direction they face.

Returns (hd, unfound, rays, steps): hd (N, 3) float64, per receiver the sum of
values[e] * cos_r * weight; unfound (E,) float64, per emitter the sum of
cos_e * weight over its rays that met no receiver; rays the number of rays
(emitter x direction); steps the voxels visited. With send_scale (area / S)
and recv_area (area), each ray's power val[e] * cos_e * weight * send_scale[e]
is shared by its receivers in proportion to recv_area * cos_r and hd holds
power (sender-side deposit). With coverage (the records' areas in voxel
units), each receiver-side deposit is scaled by the share of the line that e
covers, coverage[e] |n_e.d| / |d_m|, and records of e's own sheet do not
occlude it; a negative coverage[e] keeps the whole line for e. With stand_in
(N,) bool (see gather), a stand-in receiver takes the nearest facing F that is
not a stand-in as its sender. With object (N,) int32 and sil_area (N,) float64
(every record's area in voxel units), a line that leaves an object through
another face of it (convex edge) within one step of its band of receivers only
grazed it: the share of the line that the band does not cover goes on, past
that object's F records, to the receivers behind (silhouettes).)doc")
        .def(
            "keys",
            [](const voxgi::LineSystem &s, I32 v) {
                check_1d(v, 3, "v");
                int32_t vv[3] = {v.data()[0], v.data()[1], v.data()[2]};
                int m = 0;
                for (int i = 1; i < 3; ++i)
                    if (std::abs(vv[i]) > std::abs(vv[m])) m = i;
                if (vv[m] <= 0) throw py::value_error("v: the largest component must be positive");
                py::array_t<uint32_t> out(s.size());
                s.keys(vv, out.mutable_data());
                return out;
            },
            "v"_a.noconvert(), "Line key of every record for family v, (N,) uint32.");

    m.def(
        "gather_families",
        [](I32 ijk, F32 normal, F32 point, I32 families, F64 weights, F32 values, I64 family_indices,
           float epsilon, int history, int threads, std::optional<Bool> stand_in) {
            std::unique_ptr<voxgi::LineSystem> s(make_system(ijk, normal, point, epsilon, history));
            auto fams = to_families(families, weights);
            const py::ssize_t n = s->size();
            check_2d(values, n, 3, "values");
            check_1d(family_indices, -1, "family_indices");
            const py::ssize_t ns = family_indices.shape(0);
            const int64_t *sel = family_indices.data();
            for (py::ssize_t k = 0; k < ns; ++k)
                if (sel[k] < 0 || sel[k] >= static_cast<int64_t>(fams.size()))
                    throw py::value_error("family_indices out of range");
            F64 out({n, py::ssize_t(3)});
            const float *v = values.data();
            double *o = out.mutable_data();
            const uint8_t *sb = stand_in_ptr(stand_in, n);
            auto stop = voxgi::py_helpers::make_stop_check();
            {
                py::gil_scoped_release release;
                s->gather(fams.data(), sel, ns, v, o, nullptr, threads, stop, true, sb);
            }
            return out;
        },
        "ijk"_a.noconvert(), "normal"_a.noconvert(), "point"_a.noconvert(), "families"_a.noconvert(),
        "weights"_a.noconvert(), "values"_a.noconvert(), "family_indices"_a.noconvert(),
        "epsilon"_a = 0.05f, "history"_a = 8, "threads"_a = 0, "stand_in"_a.noconvert() = py::none(),
        R"doc(One Jacobi gathering pass over a subset of direction families (for a Dask worker).

Builds the line system from the records, gathers values over
families[family_indices] and returns the partial sums, (N, 3) float64 (see
LineSystem.gather); sums from disjoint subsets add up to the full pass.)doc");
}
