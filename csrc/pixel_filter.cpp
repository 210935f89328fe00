#include "pixel_filter.h"

#include <algorithm>
#include <cmath>

namespace voxgi {

void geometry_filter(const FilterPixels& px, int radius, const float* in, float* out, int threads,
                     const StopCheck& stop) {
    const int64_t W = px.width, H = px.height;
    parallel_for(H, threads, stop, [&](int64_t row, int) {
        for (int64_t col = 0; col < W; ++col) {
            const int64_t p = row * W + col;
            const int32_t m = px.material[p];
            if (m < 0 || m >= px.n_materials || px.glossy[m]) {
                for (int ch = 0; ch < 3; ++ch) out[3 * p + ch] += in[3 * p + ch];
                continue;
            }
            const double* x = px.pos + 3 * p;
            const float* n = px.normal + 3 * p;
            const double dist = std::sqrt((x[0] - px.eye[0]) * (x[0] - px.eye[0]) +
                                          (x[1] - px.eye[1]) * (x[1] - px.eye[1]) +
                                          (x[2] - px.eye[2]) * (x[2] - px.eye[2]));
            const double foot = px.pixel_angle * dist;
            const double plane = 2.0 * foot, reach2 = std::pow(3.0 * (radius + 1) * foot, 2);
            double sum[3] = {0.0, 0.0, 0.0};
            int count = 0;
            const int64_t r0 = std::max<int64_t>(0, row - radius);
            const int64_t r1 = std::min<int64_t>(H - 1, row + radius);
            const int64_t c0 = std::max<int64_t>(0, col - radius);
            const int64_t c1 = std::min<int64_t>(W - 1, col + radius);
            for (int64_t r = r0; r <= r1; ++r)
                for (int64_t c = c0; c <= c1; ++c) {
                    const int64_t q = r * W + c;
                    if (q != p) {
                        if (px.material[q] != m) continue;
                        const float* nq = px.normal + 3 * q;
                        if (n[0] * nq[0] + n[1] * nq[1] + n[2] * nq[2] <= 0.9f) continue;
                        const double* y = px.pos + 3 * q;
                        const double d[3] = {y[0] - x[0], y[1] - x[1], y[2] - x[2]};
                        if (std::abs(d[0] * n[0] + d[1] * n[1] + d[2] * n[2]) > plane) continue;
                        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > reach2) continue;
                    }
                    for (int ch = 0; ch < 3; ++ch) sum[ch] += in[3 * q + ch];
                    ++count;
                }
            for (int ch = 0; ch < 3; ++ch) out[3 * p + ch] += float(sum[ch] / count);
        }
    });
}

}  // namespace voxgi
