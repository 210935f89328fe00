// The shooting's march along one discrete ray, shared by the receiver-side
// deposit (shoot.cpp) and the sender-side one (reference.cpp). Internal to
// those two files; it reads the line system's records and voxel index.
#pragma once

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "lineorder.h"
#include "shoot.h"
#include "util/simd.h"

namespace voxgi {

// A receiver of one ray: its record, cos_r, and the share of the ray still
// travelling when it was reached (silhouettes; 1 otherwise).
struct RayHit {
    int32_t p;
    float c;
    double T;
};

// One deposit of a ray on a receiver: hd[r] += v.
struct Deposit {
    int32_t r;
    double v[3];
};

// The march of one ray: where it starts, how it steps, and what it has met.
struct Ray {
    int32_t e;
    int s;        // +1: along +v, -1: along -v (whichever e faces)
    float sd[3];  // unit direction of travel
    double ce;    // |n_e.d| * weight
    bool partial;
    double alpha;   // the share of the line's cross-section that e covers (1: all of it)
    double inv_dm;  // 1 / |d_m|
    // history of F records (hp[0] = e)
    int32_t hp[kMaxHistory];
    int hn = 1;
    bool found = false, stopped = false;
    // Silhouettes: T is the share of e's ray still travelling. The current
    // band of receivers (one object, consecutive steps) covers band_cov of
    // the line's cross-section; if the line then leaves that object through
    // another face of it (convex edge, within one step of the band), it only
    // grazed the object: the uncovered share 1 - band_cov goes on, and the
    // object's F records on that exit do not occlude it.
    double T = 1.0;
    int32_t band_obj = -1, band_last = -1, carry_obj = -1, carry_face = -1, crease_rec = -1;
    int64_t band_step = -8, carry_step = -8, istep = -1;
    double band_cov = 0.0;
    bool found_seg = false, carried = false, band_crease = false;

    // the state of a ray that has not started (hp past hp[0] is not read)
    void reset() {
        hn = 1;
        found = stopped = false;
        T = 1.0;
        band_obj = band_last = carry_obj = carry_face = crease_rec = -1;
        band_step = carry_step = -8;
        istep = -1;
        band_cov = 0.0;
        found_seg = carried = band_crease = false;
    }
};

// Per-call data of the march: the families' frames and directions, the
// records' positions, and the options.
class ShootMarch {
   public:
    ShootMarch(const LineSystem& s, const Family* fams, int64_t nf, const ShootOptions& opt,
               bool keep_shadowed)
        : s_(s), fams_(fams), nf_(nf), opt_(opt), keep_shadowed_(keep_shadowed) {
        s.build_occupancy();
        frames_.reserve(nf);
        dhat_.resize(3 * nf);
        for (int64_t f = 0; f < nf; ++f) {
            frames_.emplace_back(fams[f].v, s.lo(), s.hi());
            unit_direction(fams[f], &dhat_[3 * f]);
        }
        const LineSystem::Axis& a0 = s.axis(0);
        pos0_.resize(s.size());
        for (int64_t i = 0; i < s.size(); ++i) pos0_[a0.order[i]] = static_cast<int32_t>(i);
        P_ = s.point();
        N_ = s.normal();
        eps_ = s.epsilon();
        K_ = s.history();
    }

    int64_t families() const { return nf_; }
    const Family& family(int64_t f) const { return fams_[f]; }

    // Start e's ray along family f; false when e is parallel to it.
    bool start(int32_t e, int64_t f, Ray& r) const {
        const float* dv = &dhat_[3 * f];
        const float cv = dot3(N_ + 3 * int64_t(e), dv);
        if (std::abs(cv) <= kTiny) return false;
        r.reset();
        r.e = e;
        r.s = cv > 0 ? 1 : -1;
        for (int c = 0; c < 3; ++c) r.sd[c] = r.s * dv[c];
        r.ce = std::abs(double(cv)) * fams_[f].weight;
        r.partial = opt_.coverage && opt_.coverage[e] >= 0;
        r.alpha = r.partial
                      ? opt_.coverage[e] * std::abs(double(cv)) / std::abs(double(dv[frames_[f].m]))
                      : 1.0;
        r.inv_dm = 1.0 / std::abs(double(dv[frames_[f].m]));
        r.hp[0] = e;
        return true;
    }

    // March the ray to the end of its line, or until it stops; the
    // receivers whose nearest facing sender is e go to `recv`. Returns the
    // voxels visited.
    int64_t run(const LineFrame& fr, Ray& r, std::vector<Hit>& group,
                std::vector<RayHit>& recv) const;

   private:
    const LineSystem& s_;
    const Family* fams_;
    int64_t nf_;
    const ShootOptions& opt_;
    bool keep_shadowed_;  // sender side: a shadowed receiver that e faces takes e's power
    std::vector<LineFrame> frames_;
    std::vector<float> dhat_;
    std::vector<int32_t> pos0_;  // position of every record in the (x, y, z) order
    const float *P_, *N_;
    float eps_;
    int K_;

   public:
    const LineFrame& frame(int64_t f) const { return frames_[f]; }

   private:
    bool same_plane(int32_t q, int32_t p) const;
    void visit(int64_t slot, bool first, Ray& r, std::vector<Hit>& group,
               std::vector<RayHit>& recv) const;
    bool on_front(int32_t p, Ray& r) const;
    bool leave_band(int32_t p, Ray& r) const;
    bool on_back(int32_t p, float c, Ray& r, const std::vector<Hit>& group,
                 std::vector<RayHit>& recv) const;
    void join_band(int32_t p, float c, Ray& r, const std::vector<Hit>& group) const;
};

// q and p lie in one plane with one normal (to 1e-5 in the normal, eps along
// it), and are alike for the rules that pick among F records (one object,
// both stand-ins or neither).
inline bool ShootMarch::same_plane(int32_t q, int32_t p) const {
    if (opt_.object && opt_.object[q] != opt_.object[p]) return false;
    if (opt_.stand_in && opt_.stand_in[q] != opt_.stand_in[p]) return false;
    const float *nq = N_ + 3 * int64_t(q), *np = N_ + 3 * int64_t(p);
    if (dot3(nq, np) < 1.0f - 1e-5f) return false;
    const float *pq = P_ + 3 * int64_t(q), *pp = P_ + 3 * int64_t(p);
    const float off = (pp[0] - pq[0]) * nq[0] + (pp[1] - pq[1]) * nq[1] + (pp[2] - pq[2]) * nq[2];
    return std::abs(off) <= eps_;
}

inline int64_t ShootMarch::run(const LineFrame& fr, Ray& r, std::vector<Hit>& group,
                               std::vector<RayHit>& recv) const {
    const LineSystem::Axis& a0 = s_.axis(0);
    const int32_t pe = pos0_[r.e];
    const int32_t eijk[3] = {a0.X[pe], a0.Y[pe], a0.Z[pe]};
    // the line through e's voxel: u, w fixed; y', z' follow from x'
    const int m = fr.m, o1 = fr.o1, o2 = fr.o2, s = r.s;
    const int64_t X0 = eijk[m] - fr.lo[m];
    const int64_t Y0 = fr.yprime(eijk[o1]), Z0 = fr.zprime(eijk[o2]);
    const int64_t h = fr.A / 2;
    const int64_t u = (fr.A * Y0 + fr.B * (fr.XmA - X0) + h) / fr.A;
    const int64_t w = (fr.A * Z0 + fr.C * (fr.XmA - X0) + h) / fr.A;
    const int64_t Xr = int64_t(fr.hi[m]) - fr.lo[m];
    const int64_t Yr = int64_t(fr.hi[o1]) - fr.lo[o1], Zr = int64_t(fr.hi[o2]) - fr.lo[o2];
    // y' = u - floor((B (XmA - x') + h) / A), z' likewise, kept as quotient
    // and remainder updated by +-B, +-C per step (B, C <= A): integer-only,
    // no division in the loop.
    int64_t numy = fr.B * (fr.XmA - X0) + h, numz = fr.C * (fr.XmA - X0) + h;
    int64_t qy = numy / fr.A, ry = numy % fr.A, qz = numz / fr.A, rz = numz % fr.A;
    const uint64_t* occ = s_.occupancy();
    int64_t nsteps = 0;
    bool first = true;
    for (int64_t X = X0; X >= 0 && X <= Xr && !r.stopped; first = false) {
        ++nsteps;
        ++r.istep;
        const int64_t Y = u - qy;
        const int64_t Z = w - qz;
        if (Y < 0 || Y > Yr || Z < 0 || Z > Zr) break;
        int32_t c3[3];
        c3[m] = static_cast<int32_t>(X + fr.lo[m]);
        c3[o1] = static_cast<int32_t>(fr.pos1 ? Y + fr.lo[o1] : fr.hi[o1] - Y);
        c3[o2] = static_cast<int32_t>(fr.pos2 ? Z + fr.lo[o2] : fr.hi[o2] - Z);
        // next voxel of the line, without branches (whether a remainder
        // wraps is a coin toss from one step to the next; my, mz have every
        // bit set where it does)
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
        const int64_t lin = s_.linear(c3[0], c3[1], c3[2]);
        if (!((occ[lin >> 6] >> (lin & 63)) & 1)) continue;
        const uint64_t below = occ[lin >> 6] & ((uint64_t(1) << (lin & 63)) - 1);
        visit(s_.occupancy_rank()[lin >> 6] + __builtin_popcountll(below), first, r, group, recv);
    }
    return nsteps;
}

// The records of one occupied voxel in their order along the ray.
inline void ShootMarch::visit(int64_t slot, bool first, Ray& r, std::vector<Hit>& group,
                              std::vector<RayHit>& recv) const {
    const LineSystem::Axis& a0 = s_.axis(0);
    const int32_t* vstart = s_.voxel_start();
    const int32_t b = vstart[slot], en = vstart[slot + 1];
    group.clear();
    for (int32_t i = b; i < en; ++i) {
        const int32_t q = a0.order[i];
        group.push_back(Hit{q, dot3(P_ + 3 * int64_t(q), r.sd), dot3(N_ + 3 * int64_t(q), r.sd)});
    }
    sort_group(group.data(), static_cast<int>(group.size()));
    size_t a = 0;
    if (first) {  // start just after e in its own voxel
        while (a < group.size() && group[a].p != r.e) ++a;
        ++a;
    }
    for (; a < group.size(); ++a) {
        const int32_t p = group[a].p;
        const float c = group[a].c;
        if (c > kTiny) {
            if (!on_front(p, r)) break;
        } else if (c < -kTiny) {
            if (!on_back(p, c, r, group, recv)) break;
        }
    }
}

// An F record on the ray: it joins the history, or lets the ray through
// (e's own sheet, a grazed object), or stops the ray (the history is full).
// False: the ray stops.
inline bool ShootMarch::on_front(int32_t p, Ray& r) const {
    if (r.partial) {  // e's own sheet (or behind it) does not occlude e
        const float *pq = P_ + 3 * int64_t(p), *pe = P_ + 3 * int64_t(r.e);
        const float* nE = N_ + 3 * int64_t(r.e);
        const float off =
            (pq[0] - pe[0]) * nE[0] + (pq[1] - pe[1]) * nE[1] + (pq[2] - pe[2]) * nE[2];
        if (off <= eps_) return true;
    }
    if (opt_.object) {
        if (opt_.object[p] == r.carry_obj) {  // the remainder is outside this object
            r.carry_step = r.istep;
            return true;
        }
        if (leave_band(p, r)) return !r.stopped;
    }
    // A run of F records in one plane with one normal (the back twins of a
    // face the line runs along, nearly parallel to it) keeps only its first
    // and latest records: whether a later receiver lies behind such a
    // record's plane is one test for the whole run, and whether the record
    // lies in front of the receiver's plane, a linear function along the
    // run, is decided at its ends. The run would otherwise fill the history
    // and stop e's light with nothing received (docs/design.md §5).
    if (r.hn >= 3 && same_plane(r.hp[r.hn - 1], p) && same_plane(r.hp[r.hn - 2], p)) {
        r.hp[r.hn - 1] = p;
        return true;
    }
    if (r.hn == K_) {  // e would be forgotten: its light stops here
        r.stopped = true;
        return false;
    }
    r.hp[r.hn++] = p;
    return true;
}

// F record p of the band's object, after the band touched a convex crease
// of it: the line now leaves the object (its back twins or another face,
// behind the band's plane), so it only clipped the edge; the share of the
// line the band did not cover goes on. True: p was such a record.
inline bool ShootMarch::leave_band(int32_t p, Ray& r) const {
    const int32_t op = opt_.object[p];
    if (!(op == r.band_obj && r.band_crease && r.istep <= r.band_step + 1)) return false;
    const float *pq = P_ + 3 * int64_t(p), *nq = N_ + 3 * int64_t(p);
    const float *pb = P_ + 3 * int64_t(r.band_last), *nb = N_ + 3 * int64_t(r.band_last);
    const float d0 = pq[0] - pb[0], d1 = pq[1] - pb[1], d2 = pq[2] - pb[2];
    const bool convex = (d0 * nb[0] + d1 * nb[1] + d2 * nb[2] < eps_) &&
                        (-(d0 * nq[0] + d1 * nq[1] + d2 * nq[2]) < eps_);
    if (!convex) return false;
    r.T *= std::max(0.0, 1.0 - r.band_cov);
    r.carry_obj = op;
    r.carry_face = r.crease_rec;  // the face the line grazed
    r.carry_step = r.istep;
    r.band_obj = -1;
    r.carried = true;
    r.found_seg = false;
    // the object's F records seen so far stop occluding
    int hk = 1;
    for (int hh = 1; hh < r.hn; ++hh)
        if (opt_.object[r.hp[hh]] != op) r.hp[hk++] = r.hp[hh];
    r.hn = hk;
    if (r.T <= 1e-12) r.stopped = true;
    return true;
}

// A B record on the ray: it receives from e if e is its nearest facing
// sender; if another F is, e is shadowed there and the ray stops. False: the
// ray stops.
inline bool ShootMarch::on_back(int32_t p, float c, Ray& r, const std::vector<Hit>& group,
                                std::vector<RayHit>& recv) const {
    const int32_t* object = opt_.object;
    const uint8_t* stand_in = opt_.stand_in;
    // the grazing remainder does not see the inside of the object it passed
    // (its back records) nor, while the line still runs along it, its front
    // records (another face of it, which the remainder runs towards, does
    // receive it: a lit side below a grazed top edge)
    if (object && object[p] == r.carry_obj &&
        (opt_.back[p] || (r.istep <= r.carry_step + 1 &&
                          dot3(N_ + 3 * int64_t(p), N_ + 3 * int64_t(r.carry_face)) > 0.5f))) {
        r.carry_step = r.istep;
        return true;
    }
    const float *pp = P_ + 3 * int64_t(p), *np = N_ + 3 * int64_t(p);
    int nearest = -1;
    const bool sp = stand_in && stand_in[p];  // two stand-ins never pair
    for (int hh = r.hn - 1; hh >= 0; --hh) {
        const int32_t fq = r.hp[hh];
        if (sp && stand_in[fq]) continue;
        if (facing(P_ + 3 * int64_t(fq), N_ + 3 * int64_t(fq), pp, np, eps_)) {
            nearest = hh;
            break;
        }
    }
    if (nearest == 0) {  // e is p's sender along this line
        r.found = true;
        r.found_seg = true;
        r.carry_obj = -1;  // a receiver ends the transparent exit
        recv.push_back(RayHit{p, -c, r.T});
        if (object) join_band(p, c, r, group);
    } else if (nearest > 0) {  // someone nearer sends to p: e is shadowed
        const float *pe = P_ + 3 * int64_t(r.e), *nE = N_ + 3 * int64_t(r.e);
        if (facing(pe, nE, pp, np, eps_)) {
            // e's light reached p's surface: counted as received; with the
            // sender-side deposit p takes e's power
            r.found = true;
            r.found_seg = true;
            if (keep_shadowed_) recv.push_back(RayHit{p, -c, r.T});
        }
        r.stopped = true;
        return false;
    }
    return true;
}

// Receiver p joins the ray's band of its object (silhouettes); a silhouette
// when p's voxel holds another face of p's object that this line leaves
// (F), at a convex edge.
inline void ShootMarch::join_band(int32_t p, float c, Ray& r, const std::vector<Hit>& group) const {
    const int32_t* object = opt_.object;
    if (object[p] != r.band_obj || r.istep > r.band_step + 1) {
        r.band_obj = object[p];
        r.band_cov = 0.0;
        r.band_crease = false;
    }
    if (!r.band_crease && opt_.sil_area[p] >= 0) {
        const float *pp = P_ + 3 * int64_t(p), *np_ = N_ + 3 * int64_t(p);
        for (const Hit& g : group) {
            const int32_t q = g.p;
            if (g.c <= kTiny || object[q] != object[p]) continue;
            const float *pq = P_ + 3 * int64_t(q), *nq = N_ + 3 * int64_t(q);
            const float dn = dot3(np_, nq);
            if (dn >= 0.5f || dn <= -0.9f) continue;  // same face, or a twin
            const float d0 = pq[0] - pp[0], d1 = pq[1] - pp[1], d2 = pq[2] - pp[2];
            if (d0 * np_[0] + d1 * np_[1] + d2 * np_[2] < eps_ &&
                -(d0 * nq[0] + d1 * nq[1] + d2 * nq[2]) < eps_) {
                r.band_crease = true;
                r.crease_rec = p;  // the grazed face's record
                break;
            }
        }
    }
    r.band_cov += opt_.sil_area[p] * double(-c) * r.inv_dm;
    r.band_step = r.istep;
    r.band_last = p;
}

// The march of every emitter's rays, `deposit(march, ray, family, recv,
// deposits)` turning each ray's receivers into deposits (false: the ray
// delivered nothing after all). Tasks of kChunk emitters; their deposits are
// added to hd in task order, so hd does not depend on the threads.
template <class DepositFn>
ShootCount shoot_march(const LineSystem& ls, const int32_t* emit, int64_t ne, const Family* fams,
                       int64_t nf, const float* val, double* hd, double* unfound,
                       const ShootOptions& opt, const DepositFn& deposit, const StopCheck& stop) {
    for (int64_t k = 0; k < ne; ++k)
        if (emit[k] < 0 || emit[k] >= ls.size())
            throw std::invalid_argument("emitter index out of range");
    const ShootMarch sm(ls, fams, nf, opt, DepositFn::kKeepShadowed);
    constexpr int64_t kChunk = 4;
    const int64_t tasks = (ne + kChunk - 1) / kChunk;
    const int threads = static_cast<int>(
        std::max<int64_t>(1, std::min<int64_t>(resolve_threads(opt.threads), tasks)));
    std::vector<int64_t> rays(threads, 0), steps(threads, 0);
    std::fill(hd, hd + 3 * ls.size(), 0.0);
    InOrder<std::vector<Deposit>> in_order;
    auto add = [&](std::vector<Deposit>& d) {
        for (const Deposit& x : d) {
            double* H = hd + 3 * int64_t(x.r);
            H[0] += x.v[0];
            H[1] += x.v[1];
            H[2] += x.v[2];
        }
    };
    parallel_for(tasks, threads, stop, [&](int64_t task, int t) {
        std::vector<Hit> group;
        std::vector<RayHit> recv;
        std::vector<Deposit> deposits;
        int64_t nsteps = 0, nrays = 0;  // locals: no store per step
        Ray r;
        for (int64_t k = task * kChunk; k < std::min(ne, (task + 1) * kChunk); ++k) {
            const float* ve = val + 3 * int64_t(emit[k]);
            double lost = 0.0;
            for (int64_t f = 0; f < nf; ++f) {
                if (!sm.start(emit[k], f, r)) continue;
                ++nrays;
                recv.clear();
                nsteps += sm.run(sm.frame(f), r, group, recv);
                if (!recv.empty() && !deposit(r, fams[f], ve, recv, deposits)) r.found = false;
                if (!r.found)
                    lost += r.ce;
                else if (r.carried && !r.found_seg)
                    lost += r.ce * r.T;  // the grazing remainder escaped
            }
            unfound[k] = lost;
        }
        steps[t] += nsteps;
        rays[t] += nrays;
        in_order.finish(task, std::move(deposits), add);
    });
    ShootCount count;
    for (int t = 0; t < threads; ++t) {
        count.rays += rays[t];
        count.steps += steps[t];
    }
    return count;
}

}  // namespace voxgi
