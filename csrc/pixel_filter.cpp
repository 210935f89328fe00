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
            // A neighbour counts only with its mirror image through p: a mean
            // over point-symmetric pairs has no first moment, so a gradient of
            // the light across p leaves it unchanged, where a one-sided set of
            // neighbours (a pixel beside a corner or an outline) would shift it
            // toward that side by the gradient times a pixel.
            auto accepts = [&](int64_t r, int64_t c) {
                if (r < 0 || r >= H || c < 0 || c >= W) return false;
                const int64_t q = r * W + c;
                if (px.material[q] != m) return false;
                const float* nq = px.normal + 3 * q;
                if (n[0] * nq[0] + n[1] * nq[1] + n[2] * nq[2] <= 0.9f) return false;
                const double* y = px.pos + 3 * q;
                const double d[3] = {y[0] - x[0], y[1] - x[1], y[2] - x[2]};
                if (std::abs(d[0] * n[0] + d[1] * n[1] + d[2] * n[2]) > plane) return false;
                return d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= reach2;
            };
            double sum[3] = {in[3 * p], in[3 * p + 1], in[3 * p + 2]};
            int count = 1;
            // Half of the square's offsets; each stands for itself and its mirror.
            for (int dr = 0; dr <= radius; ++dr)
                for (int dc = dr == 0 ? 1 : -radius; dc <= radius; ++dc) {
                    if (!accepts(row + dr, col + dc) || !accepts(row - dr, col - dc)) continue;
                    const int64_t q0 = (row + dr) * W + col + dc, q1 = (row - dr) * W + col - dc;
                    for (int ch = 0; ch < 3; ++ch)
                        sum[ch] += double(in[3 * q0 + ch]) + in[3 * q1 + ch];
                    count += 2;
                }
            for (int ch = 0; ch < 3; ++ch) out[3 * p + ch] += float(sum[ch] / count);
        }
    });
}

}  // namespace voxgi
