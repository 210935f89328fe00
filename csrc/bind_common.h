// pybind11 conversions and checks shared by the bind_*.cpp files.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>

#include "incidence_response.h"
#include "util/parallel.h"

namespace voxgi::py_helpers {
namespace py = pybind11;

// Arrays reach the kernels C-contiguous and aligned for their type. NumPy
// allows misaligned arrays (np.frombuffer at an odd offset; Dask and pickle
// protocol 5 hand workers buffers at any offset within a message), and a
// kernel reading int32 or double through a misaligned pointer is undefined
// behaviour: vectorized code may fault on it. pybind11 passes these flags to
// NumPy's conversion, which copies such an array (and only such an array).
constexpr int kInput = py::array::c_style | py::detail::npy_api::NPY_ARRAY_ALIGNED_;
using I32 = py::array_t<int32_t, kInput>;
using I64 = py::array_t<int64_t, kInput>;
using F32 = py::array_t<float, kInput>;
using F64 = py::array_t<double, kInput>;
using U8 = py::array_t<uint8_t, kInput>;
using U32 = py::array_t<uint32_t, kInput>;

// Arrays a kernel writes into in place are taken as they are, never copied
// (a copy would keep the answer from the caller): C-contiguous (noconvert),
// then check_inplace refuses one that is read-only or misaligned.
using I32Out = py::array_t<int32_t, py::array::c_style>;
using I64Out = py::array_t<int64_t, py::array::c_style>;
using F32Out = py::array_t<float, py::array::c_style>;

// A StopCheck for kernels running with the GIL released: at most every
// 50 ms it re-acquires the GIL and asks Python whether a signal (Ctrl-C)
// is pending. The pending KeyboardInterrupt stays set and is raised when
// the binding returns through `error_already_set`.
inline voxgi::StopCheck make_stop_check() {
    auto last =
        std::make_shared<std::chrono::steady_clock::time_point>(std::chrono::steady_clock::now());
    auto flagged = std::make_shared<bool>(false);
    return [last, flagged]() -> bool {
        if (*flagged) return true;
        auto now = std::chrono::steady_clock::now();
        if (now - *last < std::chrono::milliseconds(50)) return false;
        *last = now;
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) {
            *flagged = true;
            return true;
        }
        return false;
    };
}

template <class A>
void check_inplace(const A& a, const char* name) {
    if (!a.writeable()) throw py::value_error(std::string(name) + " must be writeable");
    if (reinterpret_cast<std::uintptr_t>(a.data()) % sizeof(typename A::value_type) != 0)
        throw py::value_error(std::string(name) + " must be aligned for its type");
}

// Check shape of a 2-D array: (n, cols), n == -1 accepts any n.
template <class A>
void check_2d(const A& a, py::ssize_t n, py::ssize_t cols, const char* name) {
    if (a.ndim() != 2 || a.shape(1) != cols || (n >= 0 && a.shape(0) != n))
        throw py::value_error(std::string(name) + " must have shape (" +
                              (n >= 0 ? std::to_string(n) : std::string("N")) + ", " +
                              std::to_string(cols) + ")");
}
template <class A>
void check_1d(const A& a, py::ssize_t n, const char* name) {
    if (a.ndim() != 1 || (n >= 0 && a.shape(0) != n))
        throw py::value_error(std::string(name) + " must have shape (" +
                              (n >= 0 ? std::to_string(n) : std::string("N")) + ",)");
}

// A table of incidence responses (T, kIncidenceNodes, 3), every entry
// finite and >= 0; returns T.
template <class A>
py::ssize_t check_incidence_table(const A& a, const char* name) {
    if (a.ndim() != 3 || a.shape(1) != kIncidenceNodes || a.shape(2) != 3)
        throw py::value_error(std::string(name) + " must have shape (T, " +
                              std::to_string(kIncidenceNodes) + ", 3)");
    const auto* v = a.data();
    for (py::ssize_t i = 0; i < a.size(); ++i)
        if (!(v[i] >= 0) || !std::isfinite(double(v[i])))
            throw py::value_error(std::string(name) + ": entry " + std::to_string(i) + " is " +
                                  std::to_string(double(v[i])) + ", not finite and >= 0");
    return a.shape(0);
}

}  // namespace voxgi::py_helpers
