// pybind11 bindings for the voxelize kernels.
#include "pycommon.h"

namespace py = pybind11;

void bind_voxelize(py::module_ &m) {}
