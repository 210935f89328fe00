// The order of records along a line and the facing rule (docs/design.md §4),
// shared by the gathering walks and the shooting march.
#pragma once

#include <cmath>
#include <cstdint>

namespace voxgi {

constexpr float kTiny = 1e-6f;  // |n.d| below this: the record is parallel to d (neither F nor B)
constexpr int kMaxHistory = 32;
// The most F records one B looks at: a line grazing a face passes one of the
// face's records per voxel, which count as one against the history.
constexpr int kMaxChain = 4 * kMaxHistory;

// A record met on a line: its position (in some axis order or global), the
// depth of its surface point along d, and n.d.
struct Hit {
    int32_t p;
    float depth;
    float c;
};

// Order records of one voxel along d: by depth, then B (c < 0) before F.
inline void sort_group(Hit* g, int n) {
    for (int i = 1; i < n; ++i) {
        Hit h = g[i];
        int j = i - 1;
        while (j >= 0 && (g[j].depth > h.depth || (g[j].depth == h.depth && g[j].c > h.c))) {
            g[j + 1] = g[j];
            --j;
        }
        g[j + 1] = h;
    }
}

// B at pb (normal nb) and F at pf (normal nf) see each other when each lies
// strictly in front of the other's plane (by more than eps).
inline bool facing(const float* pf, const float* nf, const float* pb, const float* nb, float eps) {
    const float d0 = pb[0] - pf[0], d1 = pb[1] - pf[1], d2 = pb[2] - pf[2];
    return (d0 * nf[0] + d1 * nf[1] + d2 * nf[2] > eps) &&
           (-(d0 * nb[0] + d1 * nb[1] + d2 * nb[2]) > eps);
}

// Whether two records lie in one plane with one orientation (the records of
// one face along a line that grazes it): the facing rule's test against the
// F's plane gives them one answer.
inline bool same_plane(const float* pa, const float* na, const float* pb, const float* nb) {
    const float dn = na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2];
    const float off = (pa[0] - pb[0]) * nb[0] + (pa[1] - pb[1]) * nb[1] + (pa[2] - pb[2]) * nb[2];
    return dn > 1.0f - 1e-6f && std::fabs(off) < 1e-4f;
}

// Whether an F record at pf, older on a line than an F already answered by
// the B record at pw (normal nw), is hidden from later B records by that B's
// surface: it lies in front of it, as the answered F does. One behind that
// plane (or in it) sits on the far side of the surface, which then stands
// beside it in the line's voxels, not between: two surfaces crossing in a
// voxel (a thin wall meeting a floor) put records of both rooms on one line.
inline bool hidden_behind(const float* pf, const float* pw, const float* nw, float eps) {
    return (pf[0] - pw[0]) * nw[0] + (pf[1] - pw[1]) * nw[1] + (pf[2] - pw[2]) * nw[2] > eps;
}

}  // namespace voxgi
