// The gathering pass: one walk of the records in x_m order per family, a
// per-line state table, and the pairing of every B record with the F
// records it faces (docs/design.md §4).
#include "gather.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <string>

#include "lineorder.h"
#include "util/simd.h"

#if defined(__GNUC__)
#define VOXGI_INLINE inline __attribute__((always_inline))
#else
#define VOXGI_INLINE inline
#endif

namespace voxgi {

namespace {

// A line's state in the walk of one family: the family pass that last wrote
// it (2 * pass + 1 bit: the line holds >= 2 records), and its newest F
// record (axis-order position, -1: none).
struct LineState {
    int32_t stamp;
    int32_t last;
};

// Everything a pair touches for one record, in one 64-byte cache line: where
// a B record meets its partner F (a record far back along the line, i.e. a
// random place in memory), the facing test, the value sent and the value
// received all hit this one line instead of four arrays. Each thread owns one
// array, for the main axis it works on (acc is written). The walk along the
// records reads the compact per-axis normals and points instead (24 bytes a
// record, not 64), and keeps the line links in their own array (4 bytes a
// record, written for every record), so it streams a third of the bytes.
struct alignas(64) GatherRec {
    float pt[3];   // surface point (voxel units)
    float nrm[3];  // unit normal
    float val[3];  // value sent (RGB)
    // bit 31: a stand-in; bit 30: in a voxel where surfaces cross; bits
    // 0-29: the B that answered it, + 1 (an F's, valid while it is
    // answered). Here, not in an array of its own: the pairing has this line
    // in cache when it reads or writes them.
    uint32_t tag;
    double acc[3];  // gathered (RGB), summed over the families of one group
};
static_assert(sizeof(GatherRec) == 64, "GatherRec must fill one cache line");
constexpr uint32_t kAnswered = 0x80000000u;
constexpr uint32_t kStandIn = 0x80000000u;  // GatherRec::tag
constexpr uint32_t kCrossing = 0x40000000u;
constexpr uint32_t kAnswerer = 0x3fffffffu;

// facing() for the walk's records, B's point and normal held in registers
// across its chain. With SSE2 the two dot products take one multiply each
// and their sums are made in facing()'s order (the same floats, bit for
// bit); lane 3 of each 16-byte load is the next field and is never summed.
struct FacingB {
#if defined(__SSE2__)
    __m128 p, n;
    explicit FacingB(const GatherRec& b) : p(_mm_loadu_ps(b.pt)), n(_mm_loadu_ps(b.nrm)) {}
    bool faces(const GatherRec& f, float eps) const {
        const __m128 d = _mm_sub_ps(p, _mm_loadu_ps(f.pt));
        return sum3(_mm_mul_ps(d, _mm_loadu_ps(f.nrm))) > eps && -sum3(_mm_mul_ps(d, n)) > eps;
    }
#else
    const GatherRec& b;
    explicit FacingB(const GatherRec& b_) : b(b_) {}
    bool faces(const GatherRec& f, float eps) const {
        return facing(f.pt, f.nrm, b.pt, b.nrm, eps);
    }
#endif
};

// A B record waiting for its partner: its position, the newest F of its line
// when it was met, and n.d.
struct PendingB {
    int32_t p, f;
    float c;
};

// The working memory of one thread.
struct GatherWork {
    std::vector<LineState> table;  // per line key
    int32_t stamp = 0;
    std::vector<Hit> group;
    // the records in the order of the main axis this thread works on
    // (rec_axis; -1: none yet)
    std::vector<GatherRec> rec;
    int rec_axis = -1;
    std::vector<double> vis;     // the current group's, axis order
    std::vector<PendingB> pend;  // the queued B records of one slab
    // per record (axis order): bits 0-30 previous F on the line + 1 (0:
    // none), bit 31 answered; valid for F records
    std::vector<uint32_t> lnk;
    std::vector<int32_t> rbuf;  // recording: one tile's columns, family-major
};

// What every family's walk shares.
struct WalkShared {
    float eps;
    int K;             // history
    bool vis;          // sum vis
    bool stand;        // stand-in flags given
    int64_t max_keys;  // the largest key range among the families
};

// One record of the walk (records of a line arrive in order along +v). An F
// record (c > 0) joins the line's history at once; a B record (c < 0) with
// an F behind it is queued: the pairs are made per slab (see pair_pending).
// Without branches (which of F, B or neither a record is, is a coin toss
// from one record to the next): the link is written for every record (only
// F records are ever read through it), the B entry is written always and
// kept by advancing the count.
VOXGI_INLINE void step_record(uint32_t* lnk, int32_t p, float c, int32_t& lastF, PendingB* pend,
                              size_t& np) {
    lnk[p] = static_cast<uint32_t>(lastF + 1);
    pend[np] = PendingB{p, lastF, c};
    np += static_cast<size_t>((c < -kTiny) & (lastF >= 0));
    lastF = c > kTiny ? p : lastF;
}

VOXGI_INLINE void add(GatherRec& to, const GatherRec& from, double w) {
    to.acc[0] += from.val[0] * w;
    to.acc[1] += from.val[1] * w;
    to.acc[2] += from.val[2] * w;
}

// A queued B record receives from the newest F that faces it and answers
// the facing F records before it that nothing hides (hidden_behind). rt (nullable):
// the family's column of a PairTable (rt[p] = sender + 1). Vis, Rec, Stand:
// vs, rt are set, the records carry stand-in flags (fixed for a family's
// walk, so they are template arguments, not branches in the chain loop).
template <bool Vis, bool Rec, bool Stand>
VOXGI_INLINE void pair_record(GatherRec* rec, uint32_t* lnk, const PendingB& q, int K, float eps,
                              double wgt, const float* dh, double* vs, int32_t* rt) {
    const int32_t p = q.p;
    GatherRec& rp = rec[p];
    const double cb = -double(q.c) * wgt;
    bool got = false;
    const bool sp = Stand && (rp.tag & kStandIn);  // two stand-ins never pair
    int32_t f = q.f;
    int32_t passed_answered = -1;  // the newest answered facing F passed
    const FacingB fb(rp);
    const GatherRec* passed = nullptr;  // the last F passed over
    for (int skipped = 0, steps = 0; skipped < K && f >= 0 && steps < kMaxChain; ++steps) {
        GatherRec& rf = rec[f];
        const int32_t older = static_cast<int32_t>(lnk[f] & ~kAnswered) - 1;
        if ((Stand && sp && (rf.tag & kStandIn)) || !fb.faces(rf, eps)) {
            skipped += !(passed && same_plane(rf.pt, rf.nrm, passed->pt, passed->nrm));
            passed = &rf;
            f = older;
            continue;
        }
        if (!got) {
            add(rp, rf, cb);
            if (Vis) vs[p] += cb;
            if (Rec) rt[p] = f + 1;
            got = true;
        }
        if (lnk[f] & kAnswered) {
            if (passed_answered >= 0 || !(rf.tag & kCrossing)) break;
            passed_answered = f;
            f = older;
            continue;
        }
        if (passed_answered >= 0) {
            const GatherRec& wall = rec[(rec[passed_answered].tag & kAnswerer) - 1];
            if (hidden_behind(rf.pt, wall.pt, wall.nrm, eps)) break;
        }
        const double cf = double(dot3(rf.nrm, dh)) * wgt;
        add(rf, rp, cf);
        if (Vis) vs[f] += cf;
        if (Rec) rt[f] = p + 1;
        lnk[f] |= kAnswered;
        rf.tag = (rf.tag & ~kAnswerer) | static_cast<uint32_t>(p + 1);
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
template <bool Vis, bool Rec, bool Stand>
void pair_pending(GatherRec* rec, uint32_t* lnk, const PendingB* pend, size_t np, int K, float eps,
                  double wgt, const float* dh, double* vs, int32_t* rt) {
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
        pair_record<Vis, Rec, Stand>(rec, lnk, pend[j], K, eps, wgt, dh, vs, rt);
    }
}

using PairFn = void (*)(GatherRec*, uint32_t*, const PendingB*, size_t, int, float, double,
                        const float*, double*, int32_t*);

// The pair_pending instance for a walk's options.
template <bool Vis>
PairFn pick_pairing(bool rec, bool stand) {
    if (rec) return stand ? &pair_pending<Vis, true, true> : &pair_pending<Vis, true, false>;
    return stand ? &pair_pending<Vis, false, true> : &pair_pending<Vis, false, false>;
}
PairFn pick_pairing(bool vis, bool rec, bool stand) {
    return vis ? pick_pairing<true>(rec, stand) : pick_pairing<false>(rec, stand);
}

// The records of voxel g that are not a twin pair, in their order along d
// (by depth, B before F at equal depth: sort_group's order), through
// step_record.
VOXGI_INLINE void step_voxel(int32_t i, int gn, const float* NR, const float* PT, const float* dh,
                             Hit* hg, uint32_t* lk, int32_t& lastF, PendingB* pq, size_t& nq) {
    if (gn == 1) {  // no depth order needed
        const float* nr = NR + 3 * int64_t(i);
        step_record(lk, i, nr[0] * dh[0] + nr[1] * dh[1] + nr[2] * dh[2], lastF, pq, nq);
    } else if (gn == 2) {
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
}

// A voxel holding a front record and its back twin (most voxels of a closed
// scene): at one depth, so the one with n.d < 0 comes first (as sort_group
// orders them); their n.d are c and -c exactly. step_record(pa, -ac) then
// step_record(pb, ac), written out: the B leaves lastF as it is, so both
// links are lastF + 1, and only the B can be queued.
VOXGI_INLINE void step_twins(int32_t i, const float* NR, const float* dh, uint32_t* lk,
                             int32_t& lastF, PendingB* pq, size_t& nq) {
    const float* nr = NR + 3 * int64_t(i);
    const float c = nr[0] * dh[0] + nr[1] * dh[1] + nr[2] * dh[2];
    const bool first_is_f = c > 0.0f;  // then the twin (i + 1) is the B, met first
    const int32_t pa = first_is_f ? i + 1 : i, pb = first_is_f ? i : i + 1;
    const float ac = std::fabs(c);
    const bool live = ac > kTiny;
    lk[pa] = lk[pb] = static_cast<uint32_t>(lastF + 1);
    pq[nq] = PendingB{pa, lastF, -ac};
    nq += static_cast<size_t>(live & (lastF >= 0));
    lastF = live ? pb : lastF;
}

// Load the records of axis m into the thread's record array.
void load_axis(GatherWork& w, const LineSystem::Axis& ax, int m, int64_t n, const float* val,
               const uint8_t* stand) {
    w.rec.resize(n);
    const float* pn0 = ax.pn.data();
    for (int64_t i = 0; i < n; ++i) {
        GatherRec& r = w.rec[i];
        for (int c = 0; c < 3; ++c) {
            r.pt[c] = pn0[8 * i + c];
            r.nrm[c] = pn0[8 * i + 3 + c];
            r.val[c] = val[3 * i + c];
            r.acc[c] = 0.0;
        }
        r.tag = (stand && stand[i] ? kStandIn : 0) | (ax.crossing[i] ? kCrossing : 0);
    }
    w.rec_axis = m;
}

// Walk the records of one family in x_m order: every line is visited in its
// own order along +v; its state (the newest F record, older ones chained
// through the links) lives in a table indexed by the line key. Slab by slab,
// its queue paired after it: the voxel loop itself calls nothing, so its
// values stay in registers. Returns the lines walked (>= 2 records).
int64_t walk_family(GatherWork& w, const LineSystem::Axis& ax, const LineFrame& fr, const Family& F,
                    const WalkShared& ws, int32_t* rt) {
    const int64_t n = static_cast<int64_t>(ax.order.size());
    if (w.table.empty()) w.table.assign(ws.max_keys, LineState{0, -1});
    if (ws.vis && w.vis.empty()) w.vis.assign(n, 0.0);
    // the queue has room for all n: the branch-free step writes one entry past the kept ones
    if (w.pend.size() < static_cast<size_t>(n) + 1) w.pend.resize(n + 1);
    if (w.lnk.size() < static_cast<size_t>(n)) w.lnk.assign(n, 0);
    if (static_cast<int>(w.group.size()) < ax.gmax) w.group.resize(ax.gmax);
    const int32_t cur = ++w.stamp;        // no clearing: entries of other families carry old stamps
    const int32_t counted = 2 * cur + 1;  // the stamp of a line with >= 2 records in this pass
    float dh[3];
    unit_direction(F, dh);
    const PairFn pair_fn = pick_pairing(ws.vis, rt != nullptr, ws.stand);
    // Locals only in the loop: the pointers copied out of the containers, so
    // that the stores to the table, the links and the queue (int32 arrays,
    // which could alias the frame's int32 members) do not force them back to
    // memory on every voxel.
    const SlabKey sk(fr);
    const int32_t* __restrict AX = ax.X.data(), * __restrict AY = ax.Y.data();
    const int32_t* __restrict AZ = ax.Z.data();
    const int32_t* __restrict GS = ax.gstart.data();
    const uint8_t* __restrict GL = ax.gflag.data();
    const float* __restrict NR = ax.nrm.data();  // compact: the walk streams 24 B a record, not 64
    const float* __restrict PT = ax.pt.data();
    const int32_t* __restrict SL = ax.gslab.data();
    LineState* __restrict tbl = w.table.data();
    uint32_t* __restrict lk = w.lnk.data();
    PendingB* __restrict pq = w.pend.data();
    Hit* hg = w.group.data();
    GatherRec* rec = w.rec.data();
    double* vs = ws.vis ? w.vis.data() : nullptr;
    const int64_t nslab = static_cast<int64_t>(ax.gslab.size()) - 1;
    int64_t nwalked = 0;
    for (int64_t sl = 0; sl < nslab; ++sl) {
        const int64_t g1 = SL[sl + 1];
        const int64_t base = sk.base(AX[GS[SL[sl]]]);
        size_t nq = 0;
        for (int64_t g = SL[sl]; g < g1; ++g) {
            const int32_t i = GS[g];
            // (the tests hold this key and LineFrame::key, through the two
            // walks, to the same pairs)
            LineState& ls = tbl[sk.key(AY[i], AZ[i], base)];
            const int32_t old = ls.stamp;
            const bool seen = (old >> 1) == cur;
            int32_t lastF = seen ? ls.last : -1;
            if (GL[g] & LineSystem::Axis::kTwin) {
                step_twins(i, NR, dh, lk, lastF, pq, nq);
                nwalked += old != counted;  // two records: the line has two now
                ls.stamp = counted;
                ls.last = lastF;
                continue;
            }
            const int gn = GS[g + 1] - i;
            const bool multi = seen || gn > 1;
            nwalked += multi & (old != counted);
            step_voxel(i, gn, NR, PT, dh, hg, lk, lastF, pq, nq);
            ls.stamp = multi ? counted : 2 * cur;
            ls.last = lastF;
        }
        if (nq) pair_fn(rec, w.lnk.data(), w.pend.data(), nq, ws.K, ws.eps, F.weight, dh, vs, rt);
    }
    return nwalked;
}

// A group's sums in its axis's order, (n,3) and (n,) (vis, when summed).
struct GroupSums {
    int m = 0;
    std::unique_ptr<double[]> acc, vis;
};

// Sums buffers kept for the next groups (a group's sums wait here until the
// groups before it have been added).
class SumsPool {
   public:
    SumsPool(int64_t n, bool vis) : n_(n), vis_(vis) {}
    GroupSums take() {
        {
            std::lock_guard<std::mutex> lock(mu_);
            if (!free_.empty()) {
                GroupSums s = std::move(free_.back());
                free_.pop_back();
                return s;
            }
        }
        GroupSums s;
        s.acc.reset(new double[3 * n_]);
        if (vis_) s.vis.reset(new double[n_]);
        return s;
    }
    void give(GroupSums&& s) {
        std::lock_guard<std::mutex> lock(mu_);
        free_.push_back(std::move(s));
    }

   private:
    int64_t n_;
    bool vis_;
    std::mutex mu_;
    std::vector<GroupSums> free_;
};

// Move the thread's sums into `s`, leaving them zero.
void collect(GatherWork& w, int m, int64_t n, GroupSums& s) {
    s.m = m;
    GatherRec* a = w.rec.data();
    double* o = s.acc.get();
    for (int64_t i = 0; i < n; ++i) {
        o[3 * i] = a[i].acc[0];
        o[3 * i + 1] = a[i].acc[1];
        o[3 * i + 2] = a[i].acc[2];
        a[i].acc[0] = a[i].acc[1] = a[i].acc[2] = 0.0;
    }
    if (s.vis) {
        std::copy(w.vis.begin(), w.vis.begin() + n, s.vis.get());
        std::fill(w.vis.begin(), w.vis.begin() + n, 0.0);
    }
}

// The groups of a pass: the selected families in by-axis order (by column
// within an axis when recording), cut into groups of whole tiles of one
// axis. A group's sums are made by one task, and the groups' sums are added
// in group order: the result does not depend on the number of threads. The
// group size depends on the selection only: 16 families, up to 64 for large
// selections (fewer sums to add).
struct GatherPlan {
    std::vector<LineFrame> frames;  // per selected family
    std::vector<int64_t> order;     // selected families (indices into sel) in group order
    std::vector<int64_t> start;     // group g: order[start[g] .. start[g+1])
    int64_t groups() const { return static_cast<int64_t>(start.size()) - 1; }
};

GatherPlan plan_groups(const Family* fams, const int64_t* sel, int64_t nsel, const int32_t* lo,
                       const int32_t* hi, const PairTable* record) {
    GatherPlan plan;
    plan.frames.reserve(nsel);
    for (int64_t k = 0; k < nsel; ++k) plan.frames.emplace_back(fams[sel[k]].v, lo, hi);
    const auto& frames = plan.frames;
    const int64_t size = PairTable::kTile *
                         std::min<int64_t>(4, std::max<int64_t>(1, nsel / (32 * PairTable::kTile)));
    plan.order.resize(nsel);
    std::iota(plan.order.begin(), plan.order.end(), int64_t(0));
    auto column = [&](int64_t k) { return record ? int64_t(record->slot[sel[k]]) : int64_t(0); };
    std::stable_sort(plan.order.begin(), plan.order.end(), [&](int64_t a, int64_t b) {
        if (frames[a].m != frames[b].m) return frames[a].m < frames[b].m;
        return column(a) < column(b);
    });
    // a group ends after `size` families, or when recording at the first
    // tile boundary after that (whole tiles, however sparse the selection)
    for (int64_t q = 0, in_group = 0; q < nsel; ++q, ++in_group) {
        const int64_t k = plan.order[q];
        const bool new_axis = q == 0 || frames[k].m != frames[plan.order[q - 1]].m;
        const bool full = in_group >= size;
        const bool cut =
            new_axis || (full && (!record || column(k) / PairTable::kTile !=
                                                 column(plan.order[q - 1]) / PairTable::kTile));
        if (cut) {
            plan.start.push_back(q);
            in_group = 0;
        }
    }
    plan.start.push_back(nsel);
    return plan;
}

// Recording: the tile being filled by a group's task, written out when the
// group moves to the next tile and at its end; its families are marked
// recorded only then (a pass stopped half-way leaves them unrecorded).
struct TileWriter {
    PairTable* table;
    int m;
    int32_t* buf;  // the thread's family-major buffer: a family's writes stay within n entries
    int64_t tile = -1;
    uint32_t lanes = 0;
    std::vector<int64_t> families;
    // the column to write family f's pairs into
    int32_t* column(int64_t f) {
        const int64_t t = table->slot[f] / PairTable::kTile;
        if (t != tile) flush();
        tile = t;
        const int lane = table->slot[f] % PairTable::kTile;
        lanes |= 1u << lane;
        families.push_back(f);
        return buf + int64_t(lane) * table->n;
    }
    void flush() {
        if (tile < 0) return;
        table->write_tile(m, tile, lanes, buf);
        for (int64_t f : families) table->filled[f] = 1;
        families.clear();
        lanes = 0;
        tile = -1;
    }
};

}  // namespace

// The table given to record into is the one for this pass.
static void check_record(const LineSystem& ls, const Family* fams, const int64_t* sel, int64_t nsel,
                         const GatherOptions& opt) {
    const PairTable& t = *opt.record;
    if (t.n != ls.size()) throw std::invalid_argument("pair table made for another line system");
    if (t.with_stand_in != (opt.stand_in != nullptr))
        throw std::invalid_argument("pair table made with other stand-in flags");
    for (int64_t k = 0; k < nsel; ++k) {
        if (sel[k] < 0 || sel[k] >= t.nfam)
            throw std::invalid_argument("family outside the pair table");
        for (int c = 0; c < 3; ++c)
            if (fams[sel[k]].v[c] != t.vec[3 * sel[k] + c])
                throw std::invalid_argument("pair table made for other families");
    }
}

int64_t gather(const LineSystem& ls, const Family* fams, const int64_t* sel, int64_t nsel,
               const float* val, double* out, double* vis, const GatherOptions& opt,
               const StopCheck& stop) {
    PairTable* record = opt.record;
    if (record) check_record(ls, fams, sel, nsel, opt);
    if (ls.size() >= int64_t(kAnswerer))
        throw std::invalid_argument("too many records for the gathering (at most 2^30 - 2)");
    const GatherPlan plan = plan_groups(fams, sel, nsel, ls.lo(), ls.hi(), record);
    // values and stand-in flags in each needed axis order
    std::vector<float> valax[3];
    std::vector<uint8_t> sbax[3];
    for (const auto& fr : plan.frames) {
        const int m = fr.m;
        if (!valax[m].empty()) continue;
        ls.to_axis_order(m, val, valax[m]);
        if (!opt.stand_in) continue;
        sbax[m].resize(ls.size());
        const int32_t* ord = ls.axis(m).order.data();
        for (int64_t i = 0; i < ls.size(); ++i) sbax[m][i] = opt.stand_in[ord[i]] ? 1 : 0;
    }
    WalkShared ws{ls.epsilon(), ls.history(), vis != nullptr, opt.stand_in != nullptr, 1};
    for (const auto& fr : plan.frames) ws.max_keys = std::max<int64_t>(ws.max_keys, fr.nu * fr.nw);

    // the sums of each axis's groups, in that axis's order
    std::vector<double> tot[3], tvis[3];
    SumsPool pool(ls.size(), vis != nullptr);
    InOrder<GroupSums> in_order;
    auto add_group = [&](GroupSums& s) {
        std::vector<double>&ta = tot[s.m], &tv = tvis[s.m];
        if (ta.empty()) ta.assign(3 * ls.size(), 0.0);
        for (int64_t i = 0; i < 3 * ls.size(); ++i) ta[i] += s.acc[i];
        if (vis) {
            if (tv.empty()) tv.assign(ls.size(), 0.0);
            for (int64_t i = 0; i < ls.size(); ++i) tv[i] += s.vis[i];
        }
        pool.give(std::move(s));
    };
    const int threads = static_cast<int>(
        std::max<int64_t>(1, std::min<int64_t>(resolve_threads(opt.threads), plan.groups())));
    std::vector<GatherWork> work(threads);
    std::vector<int64_t> lines(threads, 0);
    parallel_for(plan.groups(), threads, stop, [&](int64_t g, int t) {
        GatherWork& w = work[t];
        const int m = plan.frames[plan.order[plan.start[g]]].m;
        if (w.rec_axis != m)
            load_axis(w, ls.axis(m), m, ls.size(), valax[m].data(),
                      opt.stand_in ? sbax[m].data() : nullptr);
        if (record && w.rbuf.empty())
            w.rbuf.assign(static_cast<size_t>(PairTable::kTile) * ls.size(), 0);
        TileWriter tw{record, m, w.rbuf.data(), -1, 0, {}};
        for (int64_t q = plan.start[g]; q < plan.start[g + 1]; ++q) {
            const int64_t k = plan.order[q];
            int32_t* rt = record ? tw.column(sel[k]) : nullptr;
            lines[t] += walk_family(w, ls.axis(m), plan.frames[k], fams[sel[k]], ws, rt);
        }
        if (record) tw.flush();
        GroupSums s = pool.take();
        collect(w, m, ls.size(), s);
        in_order.finish(g, std::move(s), add_group);
    });
    // into the global order, axis by axis
    std::fill(out, out + 3 * ls.size(), 0.0);
    if (vis) std::fill(vis, vis + ls.size(), 0.0);
    for (int m = 0; m < 3; ++m) {
        if (tot[m].empty()) continue;
        const int32_t* ord = ls.axis(m).order.data();
        for (int64_t i = 0; i < ls.size(); ++i) {
            const int64_t r = ord[i];
            out[3 * r] += tot[m][3 * i];
            out[3 * r + 1] += tot[m][3 * i + 1];
            out[3 * r + 2] += tot[m][3 * i + 2];
            if (vis) vis[r] += tvis[m][i];
        }
    }
    int64_t total = 0;
    for (auto x : lines) total += x;
    return total;
}

}  // namespace voxgi
