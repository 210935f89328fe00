// Internal to the voxelizer (voxelize.cpp, voxelize_records.cpp): the convex
// polygons both phases clip, the grid-space triangle, the (voxel, triangle)
// pairs that phase 1 emits and phase 3 reads, and phase 3's entry point.
// Not part of the module's interface (see voxelize.h).
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "voxelize.h"

namespace voxgi {
namespace voxelize_internal {

using Clock = std::chrono::steady_clock;
inline double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

// A convex polygon: a triangle (3) clipped by 6 planes has at most 9
// vertices; each cutting plane adds at most one more.
constexpr int kMaxV = 9 + kMaxCuts + 2;
struct Poly {
    int n = 0;
    bool overflow = false;
    double v[kMaxV][3];
    Poly() {}  // user-provided: no zeroing of v (hot path)
    void push(const double* p) {
        if (n == kMaxV) {
            overflow = true;
            return;
        }
        v[n][0] = p[0];
        v[n][1] = p[1];
        v[n][2] = p[2];
        ++n;
    }
};

// A read-only view of polygon vertices (a Poly, or a run of a vertex pool).
struct PolyView {
    const double (*v)[3];
    int n;
};
inline PolyView view(const Poly& P) { return PolyView{P.v, P.n}; }

inline double dot3(const double* a, const double* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
inline void cross3(const double* a, const double* b, double* o) {
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}

// Keep the part of `in` where sgn * (v[axis] - c) >= 0 (closed half-space).
// New vertices get v[axis] = c exactly, so neighbouring voxels' pieces share
// their boundary bit for bit.
inline void clip_axis(const Poly& in, Poly& out, int axis, double c, double sgn) {
    out.n = 0;
    out.overflow = in.overflow;
    const int n = in.n;
    for (int p = 0; p < n; ++p) {
        const double* a = in.v[p];
        const double* b = in.v[p + 1 == n ? 0 : p + 1];
        const double da = sgn * (a[axis] - c), db = sgn * (b[axis] - c);
        if (da >= 0) out.push(a);
        if ((da >= 0) != (db >= 0)) {
            const double t = da / (da - db);
            double q[3] = {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]),
                           a[2] + t * (b[2] - a[2])};
            q[axis] = c;
            out.push(q);
        }
    }
}

// Keep the part of `in` where sgn * (n·v - off) >= 0.
inline void clip_plane(const PolyView& in, Poly& out, const double* nrm, double off, double sgn) {
    out.n = 0;
    out.overflow = false;
    const int n = in.n;
    for (int p = 0; p < n; ++p) {
        const double* a = in.v[p];
        const double* b = in.v[p + 1 == n ? 0 : p + 1];
        const double da = sgn * (dot3(nrm, a) - off), db = sgn * (dot3(nrm, b) - off);
        if (da >= 0) out.push(a);
        if ((da >= 0) != (db >= 0)) {
            const double t = da / (da - db);
            const double q[3] = {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]),
                                 a[2] + t * (b[2] - a[2])};
            out.push(q);
        }
    }
}

// Area (along the unit normal n of the polygon's plane) and area-weighted
// centroid; the mean of the vertices when the area is zero.
inline double area_centroid(const PolyView& P, const double* n, double* c) {
    c[0] = c[1] = c[2] = 0;
    if (P.n == 0) return 0;
    double A = 0;
    const double* v0 = P.v[0];
    for (int i = 1; i + 1 < P.n; ++i) {
        const double e1[3] = {P.v[i][0] - v0[0], P.v[i][1] - v0[1], P.v[i][2] - v0[2]};
        const double e2[3] = {P.v[i + 1][0] - v0[0], P.v[i + 1][1] - v0[1], P.v[i + 1][2] - v0[2]};
        double cr[3];
        cross3(e1, e2, cr);
        const double a = 0.5 * dot3(cr, n);
        A += a;
        for (int d = 0; d < 3; ++d) c[d] += a * (v0[d] + P.v[i][d] + P.v[i + 1][d]);
    }
    if (A > 0) {
        for (int d = 0; d < 3; ++d) c[d] /= 3 * A;
        return A;
    }
    // Zero (or round-off negative) area: a segment or a point.
    c[0] = c[1] = c[2] = 0;
    for (int i = 0; i < P.n; ++i)
        for (int d = 0; d < 3; ++d) c[d] += P.v[i][d];
    for (int d = 0; d < 3; ++d) c[d] /= P.n;
    return 0;
}

// Closest point of the convex polygon P (plane normal n) to x; returns squared distance.
inline double closest_on_poly(const PolyView& P, const double* n, const double* x, double* out) {
    const double* v0 = P.v[0];
    const double h = (x[0] - v0[0]) * n[0] + (x[1] - v0[1]) * n[1] + (x[2] - v0[2]) * n[2];
    const double y[3] = {x[0] - h * n[0], x[1] - h * n[1], x[2] - h * n[2]};
    if (P.n >= 3) {
        bool pos = true, neg = true;
        for (int i = 0; i < P.n; ++i) {
            const double *a = P.v[i], *b = P.v[i + 1 == P.n ? 0 : i + 1];
            const double e[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            const double w[3] = {y[0] - a[0], y[1] - a[1], y[2] - a[2]};
            double cr[3];
            cross3(e, w, cr);
            const double s = dot3(cr, n);
            if (s < 0) pos = false;
            if (s > 0) neg = false;
        }
        if (pos || neg) {
            std::memcpy(out, y, sizeof(y));
            return h * h;
        }
    }
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < P.n; ++i) {
        const double *a = P.v[i], *b = P.v[i + 1 == P.n ? 0 : i + 1];
        const double e[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double ee = dot3(e, e);
        double t = 0;
        if (ee > 0) {
            const double w[3] = {x[0] - a[0], x[1] - a[1], x[2] - a[2]};
            t = std::min(1.0, std::max(0.0, dot3(w, e) / ee));
        }
        const double q[3] = {a[0] + t * e[0], a[1] + t * e[1], a[2] + t * e[2]};
        const double d[3] = {x[0] - q[0], x[1] - q[1], x[2] - q[2]};
        const double dd = dot3(d, d);
        if (dd < best) {
            best = dd;
            std::memcpy(out, q, sizeof(q));
        }
    }
    return best;
}

struct Pair {
    uint64_t key;
    uint32_t tri;
};

// Grid-space triangle and its unit normal; false when the normal is unusable.
struct Tri {
    double g[3][3];
    double n[3];
};
inline bool load_tri(const double* tris, int64_t t, const VoxelizeParams& P, Tri& T) {
    const double inv = 1.0 / P.pitch;
    for (int v = 0; v < 3; ++v)
        for (int d = 0; d < 3; ++d) T.g[v][d] = (tris[t * 9 + v * 3 + d] - P.origin[d]) * inv;
    const double e1[3] = {T.g[1][0] - T.g[0][0], T.g[1][1] - T.g[0][1], T.g[1][2] - T.g[0][2]};
    const double e2[3] = {T.g[2][0] - T.g[0][0], T.g[2][1] - T.g[0][1], T.g[2][2] - T.g[0][2]};
    double cr[3];
    cross3(e1, e2, cr);
    const double len = std::sqrt(dot3(cr, cr));
    // A normal needs a doubled area well above underflow: below 1e-200
    // voxel faces the triangle carries no light at any useful resolution.
    if (!(len > 1e-200) || !std::isfinite(len)) return false;
    for (int d = 0; d < 3; ++d) T.n[d] = cr[d] / len;
    return true;
}

inline void set_phase(VoxelizeProgress* progress, int ph, int64_t total) {
    if (!progress) return;
    progress->phase = ph;
    progress->done = 0;
    progress->total = total;
}

// Phase 3: the records of each voxel and its surface pieces, in chunks in
// voxel order. `pairs` are sorted by voxel key; voxel c's pairs are
// [starts[c], starts[c + 1]).
// Adds its counts, peak memory and seconds to `st`.
std::vector<VoxelChunk> cell_records(const double* tris, const int32_t* tri_object,
                                     const bool* two_sided, const float* albedo,
                                     const float* emission, const VoxelizeParams& P,
                                     const std::vector<Pair>& pairs,
                                     const std::vector<int64_t>& starts, int threads,
                                     const StopCheck& stop, VoxelizeStats& st,
                                     VoxelizeProgress* progress);

}  // namespace voxelize_internal
}  // namespace voxgi
