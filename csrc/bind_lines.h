// Conversions shared by the bindings of the line system (bind_linesystem.cpp,
// bind_pairtable.cpp, bind_testing.cpp).
#pragma once

#include <pybind11/stl.h>

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "bind_common.h"
#include "gather.h"
#include "linesystem.h"
#include "pairtable.h"
#include "reference.h"
#include "shoot.h"

namespace voxgi::py_helpers {

using Bool = py::array_t<bool, py::array::c_style>;

// (F, 3) int32 vectors and (F,) float64 weights -> families, checked.
inline std::vector<Family> to_families(const I32& families, const F64& weights) {
    check_2d(families, -1, 3, "families");
    check_1d(weights, families.shape(0), "weights");
    const py::ssize_t nf = families.shape(0);
    std::vector<Family> out(nf);
    const int32_t* v = families.data();
    const double* w = weights.data();
    for (py::ssize_t f = 0; f < nf; ++f) {
        int m = 0;
        for (int i = 1; i < 3; ++i)
            if (std::abs(v[3 * f + i]) > std::abs(v[3 * f + m])) m = i;
        if (v[3 * f + m] <= 0)
            throw py::value_error("families[" + std::to_string(f) +
                                  "]: the largest component (first on ties) must be positive");
        if (std::abs(v[3 * f + m]) > 4096) throw py::value_error("families: components too large");
        if (!std::isfinite(w[f]) || w[f] < 0)
            throw py::value_error("weights must be finite and >= 0");
        for (int c = 0; c < 3; ++c) out[f].v[c] = v[3 * f + c];
        out[f].weight = w[f];
    }
    return out;
}

// The optional per-record flags: (n,) bool, or nullptr.
inline const uint8_t* flags_ptr(const std::optional<Bool>& a, py::ssize_t n, const char* name) {
    if (!a) return nullptr;
    check_1d(*a, n, name);
    static_assert(sizeof(bool) == 1, "bool must be one byte");
    return reinterpret_cast<const uint8_t*>(a->data());
}

// (S,) int64 indices into the families, checked.
inline void check_selection(const I64& family_indices, size_t nf) {
    check_1d(family_indices, -1, "family_indices");
    const int64_t* sel = family_indices.data();
    for (py::ssize_t k = 0; k < family_indices.shape(0); ++k)
        if (sel[k] < 0 || sel[k] >= static_cast<int64_t>(nf))
            throw py::value_error("family_indices[" + std::to_string(k) +
                                  "] = " + std::to_string(sel[k]) + " is out of range");
}

// The (sums, vis) arrays a gathering fills: (n, 3) and (n,) or None.
struct GatherArrays {
    F64 sums, vis;
    bool want_vis;
    GatherArrays(py::ssize_t n, bool want)
        : sums({n, py::ssize_t(3)}), vis(want ? n : 0), want_vis(want) {}
    double* vis_ptr() { return want_vis ? vis.mutable_data() : nullptr; }
    py::object vis_or_none() const { return want_vis ? py::object(vis) : py::object(py::none()); }
};

}  // namespace voxgi::py_helpers
