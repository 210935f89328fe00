// How a record's reflectance depends on where its light comes from
// (docs/design.md §14): a record of a glossy material reflects the light
// arriving at cos θ with its directional albedo R(cos θ), not with the mean
// A the solve multiplies by, so the light it gathers is weighed by R / A.
// A table row holds R / A per channel at kIncidenceNodes cosines i / (nodes - 1).
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <algorithm>
#include <cstdint>

namespace voxgi {

constexpr int kIncidenceNodes = 33;

// R / A (3,) of table row `row` ((kIncidenceNodes, 3) float32, or null: 1)
// at incidence cosine mu, by linear interpolation.
inline void incidence_response(const float* row, double mu, double out[3]) {
    if (!row) {
        out[0] = out[1] = out[2] = 1.0;
        return;
    }
    const double x = std::clamp(mu, 0.0, 1.0) * (kIncidenceNodes - 1);
    const int i = std::min(int(x), kIncidenceNodes - 2);
    const double t = x - i;
    for (int c = 0; c < 3; ++c) out[c] = (1.0 - t) * row[3 * i + c] + t * row[3 * (i + 1) + c];
}

// The row of record r: table + 3 * nodes * row_of[r], or null where the
// record has none (row_of null or negative).
inline const float* incidence_row(const float* table, const int32_t* row_of, int64_t r) {
    if (!table || !row_of || row_of[r] < 0) return nullptr;
    return table + int64_t(3) * kIncidenceNodes * row_of[r];
}

}  // namespace voxgi
