// The record at a ray's hit point (see record_lookup.h and docs/design.md §6).
//
// A cluttered interior puts tens to hundreds of records in one voxel (a
// plant, a shelf of objects), and whether a record may stand for the hit
// point asks every other record of the voxel (separation below). So the
// lookup asks it of as few candidates as it can: in the order of their
// scores, stopping at the first that nothing separates, since no later one
// can then win; and what a record's plane says of the hit point alone is
// worked out once per voxel record, not once per candidate. Where no
// record of the hit's voxel is clean, the neighbouring voxels' records are
// mostly set apart by the same few walls: those are settled as they are
// collected, and only the rest are asked.
#include "record_lookup.h"

#include <algorithm>
#include <utility>

namespace voxgi {

namespace {

using Plane = LookupScratch::Plane;
using Candidate = LookupScratch::Candidate;

inline float dot3(const float* a, const float* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// The records of voxel (i, j, k): [q0, q1) in the grid's order (empty outside it).
inline void cell_records(const RecordGrid& g, int64_t i, int64_t j, int64_t k, int64_t& q0,
                         int64_t& q1) {
    q0 = q1 = 0;
    const int64_t key = grid_key(g, i, j, k);
    if (key < 0) return;
    if (g.cell_start) {
        q0 = g.cell_start[key], q1 = g.cell_start[key + 1];
    } else {
        q0 = std::lower_bound(g.sorted_key, g.sorted_key + g.count, key) - g.sorted_key;
        q1 = std::upper_bound(g.sorted_key + q0, g.sorted_key + g.count, key) - g.sorted_key;
    }
}

// Record o's plane as the hit point y (seen from the side of n) meets it.
inline Plane plane_at_hit(const RecordGrid& g, const PackedRecord& o, const double y[3],
                          const float n[3]) {
    Plane p;
    // o's plane is as good as its float centroid: a few units in the last
    // place of its coordinates.
    p.tol = 1e-6 * g.pitch + 3e-7 * std::max({std::fabs(o.centroid[0]), std::fabs(o.centroid[1]),
                                              std::fabs(o.centroid[2])});
    double sy = 0.0;
    for (int a = 0; a < 3; ++a) sy += (y[a] - o.centroid[a]) * o.normal[a];
    p.sy = sy;
    p.holds = std::fabs(sy) <= p.tol && dot3(o.normal, n) > 0.5f;
    p.cut = -1;
    return p;
}

// How far record r stands apart from the hit point y across record o's
// plane, which meets y as p says without holding it: 2 when o is of another
// object, or of an orientation more than 60° away (another cluster of the
// voxelization), has y strictly on one side of its plane and r's centroid
// not on that side. Those are the planes junction cutting split r's surface
// by, so this keeps a hit on one side of a thin wall from reading the record
// on the other. 1 when it is apart only by the signs of y's distances within
// rounding of such a plane (the best guess there); 0 otherwise.
inline int apart_across(const PackedRecord& o, const Plane& p, const PackedRecord& r) {
    double sr = 0.0;
    for (int a = 0; a < 3; ++a) sr += (double(r.centroid[a]) - o.centroid[a]) * o.normal[a];
    const float along = dot3(o.normal, r.normal);
    // r's own sheet: its orientation, or its other side through r's
    // centroid (a curved sheet's y lies off that plane on either side).
    if (o.object == r.object && (along > 0.5f || (along < -0.5f && std::fabs(sr) <= p.tol)))
        return 0;
    const double sy = p.sy, tol = p.tol;
    // A centroid on that plane (a sliver cut off at a junction) is on
    // neither side: it does not stand for a point off the plane.
    if ((sy > tol && sr < tol) || (sy < -tol && sr > -tol)) return 2;
    return (sy > 0.0 && sr < 0.0) || (sy < 0.0 && sr > 0.0) ? 1 : 0;
}

// Whether the record h, whose plane holds y, lies across another surface
// of the voxel [q0, q1) from y (planes[q - q0] is record q's plane at y).
// Such a record is a sliver of the hit's face beyond that surface (the top
// of a moulding poking a hair through a ceiling, cut off by it), not the
// hit's own sheet: its plane then sets no record apart.
template <class PlaneAt>
bool holding_record_cut(const RecordGrid& g, int64_t h, int64_t q0, int64_t q1, PlaneAt plane_of) {
    for (int64_t q = q0; q < q1; ++q) {
        if (q == h) continue;
        const Plane p = plane_of(q);
        if (!p.holds && apart_across(g.rec[q], p, g.rec[h]) == 2) return true;
    }
    return false;
}

// How far record r stands apart from the hit point y (on a surface seen from
// the side of normal n) by another record o of a voxel, whose plane meets y
// as p says: 2 when
// - it lies off the hit's own sheet: o's plane holds y, facing n's side, and
//   has r's centroid strictly in front of or behind it (the other face of a
//   slab thinner than a voxel, or its black back); unless r is of o's object
//   and orientation (a bent sheet's neighbouring cluster) and o itself lies
//   across another surface from y (`cut_off(o)`, holding_record_cut): a
//   sliver of the hit's face beyond that surface does not stand for the
//   hit's sheet;
// - or across another surface (apart_across);
// 1 when it is apart only by the signs of y's distances within rounding of
// such a plane (the best guess there); 0 otherwise.
template <class CutOff>
inline int apart_by(const PackedRecord& o, const Plane& p, const PackedRecord& r, const float n[3],
                    CutOff cut_off) {
    if (p.holds) {
        double behind = 0.0;
        for (int a = 0; a < 3; ++a) behind += (double(r.centroid[a]) - o.centroid[a]) * n[a];
        if (!(std::fabs(behind) > p.tol)) return 0;
        if (o.object == r.object && dot3(o.normal, r.normal) > 0.5f && cut_off()) return 0;
        return 2;
    }
    return apart_across(o, p, r);
}

// The most any other record of the voxel [q0, q1) sets r apart from the hit
// point (apart_by), each one's plane at the hit worked out here.
int separation(const RecordGrid& g, const double y[3], const float n[3], const PackedRecord& r,
               int64_t q0, int64_t q1) {
    int level = 0;
    for (int64_t q = q0; q < q1; ++q) {
        const PackedRecord& o = g.rec[q];
        if (&o == &r) continue;
        const Plane p = plane_at_hit(g, o, y, n);
        const int apart = apart_by(o, p, r, n, [&] {
            return holding_record_cut(g, q, q0, q1,
                                      [&](int64_t k) { return plane_at_hit(g, g.rec[k], y, n); });
        });
        if (apart == 2) return 2;
        level = std::max(level, apart);
    }
    return level;
}

// How far own record i (of the hit's voxel, from h0) sets r apart (apart_by).
// Whether a holding plane's record is cut off is asked at most once per
// lookup, and only where the answer matters.
inline int apart_by_own(const RecordGrid& g, const float n[3], const PackedRecord& r, int64_t h0,
                        int32_t i, LookupScratch& S) {
    return apart_by(g.rec[h0 + i], S.own[size_t(i)], r, n, [&] {
        Plane& p = S.own[size_t(i)];
        if (p.cut < 0) {
            const int64_t h1 = h0 + int64_t(S.own.size());
            p.cut = holding_record_cut(g, h0 + i, h0, h1,
                                       [&](int64_t k) { return S.own[size_t(k - h0)]; });
        }
        return p.cut == 1;
    });
}

// Whether one of the own records that set the last candidates apart sets r
// apart too (then the one that does moves to the front of S.recent).
inline bool apart_by_recent(const RecordGrid& g, const float n[3], const PackedRecord& r,
                            int64_t h0, LookupScratch& S, int& level) {
    constexpr int R = LookupScratch::kRecent;
    for (int k = 0; k < R && S.recent[k] >= 0; ++k) {
        const int32_t i = S.recent[k];
        if (&g.rec[h0 + i] == &r) continue;
        const int apart = apart_by_own(g, n, r, h0, i, S);
        if (apart == 2) {
            for (; k > 0; --k) S.recent[k] = S.recent[k - 1];
            S.recent[0] = i;
            return true;
        }
        level = std::max(level, apart);
    }
    return false;
}

// The same over the hit's own voxel, whose records' planes at the hit are
// S.own. The answer is the largest of the records' verdicts, in any order,
// so the records most likely to set r apart are asked first: the few that
// set the last candidates apart (a wall between the hit and a cluster of
// records sets them all apart; a crowded voxel has a few such walls), then
// the planes that hold the hit (any record off the hit's own sheet is apart
// by them).
int separation_own(const RecordGrid& g, const float n[3], const PackedRecord& r, int64_t h0,
                   LookupScratch& S) {
    int level = 0;
    if (apart_by_recent(g, n, r, h0, S, level)) return 2;
    constexpr int R = LookupScratch::kRecent;
    const int32_t count = int32_t(S.own.size());
    const bool ordered = !S.own_order.empty();
    for (int32_t j = 0; j < count; ++j) {
        const int32_t i = ordered ? S.own_order[size_t(j)] : j;
        const PackedRecord& o = g.rec[h0 + i];
        if (&o == &r) continue;
        bool asked = false;
        for (int k = 0; k < R && S.recent[k] >= 0; ++k) asked |= S.recent[k] == i;
        if (asked) continue;
        const int apart = apart_by_own(g, n, r, h0, i, S);
        if (apart == 2) {
            for (int k = R - 1; k > 0; --k) S.recent[k] = S.recent[k - 1];
            S.recent[0] = i;
            return 2;
        }
        level = std::max(level, apart);
    }
    return level;
}

// Candidate a comes before b: nearer, or as near and visited first.
inline bool before(const Candidate& a, const Candidate& b) {
    return a.score < b.score || (a.score == b.score && a.order < b.order);
}

}  // namespace

int64_t lookup_in_cell(const RecordGrid& g, const double y[3], const float n[3], int32_t obj,
                       const int64_t c[3], int32_t tri, bool front, LookupScratch& S) {
    // The record the voxelization put y's part of its triangle in: the
    // answer the search below can only approach by the records' points.
    if (g.piece_first && tri >= 0 && tri < g.piece_tris) {
        const int64_t key = grid_key(g, c[0], c[1], c[2]);
        for (int64_t e = g.piece_first[tri]; e < g.piece_first[tri + 1]; ++e) {
            if (g.piece_key[e] != key) continue;
            // a split piece: the part on y's side of each plane that split it
            bool part = true;
            for (int64_t k = g.piece_plane_first[e]; part && k < g.piece_plane_first[e + 1]; ++k) {
                const double* pl = g.piece_plane + 4 * k;
                double s = -pl[3];
                for (int a = 0; a < 3; ++a) s += pl[a] * (y[a] - g.origin[a]) / g.pitch;
                part = (s >= 0.0) == bool((g.piece_side[e] >> (k - g.piece_plane_first[e])) & 1u);
            }
            if (!part) continue;
            const int64_t r = g.piece_record[2 * e + (front ? 0 : 1)];
            if (dot3(g.rec[r].normal, n) > 0.f) return r;
            break;
        }
    }
    const double p2 = g.pitch * g.pitch;
    int64_t best = -1, h0, h1;
    int best_apart = 0;
    double best_score = 0.0, best_penalty = 0.0;
    cell_records(g, c[0], c[1], c[2], h0, h1);
    S.own.resize(size_t(h1 - h0));
    for (int64_t q = h0; q < h1; ++q) S.own[size_t(q - h0)] = plane_at_hit(g, g.rec[q], y, n);
    // the order the records of a crowded voxel are asked in (a sparse one
    // is asked as it lies)
    constexpr int64_t kCrowded = 8;
    S.own_order.clear();
    if (h1 - h0 > kCrowded) {
        for (int pass = 0; pass < 2; ++pass)
            for (int64_t q = h0; q < h1; ++q)
                if (S.own[size_t(q - h0)].holds == (pass == 0))
                    S.own_order.push_back(int32_t(q - h0));
    }
    for (int32_t& i : S.recent) i = -1;
    std::vector<Candidate>& C = S.candidates;
    C.clear();
    S.cell_first.clear();
    S.cell_end.clear();
    int32_t visited = 0;
    // The records of voxel [q0, q1) facing n's side, with their scores; none
    // that could not beat a clean best.
    int32_t best_order = 0;
    // With `settle`, a record that one of the own records which set the last
    // candidates apart sets apart too is settled here, not asked later: it is
    // apart (2, the most), so it wins only as the nearest of those apart.
    // The best is the least of (separation, score, order) in any order of
    // asking, so this changes no answer; it spares the neighbours' many such
    // records (most of a crowded voxel's, behind one wall) their asking.
    auto collect = [&](int64_t q0, int64_t q1, bool settle) {
        const int32_t cell = int32_t(S.cell_first.size());
        S.cell_first.push_back(q0);
        S.cell_end.push_back(q1);
        for (int64_t q = q0; q < q1; ++q, ++visited) {
            const PackedRecord& r = g.rec[q];
            const float facing = dot3(r.normal, n);
            if (!(facing > 0.f)) continue;  // the other side of a sheet, or of a fold
            const double dx = y[0] - r.centroid[0], dy = y[1] - r.centroid[1],
                         dz = y[2] - r.centroid[2];
            const double penalty = 4.0 * (1.0 - facing) + (r.object != obj ? 4.0 : 0.0);
            const double score = dx * dx + dy * dy + dz * dz + p2 * penalty;
            if (best >= 0 && best_apart == 0 && score >= best_score) continue;
            int level = 0;
            if (settle && best >= 0 && apart_by_recent(g, n, r, h0, S, level)) {
                if (best_apart == 2 &&
                    (score < best_score || (score == best_score && visited < best_order)))
                    best = q, best_score = score, best_penalty = penalty, best_order = visited;
                continue;
            }
            C.push_back({score, penalty, q, visited, cell});
        }
    };
    // The best of the candidates, against the best so far: the least
    // separated, then the nearest, then the first visited (the order they
    // are asked in does not matter). The nearest few are asked first, as one
    // of them is most often clean, and then no later one can win; the rest
    // as they come (where none is clean all are asked anyway, and sorting
    // them would cost more than it saves).
    auto nearer = [&](const Candidate& k) {  // k before the best, at the same separation
        return k.score < best_score || (k.score == best_score && k.order < best_order);
    };
    auto ask = [&](const Candidate& k, bool own) {
        if (best >= 0 && best_apart == 0 && !nearer(k)) return;
        const PackedRecord& r = g.rec[k.index];
        int apart = separation_own(g, n, r, h0, S);
        if (!own && apart < 2)
            apart =
                std::max(apart, separation(g, y, n, r, S.cell_first[k.cell], S.cell_end[k.cell]));
        if (best < 0 || apart < best_apart || (apart == best_apart && nearer(k)))
            best = k.index, best_score = k.score, best_penalty = k.penalty, best_apart = apart,
            best_order = k.order;
    };
    auto choose = [&](bool own) {
        constexpr size_t kNearestFirst = 4;
        const size_t first = std::min(kNearestFirst, C.size());
        for (size_t i = 0; i < first; ++i) {
            size_t m = i;
            for (size_t j = i + 1; j < C.size(); ++j)
                if (before(C[j], C[m])) m = j;
            std::swap(C[i], C[m]);
            if (best >= 0 && best_apart == 0 && !nearer(C[i])) return;  // nor any after it
            ask(C[i], own);
        }
        for (size_t i = first; i < C.size(); ++i) ask(C[i], own);
    };
    collect(h0, h1, false);
    choose(true);
    if (best >= 0 && best_penalty < 0.5 && best_apart == 0) return best;
    C.clear();
    for (int di = -1; di <= 1; ++di)
        for (int dj = -1; dj <= 1; ++dj)
            for (int dk = -1; dk <= 1; ++dk)
                if ((di || dj || dk) && neighbour_within_reach(g, y, c, di, dj, dk)) {
                    int64_t q0, q1;
                    cell_records(g, c[0] + di, c[1] + dj, c[2] + dk, q0, q1);
                    collect(q0, q1, true);
                }
    choose(false);
    return best;
}

}  // namespace voxgi
