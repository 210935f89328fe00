// pybind11 bindings for the display kernels.
#include "pycommon.h"

namespace py = pybind11;

void bind_display(py::module_ &m) {}
