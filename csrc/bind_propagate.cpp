// pybind11 bindings for the propagate kernels.
#include "pycommon.h"

namespace py = pybind11;

void bind_propagate(py::module_ &m) {}
