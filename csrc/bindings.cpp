// The voxgi._core extension: gathers the per-kernel binding files.
#include <pybind11/pybind11.h>

#include "util/parallel.h"

namespace py = pybind11;

void bind_voxelize(py::module_& m);
void bind_pairtable(py::module_& m);
void bind_linesystem(py::module_& m);
void bind_testing(py::module_& m);
void bind_batch_error(py::module_& m);
void bind_camera(py::module_& m);
void bind_vpl_shade(py::module_& m);
void bind_gather_light(py::module_& m);
void bind_traced_transport(py::module_& m);
void bind_pixel_filter(py::module_& m);
void bind_direct_light(py::module_& m);
void bind_rays(py::module_& m);

PYBIND11_MODULE(_core, m) {
    m.doc() = "voxgi compiled core: voxelization, discrete-line propagation, VPL shading";
#ifdef VOXGI_VERSION
    m.attr("__version__") = VOXGI_VERSION;
#endif
    // Ctrl-C inside a kernel surfaces as KeyboardInterrupt.
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const voxgi::Interrupted&) {
            if (!PyErr_Occurred()) PyErr_SetNone(PyExc_KeyboardInterrupt);
            throw py::error_already_set();
        }
    });
    m.def(
        "hardware_threads", [] { return voxgi::resolve_threads(0); },
        "Number of hardware threads the kernels use when threads=None.");
    bind_voxelize(m);
    bind_pairtable(m);
    bind_linesystem(m);
    bind_testing(m);
    bind_batch_error(m);
    bind_camera(m);
    bind_vpl_shade(m);
    bind_gather_light(m);
    bind_traced_transport(m);
    bind_pixel_filter(m);
    bind_direct_light(m);
    bind_rays(m);
}
