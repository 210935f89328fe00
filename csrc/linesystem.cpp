// Preparing the records (orders, voxels, occupancy) and the normalisation
// S(n) (docs/design.md §3, §4).
#include "linesystem.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "lineorder.h"

namespace voxgi {

LineSystem::LineSystem(int64_t n, const int32_t* ijk, const float* normal, const float* point,
                       float epsilon, int history)
    : n_(n), eps_(epsilon), hist_(history), normal_(nullptr), point_(nullptr) {
    if (n < 1) throw std::invalid_argument("no records");
    if (n >= (int64_t(1) << 31) - 1) throw std::invalid_argument("too many records");
    if (history < 1 || history > kMaxHistory)
        throw std::invalid_argument("history must be in 1.." + std::to_string(kMaxHistory));
    for (int a = 0; a < 3; ++a) {
        lo_[a] = std::numeric_limits<int32_t>::max();
        hi_[a] = std::numeric_limits<int32_t>::min();
    }
    for (int64_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) {
            lo_[a] = std::min(lo_[a], ijk[3 * i + a]);
            hi_[a] = std::max(hi_[a], ijk[3 * i + a]);
        }
    for (int a = 0; a < 3; ++a)
        if (int64_t(hi_[a]) - lo_[a] >= (int64_t(1) << 24))
            throw std::invalid_argument("voxel coordinates span more than 2^24");
    own_normal_.assign(normal, normal + 3 * n);
    own_point_.assign(point, point + 3 * n);
    normal_ = own_normal_.data();
    point_ = own_point_.data();
    for (int m = 0; m < 3; ++m) {
        sort_axis(m, ijk);
        find_voxels(m);
    }
    // Voxel index from the (x, y, z) order (the occupancy bitset is built on
    // the first shoot: gathering does not need it).
    const Axis& a0 = ax_[0];
    for (int64_t i = 0; i < n; ++i) {
        const int64_t k = linear(a0.X[i], a0.Y[i], a0.Z[i]);
        if (vkey_.empty() || vkey_.back() != k) {
            vkey_.push_back(k);
            vstart_.push_back(static_cast<int32_t>(i));
        }
    }
    vstart_.push_back(static_cast<int32_t>(n));
}

// The lexicographic order of main axis m, keys (x_m, x_o1, x_o2): LSD
// counting sort, three stable passes, O(n + extent); then the records'
// coordinates, normals and points copied into that order.
void LineSystem::sort_axis(int m, const int32_t* ijk) {
    const int64_t n = n_;
    const int o1 = (m == 0) ? 1 : 0, o2 = (m == 2) ? 1 : 2;
    Axis& ax = ax_[m];
    std::vector<int32_t> tmp(n), cnt;
    ax.order.resize(n);
    std::iota(ax.order.begin(), ax.order.end(), 0);
    for (int a : {o2, o1, m}) {
        const int64_t ext = int64_t(hi_[a]) - lo_[a] + 1;
        cnt.assign(ext + 1, 0);
        for (int64_t i = 0; i < n; ++i) ++cnt[ijk[3 * int64_t(ax.order[i]) + a] - lo_[a] + 1];
        for (int64_t k = 0; k < ext; ++k) cnt[k + 1] += cnt[k];
        for (int64_t i = 0; i < n; ++i) {
            const int32_t r = ax.order[i];
            tmp[cnt[ijk[3 * int64_t(r) + a] - lo_[a]]++] = r;
        }
        ax.order.swap(tmp);
    }
    ax.X.resize(n);
    ax.Y.resize(n);
    ax.Z.resize(n);
    ax.nrm.resize(3 * n);
    ax.pt.resize(3 * n);
    ax.pn.assign(8 * n, 0.0f);
    for (int64_t i = 0; i < n; ++i) {
        const int64_t r = ax.order[i];
        ax.X[i] = ijk[3 * r + m];
        ax.Y[i] = ijk[3 * r + o1];
        ax.Z[i] = ijk[3 * r + o2];
        for (int c = 0; c < 3; ++c) {
            ax.nrm[3 * i + c] = normal_[3 * r + c];
            ax.pt[3 * i + c] = point_[3 * r + c];
            ax.pn[8 * i + c] = point_[3 * r + c];
            ax.pn[8 * i + 3 + c] = normal_[3 * r + c];
        }
    }
}

// The voxels and slabs of axis m's order, and which voxels hold twins.
void LineSystem::find_voxels(int m) {
    Axis& ax = ax_[m];
    for (int64_t i = 0; i < n_; ++i) {
        const bool slab = i == 0 || ax.X[i] != ax.X[i - 1];
        if (slab || ax.Y[i] != ax.Y[i - 1] || ax.Z[i] != ax.Z[i - 1]) {
            if (slab) ax.gslab.push_back(static_cast<int32_t>(ax.gstart.size()));
            ax.gstart.push_back(static_cast<int32_t>(i));
            ax.gflag.push_back(0);
        }
    }
    ax.gslab.push_back(static_cast<int32_t>(ax.gstart.size()));
    ax.gstart.push_back(static_cast<int32_t>(n_));
    ax.crossing.assign(n_, 0);
    for (size_t k = 0; k + 1 < ax.gstart.size(); ++k) {
        const int64_t i = ax.gstart[k], i1 = ax.gstart[k + 1];
        ax.gmax = std::max(ax.gmax, ax.gstart[k + 1] - ax.gstart[k]);
        bool one_plane = true;
        for (int64_t j = i + 1; j < i1; ++j) {
            const float *pj = &ax.pt[3 * j], *nj = &ax.nrm[3 * j];
            const float flip[3] = {-nj[0], -nj[1], -nj[2]};
            one_plane = one_plane && (same_plane(pj, nj, &ax.pt[3 * i], &ax.nrm[3 * i]) ||
                                      same_plane(pj, flip, &ax.pt[3 * i], &ax.nrm[3 * i]));
        }
        if (!one_plane) std::fill(ax.crossing.begin() + i, ax.crossing.begin() + i1, uint8_t(1));
        if (i1 - i != 2) continue;
        const float *p0 = &ax.pt[3 * i], *n0 = &ax.nrm[3 * i];
        bool twin = true;
        for (int c = 0; c < 3; ++c) twin = twin && p0[c] == p0[3 + c] && n0[c] == -n0[3 + c];
        if (twin) ax.gflag[k] |= Axis::kTwin;
    }
}

void LineSystem::build_occupancy() const {
    std::call_once(occ_once_, [this] {
        const int64_t nx = int64_t(hi_[0]) - lo_[0] + 1, ny = int64_t(hi_[1]) - lo_[1] + 1,
                      nz = int64_t(hi_[2]) - lo_[2] + 1;
        // one bit per voxel of the bounding box: 2^34 bits = 2 GiB at most
        if (nx * ny * nz > (int64_t(1) << 34))
            throw std::invalid_argument("voxel box too large for the shooting bitset");
        occ_.assign((nx * ny * nz + 63) / 64, 0);
        for (int64_t k : vkey_) occ_[k >> 6] |= uint64_t(1) << (k & 63);
        // vkey_ is sorted, so an occupied voxel's slot in it is the number of
        // set bits before its own: a prefix count per word and a popcount
        occ_rank_.resize(occ_.size());
        int64_t before = 0;
        for (size_t w = 0; w < occ_.size(); ++w) {
            occ_rank_[w] = static_cast<int32_t>(before);
            before += __builtin_popcountll(occ_[w]);
        }
    });
}

int64_t LineSystem::linear(int32_t x, int32_t y, int32_t z) const {
    const int64_t ny = int64_t(hi_[1]) - lo_[1] + 1, nz = int64_t(hi_[2]) - lo_[2] + 1;
    return ((int64_t(x) - lo_[0]) * ny + (int64_t(y) - lo_[1])) * nz + (int64_t(z) - lo_[2]);
}

void LineSystem::to_axis_order(int m, const float* val, std::vector<float>& out) const {
    out.resize(3 * n_);
    const int32_t* ord = ax_[m].order.data();
    for (int64_t i = 0; i < n_; ++i)
        for (int c = 0; c < 3; ++c) out[3 * i + c] = val[3 * int64_t(ord[i]) + c];
}

void LineSystem::keys(const int32_t v[3], uint32_t* out) const {
    LineFrame fr(v, lo_, hi_);
    const Axis& ax = ax_[fr.m];
    for (int64_t i = 0; i < n_; ++i)
        out[ax.order[i]] = fr.key(ax.X[i] - fr.lo[fr.m], fr.yprime(ax.Y[i]), fr.zprime(ax.Z[i]));
}

namespace {

// S depends on the normal only, and flat walls give many records one normal:
// the first record of every distinct normal (bit-exact equality) and, for
// every record, the index of its normal among them.
void distinct_normals(int64_t n, const float* normal, std::vector<int64_t>& first,
                      std::vector<int64_t>& which) {
    struct Key {
        uint32_t a, b, c;
        bool operator==(const Key& o) const { return a == o.a && b == o.b && c == o.c; }
    };
    struct Hash {
        size_t operator()(const Key& k) const {
            uint64_t h = k.a * 0x9E3779B97F4A7C15ull;
            h ^= (k.b + 0x7F4A7C15ull) * 0xC2B2AE3D27D4EB4Full;
            h ^= (k.c + 0x165667B1ull) * 0x94D049BB133111EBull;
            return static_cast<size_t>(h ^ (h >> 31));
        }
    };
    std::unordered_map<Key, int64_t, Hash> seen;
    seen.reserve(1024);
    which.resize(n);
    for (int64_t i = 0; i < n; ++i) {
        Key k;
        std::memcpy(&k.a, normal + 3 * i, 4);
        std::memcpy(&k.b, normal + 3 * i + 1, 4);
        std::memcpy(&k.c, normal + 3 * i + 2, 4);
        auto it = seen.emplace(k, static_cast<int64_t>(first.size()));
        if (it.second) first.push_back(i);
        which[i] = it.first->second;
    }
}

}  // namespace

void LineSystem::normalisation(const Family* fams, int64_t nf, double* S, int threads,
                               const StopCheck& stop) const {
    // Unit vectors once; each record sums |n.s| * weight over the families
    // (one of +v, -v faces it).
    std::vector<double> u(3 * nf);
    for (int64_t f = 0; f < nf; ++f) {
        const double l =
            std::sqrt(double(fams[f].v[0]) * fams[f].v[0] + double(fams[f].v[1]) * fams[f].v[1] +
                      double(fams[f].v[2]) * fams[f].v[2]);
        for (int c = 0; c < 3; ++c) u[3 * f + c] = fams[f].v[c] / l;
    }
    std::vector<int64_t> first, which;
    distinct_normals(n_, normal_, first, which);
    const int64_t nu = static_cast<int64_t>(first.size());
    std::vector<double> Su(nu);
    const int64_t chunk = 256;
    const int64_t tasks = (nu + chunk - 1) / chunk;
    // each normal's sum is made by one task, in family order
    parallel_for(tasks, resolve_threads(threads), stop, [&](int64_t t, int) {
        const int64_t b = t * chunk, e = std::min(nu, b + chunk);
        for (int64_t j = b; j < e; ++j) {
            const int64_t i = first[j];
            const double n0 = normal_[3 * i], n1 = normal_[3 * i + 1], n2 = normal_[3 * i + 2];
            double s = 0.0;
            for (int64_t f = 0; f < nf; ++f)
                s += std::abs(n0 * u[3 * f] + n1 * u[3 * f + 1] + n2 * u[3 * f + 2]) *
                     fams[f].weight;
            Su[j] = s;
        }
    });
    for (int64_t i = 0; i < n_; ++i) S[i] = Su[which[i]];
}

}  // namespace voxgi
