// pybind11 bindings of PairTable (pairtable.h).
#include "bind_lines.h"

namespace py = pybind11;
using namespace pybind11::literals;

void bind_pairtable(py::module_& m) {
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
        .def_property_readonly(
            "nbytes", [](const voxgi::PairTable& t) { return t.bytes(); },
            "Bytes of the table's blocks (address space; pages are used as they are written).")
        .def_property_readonly(
            "families", [](const voxgi::PairTable& t) { return t.nfam; },
            "Families of the set the table was made for.")
        .def_property_readonly(
            "recorded",
            [](const voxgi::PairTable& t) {
                int64_t k = 0;
                for (auto f : t.filled) k += f;
                return k;
            },
            "How many families' pairs are recorded.")
        .def_property_readonly(
            "recorded_mask",
            [](const voxgi::PairTable& t) {
                py::array_t<bool> out(static_cast<py::ssize_t>(t.filled.size()));
                bool* o = out.mutable_data();
                for (size_t f = 0; f < t.filled.size(); ++f) o[f] = t.filled[f] != 0;
                return out;
            },
            "(families,) bool: which families' pairs are recorded");
}
