// Bitmap texture lookups and means (see texture.h).
#include "texture.h"

#include <algorithm>
#include <cmath>

namespace voxgi {

namespace {

// The linear value of each 8-bit code: sRGB decoded (IEC 61966-2-1, as
// Mitsuba 3 decodes an 8-bit image) and, for a raw texture, code / 255.
struct LinearTables {
    float srgb[256], raw[256];
    LinearTables() {
        for (int i = 0; i < 256; ++i) {
            const double c = i / 255.0;
            srgb[i] = float(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
            raw[i] = float(c);
        }
    }
};
const LinearTables& tables() {
    static const LinearTables t;
    return t;
}

// Texel index i wrapped into [0, n).
inline int64_t wrap_index(int64_t i, int64_t n, Texture::Wrap w) {
    // inside the image every mode keeps it (and a division costs more
    // than the rest of a bilinear lookup)
    if (i >= 0 && i < n) return i;
    switch (w) {
        case Texture::kClamp:
            return std::min(std::max(i, int64_t(0)), n - 1);
        case Texture::kMirror: {
            const int64_t m = ((i % (2 * n)) + 2 * n) % (2 * n);
            return m < n ? m : 2 * n - 1 - m;
        }
        default:
            return ((i % n) + n) % n;
    }
}

// The filtered texture at (u, v) already through to_uv, times the factor.
void lookup(const Texture& t, double u, double v, const float* lin, float out[3]) {
    if (!std::isfinite(u) || !std::isfinite(v)) u = v = 0.0;
    const int64_t W = t.width, H = t.height;
    auto texel = [&](int64_t x, int64_t y) {
        return t.texels + 3 * (wrap_index(y, H, t.wrap) * W + wrap_index(x, W, t.wrap));
    };
    if (t.filter == Texture::kNearest) {
        const uint8_t* p =
            texel(int64_t(std::floor(u * double(W))), int64_t(std::floor(v * double(H))));
        for (int c = 0; c < 3; ++c) out[c] = lin[p[c]] * t.factor[c];
        return;
    }
    // bilinear between the four texel centres around (u W - 1/2, v H - 1/2)
    const double x = u * double(W) - 0.5, y = v * double(H) - 0.5;
    const double fx0 = std::floor(x), fy0 = std::floor(y);
    const int64_t x0 = int64_t(fx0), y0 = int64_t(fy0);
    const float ax = float(x - fx0), ay = float(y - fy0);
    const uint8_t *p00 = texel(x0, y0), *p10 = texel(x0 + 1, y0), *p01 = texel(x0, y0 + 1),
                  *p11 = texel(x0 + 1, y0 + 1);
    for (int c = 0; c < 3; ++c) {
        const float top = lin[p00[c]] + ax * (lin[p10[c]] - lin[p00[c]]);
        const float bot = lin[p01[c]] + ax * (lin[p11[c]] - lin[p01[c]]);
        out[c] = (top + ay * (bot - top)) * t.factor[c];
    }
}

inline void to_uv(const Texture& t, double u, double v, double& s, double& r) {
    s = t.to_uv[0] * u + t.to_uv[1] * v + t.to_uv[2];
    r = t.to_uv[3] * u + t.to_uv[4] * v + t.to_uv[5];
}

}  // namespace

void texture_eval(const Texture& t, double u, double v, float out[3]) {
    double s, r;
    to_uv(t, u, v, s, r);
    lookup(t, s, r, t.raw ? tables().raw : tables().srgb, out);
}

void barycentric(const double v0[3], const double v1[3], const double v2[3], const double x[3],
                 double& b1, double& b2) {
    double e1[3], e2[3], q[3];
    for (int c = 0; c < 3; ++c) e1[c] = v1[c] - v0[c], e2[c] = v2[c] - v0[c], q[c] = x[c] - v0[c];
    // least squares on the plane: [e1 e2] (b1, b2) = q
    const double a = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2];
    const double b = e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2];
    const double d = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2];
    const double p = e1[0] * q[0] + e1[1] * q[1] + e1[2] * q[2];
    const double r = e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2];
    const double det = a * d - b * b;
    if (!(det > 0.0)) {
        b1 = b2 = 0.0;
        return;
    }
    b1 = (d * p - b * r) / det;
    b2 = (a * r - b * p) / det;
}

bool surface_albedo(const SurfaceTextures& s, int64_t tri, int32_t obj, double b1, double b2,
                    float out[3]) {
    if (!s.object_texture) return false;
    const int32_t k = s.object_texture[obj];
    if (k < 0) return false;
    const float* uv = s.corner_uv + 6 * tri;
    const double b0 = 1.0 - b1 - b2;
    const double u = b0 * uv[0] + b1 * uv[2] + b2 * uv[4];
    const double v = b0 * uv[1] + b1 * uv[3] + b2 * uv[5];
    texture_eval(s.textures[k], u, v, out);
    return true;
}

void texture_triangle_mean(const Texture& t, const double uv[3][2], double mean[3]) {
    double p[3][2];
    for (int i = 0; i < 3; ++i) to_uv(t, uv[i][0], uv[i][1], p[i][0], p[i][1]);
    const double e1[2] = {p[1][0] - p[0][0], p[1][1] - p[0][1]};
    const double e2[2] = {p[2][0] - p[0][0], p[2][1] - p[0][1]};
    // texels the triangle covers, and kSamplesPerTexel samples each (up to kMaxSplit²)
    const double texels =
        0.5 * std::fabs(e1[0] * e2[1] - e1[1] * e2[0]) * double(t.width) * double(t.height);
    const double want = std::ceil(std::sqrt(kSamplesPerTexel * std::min(texels, 1e12)));
    const int k = int(std::min<double>(kMaxSplit, std::max(1.0, want)));
    const float* lin = t.raw ? tables().raw : tables().srgb;
    double sum[3] = {0.0, 0.0, 0.0};
    auto sample = [&](double a, double b) {
        float f[3];
        lookup(t, p[0][0] + a * e1[0] + b * e2[0], p[0][1] + a * e1[1] + b * e2[1], lin, f);
        for (int c = 0; c < 3; ++c) sum[c] += f[c];
    };
    // the k² congruent sub-triangles of the k-fold split, each at its centroid
    for (int i = 0; i < k; ++i)
        for (int j = 0; i + j < k; ++j) {
            sample((i + 1.0 / 3.0) / k, (j + 1.0 / 3.0) / k);
            if (i + j < k - 1) sample((i + 2.0 / 3.0) / k, (j + 2.0 / 3.0) / k);
        }
    for (int c = 0; c < 3; ++c) mean[c] = sum[c] / double(k * k);
}

}  // namespace voxgi
