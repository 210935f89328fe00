#include "batch_error.h"

#include <algorithm>
#include <cmath>

namespace voxgi {

void batch_error(const float* batches, int64_t k, int64_t n, double size, double frames,
                 double crit, double* stderr_out, uint8_t* flagged, int threads,
                 const StopCheck& stop) {
    constexpr int64_t kBlock = 4096;  // values per task: one pass over k rows of a block
    const int64_t tasks = (n + kBlock - 1) / kBlock;
    const double scale_se = size / frames;
    const bool test = k >= 4 && std::isfinite(crit);
    parallel_for(tasks, resolve_threads(threads), stop, [&](int64_t task, int) {
        const int64_t i0 = task * kBlock, i1 = std::min(n, i0 + kBlock);
        for (int64_t i = i0; i < i1; ++i) {
            double m = 0.0;
            for (int64_t j = 0; j < k; ++j) m += batches[j * n + i];
            m /= double(k);
            double ss = 0.0, jump = 0.0;
            for (int64_t j = 0; j < k; ++j) {
                const double d = batches[j * n + i] - m;
                ss += d * d;
                jump = std::max(jump, std::fabs(d));
            }
            double se = std::sqrt(ss / double(k - 1) * scale_se);
            uint8_t tail = 0;
            if (test) {
                const double rest = std::max(ss - jump * jump * (k / (k - 1.0)), 0.0);
                const double spread = std::sqrt(rest / double(k - 2) * (k - 1.0) / double(k));
                if (jump > crit * spread) {
                    tail = 1;
                    se = std::max(se, jump * scale_se);
                }
            }
            stderr_out[i] = se;
            flagged[i] = tail;
        }
    });
}

}  // namespace voxgi
