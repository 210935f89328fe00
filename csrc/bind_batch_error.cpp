// pybind11 bindings for the batch-means error (batch_error.h).
#include <vector>

#include "batch_error.h"
#include "bind_common.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace voxgi::py_helpers;

namespace {

py::tuple batch_error_py(const F32& batches, double size, double frames, double crit, int threads) {
    if (batches.ndim() < 2) throw py::value_error("batches must have shape (k, ...)");
    const py::ssize_t k = batches.shape(0);
    if (k < 2) throw py::value_error("batch_error needs at least 2 batches");
    if (!(size > 0.0) || !(frames >= size * k) || !std::isfinite(frames))
        throw py::value_error("frames must hold the k batches of size frames each");
    if (!(crit > 0.0)) throw py::value_error("crit must be > 0 (inf: no heavy-tail test)");
    std::vector<py::ssize_t> shape(batches.shape() + 1, batches.shape() + batches.ndim());
    const py::ssize_t n = batches.size() / k;
    F64 se(shape);
    U8 flagged(shape);
    const float* pb = batches.data();
    double* ps = se.mutable_data();
    uint8_t* pf = flagged.mutable_data();
    auto stop = make_stop_check();
    {
        py::gil_scoped_release release;
        voxgi::batch_error(pb, k, n, size, frames, crit, ps, pf, threads, stop);
    }
    return py::make_tuple(se, flagged);
}

}  // namespace

void bind_batch_error(py::module_& m) {
    m.def("batch_error", &batch_error_py, "batches"_a.noconvert(), "size"_a, "frames"_a, "crit"_a,
          "threads"_a = 0,
          R"doc(Per-value standard error of a running mean of `frames` frames from k
batch means (k, ...) float32 of `size` frames each, raised to the largest
single-batch jump where the farthest batch is an outlier beyond `crit`
(externally studentized; inf: no test). Returns (stderr float64, flagged
uint8), each of the batches' shape without k.)doc");
}
