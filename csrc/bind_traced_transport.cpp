// pybind11 bindings for the traced passes' sparse matrix (traced_transport.h).
#include <pybind11/stl.h>

#include <optional>

#include "bind_common.h"
#include "traced_transport.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

int64_t transport_compact_py(int n, const std::optional<I32>& to_column, I32Out record,
                             F32Out weight, I64Out row_ptr, int threads) {
    if (n < 1) throw py::value_error("n must be >= 1");
    check_1d(record, -1, "record");
    const py::ssize_t R = record.shape(0);
    if (R % n != 0) throw py::value_error("record: length must be a multiple of n");
    const int64_t P = R / n;
    check_2d(weight, R, 3, "weight");
    check_1d(row_ptr, P + 1, "row_ptr");
    check_inplace(record, "record");
    check_inplace(weight, "weight");
    check_inplace(row_ptr, "row_ptr");
    int32_t* rc = record.mutable_data();
    const int32_t* tc = nullptr;
    if (to_column) {
        check_1d(*to_column, -1, "to_column");
        const py::ssize_t M = to_column->shape(0);
        for (py::ssize_t r = 0; r < R; ++r)
            if (rc[r] >= M) throw py::value_error("record: index beyond to_column");
        tc = to_column->data();
    }
    auto stop = make_stop_check();
    py::gil_scoped_release release;
    return voxgi::transport_compact(P, n, tc, rc, weight.mutable_data(), row_ptr.mutable_data(),
                                    threads, stop);
}

void transport_apply_py(const I64& row_ptr, const I32& column, const F32& weight, const F64& val,
                        py::array_t<double, py::array::c_style> out, int threads) {
    check_1d(row_ptr, -1, "row_ptr");
    const int64_t P = row_ptr.shape(0) - 1;
    if (P < 0) throw py::value_error("row_ptr must have P + 1 entries");
    check_1d(column, -1, "column");
    const py::ssize_t nnz = column.shape(0);
    check_2d(weight, nnz, 3, "weight");
    check_2d(val, -1, 3, "val");
    check_2d(out, P, 3, "out");
    check_inplace(out, "out");
    const int64_t* rp = row_ptr.data();
    if (rp[0] != 0 || rp[P] != nnz) throw py::value_error("row_ptr: bad bounds");
    for (int64_t p = 0; p < P; ++p)
        if (rp[p + 1] < rp[p]) throw py::value_error("row_ptr must be ascending");
    auto stop = make_stop_check();
    py::gil_scoped_release release;
    voxgi::transport_apply(P, val.shape(0), rp, column.data(), weight.data(), val.data(),
                           out.mutable_data(), threads, stop);
}

}  // namespace

void bind_traced_transport(py::module_& m) {
    m.def("transport_compact", &transport_compact_py, "n"_a, "to_column"_a.noconvert(),
          "record"_a.noconvert(), "weight"_a.noconvert(), "row_ptr"_a.noconvert(), "threads"_a = 0,
          R"doc(In place: the n rays of each row of record (P * n,) int32 and weight
(P * n, 3) float32, as gather_light's transport_record and transport_weight
hold them, become that row's distinct columns (to_column[record], or the
record itself when to_column is None), ascending, each with the sum of its
rays' weights; rays that read nothing or with weight 0 are dropped. The rows
are moved to the front: row p holds entries [row_ptr[p], row_ptr[p + 1])
(row_ptr (P + 1,) int64, written). Returns the number of entries.)doc");
    m.def("transport_apply", &transport_apply_py, "row_ptr"_a.noconvert(), "column"_a.noconvert(),
          "weight"_a.noconvert(), "val"_a.noconvert(), "out"_a.noconvert(), "threads"_a = 0,
          R"doc(out[p] = sum of weight[e] * val[column[e]] over the entries e of row p
(row_ptr (P + 1,) int64, column (nnz,) int32, weight (nnz, 3) float32,
val (N, 3) float64), per channel, summed in double; out (P, 3) float64 is
overwritten. The same for any thread count.)doc");
}
