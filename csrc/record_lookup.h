// The record standing for a surface point where a ray lands (docs/design.md §6):
// the records sorted by voxel, and the lookup the display's gather rays and
// the solve's traced passes share. No pybind11 here: plain pointers and sizes.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

namespace voxgi {

// What a gather ray's lookup reads of one record: one 64-byte row, so that
// scoring a voxel's records and reading the chosen one's light touch a cache
// line or two instead of one per array (the lookup is bound by these loads).
struct PackedRecord {
    float centroid[3];  // in the tracer's frame; it only ranks records in a voxel
    float normal[3];
    int32_t object;
    float pa;           // n_v p_a of the record (0: not a MIS VPL)
    float radiance[3];  // B / pi
    float albedo[3];    // the record's albedo (a texture's mean over its surface)
    float unused[2];
};
static_assert(sizeof(PackedRecord) == 64, "one record, one 64-byte row");

// Voxel records for looking up the radiance where a gather ray lands, in the
// order of their voxel keys: a voxel's records are neighbours.
struct RecordGrid {
    int64_t count = 0;
    const int64_t* sorted_key = nullptr;  // (N,) linear voxel keys, ascending
    const int32_t* cell_start = nullptr;  // (dims product + 1,) first sorted index of each key,
                                          // or null: binary search in sorted_key
    const PackedRecord* rec = nullptr;    // (N,) in the order of sorted_key
    int64_t dims[3] = {0, 0, 0};          // key = (i * dims[1] + j) * dims[2] + k
    int64_t lo[3] = {0, 0, 0};            // ijk of key 0
    double origin[3] = {0.0, 0.0, 0.0};
    double pitch = 1.0;
    // (N, 3) in the order of sorted_key, or null: the share of each record's
    // light that its diffuse base reflects (docs/design.md §14)
    const float* share = nullptr;
    // (N,) in the order of sorted_key, or null: 1 for a record of a stack of
    // sheets finer than a voxel, whose light a gather ray does not read as
    // the record's mean but from bounces on from the point it lands on
    // (follow_sheet in vpl_shade.cpp); 2 for one that also emits, where a
    // ray bounced on from another sheet stops
    const uint8_t* stacked = nullptr;
    // Or null: the records of each triangle's pieces (VoxelSet.piece_record).
    // Triangle t < piece_tris has entries [piece_first[t], piece_first[t + 1]),
    // each in voxel piece_key[e] with its records at piece_record[2e] (the
    // side t's winding faces) and piece_record[2e + 1], in sorted_key's order,
    // for the points of the piece on the sides piece_side[e] of its planes
    // [piece_plane_first[e], piece_plane_first[e + 1]) (n, off: 4 doubles each,
    // in voxel units from origin; bit k of piece_side: n·x >= off for the k-th).
    int64_t piece_tris = 0;
    const int64_t* piece_first = nullptr;
    const int64_t* piece_key = nullptr;
    const int32_t* piece_record = nullptr;
    const uint32_t* piece_side = nullptr;
    const int64_t* piece_plane_first = nullptr;
    const double* piece_plane = nullptr;
    // The pieces are read only to find the stacked sheets a ray lands on and
    // to walk them; every other lookup searches (the display's gather rays:
    // docs/design.md §6). Then stacked_objects (stacked_object_count,) is 1
    // for the objects that have stacked records: a ray that lands on any
    // other object needs no second lookup.
    bool pieces_for_sheets = false;
    int64_t stacked_object_count = 0;
    const uint8_t* stacked_objects = nullptr;
};

// The voxel of the grid that holds y.
inline void cell_of(const RecordGrid& g, const double y[3], int64_t c[3]) {
    for (int a = 0; a < 3; ++a) c[a] = int64_t(std::floor((y[a] - g.origin[a]) / g.pitch));
}

// Key of voxel (i, j, k) on the records' bounding grid, or -1 outside it.
inline int64_t grid_key(const RecordGrid& g, int64_t i, int64_t j, int64_t k) {
    i -= g.lo[0], j -= g.lo[1], k -= g.lo[2];
    if (i < 0 || j < 0 || k < 0 || i >= g.dims[0] || j >= g.dims[1] || k >= g.dims[2]) return -1;
    return (i * g.dims[1] + j) * g.dims[2] + k;
}

// How near the hit point y a neighbour of its voxel c must lie for the
// lookup to search it, in voxel edges: the record of y's own surface there
// stands for y only if its part of the surface comes that close. Searching
// only those voxels (about 6 of the 26 for a point inside a voxel) takes
// 7-14% off the display's gather time in Bitterli's crowded interiors and
// changes what 0.1-0.4% of the lookups read, with the same pictures
// (docs/performance.md §7, "The record a ray lands on").
constexpr double kNeighbourReach = 0.5;

// Whether voxel c + (di, dj, dk) lies within kNeighbourReach voxel edges of y.
inline bool neighbour_within_reach(const RecordGrid& g, const double y[3], const int64_t c[3],
                                   int di, int dj, int dk) {
    const int d[3] = {di, dj, dk};
    double gap2 = 0.0;
    for (int a = 0; a < 3; ++a) {
        const double lo = g.origin[a] + double(c[a] + d[a]) * g.pitch;
        const double gap = std::fmax(lo - y[a], y[a] - (lo + g.pitch));
        if (gap > 0.0) gap2 += gap * gap;
    }
    return gap2 <= kNeighbourReach * kNeighbourReach * g.pitch * g.pitch;
}

// Working memory of lookups, reused from one to the next (one per thread).
struct LookupScratch {
    struct Plane {   // a record of the hit's voxel, as seen from the hit point
        double sy;   // the hit's signed distance to the record's plane
        double tol;  // within rounding of that plane
        bool holds;  // the plane holds the hit, facing its side: the hit's own sheet
        int8_t cut;  // for a plane that holds the hit: 1 when its record lies across
                     // another surface from the hit, 0 when not, -1 not yet known
    };
    struct Candidate {  // a record facing the hit's side
        double score;   // squared distance to its centroid plus the penalty, pitch² units
        double penalty;
        int64_t index;  // in the grid's order
        int32_t order;  // in the order the voxels and their records are visited
        int32_t cell;   // which of the voxels visited holds it
    };
    std::vector<Plane> own;          // of each record of the hit's voxel
    std::vector<int32_t> own_order;  // those records in the order they are asked
    // the last few of them that set a candidate apart, the latest first (-1: none)
    static constexpr int kRecent = 4;
    int32_t recent[kRecent] = {-1, -1, -1, -1};
    std::vector<Candidate> candidates;
    std::vector<int64_t> cell_first, cell_end;  // the voxels visited
};

// Position in the grid's order of the record that stands for the surface
// point y, in voxel c, on object `obj` seen from the side of unit normal n,
// or -1. Where y lies on triangle `tri` (-1: unknown), on the side its
// winding faces when `front`, and the grid lists that triangle's piece in
// c, the record on that side of the piece's part that holds y. Otherwise a
// search: only records
// whose normal faces n's side qualify, and of those the ones no other
// surface of y's voxel (or of their own) separates from y; among them the
// nearest centroid, strongly preferring the same object and orientation.
// The neighbouring voxels within reach of y (neighbour_within_reach) are
// searched only when c has no such record of this surface. The answer does
// not depend on `scratch`.
int64_t lookup_in_cell(const RecordGrid& g, const double y[3], const float n[3], int32_t obj,
                       const int64_t c[3], int32_t tri, bool front, LookupScratch& scratch);

}  // namespace voxgi
