// Direction families and their naive discrete lines: the key of a voxel's
// line in O(1) (docs/design.md §4).
#pragma once

#include <cmath>
#include <cstdint>

namespace voxgi {

// A direction family: the integer vector v and its opposite -v share one
// partition of space into naive discrete lines. `v` is stored with its main
// component (the largest |v_i|, lowest i on ties) positive.
struct Family {
    int32_t v[3];
    double weight;  // solid angle of each of +v and -v, divided by pi
};

// The unit vector of a family in float (the one every kernel uses for n.d).
inline void unit_direction(const Family& f, float d[3]) {
    const float len =
        std::sqrt(float(f.v[0]) * f.v[0] + float(f.v[1]) * f.v[1] + float(f.v[2]) * f.v[2]);
    for (int c = 0; c < 3; ++c) d[c] = f.v[c] / len;
}

// The naive-line key of voxel `ijk` for family `v` (main component > 0),
// relative to the box [lo, hi] (inclusive voxel bounds): two integers (u, w)
// packed as u * nw + w with 0 <= key < nu * nw.
struct LineFrame {
    int m, o1, o2;    // main axis and the two others (increasing order)
    int32_t A, B, C;  // |v| components along m, o1, o2 (A >= B, C >= 0)
    bool pos1, pos2;  // sign of v along o1, o2 (true: >= 0)
    int32_t lo[3], hi[3];
    int64_t XmA;     // multiple of A >= hi[m] - lo[m]: keeps numerators >= 0
    int64_t nu, nw;  // key ranges
    uint64_t magic;  // ceil(2^32 / A): exact division for numerators < 2^32 / A
    LineFrame(const int32_t v[3], const int32_t lo_[3], const int32_t hi_[3]);
    int64_t yprime(int32_t y) const { return pos1 ? y - lo[o1] : hi[o1] - y; }
    int64_t zprime(int32_t z) const { return pos2 ? z - lo[o2] : hi[o2] - z; }
    uint32_t div(uint64_t num) const { return static_cast<uint32_t>((num * magic) >> 32); }
    // key from main-axis-relative coordinates X' = x_m - lo[m], Y', Z':
    // key = u(X', Y') * nw + w(X', Z') (the one-pass walk forms the same key
    // from a constant per slab: SlabKey)
    uint32_t key(int64_t Xp, int64_t Yp, int64_t Zp) const {
        const uint64_t h = static_cast<uint64_t>(A / 2);
        const uint64_t u = div(static_cast<uint64_t>(A * Yp + B * (XmA - Xp)) + h);
        const uint64_t w = div(static_cast<uint64_t>(A * Zp + C * (XmA - Xp)) + h);
        return static_cast<uint32_t>(u * static_cast<uint64_t>(nw) + w);
    }
};

// LineFrame::key without a division per voxel. With X' fixed (one slab),
// u = floor((A Y' + B X' + h) / A) = Y' + floor((B X' + h) / A) exactly (A Y'
// is a multiple of A), the same for w, so the key u nw + w is Y' nw + Z' + (a
// constant of the slab). With Y' = y ys + yo and Z' = z zs + zo (ys, zs =
// +-1), a voxel's key is y (ys nw) + z zs + base: the divisions happen once
// per slab.
struct SlabKey {
    int64_t A, B, C, XmA, nw, half, xlo, yo, zo, ysn, zs;
    explicit SlabKey(const LineFrame& fr)
        : A(fr.A),
          B(fr.B),
          C(fr.C),
          XmA(fr.XmA),
          nw(fr.nw),
          half(fr.A / 2),
          xlo(fr.lo[fr.m]),
          yo(fr.pos1 ? -int64_t(fr.lo[fr.o1]) : int64_t(fr.hi[fr.o1])),
          zo(fr.pos2 ? -int64_t(fr.lo[fr.o2]) : int64_t(fr.hi[fr.o2])),
          ysn((fr.pos1 ? 1 : -1) * fr.nw),
          zs(fr.pos2 ? 1 : -1) {}
    // the constant of slab x (x_m)
    int64_t base(int32_t x) const {
        const int64_t Xr = XmA - (int64_t(x) - xlo);
        return (yo + (B * Xr + half) / A) * nw + zo + (C * Xr + half) / A;
    }
    uint32_t key(int32_t y, int32_t z, int64_t base) const {
        return static_cast<uint32_t>(int64_t(y) * ysn + int64_t(z) * zs + base);
    }
};

}  // namespace voxgi
