// Directions about a surface normal.
#pragma once

#include <algorithm>
#include <cmath>

namespace voxgi {

// Cosine-distributed direction about n (Malley's method) in an orthonormal
// frame built without branches (Duff et al. 2017).
inline void cosine_direction(const double n[3], double u1, double u2, double w[3]) {
    constexpr double kTwoPi = 6.28318530717958647692;
    const double sign = std::copysign(1.0, n[2]);
    const double a = -1.0 / (sign + n[2]), b = n[0] * n[1] * a;
    const double t[3] = {1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]};
    const double bt[3] = {b, sign + n[1] * n[1] * a, -n[1]};
    const double rad = std::sqrt(u1), phi = kTwoPi * u2;
    const double x = rad * std::cos(phi), y = rad * std::sin(phi),
                 z = std::sqrt(std::max(0.0, 1.0 - u1));
    for (int i = 0; i < 3; ++i) w[i] = x * t[i] + y * bt[i] + z * n[i];
}

}  // namespace voxgi
