// pybind11 bindings of the reference and adjoint variants (reference.cpp),
// in the private submodule voxgi._core.testing: for the tests only.
#include "bind_lines.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

py::tuple gather_sorted(const voxgi::LineSystem& s, I32 families, F64 weights, F32 values,
                        I64 family_indices, bool want_vis, int threads,
                        std::optional<Bool> stand_in, bool transpose) {
    auto fams = to_families(families, weights);
    const py::ssize_t n = s.size();
    check_2d(values, n, 3, "values");
    check_selection(family_indices, fams.size());
    GatherArrays out(n, want_vis);
    const uint8_t* sb = flags_ptr(stand_in, n, "stand_in");
    const float* v = values.data();
    const int64_t* sel = family_indices.data();
    const py::ssize_t ns = family_indices.shape(0);
    double *o = out.sums.mutable_data(), *vp = out.vis_ptr();
    auto stop = make_stop_check();
    int64_t lines;
    {
        py::gil_scoped_release release;
        voxgi::GatherOptions opt;
        opt.stand_in = sb;
        opt.threads = threads;
        lines = voxgi::gather_sorted(s, fams.data(), sel, ns, v, o, vp, transpose, opt, stop);
    }
    return py::make_tuple(out.sums, out.vis_or_none(), lines);
}

py::tuple shoot_sender_side(const voxgi::LineSystem& s, I32 emitters, I32 families, F64 weights,
                            F32 values, F64 send_scale, F64 recv_area, int threads,
                            std::optional<Bool> stand_in) {
    auto fams = to_families(families, weights);
    const py::ssize_t n = s.size();
    check_1d(emitters, -1, "emitters");
    check_2d(values, n, 3, "values");
    check_1d(send_scale, n, "send_scale");
    check_1d(recv_area, n, "recv_area");
    const py::ssize_t ne = emitters.shape(0);
    F64 hd({n, py::ssize_t(3)});
    F64 unfound(ne);
    const int32_t* e = emitters.data();
    const float* v = values.data();
    const double *ss = send_scale.data(), *ra = recv_area.data();
    const uint8_t* sb = flags_ptr(stand_in, n, "stand_in");
    double *h = hd.mutable_data(), *u = unfound.mutable_data();
    auto stop = make_stop_check();
    voxgi::ShootCount count;
    {
        py::gil_scoped_release release;
        voxgi::ShootOptions opt;
        opt.stand_in = sb;
        opt.threads = threads;
        count = voxgi::shoot_sender_side(s, e, ne, fams.data(), static_cast<int64_t>(fams.size()),
                                         v, ss, ra, h, u, opt, stop);
    }
    return py::make_tuple(hd, unfound, count.rays, count.steps);
}

// Whether each array reaches the kernels aligned for its element type (the
// input aliases of bind_common.h promise it, whatever the caller passes).
py::tuple input_alignment(I32 i32, I64 i64, F32 f32, F64 f64) {
    auto aligned = [](const void* p, size_t a) { return reinterpret_cast<uintptr_t>(p) % a == 0; };
    return py::make_tuple(
        aligned(i32.data(), alignof(int32_t)), aligned(i64.data(), alignof(int64_t)),
        aligned(f32.data(), alignof(float)), aligned(f64.data(), alignof(double)));
}

}  // namespace

void bind_testing(py::module_& m) {
    py::module_ t = m.def_submodule(
        "testing", "Reference and adjoint variants of the kernels, for the tests only.");
    t.def("gather_sorted", &gather_sorted, "system"_a, "families"_a.noconvert(),
          "weights"_a.noconvert(), "values"_a.noconvert(), "family_indices"_a.noconvert(),
          "want_vis"_a = false, "threads"_a = 0, "stand_in"_a.noconvert() = py::none(),
          "transpose"_a = false,
          R"doc(LineSystem.gather by a counting sort of each family's records by line key.

Returns (sums, vis, lines) as LineSystem.gather. transpose: the transposed
operator over the same pairs (sums[partner] += values[x] * cos_x * weight:
x's weight, the partner receives); vis is unchanged by it.)doc");
    t.def("shoot_sender_side", &shoot_sender_side, "system"_a, "emitters"_a.noconvert(),
          "families"_a.noconvert(), "weights"_a.noconvert(), "values"_a.noconvert(),
          "send_scale"_a.noconvert(), "recv_area"_a.noconvert(), "threads"_a = 0,
          "stand_in"_a.noconvert() = py::none(),
          R"doc(LineSystem.shoot with the deposit on the sender side.

Each ray's power values[e] * cos_e * weight * send_scale[e] (send_scale =
area / S) is shared by its receivers in proportion to recv_area * cos_r; hd
holds power. Returns (hd, unfound, rays, steps) as LineSystem.shoot.)doc");
    t.def("input_alignment", &input_alignment, "i32"_a.noconvert(), "i64"_a.noconvert(),
          "f32"_a.noconvert(), "f64"_a.noconvert(),
          "Whether each array, as a kernel sees it, is aligned for its type: (4,) bools.");
}
