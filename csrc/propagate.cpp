// Discrete-line propagation kernels (see propagate.h and DESIGN-NOTES §3-§5).
#include "propagate.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sys/mman.h>
#include <cstring>
#include <limits>
#include <mutex>
#include <numeric>
#include <stdexcept>
#include <string>
#include <unordered_map>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace voxgi {

namespace {

constexpr float kTiny = 1e-6f;  // |n.d| below this: the record is parallel to d (neither F nor B)
constexpr int kMaxHistory = 32;

// Floor division for a positive divisor (numerators may be negative).
inline int64_t floordiv(int64_t a, int64_t b) {
    int64_t q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

// A record met on a line: its position (in some axis order or global), the
// depth of its surface point along d, and n.d.
struct Hit {
    int32_t p;
    float depth;
    float c;
};

// Order records of one voxel along d: by depth, then B (c < 0) before F.
inline void sort_group(Hit *g, int n) {
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

inline float dot3(const float *a, const float *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// The facing rule (DESIGN-NOTES §4): B at pb (normal nb) and F at pf (normal
// nf) see each other when each lies strictly in front of the other's plane.
inline bool facing(const float *pf, const float *nf, const float *pb, const float *nb, float eps) {
    const float d0 = pb[0] - pf[0], d1 = pb[1] - pf[1], d2 = pb[2] - pf[2];
    return (d0 * nf[0] + d1 * nf[1] + d2 * nf[2] > eps) && (-(d0 * nb[0] + d1 * nb[1] + d2 * nb[2]) > eps);
}

}  // namespace

// ---------------------------------------------------------------- LineFrame

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
    // (num * ceil(2^32/A)) >> 32 == num / A exactly while num * (ceil(2^32/A)*A - 2^32) < 2^32,
    // which holds for num < 2^32 / A.
    if (std::max(maxu, maxw) >= (int64_t(1) << 32) / A)
        throw std::invalid_argument("scene too large for 32-bit line keys at this direction radius");
    magic = ((uint64_t(1) << 32) + uint64_t(A) - 1) / uint64_t(A);
    nu = maxu / A + 1;
    nw = maxw / A + 1;
    if (nu * nw >= (int64_t(1) << 32)) throw std::invalid_argument("too many lines for 32-bit keys");
}

// ---------------------------------------------------------------- LineSystem

LineSystem::LineSystem(int64_t n, const int32_t *ijk, const float *normal, const float *point,
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

    // One lexicographic order per main axis m, keys (x_m, x_o1, x_o2): LSD
    // counting sort, three stable passes, O(n + extent).
    std::vector<int32_t> tmp(n), cnt;
    for (int m = 0; m < 3; ++m) {
        const int o1 = (m == 0) ? 1 : 0, o2 = (m == 2) ? 1 : 2;
        Axis &ax = ax_[m];
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
                ax.nrm[3 * i + c] = normal[3 * r + c];
                ax.pt[3 * i + c] = point[3 * r + c];
                ax.pn[8 * i + c] = point[3 * r + c];
                ax.pn[8 * i + 3 + c] = normal[3 * r + c];
            }
        }
    }

    for (int m = 0; m < 3; ++m) {
        Axis &ax = ax_[m];
        for (int64_t i = 0; i < n; ++i) {
            const bool slab = i == 0 || ax.X[i] != ax.X[i - 1];
            if (slab || ax.Y[i] != ax.Y[i - 1] || ax.Z[i] != ax.Z[i - 1]) {
                if (slab) ax.gslab.push_back(static_cast<int32_t>(ax.gstart.size()));
                ax.gstart.push_back(static_cast<int32_t>(i));
                ax.gflag.push_back(0);
            }
        }
        ax.gslab.push_back(static_cast<int32_t>(ax.gstart.size()));
        ax.gstart.push_back(static_cast<int32_t>(n));
        for (size_t k = 0; k + 1 < ax.gstart.size(); ++k) {
            const int64_t i = ax.gstart[k];
            ax.gmax = std::max(ax.gmax, ax.gstart[k + 1] - ax.gstart[k]);
            if (ax.gstart[k + 1] - i != 2) continue;
            const float *p0 = &ax.pt[3 * i], *n0 = &ax.nrm[3 * i];
            bool twin = true;
            for (int c = 0; c < 3; ++c) twin = twin && p0[c] == p0[3 + c] && n0[c] == -n0[3 + c];
            if (twin) ax.gflag[k] |= Axis::kTwin;
        }
    }

    // Voxel index from the (x, y, z) order (the occupancy bitset is built on
    // the first shoot: gathering does not need it).
    const Axis &a0 = ax_[0];
    for (int64_t i = 0; i < n; ++i) {
        const int64_t k = linear(a0.X[i], a0.Y[i], a0.Z[i]);
        if (vkey_.empty() || vkey_.back() != k) {
            vkey_.push_back(k);
            vstart_.push_back(static_cast<int32_t>(i));
        }
    }
    vstart_.push_back(static_cast<int32_t>(n));
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

void LineSystem::to_axis_order(int m, const float *val, std::vector<float> &out) const {
    out.resize(3 * n_);
    const int32_t *ord = ax_[m].order.data();
    for (int64_t i = 0; i < n_; ++i)
        for (int c = 0; c < 3; ++c) out[3 * i + c] = val[3 * int64_t(ord[i]) + c];
}

void LineSystem::keys(const int32_t v[3], uint32_t *out) const {
    LineFrame fr(v, lo_, hi_);
    const Axis &ax = ax_[fr.m];
    for (int64_t i = 0; i < n_; ++i)
        out[ax.order[i]] = fr.key(ax.X[i] - fr.lo[fr.m], fr.yprime(ax.Y[i]), fr.zprime(ax.Z[i]));
}

void LineSystem::normalisation(const Family *fams, int64_t nf, double *S, int threads,
                               const StopCheck &stop) const {
    // Unit vectors once; each record sums |n.s| * weight over the families
    // (one of +v, -v faces it).
    std::vector<double> u(3 * nf);
    for (int64_t f = 0; f < nf; ++f) {
        const double l = std::sqrt(double(fams[f].v[0]) * fams[f].v[0] +
                                   double(fams[f].v[1]) * fams[f].v[1] +
                                   double(fams[f].v[2]) * fams[f].v[2]);
        for (int c = 0; c < 3; ++c) u[3 * f + c] = fams[f].v[c] / l;
    }
    // S depends on the normal only, and flat walls give many records one
    // normal: sum once per distinct normal (bit-exact equality), then copy.
    std::vector<int64_t> first;  // index of the first record of each distinct normal
    std::vector<int64_t> which(n_);
    {
        struct Key {
            uint32_t a, b, c;
            bool operator==(const Key &o) const { return a == o.a && b == o.b && c == o.c; }
        };
        struct Hash {
            size_t operator()(const Key &k) const {
                uint64_t h = k.a * 0x9E3779B97F4A7C15ull;
                h ^= (k.b + 0x7F4A7C15ull) * 0xC2B2AE3D27D4EB4Full;
                h ^= (k.c + 0x165667B1ull) * 0x94D049BB133111EBull;
                return static_cast<size_t>(h ^ (h >> 31));
            }
        };
        std::unordered_map<Key, int64_t, Hash> seen;
        seen.reserve(1024);
        for (int64_t i = 0; i < n_; ++i) {
            Key k;
            std::memcpy(&k.a, normal_ + 3 * i, 4);
            std::memcpy(&k.b, normal_ + 3 * i + 1, 4);
            std::memcpy(&k.c, normal_ + 3 * i + 2, 4);
            auto it = seen.emplace(k, static_cast<int64_t>(first.size()));
            if (it.second) first.push_back(i);
            which[i] = it.first->second;
        }
    }
    const int64_t nu = static_cast<int64_t>(first.size());
    std::vector<double> Su(nu);
    const int64_t chunk = 256;
    const int64_t tasks = (nu + chunk - 1) / chunk;
    parallel_for(tasks, resolve_threads(threads), stop, [&](int64_t t, int) {
        const int64_t b = t * chunk, e = std::min(nu, b + chunk);
        for (int64_t j = b; j < e; ++j) {
            const int64_t i = first[j];
            const double n0 = normal_[3 * i], n1 = normal_[3 * i + 1], n2 = normal_[3 * i + 2];
            double s = 0.0;
            for (int64_t f = 0; f < nf; ++f)
                s += std::abs(n0 * u[3 * f] + n1 * u[3 * f + 1] + n2 * u[3 * f + 2]) * fams[f].weight;
            Su[j] = s;
        }
    });
    for (int64_t i = 0; i < n_; ++i) S[i] = Su[which[i]];
}

// ---------------------------------------------------------------- gathering

namespace {

struct LineState {
    int32_t stamp;  // family pass that last wrote the entry (the one-pass walk: 2 * pass + 1 bit)
    int32_t last;   // newest F record on the line (axis-order position), -1: none
};

// Everything a pair of the one-pass walk touches for one record, in one
// 64-byte cache line: where a B record meets its partner F (a record far
// back along the line, i.e. a random place in memory), the facing test, the
// value sent and the value received all hit this one line instead of four
// arrays. Each thread owns a copy per main axis (acc is written). The walk
// along the records reads the compact per-axis normals and points instead
// (24 bytes a record, not 64), and keeps the line links in their own array
// (4 bytes a record, written for every record), so it streams a third of
// the bytes.
struct alignas(64) GatherRec {
    float pt[3];     // surface point (voxel units)
    float nrm[3];    // unit normal
    float val[3];    // value sent (RGB)
    uint32_t stand;  // 1: a stand-in (its flag on the line the pairing reads anyway); the line links live in GatherWork::lnk
    double acc[3];   // gathered (RGB), summed over this thread's families
};
static_assert(sizeof(GatherRec) == 64, "GatherRec must fill one cache line");
constexpr uint32_t kAnswered = 0x80000000u;

// facing() for the one-pass walk's records, B's point and normal held in
// registers across its chain. With SSE2 (every x86-64) the two dot
// products take one multiply each and their sums are made in facing()'s
// order ((x0 + x1) + x2: the same floats, bit for bit); lane 3 of each
// 16-byte load is the next field and is never summed.
struct FacingB {
#if defined(__SSE2__)
    __m128 p, n;
    explicit FacingB(const GatherRec &b) : p(_mm_loadu_ps(b.pt)), n(_mm_loadu_ps(b.nrm)) {}
    static float sum3(__m128 t) {
        const __m128 s = _mm_add_ss(t, _mm_shuffle_ps(t, t, _MM_SHUFFLE(1, 1, 1, 1)));
        return _mm_cvtss_f32(_mm_add_ss(s, _mm_shuffle_ps(t, t, _MM_SHUFFLE(2, 2, 2, 2))));
    }
    bool faces(const GatherRec &f, float eps) const {
        const __m128 d = _mm_sub_ps(p, _mm_loadu_ps(f.pt));
        return sum3(_mm_mul_ps(d, _mm_loadu_ps(f.nrm))) > eps && -sum3(_mm_mul_ps(d, n)) > eps;
    }
#else
    const GatherRec &b;
    explicit FacingB(const GatherRec &b_) : b(b_) {}
    bool faces(const GatherRec &f, float eps) const { return facing(f.pt, f.nrm, b.pt, b.nrm, eps); }
#endif
};

// A B record of the one-pass walk waiting for its partner: its position,
// the newest F of its line when it was met, and n.d.
struct PendingB {
    int32_t p, f;
    float c;
};

struct GatherWork {
    std::vector<LineState> table;
    int32_t stamp = 0;
    std::vector<uint32_t> key, cnt;
    std::vector<int32_t> line;
    std::vector<Hit> group;
    std::vector<double> acc[3], vis[3];  // per axis order (the counting-sort walk)
    // The one-pass walk: the records in the order of the main axis this
    // thread works on (rec_axis; -1: none yet), and the sums of the axes it
    // has left, in the global order. A thread takes families in by-axis
    // order, so it meets each axis once and one array is enough.
    std::vector<GatherRec> rec;
    int rec_axis = -1;
    std::vector<double> sums;
    std::vector<PendingB> pend;          // the one-pass walk's queued B records
    std::vector<uint32_t> lnk;           // per record (axis order): bits 0-30 previous F on the line + 1
                                         // (0: none), bit 31 answered; valid for F records
    std::vector<int32_t> rbuf;           // recording: one tile's columns, family-major
    bool used[3] = {false, false, false};
};

// One record of the one-pass walk (records of a line arrive in order along
// +v). An F record (c > 0) joins the line's history at once; a B record
// (c < 0) with an F behind it is queued: the pairs are made per slab (see
// pair_pending). Without branches (which of F, B or neither a record is, is
// a coin toss from one record to the next): the link is written for every
// record (only F records are ever read through it), the B entry is written
// always and kept by advancing the count.
inline void step_record(uint32_t *lnk, int32_t p, float c, int32_t &lastF, PendingB *pend, size_t &np) {
    lnk[p] = static_cast<uint32_t>(lastF + 1);
    pend[np] = PendingB{p, lastF, c};
    np += static_cast<size_t>((c < -kTiny) & (lastF >= 0));
    lastF = c > kTiny ? p : lastF;
}

// A queued B record receives from the newest F that faces it and answers
// every facing F back to the first one already answered (which occludes the
// older ones).
// `receiver` takes `sender`'s value with weight w (transposed: the other way
// round, with the same weight).
template <bool Transpose>
inline void add(GatherRec &receiver, GatherRec &sender, double w) {
    GatherRec &to = Transpose ? sender : receiver;
    const GatherRec &from = Transpose ? receiver : sender;
    to.acc[0] += from.val[0] * w;
    to.acc[1] += from.val[1] * w;
    to.acc[2] += from.val[2] * w;
}

// rt (nullable): the family's column of a PairTable (rt[p * rs] = sender + 1).
// Vis, Rec: vs, rt are set; Stand: the records carry stand-in flags (fixed
// for a family's walk, so they are template arguments, not branches in the
// chain loop).
template <bool Transpose, bool Vis, bool Rec, bool Stand>
inline void pair_record(GatherRec *rec, uint32_t *lnk, const PendingB &q, int K, float eps, double wgt, const float *dh,
                        double *vs, int32_t *rt, int64_t rs) {
    const int32_t p = q.p;
    GatherRec &rp = rec[p];
    const double cb = -double(q.c) * wgt;
    bool got = false;
    const bool sp = Stand && rp.stand;  // two stand-ins never pair
    int32_t f = q.f;
    const FacingB fb(rp);
    for (int h = 0; h < K && f >= 0; ++h) {
        GatherRec &rf = rec[f];
        const int32_t older = static_cast<int32_t>(lnk[f] & ~kAnswered) - 1;
        if ((Stand && sp && rf.stand) || !fb.faces(rf, eps)) {
            f = older;
            continue;
        }
        if (!got) {
            // p receives from f with weight cb; transposed, f takes p's value with it
            add<Transpose>(rp, rf, cb);
            if (Vis) vs[p] += cb;
            if (Rec) rt[p * rs] = f + 1;
            got = true;
        }
        if (lnk[f] & kAnswered) break;  // an answered facing F occludes the older ones
        const double cf = double(dot3(rf.nrm, dh)) * wgt;
        add<Transpose>(rf, rp, cf);
        if (Vis) vs[f] += cf;
        if (Rec) rt[int64_t(f) * rs] = p + 1;
        lnk[f] |= kAnswered;
        f = older;
    }
}

// Make the queued pairs of one slab (one x_m). Exact, not an approximation:
// the B records of a slab lie on distinct lines (a naive line has one voxel
// per x_m) except those of one voxel, which stay in order, and the F records
// pushed after a B in the slab are newer than its queued F, so a B's chain
// and the answered flags it reads are those of the record-by-record walk.
// What the queue buys: a B's partner is far back in memory (a random cache
// line), and with the queue in hand the partners of the pairs kAhead places
// on are prefetched while this pair waits for its own.
template <bool Transpose, bool Vis, bool Rec, bool Stand>
inline void pair_pending(GatherRec *rec, uint32_t *lnk, const PendingB *pend, size_t np, int K, float eps, double wgt,
                         const float *dh, double *vs, int32_t *rt, int64_t rs) {
    constexpr size_t kAhead = 8;
    for (size_t j = 0; j < std::min(np, kAhead); ++j) {
        __builtin_prefetch(rec + pend[j].f, 1, 3);
        __builtin_prefetch(rec + pend[j].p, 1, 3);
        __builtin_prefetch(lnk + pend[j].f, 1, 3);
    }
    for (size_t j = 0; j < np; ++j) {
        if (j + kAhead < np) {
            __builtin_prefetch(rec + pend[j + kAhead].f, 1, 3);
            __builtin_prefetch(rec + pend[j + kAhead].p, 1, 3);
            __builtin_prefetch(lnk + pend[j + kAhead].f, 1, 3);
        }
        pair_record<Transpose, Vis, Rec, Stand>(rec, lnk, pend[j], K, eps, wgt, dh, vs, rt, rs);
    }
}

// The pair_pending instance for a walk's options.
using PairFn = void (*)(GatherRec *, uint32_t *, const PendingB *, size_t, int, float, double, const float *,
                        double *, int32_t *, int64_t);
template <bool Transpose, bool Vis>
PairFn pick_pairing(bool rec, bool stand) {
    if (rec) return stand ? &pair_pending<Transpose, Vis, true, true> : &pair_pending<Transpose, Vis, true, false>;
    return stand ? &pair_pending<Transpose, Vis, false, true> : &pair_pending<Transpose, Vis, false, false>;
}
PairFn pick_pairing(bool transpose, bool vis, bool rec, bool stand) {
    if (rec && transpose) throw std::invalid_argument("recording pairs: not transposed");
    if (transpose) return vis ? pick_pairing<true, true>(false, stand) : pick_pairing<true, false>(false, stand);
    return vis ? pick_pairing<false, true>(rec, stand) : pick_pairing<false, false>(rec, stand);
}

}  // namespace

int64_t LineSystem::gather(const Family *fams, const int64_t *sel, int64_t nsel, const float *val,
                           double *out, double *vis, int threads, const StopCheck &stop,
                           bool onepass, const uint8_t *stand_in, bool transpose,
                           PairTable *record) const {
    if (record) {
        if (!onepass || transpose) throw std::invalid_argument("recording pairs: one-pass, not transposed");
        if (record->n != n_) throw std::invalid_argument("pair table made for another line system");
        if (record->with_stand_in != (stand_in != nullptr))
            throw std::invalid_argument("pair table made with other stand-in flags");
        for (int64_t k = 0; k < nsel; ++k) {
            if (sel[k] < 0 || sel[k] >= record->nfam) throw std::invalid_argument("family outside the pair table");
            for (int c = 0; c < 3; ++c)
                if (fams[sel[k]].v[c] != record->vec[3 * sel[k] + c])
                    throw std::invalid_argument("pair table made for other families");
        }
    }
    threads = resolve_threads(threads);
    threads = static_cast<int>(std::max<int64_t>(1, std::min<int64_t>(threads, nsel)));
    // Values in each main axis's order (only the axes some family needs).
    bool need[3] = {false, false, false};
    std::vector<LineFrame> frames;
    frames.reserve(nsel);
    for (int64_t k = 0; k < nsel; ++k) {
        frames.emplace_back(fams[sel[k]].v, lo_, hi_);
        need[frames.back().m] = true;
    }
    std::vector<float> valax[3];
    for (int m = 0; m < 3; ++m) {
        if (!need[m]) continue;
        to_axis_order(m, val, valax[m]);
    }
    // stand-in flags in each needed axis order (empty: no stand-ins)
    std::vector<uint8_t> sbax[3];
    if (stand_in)
        for (int m = 0; m < 3; ++m) {
            if (!need[m]) continue;
            sbax[m].resize(n_);
            const int32_t *ord = ax_[m].order.data();
            for (int64_t i = 0; i < n_; ++i) sbax[m][i] = stand_in[ord[i]] ? 1 : 0;
        }
    std::vector<GatherWork> work(threads);
    std::vector<int64_t> lines_walked(threads, 0);
    const float eps = eps_;
    const int K = hist_;

    // size of the per-line table: the largest key range among the families
    int64_t max_keys = 1;
    for (const auto &fr : frames) max_keys = std::max<int64_t>(max_keys, fr.nu * fr.nw);

    // Add a thread's one-pass sums of its current axis to its global-order
    // sums (when it moves to the next axis, and at the end).
    auto flush_axis = [&](GatherWork &w) {
        if (w.rec_axis < 0) return;
        if (w.sums.empty()) w.sums.assign(3 * n_, 0.0);
        const int32_t *ord = ax_[w.rec_axis].order.data();
        const GatherRec *a = w.rec.data();
        double *o = w.sums.data();
        for (int64_t i = 0; i < n_; ++i) {
            const int64_t r = ord[i];
            o[3 * r] += a[i].acc[0];
            o[3 * r + 1] += a[i].acc[1];
            o[3 * r + 2] += a[i].acc[2];
        }
        w.rec_axis = -1;
    };

    if (onepass) {
    // Families grouped by main axis: a thread then works on one axis's
    // records at a time, in one GatherRec array (64 B a record) instead of
    // three.
    std::vector<int64_t> by_axis(nsel);
    std::iota(by_axis.begin(), by_axis.end(), int64_t(0));
    std::stable_sort(by_axis.begin(), by_axis.end(),
                     [&](int64_t a, int64_t b) { return frames[a].m < frames[b].m; });
    // A task is one family, or when recording the families of one tile of
    // the table (PairTable::kTile columns of one axis): one thread then
    // writes each tile, its 64-byte rows whole, record after record.
    std::vector<int64_t> task_start;
    if (record) {
        std::stable_sort(by_axis.begin(), by_axis.end(), [&](int64_t a, int64_t b) {
            if (frames[a].m != frames[b].m) return frames[a].m < frames[b].m;
            return record->slot[sel[a]] < record->slot[sel[b]];
        });
        for (int64_t q = 0; q < nsel; ++q) {
            const int64_t f = sel[by_axis[q]];
            if (q == 0 || frames[by_axis[q]].m != frames[by_axis[q - 1]].m ||
                record->slot[f] / PairTable::kTile != record->slot[sel[by_axis[q - 1]]] / PairTable::kTile)
                task_start.push_back(q);
        }
    } else {
        for (int64_t q = 0; q < nsel; ++q) task_start.push_back(q);
    }
    task_start.push_back(nsel);
    const int64_t ntasks = static_cast<int64_t>(task_start.size()) - 1;
    parallel_for(ntasks, threads, stop, [&](int64_t task, int t) {
    uint32_t lanes = 0;  // recording: the tile's columns this task fills
    for (int64_t kk_ = task_start[task]; kk_ < task_start[task + 1]; ++kk_) {
        const int64_t k = by_axis[kk_];
        GatherWork &w = work[t];
        const Family &F = fams[sel[k]];
        const LineFrame &fr = frames[k];
        const Axis &ax = ax_[fr.m];
        const int m = fr.m;
        if (w.rec_axis != m) {
            flush_axis(w);
            w.rec.resize(n_);
            const float *pn0 = ax.pn.data();
            const float *vl0 = valax[m].data();
            const uint8_t *sb0 = stand_in ? sbax[m].data() : nullptr;
            for (int64_t i = 0; i < n_; ++i) {
                GatherRec &r = w.rec[i];
                for (int c = 0; c < 3; ++c) {
                    r.pt[c] = pn0[8 * i + c];
                    r.nrm[c] = pn0[8 * i + 3 + c];
                    r.val[c] = vl0[3 * i + c];
                    r.acc[c] = 0.0;
                }
                r.stand = sb0 ? sb0[i] : 0;
            }
            w.rec_axis = m;
        }
        if (!w.used[m]) {
            if (vis) w.vis[m].assign(n_, 0.0);
            w.used[m] = true;
        }
        if (w.table.empty()) w.table.assign(max_keys, LineState{0, -1});
        const int32_t cur = ++w.stamp;  // no clearing: entries of other families carry old stamps
        LineState *table = w.table.data();
        GatherRec *rec = w.rec.data();
        double *vs = vis ? w.vis[m].data() : nullptr;
        const int32_t *AX = ax.X.data(), *AY = ax.Y.data(), *AZ = ax.Z.data();
        const double wgt = F.weight;
        const float len = std::sqrt(float(F.v[0]) * F.v[0] + float(F.v[1]) * F.v[1] + float(F.v[2]) * F.v[2]);
        const float dh[3] = {F.v[0] / len, F.v[1] / len, F.v[2] / len};
        const int32_t xlo = fr.lo[m];
        // Records in x_m order: every line is visited in its own order along
        // +v; its state (the newest F record, older ones chained through
        // link) lives in a table indexed by the line key.
        // recording: this family's column of its axis's table
        int32_t *rt = nullptr;
        int64_t rs = 0;
        if (record) {
            // into this thread's family-major buffer (a family's writes then
            // stay within n entries); the tile is written out row by row after
            const int64_t f = sel[k];
            const int lane = record->slot[f] % PairTable::kTile;
            if (w.rbuf.empty()) w.rbuf.assign(static_cast<size_t>(PairTable::kTile) * n_, 0);
            rs = 1;
            rt = w.rbuf.data() + int64_t(lane) * n_;
            lanes |= 1u << lane;
        }
        // the queued B records of the current slab (room for all n: the
        // branch-free step writes one entry past the kept ones)
        if (w.pend.size() < static_cast<size_t>(n_) + 1) w.pend.resize(n_ + 1);
        if (w.lnk.size() < static_cast<size_t>(n_)) w.lnk.assign(n_, 0);
        uint32_t *lnk = w.lnk.data();
        PendingB *pend = w.pend.data();
        // Locals only in the loop: the frame's constants, the counts and
        // the pointers copied out of the references the task captures, so
        // that the stores to the table, the links and the queue (int32
        // arrays, which could alias the frame's int32 members) do not force
        // them back to memory on every voxel.
        const int32_t *__restrict GS = ax.gstart.data();
        const uint8_t *__restrict GL = ax.gflag.data();
        const float *__restrict NR = ax.nrm.data();  // compact: the walk streams 24 B a record, not 64
        const float *__restrict PT = ax.pt.data();
        // LineFrame::key without a division per voxel: with X' fixed (one
        // slab), u = floor((A Y' + B X' + h) / A) = Y' + floor((B X' + h) / A)
        // exactly (A Y' is a multiple of A), the same for w, so the key
        // u nw + w is Y' nw + Z' + (a constant of the slab). With Y' = y ys +
        // yo and Z' = z zs + zo (ys, zs = +-1), a voxel's key is
        // y (ys nw) + z zs + base: the divisions happen once per slab.
        const int64_t fA = fr.A, fB = fr.B, fC = fr.C, fXmA = fr.XmA, fnw = fr.nw;
        const int64_t half = fA / 2;
        const int64_t ys = fr.pos1 ? 1 : -1, yo = fr.pos1 ? -int64_t(fr.lo[fr.o1]) : int64_t(fr.hi[fr.o1]);
        const int64_t zs = fr.pos2 ? 1 : -1, zo = fr.pos2 ? -int64_t(fr.lo[fr.o2]) : int64_t(fr.hi[fr.o2]);
        const int64_t ysn = ys * fnw;
        const float dh0 = dh[0], dh1 = dh[1], dh2 = dh[2];
        LineState *__restrict tbl = table;
        uint32_t *__restrict lk = lnk;
        PendingB *__restrict pq = pend;
        int64_t nwalked = 0;
        size_t nq = 0;
        // the pairing made for this walk's options (recording is never transposed)
        const PairFn pair_fn = pick_pairing(transpose, vs != nullptr, rt != nullptr, stand_in != nullptr);
        auto flush = [&](size_t cnt) { pair_fn(rec, lnk, pend, cnt, K, eps, wgt, dh, vs, rt, rs); };
        const int32_t counted = 2 * cur + 1;  // the stamp of a line with >= 2 records in this pass
        if (static_cast<int>(w.group.size()) < ax.gmax) w.group.resize(ax.gmax);
        Hit *hg = w.group.data();
        // Slab by slab, its queue paired after it: the voxel loop itself
        // calls nothing, so its values can stay in registers.
        const int32_t *__restrict SL = ax.gslab.data();
        const int64_t nslab = static_cast<int64_t>(ax.gslab.size()) - 1;
        for (int64_t sl = 0; sl < nslab; ++sl) {
          const int64_t g1 = SL[sl + 1];
          const int64_t Xr = fXmA - (int64_t(AX[GS[SL[sl]]]) - xlo);
          const int64_t base = (yo + (fB * Xr + half) / fA) * fnw + zo + (fC * Xr + half) / fA;
          for (int64_t g = SL[sl]; g < g1; ++g) {
            const int32_t i = GS[g];
            const uint8_t gf = GL[g];
            // (the tests hold this key and LineFrame::key, through the two
            // walks, to the same pairs)
            LineState &ls = tbl[static_cast<uint32_t>(int64_t(AY[i]) * ysn + int64_t(AZ[i]) * zs + base)];
            // stamp = 2 * pass + (the line holds >= 2 records so far); a
            // line counts once it has two records
            const int32_t old = ls.stamp;
            const bool seen = (old >> 1) == cur;
            int32_t lastF = seen ? ls.last : -1;
            if (gf & Axis::kTwin) {
                // a front record and its back twin (most voxels of a closed
                // scene): at one depth, so the one with n.d < 0 comes first
                // (as sort_group orders them); their n.d are c and -c exactly
                const float *nr = NR + 3 * int64_t(i);
                const float c = nr[0] * dh0 + nr[1] * dh1 + nr[2] * dh2;
                const bool first_is_f = c > 0.0f;  // then the twin (i + 1) is the B, met first
                const int32_t pa = first_is_f ? i + 1 : i, pb = first_is_f ? i : i + 1;
                const float ac = std::fabs(c);
                // step_record(pa, -ac) then step_record(pb, ac), written out:
                // the B leaves lastF as it is, so both links are lastF + 1,
                // and only the B can be queued
                const bool live = ac > kTiny;
                lk[pa] = lk[pb] = static_cast<uint32_t>(lastF + 1);
                pq[nq] = PendingB{pa, lastF, -ac};
                nq += static_cast<size_t>(live & (lastF >= 0));
                lastF = live ? pb : lastF;
                nwalked += old != counted;  // two records: the line has two now
                ls.stamp = counted;
                ls.last = lastF;
                continue;
            }
            const int gn = GS[g + 1] - i;
            const bool multi = seen || gn > 1;
            nwalked += multi & (old != counted);
            if (gn == 1) {
                // one record in the voxel: no depth order needed
                const float *nr = NR + 3 * int64_t(i);
                step_record(lk, i, nr[0] * dh0 + nr[1] * dh1 + nr[2] * dh2, lastF, pq, nq);
            } else if (gn == 2) {
                // two records that are not twins: order them along d by
                // depth, B before F at equal depth, as sort_group would
                const float d0 = dot3(PT + 3 * i, dh), d1 = dot3(PT + 3 * i + 3, dh);
                const float c0 = dot3(NR + 3 * i, dh), c1 = dot3(NR + 3 * i + 3, dh);
                const bool swap = d0 > d1 || (d0 == d1 && c0 > c1);
                const int32_t pa = swap ? i + 1 : i, pb = swap ? i : i + 1;
                const float ca = swap ? c1 : c0, cb = swap ? c0 : c1;
                step_record(lk, pa, ca, lastF, pq, nq);
                step_record(lk, pb, cb, lastF, pq, nq);
            } else {
                for (int a = 0; a < gn; ++a) {
                    const int32_t p = i + a;
                    hg[a] = Hit{p, dot3(PT + 3 * int64_t(p), dh), dot3(NR + 3 * int64_t(p), dh)};
                }
                sort_group(hg, gn);
                for (int a = 0; a < gn; ++a) step_record(lk, hg[a].p, hg[a].c, lastF, pq, nq);
            }
            ls.stamp = multi ? counted : 2 * cur;
            ls.last = lastF;
          }
          if (nq) flush(nq);
          nq = 0;
        }
        lines_walked[t] += nwalked;
    }
    if (record) {  // write the tile's filled columns, one 48-byte row per record
        GatherWork &w = work[t];
        const int64_t f0 = sel[by_axis[task_start[task]]];
        const int m = record->fam_axis[f0];
        constexpr int kT = PairTable::kTile, kE = PairTable::kEntry, kR = PairTable::kRow;
        uint8_t *blk = record->snd[m].p + int64_t(record->slot[f0] / kT) * n_ * kR;
        int32_t *buf = w.rbuf.data();
        // (the buffer is cleared as it is read: the next tile finds it zero)
        if (lanes == (1u << kT) - 1) {
            for (int64_t p = 0; p < n_; ++p) {
                uint8_t *row = blk + p * kR;
                // the row packed in order (each 4-byte write's top byte is
                // the next entry's first, or spare past the row's end) ...
                alignas(16) uint8_t tmp[kR + 16];
                for (int lane = 0; lane < kT; ++lane) {
                    const uint32_t x = static_cast<uint32_t>(buf[int64_t(lane) * n_ + p]);
                    std::memcpy(tmp + kE * lane, &x, 4);
                    buf[int64_t(lane) * n_ + p] = 0;
                }
#if defined(__SSE2__)
                // ... and streamed out: nothing reads it back in this pass
                // (no read for ownership; rows are 16-byte aligned)
                for (int q = 0; q < kR; q += 16)
                    _mm_stream_si128(reinterpret_cast<__m128i *>(row + q),
                                     _mm_load_si128(reinterpret_cast<const __m128i *>(tmp + q)));
#else
                std::memcpy(row, tmp, kR);
#endif
            }
#if defined(__SSE2__)
            _mm_sfence();
#endif
        } else {
            for (int64_t p = 0; p < n_; ++p) {
                uint8_t *row = blk + p * kR;
                for (int lane = 0; lane < kT; ++lane)
                    if (lanes >> lane & 1u) {
                        const uint32_t x = static_cast<uint32_t>(buf[int64_t(lane) * n_ + p]);
                        std::memcpy(row + kE * lane, &x, kE);  // little-endian: the low 3 bytes
                        buf[int64_t(lane) * n_ + p] = 0;
                    }
            }
        }
        // only now: a pass stopped half-way (Ctrl-C) leaves its families unrecorded
        for (int64_t kk_ = task_start[task]; kk_ < task_start[task + 1]; ++kk_)
            record->filled[sel[by_axis[kk_]]] = 1;
    }
    });
    } else {
    parallel_for(nsel, threads, stop, [&](int64_t k, int t) {
        GatherWork &w = work[t];
        const Family &F = fams[sel[k]];
        const LineFrame &fr = frames[k];
        const Axis &ax = ax_[fr.m];
        const int m = fr.m;
        if (!w.used[m]) {
            w.acc[m].assign(3 * n_, 0.0);
            if (vis) w.vis[m].assign(n_, 0.0);
            w.used[m] = true;
        }
        double *acc = w.acc[m].data();
        double *vs = vis ? w.vis[m].data() : nullptr;
        const float *vl = valax[m].data();
        const uint8_t *sb = stand_in ? sbax[m].data() : nullptr;
        const float *pn = ax.pn.data();  // point and normal, 8 floats per record
        const double wgt = F.weight;
        const float len = std::sqrt(float(F.v[0]) * F.v[0] + float(F.v[1]) * F.v[1] + float(F.v[2]) * F.v[2]);
        const float dh[3] = {F.v[0] / len, F.v[1] / len, F.v[2] / len};

        // 1. keys in the axis order (x_m ascending), 2. stable counting sort:
        // each line's records come out ordered along +v.
        const int64_t nkeys = fr.nu * fr.nw;
        w.key.resize(n_);
        w.cnt.assign(nkeys + 1, 0);
        w.line.resize(n_);
        uint32_t *key = w.key.data();
        uint32_t *cnt = w.cnt.data();
        const int32_t xlo = fr.lo[m];
        for (int64_t i = 0; i < n_; ++i) {
            const uint32_t kk = fr.key(ax.X[i] - xlo, fr.yprime(ax.Y[i]), fr.zprime(ax.Z[i]));
            key[i] = kk;
            ++cnt[kk + 1];
        }
        for (int64_t q = 0; q < nkeys; ++q) cnt[q + 1] += cnt[q];
        // cnt[q] = start of line q; scatter advances it to the line's end
        int32_t *line = w.line.data();
        for (int64_t i = 0; i < n_; ++i) line[cnt[key[i]]++] = static_cast<int32_t>(i);

        // 3. walk every line with >= 2 records
        int32_t hp[kMaxHistory];
        bool ha[kMaxHistory];
        int64_t walked = 0;
        int64_t start = 0;
        for (int64_t q = 0; q < nkeys; ++q) {
            const int64_t end = cnt[q];
            const int64_t L = end - start;
            if (L < 2) {
                start = end;
                continue;
            }
            ++walked;
            int hn = 0;
            int64_t j = start;
            while (j < end) {
                // the records of one voxel: same line and same x_m
                const int32_t x0 = ax.X[line[j]];
                int64_t ge = j + 1;
                while (ge < end && ax.X[line[ge]] == x0) ++ge;
                const int gn = static_cast<int>(ge - j);
                if (static_cast<int>(w.group.size()) < gn) w.group.resize(gn);
                Hit *g = w.group.data();
                for (int a = 0; a < gn; ++a) {
                    const int32_t p = line[j + a];
                    g[a] = Hit{p, dot3(pn + 8 * int64_t(p), dh), dot3(pn + 3 + 8 * int64_t(p), dh)};
                }
                if (gn > 1) sort_group(g, gn);
                for (int a = 0; a < gn; ++a) {
                    const int32_t p = g[a].p;
                    const float c = g[a].c;
                    if (c > kTiny) {  // F: sends along +v; remember it
                        if (hn == K) {
                            std::memmove(hp, hp + 1, sizeof(int32_t) * (K - 1));
                            std::memmove(ha, ha + 1, sizeof(bool) * (K - 1));
                            --hn;
                        }
                        hp[hn] = p;
                        ha[hn] = false;
                        ++hn;
                    } else if (c < -kTiny) {  // B: receives from the nearest facing F
                        const float *pp = pn + 8 * int64_t(p), *np = pn + 3 + 8 * int64_t(p);
                        const double cb = -double(c) * wgt;
                        bool got = false;
                        const bool sp = sb && sb[p];  // two stand-ins never pair
                        for (int h = hn - 1; h >= 0; --h) {
                            const int32_t f = hp[h];
                            if (sp && sb[f]) continue;
                            const float *pf = pn + 8 * int64_t(f), *nf = pn + 3 + 8 * int64_t(f);
                            if (!facing(pf, nf, pp, np, eps)) continue;
                            if (!got) {
                                // transposed: f takes p's value with p's weight
                                const float *vf = vl + 3 * int64_t(transpose ? p : f);
                                double *ap = acc + 3 * int64_t(transpose ? f : p);
                                ap[0] += vf[0] * cb;
                                ap[1] += vf[1] * cb;
                                ap[2] += vf[2] * cb;
                                if (vs) vs[p] += cb;
                                got = true;
                            }
                            // An answered facing F occludes the older ones.
                            if (ha[h]) break;
                            // F receives (along -v) from the first B that faces it.
                            const double cf = double(dot3(nf, dh)) * wgt;
                            const float *vp = vl + 3 * int64_t(transpose ? f : p);
                            double *af = acc + 3 * int64_t(transpose ? p : f);
                            af[0] += vp[0] * cf;
                            af[1] += vp[1] * cf;
                            af[2] += vp[2] * cf;
                            if (vs) vs[f] += cf;
                            ha[h] = true;
                        }
                    }
                }
                j = ge;
            }
            start = end;
        }
        lines_walked[t] += walked;
    });
    }

    // Reduce in a fixed order (thread, then axis) into the global order.
    std::fill(out, out + 3 * n_, 0.0);
    if (vis) std::fill(vis, vis + n_, 0.0);
    for (int t = 0; t < threads; ++t) {
        if (onepass) {
            flush_axis(work[t]);
            work[t].rec = std::vector<GatherRec>();  // free it before the next thread's sums
            const double *a = work[t].sums.data();
            if (!work[t].sums.empty())
                for (int64_t i = 0; i < 3 * n_; ++i) out[i] += a[i];
        }
        for (int m = 0; m < 3; ++m) {
            if (!work[t].used[m]) continue;
            const int32_t *ord = ax_[m].order.data();
            if (!onepass) {
                const double *a = work[t].acc[m].data();
                for (int64_t i = 0; i < n_; ++i) {
                    const int64_t r = ord[i];
                    out[3 * r] += a[3 * i];
                    out[3 * r + 1] += a[3 * i + 1];
                    out[3 * r + 2] += a[3 * i + 2];
                }
            }
            if (vis) {
                const double *v = work[t].vis[m].data();
                for (int64_t i = 0; i < n_; ++i) vis[ord[i]] += v[i];
            }
        }
    }
    int64_t total = 0;
    for (auto x : lines_walked) total += x;
    return total;
}

// ---------------------------------------------------------------- recorded pairs

PairTable::Block::~Block() { release(); }

void PairTable::Block::release() {
    if (p) munmap(p, size + kSlack);
    p = nullptr;
    size = 0;
}

void PairTable::Block::allocate(size_t bytes) {
    release();
    // anonymous pages are zero and cost nothing until written (huge pages
    // asked for: the kernel grants them in THP "madvise" mode)
    void *q = mmap(nullptr, bytes + kSlack, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (q == MAP_FAILED) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
    madvise(q, bytes + kSlack, MADV_HUGEPAGE);
#endif
    p = static_cast<uint8_t *>(q);
    size = bytes;
}

PairTable::Block &PairTable::Block::operator=(Block &&o) noexcept {
    if (this != &o) {
        release();
        p = o.p;
        size = o.size;
        o.p = nullptr;
        o.size = 0;
    }
    return *this;
}

PairTable LineSystem::make_pair_table(const Family *fams, int64_t nf, bool with_stand_in) const {
    if (n_ > PairTable::kMaxRecords)
        throw std::invalid_argument("pair table: " + std::to_string(n_) + " records, at most " +
                                    std::to_string(PairTable::kMaxRecords) + " fit its 3-byte entries");
    PairTable t;
    t.n = n_;
    t.nfam = nf;
    t.with_stand_in = with_stand_in;
    t.slot.resize(nf);
    t.fam_axis.resize(nf);
    t.vec.resize(3 * nf);
    t.dir.resize(3 * nf);
    t.weight.resize(nf);
    t.filled.assign(nf, 0);
    for (int64_t f = 0; f < nf; ++f) {
        LineFrame fr(fams[f].v, lo_, hi_);  // validates the vector
        t.fam_axis[f] = fr.m;
        t.slot[f] = static_cast<int32_t>(t.cols[fr.m]++);
        const float len = std::sqrt(float(fams[f].v[0]) * fams[f].v[0] + float(fams[f].v[1]) * fams[f].v[1] +
                                    float(fams[f].v[2]) * fams[f].v[2]);
        for (int c = 0; c < 3; ++c) {
            t.vec[3 * f + c] = fams[f].v[c];
            t.dir[3 * f + c] = fams[f].v[c] / len;
        }
        t.weight[f] = fams[f].weight;
    }
    for (int m = 0; m < 3; ++m) {
        const size_t tiles = (static_cast<size_t>(t.cols[m]) + PairTable::kTile - 1) / PairTable::kTile;
        const size_t size = static_cast<size_t>(n_) * tiles * PairTable::kRow;
        if (size == 0) continue;
        t.snd[m].allocate(size);
    }
    return t;
}

void LineSystem::gather_recorded(const PairTable &tab, const int64_t *sel, int64_t nsel, const float *val,
                                 double *out, double *vis, int threads, const StopCheck &stop) const {
    if (tab.n != n_) throw std::invalid_argument("pair table made for another line system");
    // the selected families of each axis: their columns, directions and weights
    std::vector<int32_t> cols[3];
    std::vector<float> dirs[3];
    std::vector<double> wts[3];
    for (int64_t k = 0; k < nsel; ++k) {
        const int64_t f = sel[k];
        if (f < 0 || f >= tab.nfam) throw std::invalid_argument("family outside the pair table");
        if (!tab.filled[f]) throw std::invalid_argument("family " + std::to_string(f) + " not recorded");
        const int m = tab.fam_axis[f];
        cols[m].push_back(tab.slot[f]);
        for (int c = 0; c < 3; ++c) dirs[m].push_back(tab.dir[3 * f + c]);
        wts[m].push_back(tab.weight[f]);
    }
    std::fill(out, out + 3 * n_, 0.0);
    if (vis) std::fill(vis, vis + n_, 0.0);
    threads = resolve_threads(threads);
    constexpr int kT = PairTable::kTile;
    constexpr int64_t chunk = 1024;  // records whose sums stay in L1 while the tiles stream by
    for (int m = 0; m < 3; ++m) {
        const int64_t nc = static_cast<int64_t>(cols[m].size());
        if (nc == 0) continue;
        const Axis &ax = ax_[m];
        // values in this axis's order (the senders are axis-order
        // positions), 16 bytes a record: the value, then 1 (so that one pair
        // of packed multiply-adds also sums the weight)
        std::vector<float> va(4 * n_);
        const int32_t *ord = ax.order.data();
        for (int64_t i = 0; i < n_; ++i) {
            const int64_t r = ord[i];
            va[4 * i] = val[3 * r];
            va[4 * i + 1] = val[3 * r + 1];
            va[4 * i + 2] = val[3 * r + 2];
            va[4 * i + 3] = 1.0f;
        }
        // the selected columns, in column order, grouped by tile
        std::vector<int64_t> idx(nc);
        std::iota(idx.begin(), idx.end(), int64_t(0));
        std::sort(idx.begin(), idx.end(), [&](int64_t a, int64_t b) { return cols[m][a] < cols[m][b]; });
        std::vector<int32_t> lane(nc);      // column within its tile
        std::vector<float> dx(nc), dy(nc), dz(nc);  // directions, one array per component
        std::vector<double> wt(nc);
        std::vector<int64_t> tile, tile_first;  // tiles with a selected column, and where their columns start
        for (int64_t q = 0; q < nc; ++q) {
            const int64_t j = idx[q];
            const int32_t c = cols[m][j];
            lane[q] = c % kT;
            dx[q] = dirs[m][3 * j];
            dy[q] = dirs[m][3 * j + 1];
            dz[q] = dirs[m][3 * j + 2];
            wt[q] = wts[m][j];
            if (tile.empty() || tile.back() != c / kT) {
                tile.push_back(c / kT);
                tile_first.push_back(q);
            }
        }
        tile_first.push_back(nc);
        const uint8_t *base = tab.snd[m].p;
        const float *nrm = ax.nrm.data();
        const float *v = va.data();
        // A chunk of records at a time, tile after tile: the table streams
        // (one 64-byte row per record and tile), and every record's sum is
        // added in column order by one thread (no dependence on threads).
        parallel_for((n_ + chunk - 1) / chunk, threads, stop, [&](int64_t task, int) {
            const int64_t b = task * chunk, e = std::min(n_, b + chunk);
            alignas(16) double acc[chunk][4];
            for (int64_t p = b; p < e; ++p)
                for (int c = 0; c < 4; ++c) acc[p - b][c] = 0.0;
            for (size_t ti = 0; ti < tile.size(); ++ti) {
                const uint8_t *blk = base + tile[ti] * n_ * PairTable::kRow;
                const int64_t q0 = tile_first[ti], q1 = tile_first[ti + 1];
                const int nq = static_cast<int>(q1 - q0);  // at most kT
                const float *tx = dx.data() + q0, *ty = dy.data() + q0, *tz = dz.data() + q0;
                const int32_t *tl = lane.data() + q0;
                const double *tw = wt.data() + q0;
                for (int64_t p = b; p < e; ++p) {
                    const uint8_t *row = blk + p * PairTable::kRow;
                    const float n0 = nrm[3 * p], n1 = nrm[3 * p + 1], n2 = nrm[3 * p + 2];
                    double *a = acc[p - b];
                    // the tile's |n.d| at once (a loop the compiler vectorises;
                    // each lane the same float operations in the same order)
                    alignas(16) float cs[kT];
                    for (int q = 0; q < nq; ++q) cs[q] = std::abs(n0 * tx[q] + n1 * ty[q] + n2 * tz[q]);
                    for (int q = 0; q < nq; ++q) {
                        const uint32_t s = PairTable::entry(row, tl[q]);
                        if (s == 0) continue;
                        const double c = double(cs[q]) * tw[q];
                        const float *vs = v + 4 * int64_t(s - 1);
#if defined(__SSE2__)
                        // a[k] += double(vs[k]) * c, two lanes at a time
                        // (the same IEEE operations; a[3] gets 1 * c = c)
                        const __m128 x = _mm_loadu_ps(vs);
                        const __m128d cc = _mm_set1_pd(c);
                        _mm_store_pd(a, _mm_add_pd(_mm_load_pd(a), _mm_mul_pd(_mm_cvtps_pd(x), cc)));
                        _mm_store_pd(a + 2, _mm_add_pd(_mm_load_pd(a + 2),
                                                       _mm_mul_pd(_mm_cvtps_pd(_mm_movehl_ps(x, x)), cc)));
#else
                        a[0] += vs[0] * c;
                        a[1] += vs[1] * c;
                        a[2] += vs[2] * c;
                        a[3] += vs[3] * c;
#endif
                    }
                }
            }
            for (int64_t p = b; p < e; ++p) {
                const int64_t r = ord[p];
                out[3 * r] += acc[p - b][0];
                out[3 * r + 1] += acc[p - b][1];
                out[3 * r + 2] += acc[p - b][2];
                if (vis) vis[r] += acc[p - b][3];
            }
        });
    }
}

// ---------------------------------------------------------------- shooting

int64_t LineSystem::shoot(const int32_t *emit, int64_t ne, const Family *fams, int64_t nf,
                          const float *val, double *hd, double *unfound, int threads,
                          const StopCheck &stop, int64_t *steps_out, const double *send_scale,
                          const double *recv_area, const double *coverage,
                          const uint8_t *stand_in, const int32_t *object,
                          const double *sil_area, const uint8_t *back) const {
    if (coverage && send_scale) throw std::invalid_argument("coverage is for the receiver-side deposit");
    if ((object == nullptr) != (sil_area == nullptr) || (object == nullptr) != (back == nullptr))
        throw std::invalid_argument("object, sil_area and back go together");
    if (object && send_scale) throw std::invalid_argument("silhouettes: only with the receiver-side deposit");
    const bool sil = object != nullptr;
    threads = resolve_threads(threads);
    build_occupancy();
    for (int64_t k = 0; k < ne; ++k)
        if (emit[k] < 0 || emit[k] >= n_) throw std::invalid_argument("emitter index out of range");
    std::vector<LineFrame> frames;
    frames.reserve(nf);
    std::vector<float> dhat(3 * nf);
    for (int64_t f = 0; f < nf; ++f) {
        frames.emplace_back(fams[f].v, lo_, hi_);
        const float len = std::sqrt(float(fams[f].v[0]) * fams[f].v[0] + float(fams[f].v[1]) * fams[f].v[1] +
                                    float(fams[f].v[2]) * fams[f].v[2]);
        for (int c = 0; c < 3; ++c) dhat[3 * f + c] = fams[f].v[c] / len;
    }
    // position of every record in the (x, y, z) order and its voxel slot
    const Axis &a0 = ax_[0];
    std::vector<int32_t> pos0(n_);
    for (int64_t i = 0; i < n_; ++i) pos0[a0.order[i]] = static_cast<int32_t>(i);

    const int64_t chunk = 4;
    const int64_t tasks = (ne + chunk - 1) / chunk;
    threads = static_cast<int>(std::max<int64_t>(1, std::min<int64_t>(threads, tasks)));
    std::vector<std::vector<double>> acc(threads);
    std::vector<int64_t> rays(threads, 0), steps(threads, 0);
    const float eps = eps_;
    const int K = hist_;
    const float *P = point_, *N = normal_;

    // q and p lie in one plane with one normal (to 1e-5 in the normal, eps
    // along it), and are alike for the rules that pick among F records (one
    // object, both stand-ins or neither)
    auto same_plane = [&](int32_t q, int32_t p) {
        if (object && object[q] != object[p]) return false;
        if (stand_in && stand_in[q] != stand_in[p]) return false;
        const float *nq = N + 3 * int64_t(q), *np = N + 3 * int64_t(p);
        if (dot3(nq, np) < 1.0f - 1e-5f) return false;
        const float *pq = P + 3 * int64_t(q), *pp = P + 3 * int64_t(p);
        const float off = (pp[0] - pq[0]) * nq[0] + (pp[1] - pq[1]) * nq[1] + (pp[2] - pq[2]) * nq[2];
        return std::abs(off) <= eps;
    };

    parallel_for(tasks, threads, stop, [&](int64_t task, int t) {
        if (acc[t].empty()) acc[t].assign(3 * n_, 0.0);
        double *H = acc[t].data();
        std::vector<Hit> group, recv(16);
        std::vector<double> recvT(16);
        size_t nrecv = 0;
        int32_t hp[kMaxHistory];
        // (locals: the per-thread counters share a cache line, and a counter
        // in memory would chain every step through a store)
        int64_t nsteps = 0, nrays = 0;
        for (int64_t k = task * chunk; k < std::min(ne, (task + 1) * chunk); ++k) {
            const int32_t e = emit[k];
            const float *pe = P + 3 * int64_t(e), *nE = N + 3 * int64_t(e);
            const float *ve = val + 3 * int64_t(e);
            double lost = 0.0;
            // the emitter's voxel, in (x, y, z) order coordinates
            const int32_t ex = a0.X[pos0[e]], ey = a0.Y[pos0[e]], ez = a0.Z[pos0[e]];
            const int32_t eijk[3] = {ex, ey, ez};
            for (int64_t f = 0; f < nf; ++f) {
                const LineFrame &fr = frames[f];
                const float *dv = dhat.data() + 3 * f;
                const float cv = dot3(nE, dv);
                if (std::abs(cv) <= kTiny) continue;
                const int s = cv > 0 ? 1 : -1;  // march along +v or -v, whichever e faces
                const float sd[3] = {s * dv[0], s * dv[1], s * dv[2]};
                const double ce = std::abs(double(cv)) * fams[f].weight;
                // the share of the line's cross-section that e covers (1: all of it)
                const bool partial = coverage && coverage[e] >= 0;
                const double alpha =
                    partial ? coverage[e] * std::abs(double(cv)) / std::abs(double(dv[fr.m])) : 1.0;
                ++nrays;
                // the line through e's voxel: u, w fixed; y', z' follow from x'
                const int m = fr.m, o1 = fr.o1, o2 = fr.o2;
                const int64_t X0 = eijk[m] - fr.lo[m];
                const int64_t Y0 = fr.yprime(eijk[o1]), Z0 = fr.zprime(eijk[o2]);
                const int64_t h = fr.A / 2;
                const int64_t u = (fr.A * Y0 + fr.B * (fr.XmA - X0) + h) / fr.A;
                const int64_t w = (fr.A * Z0 + fr.C * (fr.XmA - X0) + h) / fr.A;
                const int64_t Xr = int64_t(fr.hi[m]) - fr.lo[m];
                const int64_t Yr = int64_t(fr.hi[o1]) - fr.lo[o1], Zr = int64_t(fr.hi[o2]) - fr.lo[o2];
                int hn = 1;
                hp[0] = e;
                bool found = false, stopped = false;
                bool first = true;
                nrecv = 0;
                // Silhouettes (sil): T is the share of e's ray still travelling.
                // The current band of receivers (one object, consecutive steps)
                // covers band_cov of the line's cross-section; if the line then
                // leaves that object through another face of it (convex edge,
                // within one step of the band), it only grazed the object: the
                // uncovered share 1 - band_cov goes on, and the object's F
                // records on that exit do not occlude it.
                double T = 1.0;
                int32_t band_obj = -1, band_last = -1, carry_obj = -1, carry_face = -1, crease_rec = -1;
                int64_t band_step = -8, carry_step = -8, istep = -1;
                double band_cov = 0.0;
                bool found_seg = false, carried = false, band_crease = false;
                const double inv_dm = 1.0 / std::abs(double(dv[fr.m]));
                // y' = u - floor((B (XmA - x') + h) / A), z' likewise, kept as
                // quotient and remainder updated by +-B, +-C per step (B, C <= A):
                // integer-only, no division in the loop.
                int64_t numy = fr.B * (fr.XmA - X0) + h, numz = fr.C * (fr.XmA - X0) + h;
                int64_t qy = numy / fr.A, ry = numy % fr.A, qz = numz / fr.A, rz = numz % fr.A;
                for (int64_t X = X0; X >= 0 && X <= Xr && !stopped; first = false) {
                    ++nsteps;
                    ++istep;
                    const int64_t Y = u - qy;
                    const int64_t Z = w - qz;
                    if (Y < 0 || Y > Yr || Z < 0 || Z > Zr) break;
                    int32_t c3[3];
                    c3[m] = static_cast<int32_t>(X + fr.lo[m]);
                    c3[o1] = static_cast<int32_t>(fr.pos1 ? Y + fr.lo[o1] : fr.hi[o1] - Y);
                    c3[o2] = static_cast<int32_t>(fr.pos2 ? Z + fr.lo[o2] : fr.hi[o2] - Z);
                    // next voxel of the line, without branches (whether a
                    // remainder wraps is a coin toss from one step to the
                    // next; my, mz have every bit set where it does)
                    X += s;
                    if (s > 0) {  // numerators fall by B, C
                        ry -= fr.B;
                        const int64_t my = ry >> 63;
                        ry += fr.A & my;
                        qy += my;
                        rz -= fr.C;
                        const int64_t mz = rz >> 63;
                        rz += fr.A & mz;
                        qz += mz;
                    } else {
                        ry += fr.B;
                        const int64_t my = ~((ry - fr.A) >> 63);
                        ry -= fr.A & my;
                        qy -= my;
                        rz += fr.C;
                        const int64_t mz = ~((rz - fr.A) >> 63);
                        rz -= fr.A & mz;
                        qz -= mz;
                    }
                    const int64_t lin = linear(c3[0], c3[1], c3[2]);
                    if (!((occ_[lin >> 6] >> (lin & 63)) & 1)) continue;
                    const uint64_t below = occ_[lin >> 6] & ((uint64_t(1) << (lin & 63)) - 1);
                    const int64_t slot = occ_rank_[lin >> 6] + __builtin_popcountll(below);
                    const int32_t b = vstart_[slot], en = vstart_[slot + 1];
                    group.clear();
                    for (int32_t i = b; i < en; ++i) {
                        const int32_t r = a0.order[i];
                        group.push_back(Hit{r, dot3(P + 3 * int64_t(r), sd), dot3(N + 3 * int64_t(r), sd)});
                    }
                    sort_group(group.data(), static_cast<int>(group.size()));
                    size_t a = 0;
                    if (first) {  // start just after e in its own voxel
                        while (a < group.size() && group[a].p != e) ++a;
                        ++a;
                    }
                    for (; a < group.size(); ++a) {
                        const int32_t p = group[a].p;
                        const float c = group[a].c;
                        if (c > kTiny) {
                            if (partial) {  // e's own sheet (or behind it) does not occlude e
                                const float *pq = P + 3 * int64_t(p);
                                const float off = (pq[0] - pe[0]) * nE[0] + (pq[1] - pe[1]) * nE[1] +
                                                  (pq[2] - pe[2]) * nE[2];
                                if (off <= eps) continue;
                            }
                            if (sil) {
                                const int32_t op = object[p];
                                if (op == carry_obj) {  // the remainder is outside op
                                    carry_step = istep;
                                    continue;
                                }
                                if (op == band_obj && band_crease && istep <= band_step + 1) {
                                    // the band touched a convex crease of its object and the
                                    // line now leaves the object (its back twins or another
                                    // face, behind the band's plane): it clipped the edge
                                    const float *pq = P + 3 * int64_t(p), *nq = N + 3 * int64_t(p);
                                    const float *pb = P + 3 * int64_t(band_last), *nb = N + 3 * int64_t(band_last);
                                    const float d0 = pq[0] - pb[0], d1 = pq[1] - pb[1], d2 = pq[2] - pb[2];
                                    const bool convex = (d0 * nb[0] + d1 * nb[1] + d2 * nb[2] < eps) &&
                                                        (-(d0 * nq[0] + d1 * nq[1] + d2 * nq[2]) < eps);
                                    if (convex) {
                                        T *= std::max(0.0, 1.0 - band_cov);
                                        carry_obj = op;
                                        carry_face = crease_rec;  // the face the line grazed
                                        carry_step = istep;
                                        band_obj = -1;
                                        carried = true;
                                        found_seg = false;
                                        // the object's F records seen so far no longer occlude
                                        int hk = 1;
                                        for (int hh = 1; hh < hn; ++hh)
                                            if (object[hp[hh]] != op) hp[hk++] = hp[hh];
                                        hn = hk;
                                        if (T <= 1e-12) {
                                            stopped = true;
                                            break;
                                        }
                                        continue;
                                    }
                                }
                            }
                            // A run of F records in one plane with one normal (the back
                            // twins of a face the line runs along, nearly parallel to it)
                            // keeps only its first and latest records: whether a later
                            // receiver lies behind such a record's plane is one test for
                            // the whole run, and whether the record lies in front of the
                            // receiver's plane, a linear function along the run, is
                            // decided at its ends. The run would otherwise fill the
                            // history and stop e's light with nothing received (the
                            // closed black Cornell box lost 0.08% of the emitted power
                            // that way at res 128 and at 256).
                            if (hn >= 3 && same_plane(hp[hn - 1], p) && same_plane(hp[hn - 2], p)) {
                                hp[hn - 1] = p;
                                continue;
                            }
                            if (hn == K) {  // e would be forgotten: its light stops here
                                stopped = true;
                                break;
                            }
                            hp[hn++] = p;
                        } else if (c < -kTiny) {
                            // the grazing remainder does not see the inside of the object
                            // it passed (its back records)
                            // nor, while the line still runs along it, its front records
                            // (another face of it, which the remainder runs towards, does
                            // receive it: a lit side below a grazed top edge)
                            if (sil && object[p] == carry_obj &&
                                (back[p] || (istep <= carry_step + 1 &&
                                             dot3(N + 3 * int64_t(p), N + 3 * int64_t(carry_face)) > 0.5f))) {
                                carry_step = istep;
                                continue;
                            }
                            const float *pp = P + 3 * int64_t(p), *np = N + 3 * int64_t(p);
                            int nearest = -1;
                            const bool sp = stand_in && stand_in[p];  // two stand-ins never pair
                            for (int hh = hn - 1; hh >= 0; --hh) {
                                const int32_t fq = hp[hh];
                                if (sp && stand_in[fq]) continue;
                                if (facing(P + 3 * int64_t(fq), N + 3 * int64_t(fq), pp, np, eps)) {
                                    nearest = hh;
                                    break;
                                }
                            }
                            if (nearest == 0) {  // e is p's sender along this line
                                found = true;
                                found_seg = true;
                                if (nrecv == recv.size()) {
                                    recv.resize(2 * nrecv + 4);
                                    recvT.resize(2 * nrecv + 4);
                                }
                                recvT[nrecv] = T;
                                carry_obj = -1;  // a receiver ends the transparent exit
                                recv[nrecv++] = Hit{p, 0.0f, -c};
                                if (sil) {
                                    if (object[p] != band_obj || istep > band_step + 1) {
                                        band_obj = object[p];
                                        band_cov = 0.0;
                                        band_crease = false;
                                    }
                                    if (!band_crease && sil_area[p] >= 0) {
                                        // a silhouette: p's voxel holds another face of p's
                                        // object that this line leaves (F), at a convex edge
                                        const float *np_ = N + 3 * int64_t(p);
                                        for (const Hit &g : group) {
                                            const int32_t q = g.p;
                                            if (g.c <= kTiny || object[q] != object[p]) continue;
                                            const float *pq = P + 3 * int64_t(q), *nq = N + 3 * int64_t(q);
                                            const float dn = dot3(np_, nq);
                                            if (dn >= 0.5f || dn <= -0.9f) continue;  // same face, or a twin
                                            const float d0 = pq[0] - pp[0], d1 = pq[1] - pp[1], d2 = pq[2] - pp[2];
                                            if (d0 * np_[0] + d1 * np_[1] + d2 * np_[2] < eps &&
                                                -(d0 * nq[0] + d1 * nq[1] + d2 * nq[2]) < eps) {
                                                band_crease = true;
                                                crease_rec = p;  // the grazed face's record
                                                break;
                                            }
                                        }
                                    }
                                    band_cov += sil_area[p] * double(-c) * inv_dm;
                                    band_step = istep;
                                    band_last = p;
                                }
                            } else if (nearest > 0) {  // someone nearer sends to p: e is shadowed
                                if (facing(pe, nE, pp, np, eps)) {
                                    // e's light reached p's surface: counted as received; with
                                    // the sender-side deposit p takes e's power
                                    found = true;
                                    found_seg = true;
                                    if (send_scale) {
                                        if (nrecv == recv.size()) recv.resize(2 * nrecv + 4);
                                        recv[nrecv++] = Hit{p, 0.0f, -c};
                                    }
                                }
                                stopped = true;
                                break;
                            }
                        }
                    }
                }
                if (send_scale == nullptr || recv_area == nullptr) {  // receiver side: irradiance val[e] cos_r weight
                    for (size_t q = 0; q < nrecv; ++q) {
                        const double cr = double(recv[q].c) * fams[f].weight * alpha * recvT[q];
                        double *Hp = H + 3 * int64_t(recv[q].p);
                        Hp[0] += ve[0] * cr;
                        Hp[1] += ve[1] * cr;
                        Hp[2] += ve[2] * cr;
                    }
                } else if (nrecv > 0) {  // sender side: the ray's power, split by area x cos
                    double tot = 0.0;
                    for (size_t q = 0; q < nrecv; ++q) tot += recv_area[recv[q].p] * recv[q].c;
                    if (tot > 0) {
                        const double pw = ce * send_scale[e] / tot;
                        for (size_t q = 0; q < nrecv; ++q) {
                            const double share = pw * recv_area[recv[q].p] * recv[q].c;
                            double *Hp = H + 3 * int64_t(recv[q].p);
                            Hp[0] += ve[0] * share;
                            Hp[1] += ve[1] * share;
                            Hp[2] += ve[2] * share;
                        }
                    } else {
                        found = false;
                    }
                }
                if (!found) lost += ce;
                else if (carried && !found_seg) lost += ce * T;  // the grazing remainder escaped
            }
            unfound[k] = lost;
        }
        steps[t] += nsteps;
        rays[t] += nrays;
    });
    std::fill(hd, hd + 3 * n_, 0.0);
    for (int t = 0; t < threads; ++t) {
        if (acc[t].empty()) continue;
        for (int64_t i = 0; i < 3 * n_; ++i) hd[i] += acc[t][i];
    }
    int64_t total = 0, st = 0;
    for (int t = 0; t < threads; ++t) {
        total += rays[t];
        st += steps[t];
    }
    if (steps_out) *steps_out = st;
    return total;
}

}  // namespace voxgi
