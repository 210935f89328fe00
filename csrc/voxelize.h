// Exact sparse supercover voxelization of triangle meshes (docs/design.md §2, §4).
//
// Every voxel whose closed cube meets a triangle (within `eps` voxel units, so
// that shared edges and vertices never open a gap) receives records. A record
// gathers the pieces of one object with one orientation (normals within 60°
// of the cluster's first piece) on one side of the other surfaces' planes in
// that voxel; its area is the exact area of the triangles clipped to the cube
// (Sutherland–Hodgman against six planes), so areas sum to the mesh area.
// Every front record is followed by its reverse side: a black back record for
// a one-sided object, a live copy for a two-sided one.
//
// No pybind11 here: plain pointers and sizes (see bind_voxelize.cpp).
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include "texture.h"
#include "util/parallel.h"

namespace voxgi {

// One output record (array-of-structs; the binding scatters it into numpy arrays).
struct VoxelRecord {
    int32_t ijk[3];
    int32_t object;
    float normal[3];  // unit
    float area;       // scene units²
    float albedo[3];
    float emission[3];
    double centroid[3];  // world position of a point on the surface inside the voxel
    uint8_t back;        // 1: black back record of a one-sided surface
    uint8_t side;        // 0: the winding's side, 1: the reverse side (back or two-sided)
};

// Where a triangle's surface in one voxel went: the records on its two
// sides. A piece whose whole area (with area) went to one record pair is
// one entry without planes; a piece that other surfaces' cutting planes
// split is one entry per record pair its parts went to, each with the
// planes that split the piece and its part's side of each. A ray that
// lands on the triangle in that voxel reads these records without a
// search (record_lookup.h).
struct SurfacePiece {
    int32_t tri;       // the triangle, as given to voxelize
    int32_t front;     // the record on the side its winding faces (index into its chunk's records)
    int32_t back;      // the record on the other side
    uint32_t side;     // bit k: the part lies on the positive side of plane k (n·x >= off)
    int32_t n_planes;  // its planes: the next n_planes of the chunk's `planes`
};

// One chunk of the output: records, and the surface pieces that point into
// them with their planes (n[3], off in voxel units, 4 doubles each, in the
// pieces' order).
struct VoxelChunk {
    std::vector<VoxelRecord> records;
    std::vector<SurfacePiece> pieces;
    std::vector<double> planes;
};

struct VoxelizeParams {
    double origin[3] = {0, 0, 0};  // world position of voxel (0,0,0)'s minimum corner
    double pitch = 1.0;            // voxel edge, scene units
    int32_t dims[3] = {1, 1, 1};   // grid size; every triangle must lie in [0, dims]
    double cos_cluster = 0.5;      // pieces whose normals differ by more than acos(this) split
    bool cut = true;               // cut pieces by the planes of other surfaces in their voxel
    double eps = 1e-9;             // touching tolerance, voxel units
    double cut_delta = 1e-6;       // a plane cuts a piece only if it has vertices
                                   //   farther than this (voxel units) on both sides
    // nullable: a record of a textured object takes its texture's mean over
    // the record's own surface (its clipped pieces) as its albedo, times
    // nothing else; the object's albedo otherwise
    const SurfaceTextures* textures = nullptr;
};

struct VoxelizeStats {
    int64_t triangles = 0;           // triangles given
    int64_t skipped_degenerate = 0;  // triangles without a usable normal (area underflows)
    int64_t pairs = 0;               // (voxel, triangle) incidences
    int64_t cells = 0;               // distinct voxels with records
    int64_t records = 0;             // all records (front and reverse sides)
    int64_t back_records = 0;        // black back records (one-sided objects)
    int64_t two_sided_records = 0;   // reverse-side records of two-sided objects
    int64_t touch_records = 0;       // front records of zero area (surfaces touching the cube)
    int64_t clusters = 0;            // (voxel, object, orientation) clusters
    int64_t cut_clusters = 0;        // clusters split by another surface's plane
    int64_t cut_records = 0;         // front records made by those splits (beyond one each)
    int64_t cut_limit_hits = 0;      // cutting planes ignored (more than kMaxCuts in a voxel)
    int64_t cut_small_planes = 0;    // planes of small clusters (they cut only large ones)
    int64_t layer_records = 0;       // front records made by stacked sheets (beyond one each)
    int64_t polygon_overflows = 0;   // clipped polygons that hit the vertex limit (should be 0)
    int64_t peak_bytes = 0;          // peak of the kernel's own large buffers
    double seconds_pairs = 0, seconds_sort = 0, seconds_records = 0;
};

// Progress counters, written by the kernel and read by whoever polls (the
// binding's StopCheck). phase 1: triangles, 2: sorting, 3: voxels.
struct VoxelizeProgress {
    std::atomic<int> phase{0};
    std::atomic<int64_t> done{0};
    std::atomic<int64_t> total{0};
};

constexpr int kMaxCuts = 20;
// A cluster's plane cuts the other surfaces of its voxel only where the
// cluster covers at least this share of the voxel's section by that plane
// (docs/design.md §2, junction cutting).
constexpr double kSeparatingShare = 0.25;
// A small cluster's plane cuts a large cluster only where one of its pieces
// comes this close to the large cluster's plane (voxel units).
constexpr double kTouch = 0.05;
// Pieces of one cluster whose distances along its normal lie further apart
// than this (voxel units) are separate layers, each its own record
// (docs/design.md §2, stacked sheets). Nearer sheets stay one record: split,
// they cost records and the lines' convergence and improved no picture.
constexpr double kLayerGap = 0.1;

// Voxelize `n_tris` triangles.
//   tris        (n_tris, 3, 3) world corner positions, C order
//   tri_object  (n_tris,) object index in [0, n_objects)
//   two_sided   (n_objects,) 0/1
//   albedo, emission (n_objects, 3)
// Returns the records in chunks, in output order (voxels in (i, j, k)
// lexicographic order; inside a voxel by object, orientation cluster, layer,
// side of the cutting planes, then front before reverse), each chunk with
// its surface pieces. The order does not depend on `threads`. Throws std::invalid_argument on bad
// input, Interrupted when `stop` says so.
std::vector<VoxelChunk> voxelize(const double* tris, int64_t n_tris, const int32_t* tri_object,
                                 int32_t n_objects, const bool* two_sided, const float* albedo,
                                 const float* emission, const VoxelizeParams& params, int threads,
                                 const StopCheck& stop, VoxelizeStats& stats,
                                 VoxelizeProgress* progress = nullptr);

}  // namespace voxgi
