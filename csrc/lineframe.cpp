#include "lineframe.h"

#include <algorithm>
#include <cstdlib>
#include <stdexcept>

namespace voxgi {

LineFrame::LineFrame(const int32_t v[3], const int32_t lo_[3], const int32_t hi_[3]) {
    m = 0;
    for (int i = 1; i < 3; ++i)
        if (std::abs(v[i]) > std::abs(v[m])) m = i;
    if (v[m] <= 0) throw std::invalid_argument("family vector must have a positive main component");
    o1 = (m == 0) ? 1 : 0;
    o2 = (m == 2) ? 1 : 2;
    A = v[m];
    B = std::abs(v[o1]);
    C = std::abs(v[o2]);
    pos1 = v[o1] >= 0;
    pos2 = v[o2] >= 0;
    for (int i = 0; i < 3; ++i) {
        lo[i] = lo_[i];
        hi[i] = hi_[i];
    }
    const int64_t Xr = int64_t(hi[m]) - lo[m];
    XmA = ((Xr + A - 1) / A) * A;
    const int64_t h = A / 2;
    const int64_t maxu = A * (int64_t(hi[o1]) - lo[o1]) + B * XmA + h;
    const int64_t maxw = A * (int64_t(hi[o2]) - lo[o2]) + C * XmA + h;
    // (num * ceil(2^32/A)) >> 32 == num / A exactly while
    // num * (ceil(2^32/A)*A - 2^32) < 2^32, which holds for num < 2^32 / A.
    if (std::max(maxu, maxw) >= (int64_t(1) << 32) / A)
        throw std::invalid_argument(
            "scene too large for 32-bit line keys at this direction radius");
    magic = ((uint64_t(1) << 32) + uint64_t(A) - 1) / uint64_t(A);
    nu = maxu / A + 1;
    nw = maxw / A + 1;
    if (nu * nw >= (int64_t(1) << 32))
        throw std::invalid_argument("too many lines for 32-bit keys");
}

}  // namespace voxgi
